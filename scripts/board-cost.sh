#!/usr/bin/env bash
# Cost on the board, measured: executed instructions per element-step on the emulated
# Cortex-M7 (QEMU mps2-an500, exact count with the insncount TCG plugin from
# ../shared/tools/insncount), for reduced and full integration in f64 and f32, on the
# built-in coarse scene (1x1x1) after STEPS steps, when the probe presses the tube (the
# deformed state: an undeformed one is refused), and for reduced integration on a regular
# box (the cuboid kernel) and on the same box turned by 30 degrees about x (the
# parallelepiped kernel). Prints the table and the real-time
# capacity it implies at
# the PE board's clock, taking ONE INSTRUCTION PER CYCLE (QEMU counts instructions, not
# Cortex-M7 cycles: dual issue makes the core faster, FPU latencies and flash/RAM wait
# states slower). The figures are kept in pe_firmware::profile::MEASURED_COST, which the
# compile report and board-sim's timing model use; the script writes OUT/board-cost.csv
# and then runs the test that fails when MEASURED_COST is more than 3% off it (stale):
# update MEASURED_COST from this output. CI runs this script (scripts/test.sh).
#
# Env: STEPS (steps before the measured one, default 900), OUT.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
export RUST_BACKTRACE=0
# The schedule comes from the loader here, never linked into the ELF.
unset PE_SCHEDULE_IMAGE
MISSING=()
command -v qemu-system-arm >/dev/null 2>&1 || MISSING+=(qemu-system-arm)
command -v gcc >/dev/null 2>&1 || MISSING+=(gcc libc6-dev)
command -v nm >/dev/null 2>&1 || command -v llvm-nm >/dev/null 2>&1 || MISSING+=(binutils)
if [ ${#MISSING[@]} -gt 0 ]; then
    apt-get update -qq && apt-get install -y -qq "${MISSING[@]}" >/dev/null
fi
rustup target add thumbv7em-none-eabihf >/dev/null 2>&1 || rustup target add thumbv7em-none-eabihf
TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}
STEPS=${STEPS:-900}
OUT=${OUT:-$TARGET_DIR/board-cost}
PLUGIN_SRC=${PLUGIN_SRC:-$ROOT/../shared/tools/insncount/insncount.c}
rm -rf "$OUT" && mkdir -p "$OUT"
gcc -O2 -shared -fPIC -fvisibility=hidden -o "$OUT/libinsncount.so" "$PLUGIN_SRC"
source scripts/host-bins.sh

# The regular mesh: the seed's box (scenes/seed-box.toml) at 10x5x5 cells, every cell an
# axis-aligned cuboid (the cheapest kernel); one board holds it.
sed 's/cells = \[20, 10, 10\]/cells = [10, 5, 5]/' scenes/seed-box.toml >"$OUT/regular-box.toml"
grep -q 'cells = \[10, 5, 5\]' "$OUT/regular-box.toml"
# The turned mesh: the same box turned by 30 degrees about x (still clamped at x = 0,
# sagging under the same gravity), every cell a parallelepiped that is not axis-aligned
# (the parallelepiped kernel), written as legacy VTK.
python3 scripts/turned-box.py "$OUT/turned-box.vtk"
sed 's|^generate = .*$|file = "turned-box.vtk"|' "$OUT/regular-box.toml" >"$OUT/turned-box.toml"
grep -q '^file = "turned-box.vtk"' "$OUT/turned-box.toml"

printf "%-12s %-8s %8s %6s %7s %6s %10s %12s %10s %12s %10s %12s %12s %12s %10s %10s %8s\n" variant scene elements boxes cuboids nodes \
    "kernel/gen" "elem-step/gen" "kernel/box" "elem-step/box" "kernel/cub" "elem-step/cub" "step/elem" "update/node" "contact" "check" "tests"
echo "variant,scene,elements,boxes,cuboids,nodes,contact_nodes,kernel_general,element_step_general,kernel_box,element_step_box,kernel_cuboid,element_step_cuboid,step_per_element,per_node_update,contact_evaluation,check_evaluation,search_tests" >"$OUT/board-cost.csv"
for SCENE in builtin regular turned; do
  for PREC in f64 f32; do
    for INTEG in reduced full; do
        [ "$SCENE" != builtin ] && [ "$INTEG" = full ] && continue
        V=$PREC-$INTEG
        FEATURES=qemu,contact,graphics,loads
        [ "$PREC" = f32 ] && FEATURES=$FEATURES,f32
        [ "$INTEG" = full ] && FEATURES=$FEATURES,full
        D=$OUT/$SCENE-$V
        case $SCENE in
            builtin) SRC=(--builtin --level coarse) ;;
            *) SRC=("$OUT/$SCENE-box.toml") ;;
        esac
        "$PE" compile "${SRC[@]}" --boards 1x1x1 --profile qemu-mps2-an500 \
            --precision "$PREC" --integration "$INTEG" --steps "$STEPS" -o "$D" >/dev/null
        cargo build --release -q --target thumbv7em-none-eabihf \
            --manifest-path pe-firmware/board/Cargo.toml --target-dir "$TARGET_DIR" \
            --bin pe-board-bench --no-default-features --features "$FEATURES"
        ELF=$D/bench.elf
        cp "$TARGET_DIR/thumbv7em-none-eabihf/release/pe-board-bench" "$ELF"
        python3 - "$D/board-0-0-0.bin" "$D/board-0-0-0.sched" <<'PY'
