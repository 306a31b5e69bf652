#!/usr/bin/env bash
# The host on ARM (aarch64: laptops with Apple or other ARM chips), emulated: the host tools
# cross-compiled for aarch64-unknown-linux-gnu and run under QEMU's user-mode emulator
# (qemu-aarch64, whose default CPU has NEON and honours FPCR.FZ, the subnormal flush):
#   1. the solver's batched bit tests (the portable lanes, compiled for NEON by their
#      multiversion clone, against the scalar loop, f32 and f64, boards' batches), and
#   2. `pe solve` on the built-in coarse scene for 1000 steps (the probe presses the tube:
#      contact, dt tracking, the subnormal flush) on aarch64 against the same run on this
#      x86-64 machine, compared bit for bit with `pe compare` (the x86-64 run is the one
#      scripts/qemu-check.sh finds equal to the firmware's bits).
# It says nothing about speed (QEMU translates every instruction). Installs the target,
# the cross linker and qemu-user if missing. x86-64 hosts only (an aarch64 host runs the
# workspace tests natively).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "$(uname -m)" != x86_64 ]; then
    echo "lanes-aarch64.sh: for x86-64 hosts (this is $(uname -m)); skipped"
    exit 0
fi
TARGET=aarch64-unknown-linux-gnu
rustup target add "$TARGET" >/dev/null 2>&1
MISSING=()
command -v aarch64-linux-gnu-gcc >/dev/null 2>&1 || MISSING+=(gcc-aarch64-linux-gnu libc6-dev-arm64-cross)
command -v qemu-aarch64 >/dev/null 2>&1 || MISSING+=(qemu-user)
if [ ${#MISSING[@]} -gt 0 ]; then
    apt-get update -qq && apt-get install -y -qq "${MISSING[@]}" >/dev/null
fi
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
SYSROOT=/usr/aarch64-linux-gnu
OUT=${OUT:-target/lanes-aarch64}
mkdir -p "$OUT"

# 1. The batched bit tests, on aarch64 (built first with its errors shown, then asked for
# the executable's path: nothing is compiled twice).
cargo test -q -p host-tools --test solver --release --target "$TARGET" --no-run
solver=$(cargo test -p host-tools --test solver --release --target "$TARGET" --no-run \
    --message-format=json 2>/dev/null | python3 -c '
import json, sys
paths = [m["executable"] for m in map(json.loads, sys.stdin)
         if m.get("reason") == "compiler-artifact" and m.get("executable")
         and m["target"]["name"] == "solver"]
assert len(paths) == 1, paths
print(paths[0])')
out=$(timeout 900 qemu-aarch64 -L "$SYSROOT" "$solver" batched:: --nocapture --test-threads 2 2>&1) || {
    echo "$out" >&2
    echo "lanes-aarch64.sh: the solver's batched tests failed on aarch64" >&2
    exit 1
}
lanes=$(grep '^lanes tested' <<<"$out")
passed=$(grep -o '[0-9]* passed' <<<"$out" | tail -1)
grep -q 'lanes tested: portable, neon' <<<"$lanes" || { echo "$out" >&2; echo "lanes-aarch64.sh: the portable lanes were not tested" >&2; exit 1; }
echo "aarch64 (qemu-aarch64): $lanes; batched tests $passed"

# 2. `pe solve` on aarch64 = on x86-64, bit for bit.
TARGET_DIR=${CARGO_TARGET_DIR:-$(pwd)/target}
source scripts/host-bins.sh
cargo build -q -p host-tools --bin pe --release --target "$TARGET"
PE_A64=$TARGET_DIR/$TARGET/release/pe
run=(solve --builtin --level coarse --steps 1000 --quiet --threads 2)
"$PE" "${run[@]}" --output-nodes "$OUT/x86_64.csv" --report "$OUT/x86_64.json" >/dev/null
timeout 900 qemu-aarch64 -L "$SYSROOT" "$PE_A64" "${run[@]}" \
    --output-nodes "$OUT/aarch64.csv" --report "$OUT/aarch64.json" >/dev/null
python3 - "$OUT" <<'EOF'
import json, sys
# The fields compared are far from zero: the probe has pressed the tube (0.19 mm at 1000
# steps), and dt tracking ran on both.
for arch in ("x86_64", "aarch64"):
    r = json.load(open(f"{sys.argv[1]}/{arch}.json"))
    assert r["max_displacement"] > 1e-4, (arch, r["max_displacement"])
    assert r["steps"] == 1000, (arch, r["steps"])
print(f"aarch64 and x86-64 both moved the tube by {r['max_displacement']:.3e} m")
EOF
"$PE" compare "$OUT/x86_64.csv" "$OUT/aarch64.csv"
echo "lanes-aarch64.sh: pe solve on aarch64 = on x86-64, bit for bit (built-in coarse, 1000 steps)"
