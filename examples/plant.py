#!/usr/bin/env python3
"""A plant closing the controller's loop through the plant protocol v1 (controller::plant).
A pump whose speed follows the torque (J dn/dt = torque - load, the load growing as n^2),
pressure as n^2, flow as n, read by 4-20 mA transmitters (0..10 mca, 0..30 l/s) through
150 ohm into a 12-bit 3.3 V ADC. It sets mode 3 (pressure) at 3 mca, runs 10 s of 5 ms
frames and exits 1 unless the pressure ends within 5 % of 3 mca.
  python3 examples/plant.py -- cargo xtask plant-stdio   (the controller as its child)
  python3 examples/plant.py /dev/pts/N                   (cargo xtask qemu --plant pty)"""
import os, subprocess, sys, tty

def code(value, span):  # value -> loop current (NE 43 range) -> ADC code
    ma = min(max(4 + 16 * value / span, 3.8), 20.5)
    return round(ma * 0.150 / 3.3 * 4095)

if sys.argv[1] == '--':
    child = subprocess.Popen(sys.argv[2:], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    out, inp = child.stdin, child.stdout
else:
    fd = os.open(sys.argv[1], os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    out = inp = os.fdopen(fd, 'r+b', buffering=0)

def ask(line):
    out.write((line + '\n').encode()); out.flush()
    return inp.readline().decode().split()

assert ask('H 1') == ['H', '1', '5'], 'the controller does not speak protocol 1'
assert ask('W 8 3000') == ['K'] and ask('W 1 3') == ['K'], 'mode 3 at 3 mca refused'
n = torque = 0.0
for _ in range(2000):
    p, q = 1.82e-6 * n * n, 0.0125 * n
    torque = float(ask(f'S {code(p, 10)} {code(q, 30)} {n:.1f} {torque}')[2])
    for _ in range(5):  # 1 ms steps
        n += 0.001 * 29.0 * (torque - 100.0 * (n / 1760.0) ** 2)
try: ask('Q')  # 'B'; the QEMU board may close its line before it is read
except OSError: pass
print(f'pressure {p:.3f} mca after 10 s (setpoint 3 mca)')
sys.exit(0 if abs(p - 3.0) <= 0.15 else 1)
