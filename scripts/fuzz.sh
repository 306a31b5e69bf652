#!/usr/bin/env bash
# Fuzzing of every parser that reads outside data (fuzz/: frames, packets, the COBS stream,
# global payloads, schedule images, MSH, VTK, scene TOML). See fuzz/FUZZ_NOTES.md.
#
#   scripts/fuzz.sh [--seconds N]              stable Rust (CI): replays fuzz/seeds and
#                                              fuzz/regressions through every target's
#                                              check, then N s of seeded random mutations
#                                              per target (default 20; the seed is fixed and printed;
#                                              PE_FUZZ_SEED=<n> picks another). The main
#                                              workspace's release build (the test
#                                              command's): no debug assertions or
#                                              overflow checks, see fuzz/FUZZ_NOTES.md
#   scripts/fuzz.sh --libfuzzer [--seconds N] [TARGET...]
#                                              coverage-guided: cargo-fuzz 0.13 (installed if
#                                              missing) with libFuzzer and AddressSanitizer on
#                                              the stable toolchain (RUSTC_BOOTSTRAP=1), N s per
#                                              target, seeds and regressions as corpus, debug
#                                              assertions and overflow checks on
set -euo pipefail
self="$(cd "$(dirname "$0")" && pwd)/$(basename "$0")"
cd "$(dirname "$0")/../fuzz"

seconds=20
mode=stable
targets=()
while [ $# -gt 0 ]; do
    case "$1" in
        --seconds) seconds="$2"; shift 2 ;;
        --libfuzzer) mode=libfuzzer; shift ;;
        -h|--help) sed -n 2,18p "$self"; exit 0 ;;
        -*) echo "fuzz.sh: unknown option $1" >&2; exit 2 ;;
        *) targets+=("$1"); shift ;;
    esac
done
case "$seconds" in ''|*[!0-9]*) echo "fuzz.sh: --seconds wants a whole number, got '$seconds'" >&2; exit 2 ;; esac

if [ "$mode" = stable ]; then
    [ ${#targets[@]} -eq 0 ] || { echo "fuzz.sh: targets are chosen only with --libfuzzer" >&2; exit 2; }
    # fuzz/checks is a member of the main workspace: `--workspace --release` resolves the
    # same features as the test command (scripts/test.sh), so its build is reused as is.
    cd ..
    PE_FUZZ_SECONDS="$seconds" cargo test --workspace --release --test replay -- --nocapture
    exit 0
fi

export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/../target}/fuzz"

if ! cargo fuzz --version 2>/dev/null | grep -q '^cargo-fuzz 0\.13\.'; then
    cargo install cargo-fuzz --version '^0.13' --locked
fi
if [ ${#targets[@]} -eq 0 ]; then
    mapfile -t targets < <(RUSTC_BOOTSTRAP=1 cargo fuzz list)
fi
export RUSTC_BOOTSTRAP=1
# -a: debug assertions and overflow checks on (an overflow panics instead of wrapping).
cargo fuzz build -a
for t in "${targets[@]}"; do
    corpus="$CARGO_TARGET_DIR/corpus/$t"
    mkdir -p "$corpus" "regressions/$t"
    # Corpus first (new inputs go there), then the committed seeds and regressions (read).
    cargo fuzz run -a "$t" "$corpus" "seeds/$t" "regressions/$t" -- \
        -max_total_time="$seconds" -max_len=262144 -rss_limit_mb=2048 -print_final_stats=1
done
