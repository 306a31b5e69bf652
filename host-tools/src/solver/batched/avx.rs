//! Lane types over AVX registers (x86-64): 4 f64 in a `__m256d`, 8 f32 in a `__m256`, as
//! [`Real`]s whose every operation is one IEEE 754 instruction per lane (add, sub, mul,
//! div, sqrt: correctly rounded, the scalar's bits) or the scalar `libm` function per lane
//! (`ln`, `cbrt`). No fused multiply-add is used.
//!
//! Safety: the methods call AVX intrinsics. They are only executed inside functions
//! compiled with `#[target_feature(enable = "avx")]` and reached after
//! `is_x86_feature_detected!("avx")` (see [`super::Batched::build`]); a value of these types is
//! only ever built there, so no AVX instruction runs on a CPU without AVX.

use core::arch::x86_64::*;
use core::cmp::Ordering;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

use pe_firmware::physics::{LaneReal, Real};

macro_rules! avx_lanes {
    ($name:ident, $reg:ty, $s:ty, $n:expr, $add:ident, $sub:ident, $mul:ident, $div:ident,
     $sqrt:ident, $xor:ident, $andnot:ident, $set1:ident, $loadu:ident, $storeu:ident,
     $cmp:ident, $movemask:ident) => {
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
                self.each(<$s as Real>::ln)
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

        impl LaneReal<$s, $n> for $name {
            #[inline(always)]
            fn from_lanes(v: [$s; $n]) -> Self {
                Self::of(v)
            }
            #[inline(always)]
            fn to_lanes(self) -> [$s; $n] {
                self.lanes()
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
    _mm256_movemask_pd
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
    _mm256_movemask_ps
);
