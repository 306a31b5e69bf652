#!/usr/bin/env bash
# Runs every test of the workspace on a fresh machine: installs what it needs first.
set -euo pipefail
cd "$(dirname "$0")/.."

rustup target add thumbv7em-none-eabihf >/dev/null 2>&1 || rustup target add thumbv7em-none-eabihf

# The board crates must build for the board: no_std, allocation-free, Cortex-M7 FPU.
RUSTFLAGS="-C target-cpu=cortex-m7" cargo build --release --target thumbv7em-none-eabihf \
    -p pe-firmware -p link-proto

# The prototype board's register words (DMA stream configuration with TRBUFF, the MPU's
# uncached region, clocks by silicon revision), computed through the STM32H7 PAC: the
# board crate's unit tests, on the host.
cargo test --manifest-path pe-firmware/board/Cargo.toml --lib --no-default-features \
    --features stm32h743

# Host tests (optimised: the physics tests run 1e5-step simulations).
cargo test --workspace --release

# Which SIMD lanes those bit-identity tests ran on this CPU, and which they skipped and why
# (the same build: nothing is compiled again).
cargo test --workspace --release -q --test solver lanes_tested_and_skipped_are_named \
    -- --nocapture 2>/dev/null | grep '^lanes tested'

bash scripts/lanes-emulated.sh

# The host on ARM (aarch64: Apple and other ARM laptops), cross-compiled and run under
# qemu-aarch64: the batched bit tests on the portable lanes' NEON clone, and `pe solve`
# bit-identical to this machine's run (contact, dt tracking, the subnormal flush).
bash scripts/lanes-aarch64.sh

# The host's SIMD element loops keep their lanes in registers (no kernel closure, `map` or
# intrinsic left out of line): a speed property the bit-identity tests cannot see.
bash scripts/check-simd-inlined.sh

# The board firmware on an emulated Cortex-M7 (QEMU mps2-an500): bit-identical to `pe solve`
# and board-sim (f64, f32), faults reported. Installs qemu-system-arm if missing.
bash scripts/qemu-check.sh

# Board arrays under QEMU (one emulated Cortex-M7 per board, UARTs as cables): 2x1x1,
# 2x2x1, 2x2x2 bit-identical to board-sim; a dead board and crossed cables reported.
bash scripts/qemu-array.sh

# The firmware's measured cost (QEMU, exact instruction counts) against the table the
# compiler and board-sim use: fails when pe_firmware::profile::MEASURED_COST is stale.
bash scripts/board-cost.sh

# The trainer page in a real browser (Debian's chromium, headless, driven by Playwright):
# the probe dragged onto the right tube moves it and raises the force bar; surface frames
# >= 25 Hz; screenshots in target/live/. Installs chromium and playwright-core if missing.
bash scripts/live-check.sh

# OpenIGTLink with an independent client (pyigtl from PyPI, pinned, in a venv under the
# target dir): TRANSFORMs move the probe; forces (POINT) and the surface (POLYDATA) come back;
# an unknown device is answered with an error while the connection goes on.
bash scripts/igtl-check.sh

# The result frames in the readers users have: meshio 5.3.5 and pyvista (VTK's reader), pinned
# in a venv under the target dir: pe solve's volume frames and board-sim's surface frames
# load in both with the same values and the region names (tests/vtu/readers.py).
bash scripts/vtu-readers.sh
