#!/usr/bin/env bash
# Fault campaign: compiles the seed's box (2000 hexahedra sagging under gravity: moving from
# the first step) for a 2x2x2 array and runs `board-sim campaign`: RUNS short runs, each
# with faults drawn from SEED (drop, corrupt at 1e-3 .. 0.3 per frame, 1 ms delay, a stall
# at a random board and step, alone and mixed; 1, 2 or 8 worker threads) or, one run in
# six, one board's image swapped for the same board's image from a second compilation
# (Young's modulus 4.5e3 instead of 3e3 Pa), each classified as bit-identical to the clean
# run or stopped naming the true first cause (an injected fault or the swapped board, the
# ground truth). Prints a summary; fails on any silent wrong answer or wrong
# cause. Rerun with the same SEED to replay every run.
#
# Env: RUNS (default 1000), SEED (1), STEPS (100), RECOVERY (on; "off" runs without link
# recovery: every fault must then stop the run), CLOCK (wall; "simulated": time that advances
# only while every board waits, so that no verdict depends on the host's load), OUT (default $CARGO_TARGET_DIR/fault-campaign
# or target/fault-campaign).
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${RUNS:-1000}
SEED=${SEED:-1}
STEPS=${STEPS:-100}
RECOVERY=${RECOVERY:-on}
CLOCK=${CLOCK:-wall}
TARGET_DIR=${CARGO_TARGET_DIR:-$(pwd)/target}
OUT=${OUT:-$TARGET_DIR/fault-campaign}
source scripts/host-bins.sh
"$PE" compile scenes/seed-box.toml --boards 2x2x2 -o "$OUT/images" >/dev/null
mkdir -p "$OUT"
sed 's/^youngs_modulus = .*/youngs_modulus = 4.5e3/' scenes/seed-box.toml > "$OUT/seed-box-stiffer.toml"
grep -q '^youngs_modulus = 4.5e3' "$OUT/seed-box-stiffer.toml" || { echo "fault-campaign.sh: no youngs_modulus line in scenes/seed-box.toml to change" >&2; exit 1; }
"$PE" compile "$OUT/seed-box-stiffer.toml" --boards 2x2x2 -o "$OUT/images-other" >/dev/null
FLAGS=()
if [ "$RECOVERY" = off ]; then
    FLAGS+=(--no-recovery)
fi
"$SIM" campaign "$OUT/images" --swap-from "$OUT/images-other" --runs "$RUNS" --seed "$SEED" --steps "$STEPS" --clock "$CLOCK" "${FLAGS[@]}"
