#!/usr/bin/env bash
# Remakes the default NARMAX models from synthetic bench data (the paper's sizes, 40 LM epochs)
# and exports them to the firmware. Run from the workspace root: bash models/make.sh
set -euo pipefail
pb() { cargo run --quiet --release -p pumpbench -- "$@"; }
d=target/models-data
mkdir -p "$d"
# Pressure: 600 s at 50 ms (12 001 samples), na = nb = 6, 7 hidden units.
pb excite --seed 1 --seconds 600 --ts-ms 50 --output "$d/u_p.csv"
pb bench-data --input "$d/u_p.csv" --seed 11 --output "$d/train_pressure.csv"
pb identify --data "$d/train_pressure.csv" --target pressure --na 6 --nb 6 --hidden 7 --epochs 40 --seed 1 --output models/pressure.json
# Flow: 1200 s at 100 ms (12 001 samples), na = nb = 7, 6 hidden units.
pb excite --seed 3 --seconds 1200 --ts-ms 100 --output "$d/u_f.csv"
pb bench-data --input "$d/u_f.csv" --seed 13 --output "$d/train_flow.csv"
pb identify --data "$d/train_flow.csv" --target flow --na 7 --nb 7 --hidden 6 --epochs 40 --seed 1 --output models/flow.json
# The firmware compiles these in.
pb export --weights models/pressure.json --output models/src/pressure.rs
pb export --weights models/flow.json --output models/src/flow.rs
rustfmt --edition 2021 models/src/pressure.rs models/src/flow.rs
# The training data stays in target/models-data (not committed; remade by this script).
