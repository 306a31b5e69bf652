#!/usr/bin/env bash
# The board firmware on emulated board arrays: one QEMU mps2-an500 (Cortex-M7) per board,
# their CMSDK UARTs wired as the machine's cables by `board-sim qemu`, which also plays the
# global network, the host and the graphics engine.
#
# On the seed's box at 10x5x5 cells, sagging under gravity (its displacements far from
# zero, which every comparison asserts first):
#   - 2x1x1, 2x2x1 and 2x2x2 in f64, 2x2x2 in f32: the final state must be bit-identical
#     to board-sim's on the same images, and within 1e-12 (f64) of `pe solve`'s, relative
#     to the largest displacement (f32: within 1e-6 of `pe solve --precision f32`: the
#     boards sum a shared node's partial forces in another order than the serial loop);
#   - a board killed mid-run: its neighbour must report the dead link (board, face, step)
#     over the global port within the link timeout, the harness must say so, and the run
#     must end (non-zero) instead of hanging;
#   - two cables crossed in the harness: refused at boot, naming both boards of each end.
# Writes OUT/timing.md: the emulated array's wall time per step beside board-sim's.
#
# Installs what it needs (qemu-system-arm with apt, the thumbv7em target).
# Env: STEPS (default 80), OUT (default $CARGO_TARGET_DIR/qemu-array or target/qemu-array).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}
STEPS=${STEPS:-80}
OUT=${OUT:-$TARGET_DIR/qemu-array}
rm -rf "$OUT" && mkdir -p "$OUT"
source scripts/qemu-lib.sh
ELF_F64=$(build_firmware qemu,contact,graphics,loads)
ELF_F32=$(build_firmware qemu,f32,contact,graphics,loads)

sed 's/cells = \[20, 10, 10\]/cells = [10, 5, 5]/' scenes/seed-box.toml >"$OUT/box.toml"
grep -q 'cells = \[10, 5, 5\]' "$OUT/box.toml"

# Reads a JSON number: FILE KEY.
json() { python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))[sys.argv[2]])' "$1" "$2"; }

TIMING=$OUT/timing.md
{
    echo "| machine | precision | steps | QEMU array wall (s) | per step (ms) | board-sim wall (s) | per step (ms) | ratio |"
    echo "|---|---|---|---|---|---|---|---|"
} >"$TIMING"

for CASE in 2x1x1:f64 2x2x1:f64 2x2x2:f64 2x2x2:f32; do
    M=${CASE%%:*}
    PREC=${CASE##*:}
    D=$OUT/$M-$PREC
    ELF=$ELF_F64
    TOL=1e-12
    if [ "$PREC" = f32 ]; then ELF=$ELF_F32; TOL=1e-6; fi
    echo "qemu-array: $M, $PREC reduced, $STEPS steps"
    "$PE" compile "$OUT/box.toml" --boards "$M" --profile qemu-mps2-an500 --precision "$PREC" \
        --steps "$STEPS" -o "$D/compiled" >/dev/null
    "$PE" solve "$OUT/box.toml" --steps "$STEPS" --precision "$PREC" --quiet \
        --output-nodes "$D/solve.csv" >/dev/null 2>&1
    "$SIM" run "$D/compiled" --quiet --output-nodes "$D/board-sim.csv" \
        --report "$D/board-sim.json" >/dev/null 2>&1
    "$SIM" qemu "$D/compiled" --firmware "$ELF" --quiet --output-nodes "$D/qemu.csv" \
        --report "$D/qemu.json"
    # Bit for bit against board-sim, and against the serial solver within TOL of the
    # largest displacement; both refuse fields under 0.1 mm (nothing moved).
    "$PE" compare "$D/board-sim.csv" "$D/qemu.csv" --min-displacement 1e-4
    "$PE" compare "$D/solve.csv" "$D/qemu.csv" --tolerance "$TOL" --min-displacement 1e-4
    QW=$(json "$D/qemu.json" wall_s)
    SW=$(json "$D/board-sim.json" wall_s)
    python3 - "$M" "$PREC" "$STEPS" "$QW" "$SW" >>"$TIMING" <<'PY'
import sys
m, p, steps, q, s = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5])
print(f"| {m} | {p} | {steps} | {q:.2f} | {1e3*q/steps:.1f} | {s:.3f} | {1e3*s/steps:.3f} | {q/s:.0f} |")
PY
done

