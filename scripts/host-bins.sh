# Sourced by the scripts that run `pe` and `board-sim` (from the repository root, with
# TARGET_DIR set): builds them exactly as the README's test command does and sets PE and SIM.
# `cargo test --workspace --release` resolves features with the dev-dependencies (serde and
# postcard with alloc, num-traits with i128, ...), which a `cargo build -p host-tools` does
# not, so a plain build compiles host-tools and everything under it a second time (3 to 4
# minutes on 2 cores, measured). Building the bins through the CLI tests' target keeps one
# feature set: after the tests nothing is compiled again.
cargo test --workspace --release --no-run -q --test cli
PE=$TARGET_DIR/release/pe
SIM=$TARGET_DIR/release/board-sim
