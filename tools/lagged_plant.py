#!/usr/bin/env python3
"""A plant of another make behind the plant protocol v1 (docs/control.md, A plant in the loop):
the pump of examples/plant.py (speed from J dn/dt = torque - load, pressure as n^2, flow as n)
with a drive whose torque follows the reference through a first-order lag TD (s), a torque
reading at GAIN x the torque with +-NOISE % of noise, a pressure transmitter lagging TP (s),
a rotor JX x the example's, and a speed reading through a first-order lag SF (s: a drive's
filtered speed estimate) with SN rpm (1 sigma) of noise. Mode 3: pressure steps 2 -> 4 -> 1 -> 3 mca every 6 s; prints
each step's overshoot (% of the step) and 2 % settling time on the true pressure.
  TD=0.06 GAIN=0.85 NOISE=1 TP=0.12 JX=1.3 \
    python3 tools/lagged_plant.py target/release/pumpbench control --plant-stdio
Environment (defaults): TD 0.06, GAIN 1, NOISE 0.5, TP 0.1, JX 1, SF 0, SN 0. Standard library
only."""
import subprocess, sys, random, os
TD = float(os.environ.get('TD', '0.06')); GAIN = float(os.environ.get('GAIN', '1.0'))
NOISE = float(os.environ.get('NOISE', '0.5')); TP = float(os.environ.get('TP', '0.1')); J = float(os.environ.get('JX', '1'))
SF = float(os.environ.get('SF', '0')); SN = float(os.environ.get('SN', '0'))
def code(value, span):
    ma = min(max(4 + 16 * value / span, 3.8), 20.5)
    return round(ma * 0.150 / 3.3 * 4095)
child = subprocess.Popen(sys.argv[1:], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
out, inp = child.stdin, child.stdout
def ask(line):
    out.write((line + '\n').encode()); out.flush()
    return inp.readline().decode().split()
assert ask('H 1')[0] == 'H'
rng = random.Random(1)
n = 1330.0; te = 0.0; ref = 0.0; pm = 2.0; ns = n
# settle at 2 mca in mode 3
assert ask('W 8 2000') == ['K'] and ask('W 1 3') == ['K']
steps = [(0, 2.0), (6, 4.0), (12, 1.0), (18, 3.0)]
hist = []
t = 0.0
for k in range(int(24 / 0.005)):
    t = k * 0.005
    for ts, sp in steps:
        if abs(t - ts) < 1e-9 and ts > 0:
            assert ask(f'W 8 {int(sp*1000)}') == ['K']
    p = 1.82e-6 * n * n * 0.9
    q = 0.0125 * n
    reading = GAIN * te + rng.uniform(-NOISE, NOISE)
    ns += (n - ns) * (min(1.0, 0.005 / SF) if SF > 0 else 1.0)
    speed = ns + (rng.gauss(0, SN) if SN > 0 else 0.0)
    r = ask(f'S {code(pm, 10)} {code(q, 30)} {speed:.1f} {reading:.2f}')
    ref = float(r[2])
    for _ in range(5):
        te += (ref - te) * (0.001 / TD if TD > 0 else 1.0)
        n += 0.001 * 29.0 / J * (te - 100.0 * (n / 1760.0) ** 2 * 0.9)
        p = 1.82e-6 * n * n * 0.9
        pm += (p - pm) * (0.001 / TP)
    hist.append((t, p))
ask('Q')
for i in range(1, 4):
    t0, sp = steps[i]; prev = steps[i-1][1]
    seg = [pp for (tt, pp) in hist if t0 <= tt < t0 + 6]
    if sp > prev:
        ov = (max(seg) - sp) / (sp - prev) * 100
    else:
        ov = (sp - min(seg)) / (prev - sp) * 100
    last_out = max([tt for (tt, pp) in hist if t0 <= tt < t0 + 6 and abs(pp - sp) > 0.02 * sp] + [t0]) - t0
    print(f'{prev}->{sp}: overshoot {ov:.2f} %, settle {last_out:.2f} s, end {seg[-1]:.3f}')
