#!/usr/bin/env bash
# Cargo runner for the QEMU board: runs the ELF on netduinoplus2 with the firmware's arguments
# (`cargo run -- mode=1 setpoint=5000`), defmt frames from semihosting decoded by defmt-print.
set -euo pipefail
elf="$1"; shift
command -v defmt-print >/dev/null || { echo "qemu-run.sh: needs defmt-print (cargo install --locked defmt-print), or use 'cargo xtask qemu'" >&2; exit 2; }
args="pump-qemu"
for a in "$@"; do args="$args,arg=$a"; done
qemu-system-arm -cpu cortex-m4 -machine netduinoplus2 -display none -monitor none -serial null -serial null \
  -semihosting-config "enable=on,target=native,arg=$args" -kernel "$elf" | defmt-print -e "$elf"
exit "${PIPESTATUS[0]}"
