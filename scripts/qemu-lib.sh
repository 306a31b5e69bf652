# Shared by the scripts that run the firmware under QEMU (qemu-check, qemu-array,
# contact-cost, firmware-profile; sourced from the repository root, with OUT set): installs
# qemu-system-arm (apt, only if missing) and the thumbv7em target, builds pe and board-sim
# (scripts/host-bins.sh), and defines build_firmware, build_plugin and cost_mark_address.
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

build_firmware() { # FEATURES -> prints the ELF path (a copy per variant, in $OUT); FEATURES
    # are the board crate's, exactly (no defaults): the parts an image needs (contact,
    # graphics, loads) too
    cargo build --release -q --target thumbv7em-none-eabihf \
        --manifest-path pe-firmware/board/Cargo.toml --target-dir "$TARGET_DIR" \
        --bin pe-board --no-default-features --features "$1"
    local elf=$OUT/pe-board-${1//,/-}.elf
    cp "$TARGET_DIR/thumbv7em-none-eabihf/release/pe-board" "$elf"
    echo "$elf"
}

build_plugin() { # SOURCE.c OUTPUT.so: a QEMU TCG plugin (installs gcc if missing)
    command -v gcc >/dev/null 2>&1 || { apt-get update -qq && apt-get install -y -qq gcc libc6-dev >/dev/null; }
    gcc -O2 -shared -fPIC -fvisibility=hidden -o "$2" "$1"
}

cost_mark_address() { # ELF -> prints the address of pe_cost_mark (the `cost-marks` feature)
    # The crate forbids no_mangle: the marker is found by the name inside its mangled
    # symbol. awk reads to the end: an early exit makes llvm-nm fail on the closed pipe.
    local nm=nm addr
    command -v llvm-nm >/dev/null 2>&1 && nm=llvm-nm
    addr=$("$nm" "$1" | awk '/pe_cost_mark/ && m == "" { m = $1 } END { print m }')
    [ -n "$addr" ] || { echo "$(basename "$0"): no pe_cost_mark in $1" >&2; return 1; }
    echo "0x$addr"
}
