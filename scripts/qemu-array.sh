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
#   - two cables crossed in the harness: refused at boot, naming both boards of each end;
#   - a recorded live session replayed on the built-in coarse scene (1x1x2, 400 steps, the
#     host's step gate holding the boards to the poses): every step's tool force and the
#     final state bit-identical to `board-sim run --replay`.
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

# A recorded live session replayed (issue 60): the built-in coarse scene on 1x1x2 (both
# boards hold the probe and exchange contact nodes over the global network), a pose
# every step for REPLAY_STEPS steps (the probe pressed onto the right tube along the
# scene's push at 5 cm/s, half the contact speed bound, while it turns 2 mrad about its
# trocar), in the record format `pe live --record` writes. The host holds the emulated
# boards to the poses with its step gate (link_proto::gate); the tool force of every step
# and the final state must be bit-identical to `board-sim run --replay`'s, and the force
# far from zero (the probe presses) and the tube moved.
REPLAY_STEPS=${REPLAY_STEPS:-400}
REPLAY_MACHINE=${REPLAY_MACHINE:-1x1x2}
D=$OUT/replay
"$PE" compile --builtin --level coarse --boards "$REPLAY_MACHINE" --profile qemu-mps2-an500 \
    --steps "$REPLAY_STEPS" -o "$D/compiled" >/dev/null
python3 - "$D/compiled" "$REPLAY_STEPS" "$D/session.jsonl" <<'PY'
import json, math, sys
d, steps, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
m = json.load(open(f"{d}/manifest.json"))
tool = json.load(open(f"{d}/mesh.json"))["tools"][0]
end = tool["path"][-1][1]
n = math.sqrt(sum(v * v for v in end))
push, c, dt = [v / n for v in end], tool["trocar_m"], m["dt_s"]
with open(out, "w") as f:
    head = {"record": "pe-live", "version": 1, "scene": m["scene"], "dt_s": dt, "tools": [tool["name"]]}
    print(json.dumps(head), file=f)
    for k in range(steps):
        th = 0.002 * k / steps  # about y: R c = (cos th cx + sin th cz, cy, -sin th cx + cos th cz)
        rc = [math.cos(th) * c[0] + math.sin(th) * c[2], c[1], -math.sin(th) * c[0] + math.cos(th) * c[2]]
        p = [c[i] - rc[i] + push[i] * 0.05 * k * dt for i in range(3)]
        q = [math.cos(th / 2), 0.0, math.sin(th / 2), 0.0]
        print(json.dumps({"step": k, "tool": tool["name"], "orientation": q, "position_m": p}), file=f)
PY
"$SIM" run "$D/compiled" --quiet --replay "$D/session.jsonl" --output-nodes "$D/board-sim.csv" \
    --tool-force "$D/board-sim-force.csv" >/dev/null 2>&1
timeout 900 "$SIM" qemu "$D/compiled" --firmware "$ELF_F64" --quiet --replay "$D/session.jsonl" \
    --output-nodes "$D/qemu.csv" --tool-force "$D/qemu-force.csv" --report "$D/qemu.json"
"$PE" compare "$D/board-sim.csv" "$D/qemu.csv" --min-displacement 1e-4
python3 - "$D/board-sim-force.csv" "$D/qemu-force.csv" "$REPLAY_STEPS" <<'PY'
import csv, sys
a, b = (list(csv.DictReader(open(p))) for p in sys.argv[1:3])
steps = int(sys.argv[3])
assert len(a) == steps and len(b) == steps, f"rows: board-sim {len(a)}, qemu {len(b)}, steps {steps}"
f = lambda r: [float(r[k]) for k in ("fx_n", "fy_n", "fz_n")]
touched = sum(1 for r in a if any(f(r)))
peak = max(sum(v * v for v in f(r)) ** 0.5 for r in a)
# Far from trivial: the probe presses for many steps (measured: 105 of 400 on one board).
assert touched > 50 and peak > 1e-3, f"{touched} steps in contact, peak {peak} N"
diff = [r["step"] for r, s in zip(a, b) if r != s]
assert not diff, f"tool force differs at {len(diff)} steps, first {diff[0]}"
print(f"qemu-array: replay: {steps} steps, tool force bit for bit at every step ({touched} in contact, peak {peak:.4e} N)")
PY

echo "qemu-array: wall time per step (this machine):"
cat "$TIMING"
echo "qemu-array: passed (2x1x1, 2x2x1, 2x2x2 f64 and 2x2x2 f32 bit-identical to board-sim and within tolerance of pe solve; a dead board and crossed cables reported; a recorded session replayed bit for bit)"
