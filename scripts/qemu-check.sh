#!/usr/bin/env bash
# QEMU check: the board firmware runs the built-in coarse scene on one emulated Cortex-M7
# (QEMU mps2-an500) and its final state, reported via semihosting, must be bit-identical to
# `pe solve` and to board-sim for the same scene and precision (f64 and f32, reduced
# integration; full integration on two of them). Then the firmware must refuse a corrupted image, an image for another
# board and an unstable scene (the same numerical fault as the serial solver) -- each with
# a fault report and a failing exit, never a hang. Fails loudly on any mismatch. Machines of
# several boards (their links, a dead board, crossed cables) are scripts/qemu-array.sh's.
#
# Installs what it needs: qemu-system-arm (apt, only if missing) and the thumbv7em target.
# Env: STEPS (default 1000: the probe has pressed the tube, so the compared fields are far
# from zero, which the check asserts), CASES (SCENE:PRECISION:INTEGRATION ..., default all
# below), OUT (default $CARGO_TARGET_DIR/qemu-check or target/qemu-check).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}
STEPS=${STEPS:-1000}
OUT=${OUT:-$TARGET_DIR/qemu-check}
rm -rf "$OUT" && mkdir -p "$OUT"
source scripts/qemu-lib.sh
QEMU=(timeout 120 qemu-system-arm -cpu cortex-m7 -machine mps2-an500 -nographic
      -semihosting-config enable=on,target=native)
ORIGIN=0x00200000   # ORIGIN(IMAGE) of memory-qemu.x (pe image's manifest says the same)

sed 's/cells = \[20, 10, 10\]/cells = [10, 5, 5]/' scenes/seed-box.toml >"$OUT/box.toml"
grep -q 'cells = \[10, 5, 5\]' "$OUT/box.toml"
# The same box turned by 30 degrees about x: every cell a parallelepiped (the box above is
# all cuboids, the built-in all general cells), so each kernel is checked.
python3 scripts/turned-box.py "$OUT/turned-box.vtk"
sed 's|^generate = .*$|file = "turned-box.vtk"|' "$OUT/box.toml" >"$OUT/turned.toml"
grep -q '^file = "turned-box.vtk"' "$OUT/turned.toml"
# A scene where tracking lowers dt (a soft cantilever under sudden gravity): `pe solve`
# settles its step (runs again from rest at the smallest step reached) and `pe compile`
# writes that step into the image, so the three still agree bit for bit; the check asserts
# that the step moved.
cp docs/measurements/scenes/soft_cantilever_sudden_gravity.toml "$OUT/cantilever.toml"
# The box with gravity brought in along a smooth ramp ([gravity] ramp, POLY345, from a
# quarter to all of it by 0.05 s, half the run): every gravity record on the board scaled by
# the ramp's factor at its stage's time, `pe solve` scaling its external forces alike; on a
# firmware without the loads part.
sed 's|^acceleration = .*$|&\nramp = [[0.0, 0.25], [0.05, 1.0]]\nshape = "poly345"|' "$OUT/box.toml" >"$OUT/rampedbox.toml"
grep -q '^shape = "poly345"' "$OUT/rampedbox.toml"
# The box with its free end's top edge (6 nodes) moved along a three-point smooth path:
# the board evaluates the path once per node update and holds every node of the edge on it.
cp "$OUT/box.toml" "$OUT/pushedbox.toml"
cat >>"$OUT/pushedbox.toml" <<'TOML'
[[prescribed]]
box = [[0.19999, -1.0, 0.09999], [1.0, 1.0, 1.0]]
path = [[0.0, 0.0, 0.0, 0.0], [0.02, 0.0, 0.0, -0.002], [0.05, 0.0, 0.001, -0.004]]
shape = "poly345"
TOML
# Every scene in both precisions with reduced integration; full integration (eight Gauss
# points, no hourglass control: another element kernel on the board) on the built-in scene
# in f64 (general cells, contact) and the turned box in f32 (parallelepipeds).
CASES=${CASES:-"builtin:f64:reduced builtin:f32:reduced box:f64:reduced box:f32:reduced
       turned:f64:reduced turned:f32:reduced builtin:f64:full turned:f32:full
       cantilever:f64:reduced cantilever:f32:reduced rampedbox:f64:reduced
       rampedbox:f32:reduced pushedbox:f64:reduced pushedbox:f32:reduced"}
for CASE in $CASES; do
    IFS=: read -r SCENE PREC INTEG <<<"$CASE"
    case $SCENE in
      builtin) SRC=(--builtin --level coarse) ;;
      *) SRC=("$OUT/$SCENE.toml") ;;
    esac
    D=$OUT/$SCENE-$PREC-$INTEG
    echo "qemu-check: $SCENE scene, 1x1x1, $PREC $INTEG, $STEPS steps"
    "$PE" compile "${SRC[@]}" --boards 1x1x1 --profile qemu-mps2-an500 \
        --precision "$PREC" --integration "$INTEG" --steps "$STEPS" -o "$D/compiled" >/dev/null
    "$PE" solve "${SRC[@]}" --steps "$STEPS" --precision "$PREC" --integration "$INTEG" \
        --quiet --output-nodes "$D/solve.csv" >"$D/solve.txt" 2>&1
    if [ "$SCENE" = cantilever ]; then
        grep -q '^  step settled at' "$D/solve.txt" || { echo "qemu-check: the cantilever's step did not move: the case proves nothing" >&2; cat "$D/solve.txt" >&2; exit 1; }
        grep '^  step settled at' "$D/solve.txt"
    fi
    # A comparison of zero fields proves nothing: the probe must have moved the tube.
    awk -F, 'NR > 1 { for (i = 5; i <= 7; i++) { v = $i < 0 ? -$i : $i; if (v > m) m = v } }
        END { if (m + 0 <= 1e-4) { printf "qemu-check: max |u| = %g m: nothing moved, raise STEPS\n", m; exit 1 }
              printf "qemu-check: max |u| = %.3g m\n", m }' "$D/solve.csv"
    "$SIM" run "$D/compiled" --quiet --output-nodes "$D/board-sim.csv" >/dev/null
    FEATURES=qemu
    [ "$PREC" = f32 ] && FEATURES=$FEATURES,f32
    [ "$INTEG" = full ] && FEATURES=$FEATURES,full
    # The firmware with only the parts the scene needs: the boxes have no contact and no
    # loads, so their firmware is built without them (and must still match bit for bit).
    case $SCENE in
        builtin) FEATURES=$FEATURES,contact,graphics,loads ;;
        *) FEATURES=$FEATURES,graphics ;;
    esac
    ELF=$(build_firmware "$FEATURES")
    "$PE" image "$D/compiled" -o "$D/image" --firmware "$ELF" >/dev/null
    set +e
    (cd "$D/image" && "${QEMU[@]}" -kernel board-0-0-0.elf \
        -device loader,file=board-0-0-0.sched,addr=$ORIGIN) >"$D/qemu.txt" 2>"$D/qemu.err"
    RC=$?
    set -e
    if [ $RC -ne 0 ]; then
        echo "qemu-check: FAILED: the firmware exited with $RC ($SCENE $PREC); its output:" >&2
        tail -5 "$D/qemu.txt" "$D/qemu.err" >&2
        exit 1
    fi
    "$PE" compare "$D/solve.csv" "$D/qemu.txt"
    "$PE" compare "$D/solve.csv" "$D/board-sim.csv"
