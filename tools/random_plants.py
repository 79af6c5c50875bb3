#!/usr/bin/env python3
"""Random plants for `pumpbench control`: the model law and the PI alone on plants no table
in docs/control.md was tuned on, counted against the issue's targets.

Each plant draws, from one seeded generator (the same seed, the same plants):
  rotor inertia 0.5..2 x the paper's (log-uniform); drive lag 0 (one plant in four) or
  5..100 ms; pressure transmitter 10..150 ms; flow transmitter 20..200 ms (flow-steps only,
  the others keep pumpbench's 40 ms); curve error up to +-10 % and curve shape up to +-30 % on
  each curve (head, torque); a water column of 0.01..0.1 mca.s2/l on three plants in ten; a
  noise seed. Each plant runs the five built-in scenarios, both laws, with --targets.
  With --lift MCA each plant also has a static lift drawn in 0..MCA (from a generator of its
  own: the same plants otherwise), which --tell writes into holding register 20 (the
  models' static head) as commissioning would.
  --speed-lag-ms, --flow-update-ms, --transmitter-delay-ms and --drive-slew-pct-s give every
  plant the same drive speed lag, flow meter update period, transport delay ahead of the
  transmitters or drive torque ramp (the same plants otherwise); --set REG=VALUE writes a
  holding register before every run, as commissioning would.

Usage:
  python3 tools/random_plants.py --bin target/release/pumpbench --plants 200 --seed 3 \
      [--jobs 2] [--out runs.tsv] [--against older.tsv] [--speed-lag-ms 50] [--flow-update-ms 200] [--lift 2 [--tell]]
      [--transmitter-delay-ms 20] [--drive-slew-pct-s 100] [--set 12=1000 ...]

Prints the totals (figure targets met by each law, comparisons the model law won, trips,
NaN or torque-limit failures), the model law's misses per scenario and figure, and with
--against the runs that changed. Progress goes to stderr. Exit code 1 on a run that failed
(pumpbench's own error), or on a NaN or a torque outside its limits in any run.
Needs only Python 3's standard library.
"""

import argparse
import concurrent.futures as cf
import math
import random
import re
import subprocess
import sys

SCENARIOS = ["pressure-steps", "valve-steps", "flow-steps", "flow-meter-lost", "link-cut"]


def draw(rng):
    """One plant's options (without the scenario's)."""
    p = {
        "rotor-inertia": round(math.exp(rng.uniform(math.log(0.5), math.log(2.0))), 3),
        "drive-lag-ms": 0 if rng.random() < 0.25 else rng.randint(5, 100),
        "pressure-lag-ms": rng.randint(10, 150),
        "flow-lag-ms": rng.randint(20, 200),
        "curve-error": f"{rng.uniform(-10, 10):.1f},{rng.uniform(-10, 10):.1f}",
        "curve-shape": f"{rng.uniform(-30, 30):.1f},{rng.uniform(-30, 30):.1f}",
        "water-inertia": round(rng.uniform(0.01, 0.1), 3) if rng.random() < 0.3 else 0,
        "seed": rng.randint(1, 1_000_000),
    }
    return p


def args_for(plant, scenario):
    a = ["control", "--scenario", scenario, "--targets"]
    for k, v in plant.items():
        if k == "flow-lag-ms" and scenario != "flow-steps":
            continue
        for item in v if isinstance(v, list) else [v]:
            a += [f"--{k}", str(item)]
    return a


TARGETS = re.compile(r"^(model|pi): (\d+) of the (\d+) figure targets above met")
COMPARE = re.compile(r"^model against pi: (\d+) of the (\d+) comparisons above met")
TRIP = re.compile(r"^(model|pi): torque NaN steps (\d+), outside its limits (\d+).*tripped \(a protection's 0 %\) ([\d.]+) s")
EVENT = re.compile(r"^t = [\d.]+ s, mode \d: (.*?)( holding .*)?$")
FIGURE = re.compile(r"^  (\S.*?\S)\s{2,}.*(PASS|MISS) / (PASS|MISS)$")
RATIO = re.compile(r"^  IAE model / pi = [\d.]+ .*target: .* (PASS|MISS)$")
FASTER = re.compile(r"^  (model|pi) settles faster\s+target: .* (PASS|MISS)$")
SAFETY = re.compile(r"^(model|pi): target: .*")


