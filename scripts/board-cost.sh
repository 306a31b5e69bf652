#!/usr/bin/env bash
# Cost on the board, measured: executed instructions per element-step on the emulated
# Cortex-M7 (QEMU mps2-an500, exact count with the insncount TCG plugin from
# ../shared/tools/insncount), for reduced and full integration in f64 and f32, on the
# built-in coarse scene (1x1x1) after STEPS steps, when the probe presses the tube (the
# deformed state: an undeformed one is refused). Prints the table and the real-time
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
cargo build --release -q -p host-tools --bin pe
PE=$TARGET_DIR/release/pe

printf "%-12s %8s %6s %14s %16s %14s %14s\n" variant elements nodes "kernel/elem" "element-step" "step/element" "update/node"
echo "variant,elements,nodes,kernel_per_element,per_element_step,step_per_element,per_node_update" >"$OUT/board-cost.csv"
for PREC in f64 f32; do
    for INTEG in reduced full; do
        V=$PREC-$INTEG
        FEATURES=qemu
        [ "$PREC" = f32 ] && FEATURES=$FEATURES,f32
        [ "$INTEG" = full ] && FEATURES=$FEATURES,full
        "$PE" compile --builtin --level coarse --boards 1x1x1 --profile qemu-mps2-an500 \
            --precision "$PREC" --integration "$INTEG" --steps "$STEPS" -o "$OUT/$V" >/dev/null
        cargo build --release -q --target thumbv7em-none-eabihf \
            --manifest-path pe-firmware/board/Cargo.toml --target-dir "$TARGET_DIR" \
            --bin pe-board-bench --no-default-features --features "$FEATURES"
        ELF=$OUT/$V/bench.elf
        cp "$TARGET_DIR/thumbv7em-none-eabihf/release/pe-board-bench" "$ELF"
        python3 - "$OUT/$V/board-0-0-0.bin" "$OUT/$V/board-0-0-0.sched" <<'PY'
import struct, sys
b = open(sys.argv[1], "rb").read()
open(sys.argv[2], "wb").write(struct.pack("<I", len(b)) + b)
PY
        MARK=0x$( (command -v llvm-nm >/dev/null && llvm-nm "$ELF" || nm "$ELF") | awk '$3=="bench_mark"{print $1}')
        timeout 120 qemu-system-arm -cpu cortex-m7 -machine mps2-an500 -nographic \
            -semihosting-config enable=on,target=native -icount shift=0 \
            -plugin "$OUT/libinsncount.so,mark=$MARK" -d plugin -D "$OUT/$V/insn.log" \
            -kernel "$ELF" -device loader,file="$OUT/$V/board-0-0-0.sched",addr=0x00200000 \
            >"$OUT/$V/bench.txt"
        # bench,VARIANT,ELEMENTS,NODES,SAMPLES,MAX_ABS_U; marks 0..7 (see pe-firmware/board/src/bin/bench.rs)
        awk -F, -v v="$V" '/^bench,/ { ne=$3; nn=$4; k=$5; u=$6 }
            END { print v, ne, nn, k, u }' "$OUT/$V/bench.txt" >"$OUT/$V/meta"
        read -r _ NE NN K UMAX <"$OUT/$V/meta"
        if ! awk -v u="${UMAX:-0}" 'BEGIN { exit !(u + 0 > 1e-6) }'; then
            echo "board-cost: $V measured on an undeformed state (max |u| = ${UMAX:-?} m): raise STEPS" >&2
            exit 1
        fi
        awk -v v="$V" -v ne="$NE" -v nn="$NN" -v k="$K" '
            /insncount: mark/ { d[$3] = substr($7, 1, length($7) - 1) + 0 }
            END {
                o = d[1]; kern = (d[3] - o) / k; elem = (d[5] - o) / k; step = (d[7] - o) / ne
                upd = (d[7] - o - ne * elem) / nn
                printf "%-12s %8d %6d %14.0f %16.0f %14.0f %14.0f\n", v, ne, nn, kern, elem, step, upd
                printf "%s,%d,%d,%.0f,%.0f,%.0f,%.0f\n", v, ne, nn, kern, elem, step, upd >>csv
            }' csv="$OUT/board-cost.csv" "$OUT/$V/insn.log" | tee -a "$OUT/table.txt"
    done
done
echo
echo "kernel/elem: one element's internal forces; element-step: plus gathering displacements"
echo "and scattering forces; step/element: a whole runtime step divided by the elements"
echo "(includes the node updates of this scene, $(awk 'NR==1{printf "%.2f", $3/$2}' "$OUT/table.txt") nodes per element); update/node: the rest per node."
echo
awk '
    BEGIN { clock = 480e6; rate = 1e4; cycles = clock / rate
            seed = 300e6 / rate / 700
            printf "Capacity at 10 kHz on the PE board (480 MHz, one instruction per cycle: %d cycles per step):\n", cycles }
    { per = $6; epb = cycles / per; boards = 2000 / epb; if (boards > int(boards)) boards = int(boards) + 1
      printf "  %-12s %6.0f instructions per element-step (whole step) -> %5.1f elements per board; 2000 elements need %4d boards\n", $1, per, epb, boards }
    END { printf "Seed: 700 flops per element-step on 300 MFLOPS processors -> %.1f elements per processor at 10 kHz; 2000 elements need %d processors\n", seed, int(2000 / seed) + 1 }
' "$OUT/table.txt"

# The table the code relies on must match what was just measured.
PE_BOARD_COST_CSV="$OUT/board-cost.csv" cargo test --release -q -p system-tests --test board_cost \
    -- --ignored