done

# Subnormals: the host flushes them to zero as the board's FPSCR.FZ does
# (host_tools::subnormals). A scene whose state passes through the subnormal range: the box
# without gravity, pushed suddenly at its free end; for 100 steps the wave's numerical tail
# ahead of it is subnormal in f32. Flushing must change the result (else this proves
# nothing), and the board must compute the flushed bits.
D=$OUT/subnormal
mkdir -p "$D"
sed 's/acceleration = .*/acceleration = [0.0, 0.0, 0.0]/' "$OUT/box.toml" >"$D/scene.toml"
grep -q 'acceleration = \[0.0, 0.0, 0.0\]' "$D/scene.toml"
cat >>"$D/scene.toml" <<'TOML'

[[load]]
box = [[0.199, -1.0, -1.0], [1.0, 1.0, 1.0]]
force = [0.0, 0.0, -0.01]
TOML
SUB_STEPS=100
echo "qemu-check: subnormal scene, 1x1x1, f32 reduced, $SUB_STEPS steps"
"$PE" solve "$D/scene.toml" --precision f32 --steps $SUB_STEPS --quiet \
    --output-nodes "$D/solve.csv" >/dev/null 2>&1
"$PE" solve "$D/scene.toml" --precision f32 --steps $SUB_STEPS --quiet --keep-subnormals \
    --output-nodes "$D/kept.csv" >/dev/null 2>&1
if "$PE" compare "$D/solve.csv" "$D/kept.csv" >"$D/kept-vs-flushed.txt" 2>&1; then
    echo "qemu-check: FAILED: flushing subnormals changed nothing on the subnormal scene; it proves nothing" >&2
    exit 1
fi
echo "qemu-check: flushing subnormals changes $(grep -c component "$D/kept-vs-flushed.txt") components of the host's result"
"$PE" compile "$D/scene.toml" --boards 1x1x1 --profile qemu-mps2-an500 --precision f32 \
    --steps $SUB_STEPS -o "$D/compiled" >/dev/null