def run(binary, idx, plant, scenario):
    out = subprocess.run([binary] + args_for(plant, scenario), capture_output=True, text=True)
    if out.returncode != 0:
        return idx, scenario, None, out.stderr.strip()
    r = {"targets": {}, "compare": (0, 0), "trip": {}, "bad": {}, "miss": [], "pimiss": []}
    event = ""
    for line in out.stdout.splitlines():
        if m := TARGETS.match(line):
            r["targets"][m[1]] = (int(m[2]), int(m[3]))
        elif m := COMPARE.match(line):
            r["compare"] = (int(m[1]), int(m[2]))
        elif m := TRIP.match(line):
            r["trip"][m[1]] = float(m[4])
            r["bad"][m[1]] = int(m[2]) + int(m[3])
        elif m := EVENT.match(line):
            event = re.sub(r"[\d.]+", "N", m[1])
        elif m := FIGURE.match(line):
            if m[2] == "MISS":
                r["miss"].append(f"{event}: {m[1]}")
            if m[3] == "MISS":
                r["pimiss"].append(f"{event}: {m[1]}")
        elif m := RATIO.match(line):
            if m[1] == "MISS":
                r["miss"].append(f"{event}: IAE no worse than pi")
        elif m := FASTER.match(line):
            if m[2] == "MISS":
                r["miss"].append(f"{event}: model settles faster")
        elif (m := SAFETY.match(line)) and "MISS" in line:
            r["bad"][m[1]] = r["bad"].get(m[1], 0) + 1
    return idx, scenario, r, None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", required=True, help="pumpbench binary")
    ap.add_argument("--plants", type=int, default=200)
    ap.add_argument("--seed", type=int, required=True, help="the plants' generator's seed")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", help="write one row per run (tab-separated) here")
    ap.add_argument("--against", help="an earlier --out file of the same plants: runs that changed")
    ap.add_argument("--transmitter-delay-ms", type=float, default=0.0,
                    help="every plant's pressure and flow transmitters read through this "
                         "transport delay ahead of their lags, ms (the same plants otherwise; "
                         "0: none)")
    ap.add_argument("--drive-slew-pct-s", type=float, default=0.0,
                    help="every plant's drive ramps the torque reference it acts on at this "
                         "rate, %%/s (the same plants otherwise; 0: none)")
    ap.add_argument("--set", action="append", default=[], metavar="REG=VALUE",
                    help="a holding register written before every run of every plant, both "
                         "laws (pumpbench control's --set; repeatable), as commissioning would")
    ap.add_argument("--speed-lag-ms", type=float, default=0.0,
                    help="every plant's drive reads its speed through this lag, ms (the same "
                         "plants otherwise; 0: none, the speed as it is)")
    ap.add_argument("--flow-update-ms", type=float, default=0.0,
                    help="every plant's flow meter updates its output every MS ms and holds it "
                         "between (the same plants otherwise; 0: every step)")
    ap.add_argument("--lift", type=float, default=0.0,
                    help="every plant has a static lift drawn in 0..LIFT mca (pumpbench's "
                         "--static-head; the same plants otherwise; 0: the paper's -0.252)")
    ap.add_argument("--tell", action="store_true",
                    help="with --lift, write each plant's lift into holding register 20")
    a = ap.parse_args()
    if not 0.0 <= a.lift <= 5.0:
        ap.error("--lift must be within 0..5 mca")
    if a.tell and a.lift == 0.0:
        ap.error("--tell needs --lift")

    rng = random.Random(a.seed)
    plants = [draw(rng) for _ in range(a.plants)]
    if a.speed_lag_ms > 0:
        for p in plants:
            p["speed-lag-ms"] = a.speed_lag_ms
    for p in plants:
        if a.set:
            p.setdefault("set", []).extend(a.set)
    if a.transmitter_delay_ms > 0:
        for p in plants:
            p["transmitter-delay-ms"] = a.transmitter_delay_ms
    if a.drive_slew_pct_s > 0:
        for p in plants:
            p["drive-slew-pct-s"] = a.drive_slew_pct_s
    if a.flow_update_ms > 0:
        for p in plants:
            p["flow-update-ms"] = a.flow_update_ms
    if a.lift > 0:
        lifts = random.Random(a.seed ^ 0x11F7)
        for p in plants:
            h = round(lifts.uniform(0.0, a.lift), 2)
            p["static-head"] = h
            if a.tell:
                p.setdefault("set", []).append(f"20={round(h * 1000)}")
    work = [(i, p, s) for i, p in enumerate(plants) for s in SCENARIOS]
    results = {}
    failed = []
    with cf.ThreadPoolExecutor(a.jobs) as ex:
        futs = [ex.submit(run, a.bin, i, p, s) for i, p, s in work]
        for n, f in enumerate(cf.as_completed(futs), 1):
            i, s, r, err = f.result()
            if r is None:
                failed.append(f"plant {i} {s}: {err}")
            else:
                results[(i, s)] = r
            if n % 50 == 0 or n == len(work):
                print(f"\r{n} / {len(work)} runs", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)

    tot = {"model": [0, 0], "pi": [0, 0]}
    cmp_ = [0, 0]
    trips = {"model": 0, "pi": 0}
    bad = {"model": 0, "pi": 0}
    misses = {}
    rows = []
    for (i, s), r in sorted(results.items()):
        for law in ("model", "pi"):
            met, of = r["targets"].get(law, (0, 0))
            tot[law][0] += met
            tot[law][1] += of
            trips[law] += r["trip"].get(law, 0.0) > 0
            bad[law] += r["bad"].get(law, 0)
        cmp_[0] += r["compare"][0]
        cmp_[1] += r["compare"][1]
        for k, law in ((0, "miss"), (1, "pimiss")):
            for m in r[law]:
                misses.setdefault((s, m), [0, 0])[k] += 1
        rows.append((i, s, r["targets"].get("model", (0, 0))[0], r["targets"].get("pi", (0, 0))[0],
                     r["compare"][0], r["trip"].get("model", 0.0), r["trip"].get("pi", 0.0),
                     " ".join(args_for(plants[i], s)[3:])))

    print(f"{a.plants} plants, generator seed {a.seed}, {len(results)} runs ({len(failed)} failed)")
    print(f"figure targets met: model {tot['model'][0]} of {tot['model'][1]}, "
          f"pi {tot['pi'][0]} of {tot['pi'][1]}")
    print(f"comparisons the model law won: {cmp_[0]} of {cmp_[1]}")
    print(f"runs with a trip: model {trips['model']}, pi {trips['pi']}; "
          f"NaN, torque outside its limits or a step: model {bad['model']}, pi {bad['pi']}")
    print("misses per scenario and figure, the model law's and the PI alone's (comparisons: the model law's):")
    for (s, m), (n, k) in sorted(misses.items()):
        print(f"  {n:5} {k if 'pi' not in m and 'faster' not in m else '':>5}  {s}: {m}")
    for f in failed:
        print(f"FAILED {f}")

    if a.out:
        with open(a.out, "w") as fh:
            for row in rows:
                fh.write("\t".join(str(x) for x in row) + "\n")
    if a.against:
        old = {}
        for line in open(a.against):
            c = line.rstrip("\n").split("\t")
            old[(int(c[0]), c[1])] = (int(c[2]), int(c[4]), c[7])
        better = worse = 0
        for i, s, mt, _, cm, _, _, cmd in rows:
            o = old.get((i, s))
            if o is None or o[2] != cmd:
                continue
            d = (mt - o[0]) + (cm - o[1])
            if d > 0:
                better += 1
            elif d < 0:
                worse += 1
                print(f"  worse: plant {i} {s}: targets {o[0]} -> {mt}, comparisons {o[1]} -> {cm}")
        print(f"against {a.against}: {better} runs better, {worse} worse (targets + comparisons)")
    return 1 if failed or bad["model"] or bad["pi"] else 0


if __name__ == "__main__":
    sys.exit(main())
