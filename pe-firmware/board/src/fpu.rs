//! The FPU's mode: subnormal numbers flushed to zero, as the host solver computes
//! (`host_tools::subnormals`). Set once at reset, before any floating-point work.
//!
//! In flush-to-zero mode a subnormal operand is read as a zero of its sign and a result
//! whose magnitude is below the least normal number before rounding becomes a zero of its
//! sign. Besides matching the host's bits, it keeps the cost of an operation independent
//! of how small the numbers are (the tissue far from the tool is nearly at rest).

#[cfg(target_arch = "arm")]
use cortex_m::peripheral::FPU;
#[cfg(target_arch = "arm")]
use cortex_m::register::fpscr::{self, Fpscr};

/// FPSCR.FZ and FPDSCR.FZ: bit 24 of both.
#[cfg(target_arch = "arm")]
const FZ: u32 = 1 << 24;

/// Sets flush-to-zero mode for this context and for exception handlers' contexts.
#[cfg(target_arch = "arm")]
pub fn flush_subnormals() {
    // FPSCR bit 24, FZ, "Flush-to-zero mode control bit" (ARMv7-M Architecture Reference
    // Manual, DDI 0403E, "Floating-point Status and Control Register, FPSCR"; Cortex-M7
    // TRM, DDI 0489, "Floating Point Status and Control Register": 1 = flush-to-zero mode
    // enabled). The other bits are kept.
    let now = fpscr::read().bits();
    // SAFETY: only the mode bit changes; no floating-point value is live across the write
    // (called first thing at reset).
    unsafe { fpscr::write(Fpscr::from_bits(now | FZ)) };
    // FPDSCR (0xE000_EF3C) bit 24, FZ: the FPSCR.FZ value a new floating-point context
    // (an exception handler's) starts with (DDI 0403E, "Floating Point Default Status
    // Control Register, FPDSCR"), so handlers compute in the same mode.
    // SAFETY: a read-modify-write of the one register through cortex-m's register block;
    // FPU::PTR is its architected address.
    unsafe { (*FPU::PTR).fpdscr.modify(|v| v | FZ) };
}