import struct, sys
b = open(sys.argv[1], "rb").read()
open(sys.argv[2], "wb").write(struct.pack("<I", len(b)) + b)
PY
        MARK=0x$( (command -v llvm-nm >/dev/null && llvm-nm "$ELF" || nm "$ELF") | awk '$3=="bench_mark"{print $1}')
        timeout 300 qemu-system-arm -cpu cortex-m7 -machine mps2-an500 -nographic \
            -semihosting-config enable=on,target=native -icount shift=0 \
            -plugin "$OUT/libinsncount.so,mark=$MARK" -d plugin -D "$D/insn.log" \
            -kernel "$ELF" -device loader,file="$D/board-0-0-0.sched",addr=0x00200000 \
            >"$D/bench.txt"
        # bench,VARIANT,ELEMENTS,BOXES,CUBOIDS,NODES,CONTACT_NODES,SAMPLES,BOX_SAMPLES,
        # CUBOID_SAMPLES,MAX_ABS_U,SEARCH_TESTS; marks 0..19 (see
        # pe-firmware/board/src/bin/bench.rs)
        awk -F, '/^bench,/ { print $3, $4, $5, $6, $7, $8, $9, $10, $11, $12 }' "$D/bench.txt" >"$D/meta"
        read -r NE NB NQ NN NC K KB KQ UMAX NT <"$D/meta"
        if ! awk -v u="${UMAX:-0}" 'BEGIN { exit !(u + 0 > 1e-6) }'; then
            echo "board-cost: $SCENE $V measured on an undeformed state (max |u| = ${UMAX:-?} m): raise STEPS" >&2
            exit 1
        fi
        awk -v v="$V" -v sc="$SCENE" -v ne="$NE" -v nb="$NB" -v nq="$NQ" -v nn="$NN" -v nc="$NC" -v k="$K" -v kb="$KB" -v kq="$KQ" -v nt="$NT" '
            /insncount: mark/ { d[$3] = substr($7, 1, length($7) - 1) + 0 }
            END {
                o = d[1]
                kern = k ? (d[3] - o) / k : 0; elem = k ? (d[5] - o) / k : 0
                kbox = kb ? (d[9] - o) / kb : 0; ebox = kb ? (d[11] - o) / kb : 0
                kcub = kq ? (d[13] - o) / kq : 0; ecub = kq ? (d[15] - o) / kq : 0
                step = (d[7] - o) / (ne + nb + nq)
                upd = (d[7] - o - ne * elem - nb * ebox - nq * ecub) / nn
                cont = d[17] - o
                chk = d[19] - o
                printf "%-12s %-8s %8d %6d %7d %6d %10.0f %12.0f %10.0f %12.0f %10.0f %12.0f %12.0f %12.0f %10.0f %10.0f %8d\n", v, sc, ne + nb + nq, nb, nq, nn, kern, elem, kbox, ebox, kcub, ecub, step, upd, cont, chk, nt
                printf "%s,%s,%d,%d,%d,%d,%d,%.0f,%.0f,%.0f,%.0f,%.0f,%.0f,%.0f,%.0f,%.0f,%.0f,%d\n", v, sc, ne + nb + nq, nb, nq, nn, nc, kern, elem, kbox, ebox, kcub, ecub, step, upd, cont, chk, nt >>csv
            }' csv="$OUT/board-cost.csv" "$D/insn.log" | tee -a "$OUT/table.txt"
    done
  done
