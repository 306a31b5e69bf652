#!/usr/bin/env bash
# Where the firmware's contact evaluation spends its instructions, by source line: the
# built-in scene on one emulated Cortex-M7 (QEMU mps2-an500, the `cost-marks` firmware),
# every executed instruction of a stage counted by address (scripts/tools/pcprofile.c, a
# QEMU plugin) and mapped to its source lines and inlined call chain with the ELF's debug
# information (llvm-addr2line). Prints instructions per step: the top lines (the standard
# library's among them), then the top call chains through this repository's code (innermost
# first). The profile behind "what limits it" for the board's contact
# cost (docs/measurements/board-cost.md); scripts/contact-cost.sh gives the stages' totals per board.
#
#   scripts/firmware-profile.sh        Env: STAGE (positions, search, travel, tools, pairs
#                                      or all: the whole evaluation; default all), STEPS
#                                      (default 1500: the probe presses the tube from about
#                                      step 1200), LEVEL (default coarse), TOP (default 25),
#                                      OUT
#
# Not run by CI (about a minute after the builds).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}
OUT=${OUT:-$TARGET_DIR/firmware-profile}
STAGE=${STAGE:-all}
STEPS=${STEPS:-1500}
LEVEL=${LEVEL:-coarse}
TOP=${TOP:-25}
case "$STAGE" in
    positions) WINDOW=0 ;; search) WINDOW=1 ;; travel) WINDOW=2 ;; tools) WINDOW=3 ;;
    pairs) WINDOW=4 ;; all) WINDOW=all ;;
    *) echo "firmware-profile: STAGE is positions, search, travel, tools, pairs or all, not '$STAGE'" >&2; exit 2 ;;
esac
rm -rf "$OUT" && mkdir -p "$OUT"
source scripts/qemu-lib.sh
build_plugin scripts/tools/pcprofile.c "$OUT/libpcprofile.so"
ADDR2LINE=$(command -v llvm-addr2line || true)
if [ -z "$ADDR2LINE" ]; then
    rustup component add llvm-tools >/dev/null 2>&1 || true
    ADDR2LINE=$(ls "$(rustc --print sysroot)"/lib/rustlib/*/bin/llvm-addr2line 2>/dev/null | head -1)
fi
[ -n "$ADDR2LINE" ] || { echo "firmware-profile: no llvm-addr2line (rustup component add llvm-tools)" >&2; exit 1; }
ELF=$(build_firmware qemu,cost-marks,contact,graphics,loads)
MARK=$(cost_mark_address "$ELF")
cat >"$OUT/qemu.sh" <<WRAP
#!/usr/bin/env bash
[ "\${1:-}" = --version ] && exec qemu-system-arm --version
exec qemu-system-arm -plugin "$OUT/libpcprofile.so,mark=$MARK,window=$WINDOW" \\
    -d plugin -D "$OUT/pc.log" "\$@"
WRAP
chmod +x "$OUT/qemu.sh"
"$PE" compile --builtin --level "$LEVEL" --boards 1x1x1 --profile qemu-mps2-an500 \
    --steps "$STEPS" -o "$OUT/compiled" >/dev/null
"$SIM" qemu "$OUT/compiled" --firmware "$ELF" --qemu "$OUT/qemu.sh" --quiet >"$OUT/run.txt"
echo "== built-in $LEVEL, 1x1x1, $STEPS steps, stage $STAGE: instructions per step"
python3 - "$OUT/pc.log" "$ELF" "$STEPS" "$TOP" "$ADDR2LINE" <<'PY'
import collections, json, subprocess, sys
log, elf, steps, top, addr2line = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
lines = open(log).read().split("\n")
marks = [int(l.split()[1]) for l in lines if l.startswith("marks ")]
if not marks or marks[0] != 6 * steps:
    sys.exit(f"firmware-profile: {marks} marks, not six for each of {steps} steps")
pcs = [(int(l.split()[1], 16), int(l.split()[2])) for l in lines if l.startswith("pc ")]
out = subprocess.run([addr2line, "-e", elf, "--output-style=JSON", "-i", "-C"]
                     + [hex(p) for p, _ in pcs], capture_output=True, text=True, check=True).stdout
objs = []
for line in out.strip().split("\n"):
    j = json.loads(line)
    objs.extend(j if isinstance(j, list) else [j])
if len(objs) != len(pcs):
    sys.exit(f"firmware-profile: {len(objs)} addresses resolved of {len(pcs)}")
def place(s):
    return f"{s['FileName'].split('/src/')[-1]}:{s['Line']}"
by_line, by_chain = collections.Counter(), collections.Counter()
for (_, count), j in zip(pcs, objs):
    syms = j["Symbol"]
    by_line[place(syms[0])] += count
    ours = [s for s in syms if "/pe-firmware/src/" in s["FileName"] or "/link-proto/src/" in s["FileName"]]
    by_chain[" < ".join(place(s) for s in ours[:4]) or place(syms[0])] += count
total = sum(c for _, c in pcs)
print(f"{total / steps:10.0f}  in all")
print("-- by source line")
for k, v in by_line.most_common(top):
    print(f"{v / steps:10.0f}  {k}")
print("-- by inlined call chain in this repository's code (innermost first)")
for k, v in by_chain.most_common(top):
    print(f"{v / steps:10.0f}  {k}")
PY
