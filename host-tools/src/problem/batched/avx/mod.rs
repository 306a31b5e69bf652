//! Lane types over AVX registers (x86-64): 4 f64 in a `__m256d`, 8 f32 in a `__m256`, and
//! over AVX-512 registers 8 f64 in a `__m512d`, 16 f32 in a `__m512`, as
//! [`Real`]s whose every operation is one IEEE 754 instruction per lane (add, sub, mul,
//! div, sqrt: correctly rounded, the scalar's bits) or the scalar function per lane
//! (`cbrt`). `ln` is the scalar's [`Real::ln`] in the registers: the series
//! ([`ln_near_one`]) in the lanes where the scalar takes it (the kernels' Jacobians), and
//! `libm`'s own algorithm in the others (FreeBSD's `e_log.c` / `e_logf.c`: the argument
//! reduction per lane in integers, then the polynomial in the registers, in `libm`'s order
//! of operations), both in the scalar's order of operations, so the scalar's bits; the
//! scalar per lane when a lane is not a positive normal number. Tests hold it to the scalar
//! on inputs across the whole range. No fused multiply-add is used.
//!
//! Safety: the methods call AVX (AVX-512F and DQ for the 512-bit types) intrinsics. They
//! are only executed inside functions compiled with `#[target_feature(enable = "avx")]`
//! (`"avx512f,avx512dq"`) and reached after `is_x86_feature_detected!` found those features
//! (see [`super::Isa::detect`] and [`super::Batched::build`]); a value of these types is
//! only ever built there, so no AVX (AVX-512) instruction runs on a CPU without it. "AVX is
//! present" in the comments below means the type's instruction set.

use core::arch::x86_64::*;
use core::cmp::Ordering;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

use pe_firmware::physics::real::{
    ln_near_one, LN_SERIES_RADIUS, LN_SERIES_TERMS_F32, LN_SERIES_TERMS_F64,
};
use pe_firmware::physics::{LaneReal, Real};

mod gather;
mod log;

