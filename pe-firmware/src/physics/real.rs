//! The scalar type every physics routine is generic over.
//!
//! Transcendental functions go through `libm` (or, for `ln` near 1, a series written here
//! in basic arithmetic), never `std`, so the host and the board compute the same bits. Basic arithmetic is IEEE 754 on both (no fused multiply-add is
//! emitted unless asked for), and `libm::sqrt` is correctly rounded like the FPU's.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A floating-point scalar: `f32` or `f64` on the board, or a counting wrapper on the host.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + Send
    + Sync
    + 'static
{
    const ZERO: Self;
    const ONE: Self;
    /// Name used in reports ("f32", "f64").
    const NAME: &'static str;
    /// The shape of the general reduced kernel (`HexReduced`): whether it takes the
    /// hourglass displacements with each displacement component's row of `H` and adds the
    /// forces one component at a time (the synthesis and scatter of each component in
    /// turn), or all hourglass displacements after `H` and the three components per
    /// corner. A choice of code shape, not of values: every force component receives the
    /// same single addition either way, so both give the same bits. On the Cortex-M7, whose
    /// FPU holds 16 doubles or 32 singles, it is the cheaper shape in f64 and the dearer one
    /// in f32 (`scripts/board-cost.sh`, general element-step on the built-in: f64 957
    /// against 1058, f32 860 against 815).
    const FORCES_BY_COMPONENT: bool = false;
    /// Round a double to this type (round-to-nearest for `f32`).
    fn from_f64(x: f64) -> Self;
    fn to_f64(self) -> f64;
    fn sqrt(self) -> Self;
    /// Natural logarithm: [`ln_near_one`] within [`LN_SERIES_RADIUS`] of 1 (where the
    /// Jacobians of soft tissue live), `libm` elsewhere.
    fn ln(self) -> Self;
    /// Real cube root.
    fn cbrt(self) -> Self;
    fn abs(self) -> Self;
    fn is_finite(self) -> bool;
    #[inline(always)]
    fn from_i32(x: i32) -> Self {
        Self::from_f64(x as f64)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        if other > self {
            other
        } else {
            self
        }
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        if other < self {
            other
        } else {
            self
        }
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const NAME: &'static str = "f64";
    const FORCES_BY_COMPONENT: bool = true;
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        let d = self - 1.0;
        if libm::fabs(d) <= LN_SERIES_RADIUS {
            ln_near_one(d, LN_SERIES_TERMS_F64)
        } else {
            libm::log(self)
        }
    }
    #[inline(always)]
    fn cbrt(self) -> Self {
        libm::cbrt(self)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        libm::fabs(self)
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const NAME: &'static str = "f32";
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        libm::sqrtf(self)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        let d = self - 1.0;
        if libm::fabsf(d) <= LN_SERIES_RADIUS as f32 {
            ln_near_one(d, LN_SERIES_TERMS_F32)
        } else {
            libm::logf(self)
        }
    }
    #[inline(always)]
    fn cbrt(self) -> Self {
        libm::cbrtf(self)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        libm::fabsf(self)
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
}

/// Where [`Real::ln`] takes the series [`ln_near_one`]: `|x − 1| ≤ 1/8` (a volume change
/// of up to 12.5%, far beyond what nearly incompressible tissue shows), so
/// `|s| = |x − 1|/(x + 1) ≤ 1/15` and `s² ≤ 1/225`. The test is one comparison of
/// `|x − 1|`, which the series needs anyway.
pub const LN_SERIES_RADIUS: f64 = 0.125;
/// Terms of the series after the first in f64: the first left out, `s¹⁴/15 ≤ 2.3e-18` of
/// the sum, is a fiftieth of its last bit (2⁻⁵³ ≈ 1.1e-16).
pub const LN_SERIES_TERMS_F64: usize = 6;
/// The same in f32: `s⁸/9 ≤ 4.3e-11` against 2⁻²⁴ ≈ 6.0e-8 (two terms would leave
/// `s⁶/7 ≤ 1.3e-8`, a fifth of the last bit).
pub const LN_SERIES_TERMS_F32: usize = 3;

/// The larger of `a` and `b`, and NaN when either is NaN, unlike `f64::max`, which returns
/// the other operand (`NAN.max(1.0) == 1.0`): the maximum every check that folds
/// differences goes through, so a NaN result is never read as "no difference".
pub fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// `ln x = 2 artanh s = s (2 + 2s²/3 + 2s⁴/5 + … + 2s²ⁿ/(2n + 1))` with
/// `s = (x − 1)/(x + 1)`, `n = terms`, in Horner form, for `|x − 1| ≤`
/// [`LN_SERIES_RADIUS`] (`d = x − 1` given, exact there), where it needs no range reduction
/// and so costs a division and about `2n + 4` operations against `libm`'s bit
/// manipulation, reduction and special cases (on the Cortex-M7, 64 instructions for
/// `libm::log`). Within 2 ulp of `libm` on its range (the test
/// `series_logarithm_matches_libm`), and only basic arithmetic, so every target computes
/// the same bits.
#[inline(always)]
pub fn ln_near_one<T: Real>(d: T, terms: usize) -> T {
    let s = d / (d + T::from_i32(2));
    let z = s * s;
    // The coefficients 2/(2n + 1), rounded from f64 (constants on every target).
    let coefficient = |n: usize| T::from_f64(2.0 / (2 * n + 1) as f64);
    let mut p = coefficient(terms);
    for n in (0..terms).rev() {
        p = p * z + coefficient(n);
    }
    s * p
}

/// `[f(0), …, f(N − 1)]` by a plain loop, always inlined: the kernels build their small
/// arrays with it rather than `core::array::from_fn` or `map`, whose closures the
/// optimiser may keep out of line when a kernel is inlined into a batched loop (measured:
/// it then runs several times slower on the host's SIMD lanes).
#[inline(always)]
pub fn array<T: Copy + Default, const N: usize>(mut f: impl FnMut(usize) -> T) -> [T; N] {
    let mut a = [T::default(); N];
    for (i, v) in a.iter_mut().enumerate() {
        *v = f(i);
    }
    a
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    /// Distance in units in the last place between two finite values of the same sign.
    fn ulps64(a: f64, b: f64) -> u64 {
        assert_eq!(
            a.is_sign_negative(),
            b.is_sign_negative(),
            "{a:e} against {b:e}"
        );
        a.to_bits().abs_diff(b.to_bits())
    }

    fn ulps32(a: f32, b: f32) -> u32 {
        assert_eq!(
            a.is_sign_negative(),
            b.is_sign_negative(),
            "{a:e} against {b:e}"
        );
        a.to_bits().abs_diff(b.to_bits())
    }

    /// The series against `libm` (within 1 ulp of the exact logarithm) across its range:
    /// densely, at the ends, and next to 1 where the logarithm is tiny and only a relative
    /// error bound means anything. Tolerance 2 ulp: the series' own bound (the rounding of
    /// `x + 1`, of the division and of the last product; its truncation is far below).
    #[test]
    fn series_logarithm_matches_libm() {
        let r = LN_SERIES_RADIUS;
        let mut xs: Vec<f64> = (0..=1_000_000)
            .map(|k| 1.0 - r + 2.0 * r * k as f64 / 1e6)
            .collect();
        assert_eq!((xs[0], xs[1_000_000]), (1.0 - r, 1.0 + r));
        let mut near = 1.0f64;
        for _ in 0..2000 {
            near = f64::from_bits(near.to_bits() + 1);
            xs.push(near);
            xs.push(f64::from_bits(2.0f64.to_bits() - near.to_bits()));
        }
        assert!(xs.len() > 1_000_000);
        let (mut worst64, mut worst32) = (0, 0);
        let mut span = (0.0f64, 0.0f64);
        for &x in &xs {
            let (got, want) = (x.ln(), libm::log(x));
            assert!(x == 1.0 || got != 0.0, "ln({x:e}) = 0");
            if x == 1.0 {
                assert_eq!(got, 0.0);
                continue;
            }
            worst64 = worst64.max(ulps64(got, want));
            span = (span.0.min(got), span.1.max(got));
            let x32 = x as f32;
            if x32 != 1.0 {
                worst32 = worst32.max(ulps32(x32.ln(), libm::logf(x32)));
            }
        }
        assert!(span.0 < -0.13 && span.1 > 0.11, "logarithms span {span:?}");
        assert!(worst64 <= 2, "f64 series {worst64} ulp from libm::log");
        assert!(worst32 <= 2, "f32 series {worst32} ulp from libm::logf");
    }

    /// Outside its range `ln` is `libm`'s, bit for bit, special values included.
    #[test]
    fn outside_the_series_range_ln_is_libm() {
        let xs = [
            0.0,
            -1.0,
            f64::INFINITY,
            f64::NAN,
            1e-300,
            0.5,
            0.87499,
            1.12501,
            2.0,
            1e300,
        ];
        for x in xs {
            let (got, want) = (x.ln(), libm::log(x));
            assert!(got.to_bits() == want.to_bits() || got.is_nan() && want.is_nan());
            let x = x as f32;
            let (got, want) = (x.ln(), libm::logf(x));
            assert!(got.to_bits() == want.to_bits() || got.is_nan() && want.is_nan());
        }
    }
}
