#!/usr/bin/env bash
# The host's lanes on the instruction sets this CPU would not pick: the portable lanes and
# the node update are compiled for several (multiversion clones: AVX-512, AVX2, AVX, and
# the baseline), and a CPU runs only the widest it has, so an AVX-512 machine never runs
# the AVX2 clone a laptop runs. Here the bit-identity tests run again under QEMU's user-mode
# emulator posing as older CPUs (QEMU's TCG runs AVX and AVX2, not AVX-512):
#   Haswell      AVX2 + FMA, no AVX-512: the AVX2 clones and the AVX lanes
#   SandyBridge  AVX only: the AVX clones and the AVX lanes
#   Nehalem      SSE4.2, no AVX: the baseline clones, the portable lanes only
# Each prints the lanes it tested. The tests: every batched-loop bit test of the solver
# (lanes against the scalar loop, f32 and f64, boards' batches, faults named alike) and one
# board against the serial solver bit for bit (the node update's clone against the
# firmware's scalar update, 1000 steps with contact).
# x86-64 only; installs qemu-user (qemu-x86_64) with apt if it is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "$(uname -m)" != x86_64 ]; then
    echo "lanes-emulated.sh: x86-64 only (this is $(uname -m)); skipped"
    exit 0
fi
if ! command -v qemu-x86_64 >/dev/null 2>&1; then
    apt-get update -qq && apt-get install -y -qq qemu-user >/dev/null
fi
# The test executables, as `cargo test --workspace --release` built them (the same build:
# a package alone would unify other features and compile the crates again).
exe() {
    cargo test --workspace --release --no-run --message-format=json 2>/dev/null | python3 -c '
import json, sys
pkg, name = sys.argv[1], sys.argv[2]
paths = [m["executable"] for m in map(json.loads, sys.stdin)
         if m.get("reason") == "compiler-artifact" and m.get("executable") and m["profile"]["test"]
         and m["target"]["name"] == name and m["package_id"].split("#")[0].rstrip("/").split("/")[-1].split("@")[0] in (pkg, "")]
assert len(paths) == 1, (pkg, name, paths)
print(paths[0])' "$1" "$2"
}
SOLVER=$(exe host-tools solver)
BOARDS=$(exe tests board_sim)
for cpu in Haswell SandyBridge Nehalem; do
    out=$(timeout 900 qemu-x86_64 -cpu "$cpu" "$SOLVER" batched:: --nocapture --test-threads 2 2>&1) || { echo "$out" >&2; echo "lanes-emulated.sh: the solver's batched tests failed on $cpu" >&2; exit 1; }
    lanes=$(grep '^lanes tested' <<<"$out")
    passed=$(grep -o '[0-9]* passed' <<<"$out" | tail -1)
    out=$(timeout 900 qemu-x86_64 -cpu "$cpu" "$BOARDS" one_board_equals_serial_bit_for_bit 2>&1) || { echo "$out" >&2; echo "lanes-emulated.sh: one board against serial failed on $cpu" >&2; exit 1; }
    grep -q '1 passed' <<<"$out" || { echo "$out" >&2; echo "lanes-emulated.sh: the board test did not run on $cpu" >&2; exit 1; }
    echo "emulated $cpu: $lanes; batched tests $passed; one board = serial bit for bit"
done