macro_rules! avx_lanes {
    ($name:ident, $reg:ty, $s:ty, $n:expr, $add:ident, $sub:ident, $mul:ident, $div:ident,
     $sqrt:ident, $xor:ident, $andnot:ident, $set1:ident, $loadu:ident, $storeu:ident,
     $cmp:ident, $movemask:ident, $blendv:ident, $ln_terms:expr) => {
        /// AVX lanes; see the module doc.
        #[derive(Clone, Copy, Debug)]
        #[repr(transparent)]
        pub struct $name($reg);

        impl $name {
            #[inline(always)]
            fn lanes(self) -> [$s; $n] {
                let mut out = [0.0; $n];
                // SAFETY: AVX is present (module doc); `out` holds $n values.
                unsafe { $storeu(out.as_mut_ptr(), self.0) };
                out
            }
            #[inline(always)]
            fn of(v: [$s; $n]) -> Self {
                // SAFETY: AVX is present (module doc); `v` holds $n values.
                $name(unsafe { $loadu(v.as_ptr()) })
            }
            #[inline(always)]
            fn splat(x: $s) -> Self {
                // SAFETY: AVX is present (module doc).
                $name(unsafe { $set1(x) })
            }
            #[inline(always)]
            fn each(self, f: impl Fn($s) -> $s) -> Self {
                let mut v = self.lanes();
                for x in v.iter_mut() {
                    *x = f(*x);
                }
                Self::of(v)
            }
            /// Whether `cmp` holds in every lane.
            #[inline(always)]
            fn all<const CMP: i32>(self, o: Self) -> bool {
                // SAFETY: AVX is present (module doc).
                unsafe { $movemask($cmp::<CMP>(self.0, o.0)) == (1 << $n) - 1 }
            }
            /// [`Real::ln`] of the scalar lane by lane (see the module doc): the series
            /// where every lane is in its range; else `libm`'s log in the registers
            /// (`libm_log`), the series blended in for the lanes in range; the scalar per
            /// lane when a lane is not a positive normal number.
            #[inline(always)]
            fn ln_lanes(self) -> Self {
                let d = self - Self::splat(1.0);
                // SAFETY: AVX is present (module doc).
                let near = unsafe { $cmp::<_CMP_LE_OQ>(d.abs().0, $set1(LN_SERIES_RADIUS as $s)) };
                // SAFETY: as above.
                let lanes_near = unsafe { $movemask(near) };
                if lanes_near == (1 << $n) - 1 {
                    return ln_near_one(d, $ln_terms);
                }
                let Some(far) = self.libm_log() else {
                    return self.each(<$s as Real>::ln);
                };
                if lanes_near == 0 {
                    return far;
                }
                let series = ln_near_one(d, $ln_terms);
                // SAFETY: AVX is present (module doc). Takes `series` where `near` is set.
                $name(unsafe { $blendv(far.0, series.0, near) })
            }
        }

        impl Default for $name {
            #[inline(always)]
            fn default() -> Self {
                Self::ZERO
            }
        }

        impl PartialEq for $name {
            fn eq(&self, o: &Self) -> bool {
                self.lanes() == o.lanes()
            }
        }

        /// Ordered only when every lane is (as [`pe_firmware::physics::Lanes`]).
        impl PartialOrd for $name {
            fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
                let (a, b) = (self.lanes(), o.lanes());
                let first = a[0].partial_cmp(&b[0])?;
                a.iter()
                    .zip(&b)
                    .all(|(x, y)| x.partial_cmp(y) == Some(first))
                    .then_some(first)
            }
            // The same relation, one comparison instruction.
            #[inline(always)]
            fn gt(&self, o: &Self) -> bool {
                self.all::<_CMP_GT_OQ>(*o)
            }
            #[inline(always)]
            fn lt(&self, o: &Self) -> bool {
                self.all::<_CMP_LT_OQ>(*o)
            }
        }

        impl Add for $name {
            type Output = Self;
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                // SAFETY: AVX is present (module doc).
                $name(unsafe { $add(self.0, o.0) })
            }
        }
        impl Sub for $name {
            type Output = Self;
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                // SAFETY: AVX is present (module doc).
                $name(unsafe { $sub(self.0, o.0) })
            }
        }
        impl Mul for $name {
            type Output = Self;
            #[inline(always)]
            fn mul(self, o: Self) -> Self {
                // SAFETY: AVX is present (module doc).
                $name(unsafe { $mul(self.0, o.0) })
            }
        }
        impl Div for $name {
            type Output = Self;
            #[inline(always)]
            fn div(self, o: Self) -> Self {
                // SAFETY: AVX is present (module doc).
                $name(unsafe { $div(self.0, o.0) })
            }
        }
        impl Neg for $name {
            type Output = Self;
            #[inline(always)]
            fn neg(self) -> Self {
                // SAFETY: AVX is present (module doc). Flips the sign bit, as scalar `-x`.
                $name(unsafe { $xor(self.0, $set1(-0.0)) })
            }
        }
        impl AddAssign for $name {
            #[inline(always)]
            fn add_assign(&mut self, o: Self) {
                *self = *self + o;
            }
        }
        impl SubAssign for $name {
            #[inline(always)]
            fn sub_assign(&mut self, o: Self) {
                *self = *self - o;
            }
        }
        impl MulAssign for $name {
            #[inline(always)]
            fn mul_assign(&mut self, o: Self) {
                *self = *self * o;
            }
        }

        impl Real for $name {
            // SAFETY (both): plain bit patterns of $n zeros / ones.
            const ZERO: Self = $name(unsafe { core::mem::transmute::<[$s; $n], $reg>([0.0; $n]) });
            const ONE: Self = $name(unsafe { core::mem::transmute::<[$s; $n], $reg>([1.0; $n]) });
            const NAME: &'static str = <$s as Real>::NAME;
            #[inline(always)]
            fn from_f64(x: f64) -> Self {
                // SAFETY: AVX is present (module doc).
                $name(unsafe { $set1(<$s as Real>::from_f64(x)) })
            }
            #[inline(always)]
            fn to_f64(self) -> f64 {
                self.lanes()[0].to_f64()
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                // SAFETY: AVX is present (module doc). Correctly rounded, as `libm`.
                $name(unsafe { $sqrt(self.0) })
            }
            #[inline(always)]
            fn ln(self) -> Self {
                self.ln_lanes()
            }
            #[inline(always)]
            fn cbrt(self) -> Self {
                self.each(<$s as Real>::cbrt)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                // SAFETY: AVX is present (module doc). Clears the sign bit, as `fabs`.
                $name(unsafe { $andnot($set1(-0.0), self.0) })
            }
            fn is_finite(self) -> bool {
                self.lanes().iter().all(|v| v.is_finite())
            }
            fn max(self, o: Self) -> Self {
                let (a, b) = (self.lanes(), o.lanes());
                Self::of(core::array::from_fn(|l| Real::max(a[l], b[l])))
            }
            fn min(self, o: Self) -> Self {
                let (a, b) = (self.lanes(), o.lanes());
                Self::of(core::array::from_fn(|l| Real::min(a[l], b[l])))
            }
        }
        /// The gather checks every index once, then transposes (each type's `corners_in`).
        impl LaneReal<$s, $n> for $name {
            #[inline(always)]
            fn from_lanes(v: [$s; $n]) -> Self {
                Self::of(v)
            }
            #[inline(always)]
            fn to_lanes(self) -> [$s; $n] {
                self.lanes()
            }
            #[inline(always)]
            fn gather_corners(u: &[[$s; 3]], nodes: &[[u32; 8]; $n]) -> Option<[[Self; 3]; 8]> {
                if nodes.iter().flatten().any(|&n| n as usize >= u.len()) {
                    return None;
                }
                // SAFETY: every index is inside `u` (checked above).
                Some(unsafe { Self::corners_in(u, nodes) })
            }
        }
    };
}

