#!/usr/bin/env bash
# Contact cost on each board of an emulated array, measured: executed Cortex-M7
# instructions of the contact evaluation (`evaluate_contact`: positions, travel check, tool
# and pair tests) per step, on every board of the built-in coarse scene compiled for
# MACHINES (default 1x1x1 and 2x2x2), exact counts from QEMU's insncount plugin
# (../shared/tools/insncount) watching the firmware's cost marks (the `cost-marks` feature,
# pe-firmware/src/runtime/marks.rs). A 1x1x1 bench (scripts/board-cost.sh) cannot show
# what a board of a partition pays: here each board's median, mean and largest (a check
# step, which also builds the candidates) are printed beside what the compile report
# charges it (pe_firmware::profile::FirmwareCost::charged_contact_nodes: the whole contact
# table x instructions per contact node on a board that owns a contact node, nothing on
# one that owns none), and the median of each stage of the evaluation: positions, the
# check step's candidate search, travel check, tool tests, pair tests (the marks in
# pe-firmware/src/runtime/marks.rs).
#
# Slow: the plugin counts every instruction of every board (about 4 minutes for 2x2x2 at
# the default STEPS on 2 cores). Not run by CI; a measurement to rerun when the contact
# code changes. Env: STEPS (default 150), MACHINES, OUT.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}
STEPS=${STEPS:-150}
MACHINES=${MACHINES:-1x1x1 2x2x2}
OUT=${OUT:-$TARGET_DIR/contact-cost}
PLUGIN_SRC=${PLUGIN_SRC:-$ROOT/../shared/tools/insncount/insncount.c}
rm -rf "$OUT" && mkdir -p "$OUT"
source scripts/qemu-lib.sh
build_plugin "$PLUGIN_SRC" "$OUT/libinsncount.so"
ELF=$(build_firmware qemu,cost-marks,contact,graphics,loads)
MARK=$(cost_mark_address "$ELF")

# board-sim starts QEMU through this wrapper: the plugin, one log per board.
cat >"$OUT/qemu.sh" <<EOF
#!/usr/bin/env bash
[ "\${1:-}" = --version ] && exec qemu-system-arm --version
args=("\$@"); k=board
for ((i = 0; i < \${#args[@]}; i++)); do
    [ "\${args[\$i]}" = -kernel ] && k=\$(basename "\${args[\$((i + 1))]}" .elf)
done
exec qemu-system-arm -icount shift=0 -plugin "$OUT/libinsncount.so,mark=$MARK" \\
    -d plugin -D "\$INSN_LOGS/\$k.log" "\$@"
EOF
chmod +x "$OUT/qemu.sh"

for M in $MACHINES; do
    D=$OUT/$M
    mkdir -p "$D/logs"
    "$PE" compile --builtin --level coarse --boards "$M" --profile qemu-mps2-an500 \
        --steps "$STEPS" -o "$D/compiled" >/dev/null
    INSN_LOGS=$D/logs "$SIM" qemu "$D/compiled" --firmware "$ELF" --qemu "$OUT/qemu.sh" \
        --quiet >"$D/run.txt"
    echo "== builtin coarse on $M, $STEPS steps: contact instructions per step"
    python3 - "$D" <<'PY'
import glob, json, os, re, statistics, sys
d = sys.argv[1]
rep = json.load(open(os.path.join(d, "compiled", "report.json")))
per_node = rep["capacity"]["instructions_per_contact_node"]
table = rep["contact"]["contact_nodes"]
stages = ["positions", "search", "travel", "tools", "pairs"]
print(f"{'board':>13} {'contact nodes':>14} {'owned':>6} {'median':>9} {'mean':>9} {'largest':>9} "
      f"{'report charges':>15}   median per stage: " + " ".join(f"{s:>9}" for s in stages))
for b in rep["boards"]:
    name = "board-%d-%d-%d" % tuple(b["board"])
    text = open(os.path.join(d, "logs", name + ".log")).read()
    # Six marks a step (pe-firmware/src/runtime/marks.rs): 0, then 2 to 5 between the
    # stages, then 1; the deltas of the five after mark 0 are the stages' costs.
    deltas = [int(m.group(1)) for m in re.finditer(r"mark \d+ at \d+ \(delta (\d+)\)", text)]
    if not deltas or len(deltas) % 6:
        sys.exit(f"contact-cost: {len(deltas)} marks in {name}'s log, not six a step")
    steps = [deltas[k + 1:k + 6] for k in range(0, len(deltas), 6)]
    cost = [sum(s) for s in steps]
    n, owned = b["contact_nodes"], b["owned_contact_nodes"]
    per_stage = " ".join(f"{statistics.median(s[j] for s in steps):>9.0f}" for j in range(5))
    print(f"{name:>13} {n:>14} {owned:>6} {statistics.median(cost):>9.0f} "
          f"{statistics.mean(cost):>9.0f} {max(cost):>9} {(table if owned else 0) * per_node:>15}"
          f"                     {per_stage}")
PY
done