done
echo
echo "kernel: one element's internal forces, general kernel (gen), parallelepiped (box) or"
echo "axis-aligned cuboid (cub); elem-step: plus gathering displacements and scattering forces;"
echo "step/elem: a whole runtime step divided by the elements (includes the node updates of the"
echo "scene); update/node: the rest per node; contact: a step's contact evaluation (positions,"
echo "travel check, tool and pair tests; not a check step's search) on the one board, which owns"
echo "every contact node; check: a check step's (the candidate search and the groups kept, then"
echo "the same evaluation); tests: the search's node-face tests. builtin: the built-in coarse anatomy (every cell"
echo "distorted: general kernel); regular: a 10x5x5 box (every cell a cuboid); turned: the same"
echo "box turned by 30 degrees about x (every cell a parallelepiped)."
echo
awk '
    BEGIN { clock = 480e6; rate = 1e4; cycles = clock / rate
            seed = 300e6 / rate / 700
            printf "Capacity at 10 kHz on the PE board (480 MHz, one instruction per cycle: %d cycles per step):\n", cycles }
    { per = $13; epb = cycles / per; boards = 2000 / epb; if (boards > int(boards)) boards = int(boards) + 1
      printf "  %-12s %-8s %6.0f instructions per element-step (whole step) -> %5.1f elements per board; 2000 elements need %4d boards\n", $1, $2, per, epb, boards }
    END { printf "Seed: 700 flops per element-step on 300 MFLOPS processors -> %.1f elements per processor at 10 kHz; 2000 elements need %d processors\n", seed, int(2000 / seed) + 1 }
' "$OUT/table.txt"

# The tetrahedra (not yet loaded by the boards: their kernels, the shared code, on the
# deformed Kuhn patch of pe_firmware::profile::tet_cost::TetSample; marks in
# pe-firmware/board/src/bin/tet_bench.rs): instructions per tetrahedron of the plain kernel,
# the plain loop and the T4ANP loop, and the digests of the two loops' forces, which the
# test below recomputes on the host (the same bits).
echo
echo "Tetrahedra (their kernels on a deformed patch; the boards do not load tetrahedra yet):"
echo "precision,tets,nodes,kernel_plain,plain_step,nodal_step,digest_plain,digest_nodal" >"$OUT/tet-cost.csv"
for PREC in f64 f32; do
    FEATURES=qemu
    [ "$PREC" = f32 ] && FEATURES=$FEATURES,f32
    D=$OUT/tet-$PREC
    mkdir -p "$D"
    cargo build --release -q --target thumbv7em-none-eabihf \
        --manifest-path pe-firmware/board/Cargo.toml --target-dir "$TARGET_DIR" \
        --bin pe-board-tet-bench --no-default-features --features "$FEATURES"
    ELF=$D/tet-bench.elf
    cp "$TARGET_DIR/thumbv7em-none-eabihf/release/pe-board-tet-bench" "$ELF"
    MARK=0x$( (command -v llvm-nm >/dev/null && llvm-nm "$ELF" || nm "$ELF") | awk '$3=="bench_mark"{print $1}')
    timeout 120 qemu-system-arm -cpu cortex-m7 -machine mps2-an500 -nographic \
        -semihosting-config enable=on,target=native -icount shift=0 \
        -plugin "$OUT/libinsncount.so,mark=$MARK" -d plugin -D "$D/insn.log" \
        -kernel "$ELF" >"$D/bench.txt"
    # tet-bench,PRECISION,TETS,NODES,DIGEST_PLAIN,DIGEST_NODAL
    awk -F, '/^tet-bench,/ { print $2, $3, $4, $5, $6 }' "$D/bench.txt" >"$D/meta"
    read -r P NT NN DP DN <"$D/meta"
    [ "$P" = "$PREC" ] || { echo "board-cost: the $PREC tetrahedron bench printed '${P:-nothing}'" >&2; exit 1; }
    awk -v p="$P" -v nt="$NT" -v nn="$NN" -v dp="$DP" -v dn="$DN" '
        /insncount: mark/ { d[$3] = substr($7, 1, length($7) - 1) + 0 }
        END {
            o = d[1]
            printf "%s,%d,%d,%.1f,%.1f,%.1f,%s,%s\n", p, nt, nn, (d[3] - o) / nt, (d[5] - o) / nt, (d[7] - o) / nt, dp, dn >>csv
            printf "  %s: %d tetrahedra, %d nodes: plain kernel %.0f, plain loop %.0f, T4ANP loop %.0f instructions per tetrahedron-step\n", p, nt, nn, (d[3] - o) / nt, (d[5] - o) / nt, (d[7] - o) / nt
        }' csv="$OUT/tet-cost.csv" "$D/insn.log"
done

# The table the code relies on must match what was just measured.
# (--workspace: the test build's features, so nothing is compiled again; `-p system-tests`
# would resolve them without the other members' dev-dependencies and rebuild host-tools.)
PE_BOARD_COST_CSV="$OUT/board-cost.csv" PE_TET_COST_CSV="$OUT/tet-cost.csv" cargo test --workspace --release -q --test board_cost \
    -- --ignored
