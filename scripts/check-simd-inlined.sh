#!/usr/bin/env bash
# The host's SIMD element loops keep their lanes in registers: in every function compiled
# for a SIMD instruction set (`run_packs_avx` and `run_tet_packs_avx`, and the multiversion
# clones of `run_packs` and `run_tet_packs`, whose names hold those), no instruction calls or loads an out-of-line `core::arch`
# intrinsic, a kernel closure, or core's `array::map` machinery (`try_map`, `try_from_fn`).
# A closure or `map` left out of line in a kernel is compiled without the SIMD features,
# so every lane operation inside it becomes a call: that happened once (the parallelepiped
# and cuboid kernels' force-moment closures; then the tetrahedron's `map` of edge
# differences), and `pe bench` ran 2x slower with the same bits, which no test saw. Usage: bash scripts/check-simd-inlined.sh [PE_BINARY]
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
functions=$(grep -cE '^[0-9a-f]+ <.*run_(tet_)?packs_avx.*>:$' "$dis" || true)
if [ "$functions" -lt 2 ]; then
    echo "check-simd-inlined: FAIL: only $functions SIMD element loops found in $bin (renamed?)"
    exit 1
fi
# The out-of-line calls inside the SIMD element loops of the disassembly on stdin. A target
# that is a closure ends in `{{closure}}` in legacy-mangled names (stable's default), in
# `{closure#N}` in v0-mangled ones (nightly's default, or -C symbol-mangling-version=v0), and
# starts with `_RNC` where objdump cannot demangle v0. v0 names carry generic arguments: a
# jump inside a loop whose closure parameter is `...{closure#0}` ends in `}>+0x...>`, not
# a call, and is not flagged.
out_of_line() {
    awk '/^[0-9a-f]+ <.*>:$/ { inside = ($0 ~ /run_(tet_)?packs_avx/) }
        inside && /core::core_arch|9core_arch|\{\{closure\}\}>$|\{closure#[0-9]+\}>$|<_RNC|try_map|try_from_fn/'
}
# The pattern itself is checked first, on a made-up disassembly: five calls it must flag
# (both manglings), two lines it must not (a jump inside a loop whose v0 name ends in a
# closure parameter, a call outside the SIMD loops).
sample='0000000000001000 <host_tools::problem::batched::run_packs_avx>:
    1000:\tcall   2000 <host_tools::problem::batched::run_packs_avx::{{closure}}>
    1005:\tcall   2100 <host_tools::problem::batched::run_packs_avx::{closure#0}>
    100a:\tcall   2200 <_RNCNvNtNtCs1a_10host_tools7problem7batched13run_packs_avx0B7_>
    100f:\tcall   2300 <core::core_arch::x86::avx::_mm256_add_pd>
    1014:\tcall   2400 <core::array::try_from_fn>
    1019:\tjne    1100 <host_tools::problem::batched::run_packs_avx::<f64, plan::{closure#0}>+0x100>
0000000000003000 <host_tools::problem::batched::run_packs_scalar>:
    3000:\tcall   2000 <host_tools::other::{closure#1}>'
flagged=$(printf '%b\n' "$sample" | out_of_line | wc -l)
if [ "$flagged" -ne 5 ]; then
    echo "check-simd-inlined: FAIL: the pattern flags $flagged lines of the sample, not its 5 out-of-line calls"
    exit 1
fi
bad=$(out_of_line < "$dis")
if [ -n "$bad" ]; then
    echo "check-simd-inlined: FAIL: out-of-line calls in the SIMD element loops of $bin:"
    echo "$bad" | sed -E "s/^[^<]*<//; s/>$//" | sort | uniq -c | sort -rn | head -20
    exit 1
fi
echo "check-simd-inlined: passed ($functions SIMD element loops, no out-of-line intrinsic, closure or map)"
