#!/usr/bin/env bash
# Fuzzing of every parser that reads outside data (fuzz/: frames, packets, the COBS stream,
# global payloads, schedule images, MSH, VTK, scene TOML). See fuzz/FUZZ_NOTES.md.
#
#   scripts/fuzz.sh [--seconds N]              stable Rust (CI): replays fuzz/seeds and
#                                              fuzz/regressions through every target's
#                                              check, then N s of seeded random mutations
#                                              per target (default 20; the seed is printed,
#                                              PE_FUZZ_SEED=<n> replays it)
#   scripts/fuzz.sh --libfuzzer [--seconds N] [TARGET...]
#                                              coverage-guided: cargo-fuzz 0.13 (installed if
#                                              missing) with libFuzzer and AddressSanitizer on
#                                              the stable toolchain (RUSTC_BOOTSTRAP=1), N s per
#                                              target, seeds and regressions as corpus
set -euo pipefail
cd "$(dirname "$0")/../fuzz"

seconds=20
mode=stable
targets=()
while [ $# -gt 0 ]; do
    case "$1" in
        --seconds) seconds="$2"; shift 2 ;;
        --libfuzzer) mode=libfuzzer; shift ;;
        -h|--help) sed -n 2,15p "$0"; exit 0 ;;
        -*) echo "fuzz.sh: unknown option $1" >&2; exit 2 ;;
        *) targets+=("$1"); shift ;;
    esac
done
case "$seconds" in ''|*[!0-9]*) echo "fuzz.sh: --seconds wants a whole number, got '$seconds'" >&2; exit 2 ;; esac
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/../target}/fuzz"

if [ "$mode" = stable ]; then
    [ ${#targets[@]} -eq 0 ] || { echo "fuzz.sh: targets are chosen only with --libfuzzer" >&2; exit 2; }
    # Debug assertions and overflow checks on (the test profile), dependencies optimised.
    PE_FUZZ_SECONDS="$seconds" cargo test -p pe-fuzz-checks --test replay -- --nocapture
    exit 0
fi

if ! cargo fuzz --version 2>/dev/null | grep -q '^cargo-fuzz 0\.13\.'; then
    cargo install cargo-fuzz --version '^0.13' --locked
fi
if [ ${#targets[@]} -eq 0 ]; then
    mapfile -t targets < <(RUSTC_BOOTSTRAP=1 cargo fuzz list)
fi
export RUSTC_BOOTSTRAP=1
cargo fuzz build
for t in "${targets[@]}"; do
    corpus="$CARGO_TARGET_DIR/corpus/$t"
    mkdir -p "$corpus" "regressions/$t"
    # Corpus first (new inputs go there), then the committed seeds and regressions (read).
    cargo fuzz run "$t" "$corpus" "seeds/$t" "regressions/$t" -- \
        -max_total_time="$seconds" -max_len=262144 -rss_limit_mb=2048 -print_final_stats=1
done
