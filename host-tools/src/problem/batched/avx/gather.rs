//! The gather of the corners' displacements into AVX and AVX-512 lanes (see the parent
//! module's safety note).

use core::arch::x86_64::*;

use super::{F32x16, F32x8, F64x4, F64x8};

/// The gather of the corners' displacements, for both lane types: each lane's 3-vector
/// loaded whole into a register (`f64`: two loads; `f32`: one masked load, lanes `l` and
/// `l + 4` sharing a register in its two halves) and the lanes transposed by shuffles,
/// which only move bits. Measured against the default (element by element into an array,
/// then the lanes from it) on `pe bench`'s box: f32 34 -> 28 ns per element-step, f64
/// about 2% faster.
impl F64x4 {
    /// # Safety
    /// Every index in `nodes` is inside `u`.
    #[inline(always)]
    pub(super) unsafe fn corners_in(u: &[[f64; 3]], nodes: &[[u32; 8]; 4]) -> [[Self; 3]; 8] {
        eight(
            #[inline(always)]
            |a| {
                // SAFETY: AVX is present (module doc); the indices are inside `u` (the
                // caller), and the loads read within one `[f64; 3]`.
                unsafe {
                    let mut r = [_mm256_setzero_pd(); 4];
                    for (r, at) in r.iter_mut().zip(nodes) {
                        let p = u.get_unchecked(at[a] as usize).as_ptr();
                        let xy = _mm_loadu_pd(p);
                        let z = _mm_load_sd(p.add(2));
                        *r = _mm256_insertf128_pd::<1>(_mm256_castpd128_pd256(xy), z);
                        // x y z 0
                    }
                    let t0 = _mm256_unpacklo_pd(r[0], r[1]); // x0 x1 z0 z1
                    let t1 = _mm256_unpackhi_pd(r[0], r[1]); // y0 y1 0 0
                    let t2 = _mm256_unpacklo_pd(r[2], r[3]); // x2 x3 z2 z3
                    let t3 = _mm256_unpackhi_pd(r[2], r[3]); // y2 y3 0 0
                    [
                        F64x4(_mm256_permute2f128_pd::<0x20>(t0, t2)),
                        F64x4(_mm256_permute2f128_pd::<0x20>(t1, t3)),
                        F64x4(_mm256_permute2f128_pd::<0x31>(t0, t2)),
                    ]
                }
            },
        )
    }
}

impl F32x8 {
    /// # Safety
    /// Every index in `nodes` is inside `u`.
    #[inline(always)]
    pub(super) unsafe fn corners_in(u: &[[f32; 3]], nodes: &[[u32; 8]; 8]) -> [[Self; 3]; 8] {
        eight(
            #[inline(always)]
            |a| {
                // SAFETY: AVX is present (module doc); the indices are inside `u` (the
                // caller), and each masked load reads the three values of one `[f32; 3]`
                // and nothing beyond.
                unsafe {
                    let mask = _mm_setr_epi32(-1, -1, -1, 0);
                    let mut r = [_mm_setzero_ps(); 8];
                    for (r, at) in r.iter_mut().zip(nodes) {
                        let p = u.get_unchecked(at[a] as usize).as_ptr();
                        *r = _mm_maskload_ps(p, mask); // x y z 0
                    }
                    let mut h = [_mm256_setzero_ps(); 4];
                    for (l, h) in h.iter_mut().enumerate() {
                        *h = _mm256_set_m128(r[l + 4], r[l]);
                    }
                    let t0 = _mm256_unpacklo_ps(h[0], h[1]); // x0 x1 y0 y1 | x4 x5 y4 y5
                    let t1 = _mm256_unpackhi_ps(h[0], h[1]); // z0 z1 0 0 | z4 z5 0 0
                    let t2 = _mm256_unpacklo_ps(h[2], h[3]); // x2 x3 y2 y3 | x6 x7 y6 y7
                    let t3 = _mm256_unpackhi_ps(h[2], h[3]); // z2 z3 0 0 | z6 z7 0 0
                    [
                        F32x8(_mm256_shuffle_ps::<0x44>(t0, t2)),
                        F32x8(_mm256_shuffle_ps::<0xEE>(t0, t2)),
                        F32x8(_mm256_shuffle_ps::<0x44>(t1, t3)),
                    ]
                }
            },
        )
    }
}

/// `[f(0), …, f(7)]` built from the eight values, for the corners: the gathers used to
/// fill a zeroed array, and the zeroing stayed (a 768-byte `memset` per pack, 3.6% of a
/// step of the seed box in `perf`).
#[inline(always)]
fn eight<T>(mut f: impl FnMut(usize) -> T) -> [T; 8] {
    [f(0), f(1), f(2), f(3), f(4), f(5), f(6), f(7)]
}

/// The AVX-512 gathers: the two halves' lanes gathered as the AVX types gather them, then
/// joined (lanes `0..N/2` low, `N/2..N` high), which only moves bits.
impl F64x8 {
    /// # Safety
    /// Every index in `nodes` is inside `u`.
    #[inline(always)]
    pub(super) unsafe fn corners_in(u: &[[f64; 3]], nodes: &[[u32; 8]; 8]) -> [[Self; 3]; 8] {
        let lo = [nodes[0], nodes[1], nodes[2], nodes[3]];
        let hi = [nodes[4], nodes[5], nodes[6], nodes[7]];
        // SAFETY: AVX-512F is present (module doc); the indices are inside `u` (the
        // caller).
        unsafe {
            let (lo, hi) = (F64x4::corners_in(u, &lo), F64x4::corners_in(u, &hi));
            let join = |l: F64x4, h: F64x4| {
                F64x8(_mm512_insertf64x4::<1>(_mm512_castpd256_pd512(l.0), h.0))
            };
            eight(
                #[inline(always)]
                |a| {
                    [
                        join(lo[a][0], hi[a][0]),
                        join(lo[a][1], hi[a][1]),
                        join(lo[a][2], hi[a][2]),
                    ]
                },
            )
        }
    }
}

impl F32x16 {
    /// # Safety
    /// Every index in `nodes` is inside `u`.
    #[inline(always)]
    pub(super) unsafe fn corners_in(u: &[[f32; 3]], nodes: &[[u32; 8]; 16]) -> [[Self; 3]; 8] {
        let lo = [
            nodes[0], nodes[1], nodes[2], nodes[3], nodes[4], nodes[5], nodes[6], nodes[7],
        ];
        let hi = [
            nodes[8], nodes[9], nodes[10], nodes[11], nodes[12], nodes[13], nodes[14], nodes[15],
        ];
        // SAFETY: AVX-512F and DQ are present (module doc); the indices are inside `u` (the
        // caller).
        unsafe {
            let (lo, hi) = (F32x8::corners_in(u, &lo), F32x8::corners_in(u, &hi));
            let join = |l: F32x8, h: F32x8| {
                F32x16(_mm512_insertf32x8::<1>(_mm512_castps256_ps512(l.0), h.0))
            };
            eight(
                #[inline(always)]
                |a| {
                    [
                        join(lo[a][0], hi[a][0]),
                        join(lo[a][1], hi[a][1]),
                        join(lo[a][2], hi[a][2]),
                    ]
                },
            )
        }
    }
}