avx_lanes!(
    F64x4,
    __m256d,
    f64,
    4,
    _mm256_add_pd,
    _mm256_sub_pd,
    _mm256_mul_pd,
    _mm256_div_pd,
    _mm256_sqrt_pd,
    _mm256_xor_pd,
    _mm256_andnot_pd,
    _mm256_set1_pd,
    _mm256_loadu_pd,
    _mm256_storeu_pd,
    _mm256_cmp_pd,
    _mm256_movemask_pd,
    _mm256_blendv_pd,
    LN_SERIES_TERMS_F64
);
avx_lanes!(
    F32x8,
    __m256,
    f32,
    8,
    _mm256_add_ps,
    _mm256_sub_ps,
    _mm256_mul_ps,
    _mm256_div_ps,
    _mm256_sqrt_ps,
    _mm256_xor_ps,
    _mm256_andnot_ps,
    _mm256_set1_ps,
    _mm256_loadu_ps,
    _mm256_storeu_ps,
    _mm256_cmp_ps,
    _mm256_movemask_ps,
    _mm256_blendv_ps,
    LN_SERIES_TERMS_F32
);

/// AVX-512 mask helpers in the shape the lane macro expects of `movemask` and `blendv`:
/// the comparison already gives a lane mask, and the blend takes it first.
///
/// # Safety
/// None needed (unsafe only as the AVX `movemask`s it stands for).
#[inline(always)]
unsafe fn kmask8_bits(m: __mmask8) -> i32 {
    m as i32
}
/// # Safety
/// None needed (as [`kmask8_bits`]).
#[inline(always)]
unsafe fn kmask16_bits(m: __mmask16) -> i32 {
    m as i32
}
/// # Safety
/// The CPU has AVX-512F.
#[inline(always)]
unsafe fn blend512_pd(a: __m512d, b: __m512d, m: __mmask8) -> __m512d {
    // SAFETY: AVX-512F is present (module doc).
    unsafe { _mm512_mask_blend_pd(m, a, b) }
}
/// # Safety
/// The CPU has AVX-512F.
#[inline(always)]
unsafe fn blend512_ps(a: __m512, b: __m512, m: __mmask16) -> __m512 {
    // SAFETY: AVX-512F is present (module doc).
    unsafe { _mm512_mask_blend_ps(m, a, b) }
}

