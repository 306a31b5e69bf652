//! Subnormal numbers flushed to zero on the host, as the boards flush them.
//!
//! Where the tissue is nearly at rest (the far field ahead of a wave, a tool's first touch)
//! the state holds numbers below the least normal one (`2⁻¹²⁶` in `f32`, `2⁻¹⁰²²` in `f64`),
//! and every operation on such a subnormal number costs the x86 host a microcode assist:
//! a fine mesh's `f32` step ran 30 times slower. The board does not keep them either: the
//! firmware sets the Cortex-M7's flush-to-zero mode (FPSCR.FZ, `pe_board::fpu`), in which a
//! subnormal operand is read as a zero of its sign and a result whose magnitude is below the
//! least normal number *before rounding* becomes a zero of its sign (ARMv7-M Architecture
//! Reference Manual, DDI 0403E: FPSCR bit 24, and its section "Flush-to-zero mode"). The
//! host computes with the same rule ([`Subnormals::Flush`], the default):
//! - x86-64: MXCSR.DAZ (bit 6) reads subnormal operands as zeros, MXCSR.FTZ (bit 15)
//!   flushes tiny results (Intel SDM Vol. 1, 10.2.3, "MXCSR Control and Status Register");
//! - aarch64: FPCR.FZ (bit 24), the Cortex-M7's own rule, tininess before rounding
//!   included (Arm ARM DDI 0487, FPCR).
//!
//! **Where x86 differs from the board, and why it does not show.** x86 decides that a
//! result is tiny *after* rounding: a product or quotient whose exact magnitude lies in
//! `[2⁻¹²⁶ (1 − 2⁻²⁵), 2⁻¹²⁶)` (`f32`; `[2⁻¹⁰²² (1 − 2⁻⁵⁴), 2⁻¹⁰²²)` in `f64`) rounds up to
//! the least normal number on the host and flushes to zero on the board (the test
//! `x86_decides_tininess_after_rounding` finds such a product). Sums and differences are
//! never in that band: one whose exact value is below the least normal number is exact
//! (its operands' last bits are multiples of the least subnormal), so both flush it. A
//! product lands in the band with a chance of about `2⁻²⁵` per product near the threshold;
//! the QEMU checks (`scripts/qemu-check.sh`, a scene whose state holds subnormals until
//! flushed) compare every run's final state bit for bit.
//!
//! Other architectures run with the default IEEE mode ([`Mode::set`] does nothing there);
//! `pe bench` says which mode ran.
//!
//! Changing the control register is outside what the compiler models, so the mode is set
//! where no floating-point value is live ([`FlushGuard::enter`] at a step's start, a team
//! worker before its tasks: [`crate::team`]), never inside a kernel.

/// How the solver treats subnormal numbers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Subnormals {
    /// Flushed to zero, operands and results, as the boards do (the default).
    #[default]
    Flush,
    /// IEEE gradual underflow (`pe solve --keep-subnormals`): slower where the state is
    /// tiny, and different from the boards' bits where subnormals arise.
    Keep,
}

/// The bits of the thread's floating-point control register that flush subnormals.
#[cfg(target_arch = "x86_64")]
const FLUSH_BITS: u64 = (1 << 15) | (1 << 6); // MXCSR.FTZ | MXCSR.DAZ
#[cfg(target_arch = "aarch64")]
const FLUSH_BITS: u64 = 1 << 24; // FPCR.FZ
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
const FLUSH_BITS: u64 = 0;

/// A thread's floating-point control register (x86-64: MXCSR without its exception flags;
/// aarch64: FPCR; elsewhere 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mode(u64);

impl Mode {
    /// This thread's mode.
    pub fn current() -> Mode {
        Mode(read())
    }

    /// This mode with subnormals flushed or kept.
    pub fn with(self, s: Subnormals) -> Mode {
        match s {
            Subnormals::Flush => Mode(self.0 | FLUSH_BITS),
            Subnormals::Keep => Mode(self.0 & !FLUSH_BITS),
        }
    }

    /// Whether this mode flushes subnormals (false where the host cannot).
    pub fn flushes(self) -> bool {
        FLUSH_BITS != 0 && self.0 & FLUSH_BITS == FLUSH_BITS
    }

    /// Makes this the thread's mode (a write only when it differs).
    pub fn set(self) {
        if read() != self.0 {
            write(self.0);
        }
    }
}

/// The thread's mode with subnormals flushed or kept until the guard is dropped, then the
/// mode before it.
pub struct FlushGuard {
    before: Mode,
}

impl FlushGuard {
    pub fn enter(s: Subnormals) -> FlushGuard {
        let before = Mode::current();
        before.with(s).set();
        FlushGuard { before }
    }
}