# A board dies mid-run. Long enough a run that it is mid-run at the kill.
D=$OUT/kill
"$PE" compile "$OUT/box.toml" --boards 2x2x1 --profile qemu-mps2-an500 --steps 2000 \
    -o "$D/compiled" >/dev/null
set +e
START=$(date +%s)
timeout 120 "$SIM" qemu "$D/compiled" --firmware "$ELF_F64" --quiet --kill 1,0,0@3 \
    --report "$D/qemu.json" >"$D/out.txt" 2>&1
RC=$?
set -e
ELAPSED=$(( $(date +%s) - START ))
if [ $RC -eq 0 ] || [ $RC -eq 124 ]; then
    echo "qemu-array: FAILED: a killed board must end the run with a failure (exit $RC):" >&2
    cat "$D/out.txt" >&2
    exit 1
fi
# Board (1,0,0)'s neighbours across the links it exchanges over: (0,0,0) by +x and (1,1,0)
# by +y. One of them must name its link to the dead board, at a step past 0 (mid-run).
grep -q "board (1,0,0): killed by the harness" "$D/out.txt" || {
    echo "qemu-array: FAILED: the harness did not name the killed board:" >&2; cat "$D/out.txt" >&2; exit 1; }
DEAD_LINK="step [1-9][0-9]*: link (PosX|NegY): no frame within the timeout .*across that link: board \(1,0,0\), dead"
if ! grep -E -q "board \((0,0,0|1,1,0)\) $DEAD_LINK" "$D/out.txt"; then
    echo "qemu-array: FAILED: no neighbour reported its dead link to board (1,0,0) mid-run:" >&2
    cat "$D/out.txt" >&2
    exit 1
fi
echo "qemu-array: dead board reported in ${ELAPSED} s: $(grep -E -o "board \([0-9,]+\) step [0-9]+: link [A-Za-z]+: no frame within the timeout.*dead" "$D/out.txt" | head -n 1 | cut -c1-90)..."

# Two cables crossed: (0,0,0)'s +x and +y connectors swapped at their far ends.
D=$OUT/cross
"$PE" compile "$OUT/box.toml" --boards 2x2x1 --profile qemu-mps2-an500 --steps "$STEPS" \
    -o "$D/compiled" >/dev/null
set +e
timeout 120 "$SIM" qemu "$D/compiled" --firmware "$ELF_F64" --quiet \
    --cross 0,0,0:+x,0,0,0:+y >"$D/out.txt" 2>&1
RC=$?
set -e
if [ $RC -eq 0 ] || [ $RC -eq 124 ]; then
    echo "qemu-array: FAILED: crossed cables must be refused (exit $RC):" >&2
    cat "$D/out.txt" >&2
    exit 1
fi
# Each board at a crossed connector names the board its cable really reaches; (0,0,0) holds
# both crossed connectors and stops at whichever Hello it reads first.
for WANT in "board (0,1,0) step 0: link NegY: the cable goes to board (0,0,0)'s PosX" \
            "board (1,0,0) step 0: link NegX: the cable goes to board (0,0,0)'s PosY"; do
    grep -q -F "$WANT" "$D/out.txt" || {
        echo "qemu-array: FAILED: crossed cables: expected '$WANT':" >&2; cat "$D/out.txt" >&2; exit 1; }
done
grep -E -q "board \(0,0,0\) step 0: link (PosX: the cable goes to board \(0,1,0\)'s NegY|PosY: the cable goes to board \(1,0,0\)'s NegX)" "$D/out.txt" || {
    echo "qemu-array: FAILED: crossed cables: board (0,0,0) did not name a crossed cable:" >&2; cat "$D/out.txt" >&2; exit 1; }
echo "qemu-array: crossed cables refused at boot: $(grep -o -F "board (0,1,0) step 0: link NegY: the cable goes to board (0,0,0)'s PosX connector" "$D/out.txt" | head -n 1)"

echo "qemu-array: wall time per step (this machine):"
cat "$TIMING"
echo "qemu-array: passed (2x1x1, 2x2x1, 2x2x2 f64 and 2x2x2 f32 bit-identical to board-sim and within tolerance of pe solve; a dead board and crossed cables reported)"