avx_lanes!(
    F64x8,
    __m512d,
    f64,
    8,
    _mm512_add_pd,
    _mm512_sub_pd,
    _mm512_mul_pd,
    _mm512_div_pd,
    _mm512_sqrt_pd,
    _mm512_xor_pd,
    _mm512_andnot_pd,
    _mm512_set1_pd,
    _mm512_loadu_pd,
    _mm512_storeu_pd,
    _mm512_cmp_pd_mask,
    kmask8_bits,
    blend512_pd,
    LN_SERIES_TERMS_F64
);
avx_lanes!(
    F32x16,
    __m512,
    f32,
    16,
    _mm512_add_ps,
    _mm512_sub_ps,
    _mm512_mul_ps,
    _mm512_div_ps,
    _mm512_sqrt_ps,
    _mm512_xor_ps,
    _mm512_andnot_ps,
    _mm512_set1_ps,
    _mm512_loadu_ps,
    _mm512_storeu_ps,
    _mm512_cmp_ps_mask,
    kmask16_bits,
    blend512_ps,
    LN_SERIES_TERMS_F32
);

#[cfg(test)]
mod tests {
    use super::*;

    /// Inputs across the whole range: random bit patterns (every exponent, both signs,
    /// subnormals, infinities, NaNs), values near 1 (the kernels' Jacobians) and the
    /// special values.
    fn inputs64() -> Vec<f64> {
        let mut v = vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        v.extend([
            f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            std::f64::consts::FRAC_1_SQRT_2,
            std::f64::consts::SQRT_2,
        ]);
        let mut z = 0x1234_5678_9abc_def0u64;
        for k in 0..200_000u64 {
            z ^= z << 13;
            z ^= z >> 7;
            z ^= z << 17;
            v.push(f64::from_bits(z));
            v.push(1.0 + (k as f64 - 100_000.0) * 3e-7);
            // Positive normal numbers of every exponent (whole packs take the SIMD path).
            let e = (z >> 52) % 0x7fe + 1;
            v.push(f64::from_bits((e << 52) | (z & 0x000f_ffff_ffff_ffff)));
            let e32 = (z >> 23) as u32 % 0xfe + 1;
            v.push(f32::from_bits((e32 << 23) | (z as u32 & 0x007f_ffff)) as f64);
        }
        v
    }

    /// `ln` lane by lane against the scalar on `xs` in packs of `N`; the lanes checked.
    fn ln64_matches<const N: usize>(xs: &[f64], ln: impl Fn([f64; N]) -> [f64; N]) -> usize {
        let mut checked = 0;
        for chunk in xs.chunks_exact(N) {
            let x: [f64; N] = core::array::from_fn(|l| chunk[l]);
            let got = ln(x);
            for l in 0..N {
                let want = <f64 as Real>::ln(x[l]);
                assert!(
                    got[l].to_bits() == want.to_bits() || (got[l].is_nan() && want.is_nan()),
                    "log({:e}) = {:e}, scalar {:e} ({N} lanes)",
                    x[l],
                    got[l],
                    want
                );
                checked += 1;
            }
        }
        checked
    }

    /// As [`ln64_matches`] in f32: both f32 bit patterns (random) and values near 1.
    fn ln32_matches<const N: usize>(xs: &[f64], ln: impl Fn([f32; N]) -> [f32; N]) -> usize {
        let mut checked = 0;
        for chunk in xs.chunks_exact(N) {
            let x: [f32; N] = core::array::from_fn(|l| {
                if l % 2 == 0 {
                    f32::from_bits(chunk[l].to_bits() as u32)
                } else {
                    chunk[l] as f32
                }
            });
            let got = ln(x);
            for l in 0..N {
                let want = <f32 as Real>::ln(x[l]);
                assert!(
                    got[l].to_bits() == want.to_bits() || (got[l].is_nan() && want.is_nan()),
                    "logf({:e}) = {:e}, scalar {:e} ({N} lanes)",
                    x[l],
                    got[l],
                    want
                );
                checked += 1;
            }
        }
        checked
    }