impl Drop for FlushGuard {
    fn drop(&mut self) {
        self.before.set();
    }
}

#[cfg(target_arch = "x86_64")]
fn read() -> u64 {
    let mut mxcsr: u32 = 0;
    // SAFETY: STMXCSR stores the 32-bit MXCSR at the given address (SSE, present on every
    // x86-64 CPU).
    unsafe {
        core::arch::asm!("stmxcsr [{}]", in(reg) &mut mxcsr, options(nostack, preserves_flags));
    }
    // Without the six sticky exception flags (bits 0-5): a mode is the control bits.
    u64::from(mxcsr & !0x3F)
}

#[cfg(target_arch = "x86_64")]
fn write(v: u64) {
    let mxcsr = v as u32;
    // SAFETY: LDMXCSR loads MXCSR from the given address; `v` came from `read` with only
    // FTZ and DAZ changed, so no reserved bit is set (which would fault). Every x86-64 CPU
    // with SSE2 has DAZ.
    unsafe {
        core::arch::asm!("ldmxcsr [{}]", in(reg) &mxcsr, options(nostack, preserves_flags));
    }
}

#[cfg(target_arch = "aarch64")]
fn read() -> u64 {
    let fpcr: u64;
    // SAFETY: FPCR is readable at EL0.
    unsafe { core::arch::asm!("mrs {}, fpcr", out(reg) fpcr, options(nomem, nostack)) };
    fpcr
}

#[cfg(target_arch = "aarch64")]
fn write(v: u64) {
    // SAFETY: FPCR is writable at EL0; only FZ differs from the value read.
    unsafe { core::arch::asm!("msr fpcr, {}", in(reg) v, options(nomem, nostack)) };
}

#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
fn read() -> u64 {
    0
}

#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
fn write(_: u64) {}

#[cfg(test)]
mod tests {
    use super::*;
    use std::hint::black_box;

    const LEAST_NORMAL: f32 = f32::MIN_POSITIVE;

    /// Flushing reads a subnormal operand as zero and turns a tiny result into zero; the
    /// guard restores the mode it found. Checked against the IEEE results, which are
    /// subnormal (so the comparison is not between two zeros).
    #[test]
    #[cfg(any(target_arch = "x86_64", target_arch = "aarch64"))]
    fn flushing_zeroes_subnormal_operands_and_results() {
        let before = Mode::current();
        let tiny = black_box(LEAST_NORMAL / 8.0);
        assert!(tiny.is_subnormal() && tiny > 0.0, "{tiny:e}");
        let product = black_box(1e-30f32) * black_box(1e-10f32);
        assert!(
            product.is_subnormal(),
            "IEEE: 1e-40 is subnormal, got {product:e}"
        );
        {
            let _g = FlushGuard::enter(Subnormals::Flush);
            assert!(Mode::current().flushes());
            // A subnormal operand is read as zero: 1 + 0 and 2 * 0.
            assert_eq!((black_box(tiny) * black_box(2.0f32)).to_bits(), 0);
            // A tiny result is flushed.
            assert_eq!((black_box(1e-30f32) * black_box(1e-10f32)).to_bits(), 0);
            // f64 too: 1e-300 * 1e-10 is subnormal in IEEE.
            assert_eq!((black_box(1e-300f64) * black_box(1e-10f64)).to_bits(), 0);
            // And a normal result is untouched.
            assert_eq!(black_box(3.0f32) * black_box(0.5f32), 1.5);
        }
        assert_eq!(Mode::current(), before, "the guard restores the mode");
        let again = black_box(1e-30f32) * black_box(1e-10f32);
        assert_eq!(again.to_bits(), product.to_bits());
    }

    /// The band where x86 and the Cortex-M7 differ (the module doc): a product whose exact
    /// value is just below the least normal number rounds up to it on x86 even with FTZ,
    /// where the board (tininess before rounding) gives zero. The exact product is computed
    /// in f64 (24 + 24 bits fit in 53).
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn x86_decides_tininess_after_rounding() {
        let a = black_box(f32::from_bits(0x3F7F_FFFE)); // 1 − 2⁻²³
        let b = black_box(f32::from_bits(0x0080_0001)); // 2⁻¹²⁶ (1 + 2⁻²³)
        let exact = f64::from(a) * f64::from(b);
        let least = f64::from(LEAST_NORMAL);
        assert!(
            exact < least && exact > least * (1.0 - 2f64.powi(-25)),
            "{exact:e} is in the band"
        );
        let _g = FlushGuard::enter(Subnormals::Flush);
        assert_eq!((a * b).to_bits(), LEAST_NORMAL.to_bits());
    }
}
