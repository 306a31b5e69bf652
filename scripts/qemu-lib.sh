# Shared by scripts/qemu-check.sh and scripts/qemu-array.sh (sourced, from the repository
# root, with OUT set): installs qemu-system-arm (apt, only if missing) and the thumbv7em
# target, builds pe and board-sim (scripts/host-bins.sh), and defines build_firmware.
export RUST_BACKTRACE=0
# The schedule comes from the loader here, never linked into the ELF.
unset PE_SCHEDULE_IMAGE

if ! command -v qemu-system-arm >/dev/null 2>&1; then
    echo "$(basename "$0"): installing qemu-system-arm"
    apt-get update -qq && apt-get install -y -qq qemu-system-arm >/dev/null
fi
rustup target add thumbv7em-none-eabihf >/dev/null 2>&1 || rustup target add thumbv7em-none-eabihf

TARGET_DIR=${TARGET_DIR:-${CARGO_TARGET_DIR:-$(pwd)/target}}
source scripts/host-bins.sh

build_firmware() { # FEATURES -> prints the ELF path (a copy per variant, in $OUT)
    cargo build --release -q --target thumbv7em-none-eabihf \
        --manifest-path pe-firmware/board/Cargo.toml --target-dir "$TARGET_DIR" \
        --bin pe-board --no-default-features --features "$1"
    local elf=$OUT/pe-board-${1//,/-}.elf
    cp "$TARGET_DIR/thumbv7em-none-eabihf/release/pe-board" "$elf"
    echo "$elf"
}
