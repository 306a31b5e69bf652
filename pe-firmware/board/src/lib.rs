//! The PE board firmware's support code, shared by the firmware (`src/main.rs`) and the
//! on-board benchmark (`src/bin/bench.rs`): build-time configuration, the schedule image
//! region, run-time storage, link drivers, time, logging and fault reports.
//!
//! Only built for `thumbv7em-none-eabihf` (this crate is outside the host workspace). The
//! few `unsafe` blocks (memory-mapped registers, linker-provided regions, the one-time
//! take of the static buffers) live here, each with its argument; `pe-firmware` stays
//! `#![forbid(unsafe_code)]`.
//!
//! The board support's register words are unit-tested on the host (`scripts/test.sh`:
//! `cargo test --lib --target x86_64-unknown-linux-gnu` with the board's features); what
//! only a Cortex-M7 has is `#[cfg(target_arch = "arm")]`.
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_op_in_unsafe_fn)]

#[cfg(all(feature = "qemu", feature = "stm32h743"))]
compile_error!("features `qemu` and `stm32h743` are two boards: build with one (the board build: --no-default-features --features stm32h743,defmt,contact,graphics,loads)");

pub mod fmt;

// The defmt global logger (RTT), for every binary of the crate.
#[cfg(feature = "defmt")]
use defmt_rtt as _;

pub mod bsp;
pub mod clock;
pub mod config;
pub mod fpu;
pub mod links;
pub mod region;
pub mod report;
mod section;
pub mod storage;
pub mod uart;