    fn has_avx512() -> bool {
        std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx512dq")
    }

    #[test]
    fn lane_ln_is_the_scalar_ln_bit_for_bit() {
        if !std::arch::is_x86_feature_detected!("avx") {
            return;
        }
        let xs = inputs64();
        assert!(ln64_matches::<4>(&xs, |x| F64x4::of(x).ln().lanes()) >= 800_000);
        assert!(ln32_matches::<8>(&xs, |x| F32x8::of(x).ln().lanes()) >= 800_000);
        if has_avx512() {
            assert!(ln64_matches::<8>(&xs, |x| F64x8::of(x).ln().lanes()) >= 800_000);
            assert!(ln32_matches::<16>(&xs, |x| F32x16::of(x).ln().lanes()) >= 800_000);
        }
    }

    /// Whole packs inside the series range take the vector series, packs with one lane
    /// outside take the scalar per lane: both give the scalar's bits. Far from trivial:
    /// the values span the range, so their logarithms span [ln 0.8, ln 1.25].
    fn ln_series_packs<const N: usize, const M: usize>(
        ln64: impl Fn([f64; N]) -> [f64; N],
        ln32: impl Fn([f32; M]) -> [f32; M],
    ) {
        let n = 400_000;
        let r = LN_SERIES_RADIUS;
        let xs: Vec<f64> = (0..=n)
            .map(|k| 1.0 - r + 2.0 * r * k as f64 / n as f64)
            .collect();
        assert_eq!(xs.first(), Some(&(1.0 - r)));
        assert_eq!(xs.last(), Some(&(1.0 + r)));
        let (mut lo, mut hi) = (0.0f64, 0.0f64);
        for (c, chunk) in xs.chunks_exact(N).enumerate() {
            let mut x: [f64; N] = core::array::from_fn(|l| chunk[l]);
            // Every seventh pack has a lane just outside the range.
            if c % 7 == 0 {
                x[c % N] = if c % 2 == 0 { 0.87 } else { 1.13 };
            }
            let got = ln64(x);
            for l in 0..N {
                let want = <f64 as Real>::ln(x[l]);
                assert_eq!(got[l].to_bits(), want.to_bits(), "log({:e})", x[l]);
                (lo, hi) = (lo.min(got[l]), hi.max(got[l]));
            }
        }
        assert!(lo < -0.13 && hi > 0.11, "logarithms span [{lo}, {hi}]");
        let (mut lo, mut hi) = (0.0f32, 0.0f32);
        for (c, chunk) in xs.chunks_exact(M).enumerate() {
            let mut x: [f32; M] = core::array::from_fn(|l| chunk[l] as f32);
            if c % 7 == 0 {
                x[c % M] = if c % 2 == 0 { 0.87 } else { 1.13 };
            }
            let got = ln32(x);
            for l in 0..M {
                let want = <f32 as Real>::ln(x[l]);
                assert_eq!(got[l].to_bits(), want.to_bits(), "logf({:e})", x[l]);
                (lo, hi) = (lo.min(got[l]), hi.max(got[l]));
            }
        }
        assert!(lo < -0.13 && hi > 0.11, "logarithms span [{lo}, {hi}]");
    }

    #[test]
    fn lane_ln_takes_the_series_where_the_scalar_does() {
        if !std::arch::is_x86_feature_detected!("avx") {
            return;
        }
        ln_series_packs::<4, 8>(|x| F64x4::of(x).ln().lanes(), |x| F32x8::of(x).ln().lanes());
        if has_avx512() {
            ln_series_packs::<8, 16>(
                |x| F64x8::of(x).ln().lanes(),
                |x| F32x16::of(x).ln().lanes(),
            );
        }
    }
}