"$SIM" run "$D/compiled" --quiet --output-nodes "$D/board-sim.csv" >/dev/null
ELF=$(build_firmware qemu,f32,graphics,loads)
"$PE" image "$D/compiled" -o "$D/image" --firmware "$ELF" >/dev/null
(cd "$D/image" && "${QEMU[@]}" -kernel board-0-0-0.elf \
    -device loader,file=board-0-0-0.sched,addr=$ORIGIN) >"$D/qemu.txt" 2>"$D/qemu.err" || {
    echo "qemu-check: FAILED: the firmware failed on the subnormal scene:" >&2
    tail -5 "$D/qemu.txt" "$D/qemu.err" >&2
    exit 1
}
"$PE" compare "$D/solve.csv" "$D/qemu.txt"
"$PE" compare "$D/solve.csv" "$D/board-sim.csv"

# Faults end the run with a report and a failing exit.
expect_fault() { # NAME PATTERN QEMU-ARGS...
    local name=$1 pattern=$2
    shift 2
    set +e
    "${QEMU[@]}" "$@" >"$OUT/fault-$name.txt" 2>&1
    local rc=$?
    set -e
    if [ $rc -eq 0 ] || [ $rc -eq 124 ] || ! grep -q "pe-board: FAULT.*$pattern" "$OUT/fault-$name.txt"; then
        echo "qemu-check: FAILED: $name: expected a fault report matching '$pattern' and exit 1, got exit $rc:" >&2
        cat "$OUT/fault-$name.txt" >&2
        exit 1
    fi
    echo "qemu-check: $name refused: $(grep -o 'FAULT.*' "$OUT/fault-$name.txt")"
}
I=$OUT/builtin-f64-reduced/image
if [ ! -d "$I" ]; then
    echo "qemu-check: the refusal checks below need the case builtin:f64:reduced (CASES=\"$CASES\"): skipped"
    exit 0
fi
python3 - "$I/board-0-0-0.sched" "$OUT/corrupt.sched" <<'PY'
import sys
b = bytearray(open(sys.argv[1], "rb").read())
b[len(b) // 2] ^= 0x10
open(sys.argv[2], "wb").write(b)
PY
expect_fault corrupted-image "CRC mismatch" -kernel "$I/board-0-0-0.elf" \
    -device loader,file="$OUT/corrupt.sched",addr=$ORIGIN
expect_fault no-image "no schedule image" -kernel "$I/board-0-0-0.elf"
# A firmware built without contact refuses an image with contact tables, naming the part.
expect_fault no-contact "built without .contact." -kernel "$OUT/box-f64-reduced/image/board-0-0-0.elf" \
    -device loader,file="$I/board-0-0-0.sched",addr=$ORIGIN
"$PE" compile --builtin --level coarse --boards 2x1x1 --profile qemu-mps2-an500 \
    --steps 10 -o "$OUT/two/compiled" >/dev/null
"$PE" image "$OUT/two/compiled" -o "$OUT/two/image" --firmware "$OUT/pe-board-qemu-contact-graphics-loads.elf" >/dev/null
expect_fault wrong-board "is for board (0,0,0) but this is board (1,0,0)" \
    -kernel "$OUT/two/image/board-1-0-0.elf" \
    -device loader,file="$OUT/two/image/board-0-0-0.sched",addr=$ORIGIN
# A numerical fault (an explicit step twice the critical one): the board names the same
# step and element as the serial solver.
mkdir -p "$OUT/unstable"
cat >"$OUT/unstable/scene.toml" <<'TOML'
[mesh]
generate = { kind = "box", size = [0.1, 0.02, 0.02], cells = [10, 2, 2] }
[material]
law = "neo-hookean"
youngs_modulus = 3.0e3
poisson_ratio = 0.45
density = 1000.0
[[fixed]]
box = [[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]
[[prescribed]]
box = [[0.099, -1.0, -1.0], [1.0, 1.0, 1.0]]
path = [[0.0, 0.0, 0.0, 0.0], [0.01, 0.0, 0.0, -0.005]]
[solver]
dt = 5e-3
force_dt = true
steps = 2000
TOML
# The board must name the same step and element as the serial solver (the serial message
# goes on with the cell's mesh nodes and position, which the board does not hold).
SERIAL=$("$PE" solve "$OUT/unstable/scene.toml" --quiet 2>&1 | grep -o 'step [0-9]*: element [0-9]* inverted' | head -n 1 || true)
[ -n "$SERIAL" ] || { echo "qemu-check: FAILED: the serial solver did not fail on the unstable scene" >&2; exit 1; }
"$PE" compile "$OUT/unstable/scene.toml" --boards 1x1x1 --profile qemu-mps2-an500 \
    -o "$OUT/unstable/compiled" >/dev/null
"$PE" image "$OUT/unstable/compiled" -o "$OUT/unstable/image" --firmware "$OUT/pe-board-qemu-contact-graphics-loads.elf" >/dev/null
expect_fault numerical-fault "$SERIAL" -kernel "$OUT/unstable/image/board-0-0-0.elf" \
    -device loader,file="$OUT/unstable/image/board-0-0-0.sched",addr=$ORIGIN
echo "qemu-check: passed (f64 and f32 bit-identical to pe solve and board-sim; faults reported)"
