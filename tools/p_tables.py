#!/usr/bin/env python3
"""Prints docs/control.md's P tables: on each documented plant (P0..P5, P5c, P1c), every
event of the five built-in scenarios and of the pressure-meter-lost scenario file, the
model law / the PI alone, rounded to 0.01 as the tables print them.

Usage:
  python3 tools/p_tables.py [--bin target/release/pumpbench] > tables.md

Needs only Python 3's standard library. Exit code 1 if a run fails.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile

COMMISSIONED = "--set 15=250 --set 17=500 --set 16=400 --set 18=600"
# (name, plant options, heading after the name; None: the options in backquotes)
PLANTS = [
    ("P0", "", "bench-data's default (paper curves, 20 / 40 ms transmitters; "
     "150 ms flow transmitter in flow-steps)"),
    ("P2", "--curve-error -5,5 --pressure-lag-ms 40", None),
    ("P3", "--curve-error -5 --water-inertia 0.1 --drive-lag-ms 20 --seed 7", None),
    ("P4", "--curve-error 5 --drive-lag-ms 50 --pressure-lag-ms 60 --seed 3", None),
    ("P5", "--curve-error -5,5 --water-inertia 0.2 --drive-lag-ms 30 --pressure-lag-ms 100 "
     "--seed 11", None),
    ("P5c", "P5", f"P5 commissioned: `{COMMISSIONED}`"),
    ("P1", "--curve-error 5 --water-inertia 0.5 --drive-lag-ms 20", None),
    ("P1c", "P1", f"P1 commissioned: `{COMMISSIONED}`"),
]
SCENARIOS = ["pressure-steps", "valve-steps", "flow-steps", "flow-meter-lost", "link-cut"]
# The pressure transmitter lost at 3 mca, then the valve x1.3 and x1, then restored.
PML = "t_s,mode,setpoint,valve,pressure_meter\n0,3,3,1,1\n2,3,3,1,0\n5,3,3,1.3,0\n10,3,3,1,0\n15,3,3,1,1\n"
# Figure lines of `pumpbench control` and the table's columns, in order.
COLS = ["rise 10-90 % (s)", "overshoot (%)", "settle 2 % (s)", "IAE (",
        "peak deviation (%)", "back within 2 % (s)", "steady error (%)"]


def events(bin_, scenario, opts, extra=()):
    """Each event of one run (the start left out): its name and {column: (model, pi)}."""
    run = subprocess.run([bin_, "control", "--scenario", scenario, *extra, *opts],
                         capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"p_tables: {scenario} {' '.join(opts)}: {run.stderr.strip()}")
    out, ev = [], None
    for line in run.stdout.splitlines():
        m = re.match(r"t = [-0-9.]+ s, mode \d+: (.*)$", line)
        if m:
            ev = None if m.group(1).startswith("start") else (m.group(1), {})
            if ev:
                out.append(ev)
        elif ev:
            f = line.strip()
            for c in COLS:
                if f.startswith(c):
                    # The IAE's unit varies (mca·s, l/s·s): the values follow its ")".
                    rest = f.split(")", 1)[1] if c == "IAE (" else f[len(c):]
                    ev[1][c] = rest.split()[:2]
    return out


def cell(pair):
    if pair is None:
        return ""
    return " / ".join(v if v == "-" else f"{float(v):.2f}" for v in pair)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", default="target/release/pumpbench")
    a = ap.parse_args()
    opts_of = {}
    with tempfile.TemporaryDirectory() as d:
        pml = os.path.join(d, "pml.csv")
        with open(pml, "w") as f:
            f.write(PML)
        for name, opts, heading in PLANTS:
            if opts in opts_of:  # commissioned: the plant's options and the registers
                opts = f"{opts_of[opts]} {COMMISSIONED}"
            opts_of[name] = opts
            print(f"### {name}: {heading or f'`{opts}`'}\n")
            print("| scenario, event | rise s | overshoot % | settle s | IAE | peak % | back s | steady % |")
            print("|---|---|---|---|---|---|---|---|")
            runs = [(s, s, ()) for s in SCENARIOS] + [("pressure-meter-lost", pml, ("--hold-s", "5"))]
            for label, scenario, extra in runs:
                for ev, figs in events(a.bin, scenario, opts.split(), extra):
                    cells = " | ".join(cell(figs.get(c)) for c in COLS)
                    print(f"| {label}: {ev} | {cells} |")
            print()
            print(f"p_tables: {name} done", file=sys.stderr)


main()
