#!/usr/bin/env bash
# Fault campaign: compiles the seed's box (2000 hexahedra sagging under gravity: moving from
# the first step) for a 2x2x2 array and runs `board-sim campaign`: RUNS short runs, each
# with faults drawn from SEED (drop, corrupt at 1e-3 .. 0.3 per frame, 1 ms delay, a stall
# at a random board and step, alone and mixed; 1, 2 or 8 worker threads), each classified
# as bit-identical to the clean run or stopped naming the true first cause (an injected
# fault, the ground truth). Prints a summary; fails on any silent wrong answer or wrong
# cause. Rerun with the same SEED to replay every run.
#
# Env: RUNS (default 1000), SEED (1), STEPS (100), RECOVERY (on; "off" runs without link
# recovery: every fault must then stop the run), OUT (default $CARGO_TARGET_DIR/fault-campaign
# or target/fault-campaign).
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${RUNS:-1000}
SEED=${SEED:-1}
STEPS=${STEPS:-100}
RECOVERY=${RECOVERY:-on}
TARGET=${CARGO_TARGET_DIR:-target}
OUT=${OUT:-$TARGET/fault-campaign}
cargo build --release -p host-tools -p board-sim --bins
"$TARGET/release/pe" compile scenes/seed-box.toml --boards 2x2x2 -o "$OUT/images" >/dev/null
FLAGS=()
if [ "$RECOVERY" = off ]; then
    FLAGS+=(--no-recovery)
fi
"$TARGET/release/board-sim" campaign "$OUT/images" --runs "$RUNS" --seed "$SEED" --steps "$STEPS" "${FLAGS[@]}"
