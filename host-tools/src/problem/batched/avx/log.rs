//! `libm`'s `log` and `logf` in AVX and AVX-512 lanes, in libm's order of operations (its
//! bits): the argument reduction per lane in integers, the polynomial in the registers.

use super::{F32x16, F32x8, F64x4, F64x8};

/// `libm::log`'s constants (libm 0.2, `log.rs`), the same literals (kept verbatim, digits
/// beyond the type's precision included, so they are visibly libm's).
#[allow(clippy::excessive_precision)]
mod log64 {
    pub const LN2_HI: f64 = 6.93147180369123816490e-01;
    pub const LN2_LO: f64 = 1.90821492927058770002e-10;
    pub const LG1: f64 = 6.666666666666735130e-01;
    pub const LG2: f64 = 3.999999999940941908e-01;
    pub const LG3: f64 = 2.857142874366239149e-01;
    pub const LG4: f64 = 2.222219843214978396e-01;
    pub const LG5: f64 = 1.818357216161805012e-01;
    pub const LG6: f64 = 1.531383769920937332e-01;
    pub const LG7: f64 = 1.479819860511658591e-01;
}

/// `libm::logf`'s constants (libm 0.2, `logf.rs`), the same literals (verbatim).
#[allow(clippy::excessive_precision)]
mod log32 {
    pub const LN2_HI: f32 = 6.9313812256e-01;
    pub const LN2_LO: f32 = 9.0580006145e-06;
    pub const LG1: f32 = 0.66666662693;
    pub const LG2: f32 = 0.40000972152;
    pub const LG3: f32 = 0.28498786688;
    pub const LG4: f32 = 0.24279078841;
}

macro_rules! libm_log64 {
    ($name:ident, $n:expr) => {
        impl $name {
            /// `libm::log` lane by lane, in libm's order of operations (its bits); None when a
            /// lane is zero, subnormal, negative, infinite or NaN (libm's special paths).
            #[inline(always)]
            pub(super) fn libm_log(self) -> Option<Self> {
                use log64::*;
                let x = self.lanes();
                let (mut reduced, mut dk) = ([0.0f64; $n], [0.0f64; $n]);
                for l in 0..$n {
                    let ui = x[l].to_bits();
                    let hx = (ui >> 32) as u32;
                    if !(0x0010_0000..0x7ff0_0000).contains(&hx) {
                        return None;
                    }
                    // Reduce x into [sqrt(2)/2, sqrt(2)]: x = 2^k (1 + f).
                    let hx = hx + (0x3ff0_0000 - 0x3fe6_a09e);
                    let k = ((hx >> 20) as i32) - 0x3ff;
                    let hx = (hx & 0x000f_ffff) + 0x3fe6_a09e;
                    reduced[l] = f64::from_bits(((hx as u64) << 32) | (ui & 0xffff_ffff));
                    dk[l] = k as f64;
                }
                let c = Self::splat;
                let (x, dk) = (Self::of(reduced), Self::of(dk));
                let f = x - c(1.0);
                let hfsq = c(0.5) * f * f;
                let s = f / (c(2.0) + f);
                let z = s * s;
                let w = z * z;
                let t1 = w * (c(LG2) + w * (c(LG4) + w * c(LG6)));
                let t2 = z * (c(LG1) + w * (c(LG3) + w * (c(LG5) + w * c(LG7))));
                let r = t2 + t1;
                Some(s * (hfsq + r) + dk * c(LN2_LO) - hfsq + f + dk * c(LN2_HI))
            }
        }
    };
}
libm_log64!(F64x4, 4);
libm_log64!(F64x8, 8);

macro_rules! libm_log32 {
    ($name:ident, $n:expr) => {
        impl $name {
            /// `libm::logf` lane by lane (as `libm_log64`).
            #[inline(always)]
            pub(super) fn libm_log(self) -> Option<Self> {
                use log32::*;
                let x = self.lanes();
                let (mut reduced, mut dk) = ([0.0f32; $n], [0.0f32; $n]);
                for l in 0..$n {
                    let ix = x[l].to_bits();
                    if !(0x0080_0000..0x7f80_0000).contains(&ix) {
                        return None;
                    }
                    let ix = ix + (0x3f80_0000 - 0x3f35_04f3);
                    let k = ((ix >> 23) as i32) - 0x7f;
                    reduced[l] = f32::from_bits((ix & 0x007f_ffff) + 0x3f35_04f3);
                    dk[l] = k as f32;
                }
                let c = Self::splat;
                let (x, dk) = (Self::of(reduced), Self::of(dk));
                let f = x - c(1.0);
                let s = f / (c(2.0) + f);
                let z = s * s;
                let w = z * z;
                let t1 = w * (c(LG2) + w * c(LG4));
                let t2 = z * (c(LG1) + w * c(LG3));
                let r = t2 + t1;
                let hfsq = c(0.5) * f * f;
                Some(s * (hfsq + r) + dk * c(LN2_LO) - hfsq + f + dk * c(LN2_HI))
            }
        }
    };
}
libm_log32!(F32x8, 8);
libm_log32!(F32x16, 16);
