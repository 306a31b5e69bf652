#!/usr/bin/env bash
# The host's SIMD element loops keep their lanes in registers: in every function compiled
# for a SIMD instruction set (`run_packs_avx`, and `run_packs`'s multiversion clones, whose
# names hold `run_packs_avx`), no instruction calls or loads an out-of-line `core::arch`
# intrinsic, a kernel closure, or core's `array::map` machinery (`try_map`, `try_from_fn`).
# A closure or `map` left out of line in a kernel is compiled without the SIMD features,
# so every lane operation inside it becomes a call: that happened once (the parallelepiped
# and cuboid kernels' force-moment closures), and `pe bench` ran 2x slower with the same
# bits, which no test saw. Usage: bash scripts/check-simd-inlined.sh [PE_BINARY]
# (default: the release `pe` the README's test command builds). x86-64 only.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "$(uname -m)" != x86_64 ]; then
    echo "check-simd-inlined: not x86-64, nothing to check"
    exit 0
fi
bin=${1:-}
if [ -z "$bin" ]; then
    TARGET_DIR=${CARGO_TARGET_DIR:-$(pwd)/target}
    source scripts/host-bins.sh
    bin=$PE
fi
command -v objdump >/dev/null || { echo "check-simd-inlined: objdump not found (binutils)"; exit 1; }
dis=$(mktemp)
trap 'rm -f "$dis"' EXIT
objdump -d --no-show-raw-insn -C "$bin" > "$dis"
functions=$(grep -cE '^[0-9a-f]+ <.*run_packs_avx.*>:$' "$dis" || true)
if [ "$functions" -lt 2 ]; then
    echo "check-simd-inlined: FAIL: only $functions SIMD element loops found in $bin (renamed?)"
    exit 1
fi
bad=$(awk '/^[0-9a-f]+ <.*>:$/ { inside = ($0 ~ /run_packs_avx/) }
    inside && /core::core_arch|\{\{closure\}\}>|try_map|try_from_fn/' "$dis")
if [ -n "$bad" ]; then
    echo "check-simd-inlined: FAIL: out-of-line calls in the SIMD element loops of $bin:"
    echo "$bad" | sed -E "s/^[^<]*<//; s/>$//" | sort | uniq -c | sort -rn | head -20
    exit 1
fi
echo "check-simd-inlined: passed ($functions SIMD element loops, no out-of-line intrinsic, closure or map)"
