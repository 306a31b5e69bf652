//! Running packs: the pack loop compiled for each lane type's instruction set
//! ([`HostLanes`]), and one kernel's packs in order with the scalar kernel's rerun of a
//! failed pack ([`run`]).

use multiversion::multiversion;
use pe_firmware::physics::explicit::accumulate_internal_forces;
use pe_firmware::physics::{
    HexElement, LaneKernel, LaneReal, Lanes, MaterialLaw, PhysicsError, Real,
};

#[cfg(target_arch = "x86_64")]
use super::avx;
use super::tets::{run_tet_packs_body, TetPass};
use super::{Batch, Isa};
use pe_firmware::physics::element::tet_lanes::TetPack;

/// [`run_packs_body`] on the lane type's instruction set ([`HostLanes::run_packs`]).
#[inline(always)]
pub(super) fn run_with<K, S, L, const N: usize>(
    packs: &[Batch<K, L, N>],
    u: &[[S; 3]],
    scatter: &mut impl FnMut(usize, [S; 3]),
) -> Option<usize>
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: HostLanes<S, N>,
{
    L::run_packs(packs, u, scatter)
}

/// A lane type of the host's loops: its instruction set, and [`run_packs_body`] compiled
/// for it. Each lane type names its own function, so no loop is compiled for lanes wider
/// than its instruction set (whose operations would then be calls).
pub trait HostLanes<S: Real, const N: usize>: LaneReal<S, N> {
    /// The instruction set these lanes run on.
    const ISA: Isa;
    /// [`run_packs_body`] on [`Self::ISA`].
    fn run_packs<K: LaneKernel<S, Self, N>>(
        packs: &[Batch<K, Self, N>],
        u: &[[S; 3]],
        scatter: &mut impl FnMut(usize, [S; 3]),
    ) -> Option<usize>;
    /// [`run_tet_packs_body`] on [`Self::ISA`].
    fn run_tet_packs(
        packs: &[TetPack<Self, N>],
        pass: &mut TetPass<'_, S>,
        u: &[[S; 3]],
    ) -> Option<usize>;
}

impl<S: Real, const N: usize> HostLanes<S, N> for Lanes<S, N>
where
    Lanes<S, N>: LaneReal<S, N>,
{
    const ISA: Isa = Isa::Portable;
    #[inline(always)]
    fn run_packs<K: LaneKernel<S, Self, N>>(
        packs: &[Batch<K, Self, N>],
        u: &[[S; 3]],
        scatter: &mut impl FnMut(usize, [S; 3]),
    ) -> Option<usize> {
        run_packs(packs, u, scatter)
    }
    #[inline(always)]
    fn run_tet_packs(
        packs: &[TetPack<Self, N>],
        pass: &mut TetPass<'_, S>,
        u: &[[S; 3]],
    ) -> Option<usize> {
        run_tet_packs(packs, pass, u)
    }
}

/// The AVX (`avx`) and AVX-512 (`avx512`) lane types on their functions.
#[cfg(target_arch = "x86_64")]
macro_rules! host_lanes {
    ($lanes:ty, $s:ty, $n:expr, $isa:expr, $run:ident, $run_tets:ident, $why:literal) => {
        impl HostLanes<$s, $n> for $lanes {
            const ISA: Isa = $isa;
            #[inline(always)]
            fn run_packs<K: LaneKernel<$s, Self, $n>>(
                packs: &[Batch<K, Self, $n>],
                u: &[[$s; 3]],
                scatter: &mut impl FnMut(usize, [$s; 3]),
            ) -> Option<usize> {
                // SAFETY: a value of this lane type is only built where the CPU has
                // the instruction set (the `avx` module doc): $why.
                unsafe { $run(packs, u, scatter) }
            }
            #[inline(always)]
            fn run_tet_packs(
                packs: &[TetPack<Self, $n>],
                pass: &mut TetPass<'_, $s>,
                u: &[[$s; 3]],
            ) -> Option<usize> {
                // SAFETY: as above: $why.
                unsafe { $run_tets(packs, pass, u) }
            }
        }
    };
}
#[cfg(target_arch = "x86_64")]
host_lanes!(
    avx::F64x4,
    f64,
    4,
    Isa::Avx,
    run_packs_avx,
    run_tet_packs_avx,
    "AVX"
);
#[cfg(target_arch = "x86_64")]
host_lanes!(
    avx::F32x8,
    f32,
    8,
    Isa::Avx,
    run_packs_avx,
    run_tet_packs_avx,
    "AVX"
);
#[cfg(target_arch = "x86_64")]
host_lanes!(
    avx::F64x8,
    f64,
    8,
    Isa::Avx512,
    run_packs_avx512,
    run_tet_packs_avx512,
    "AVX-512F and DQ"
);
#[cfg(target_arch = "x86_64")]
host_lanes!(
    avx::F32x16,
    f32,
    16,
    Isa::Avx512,
    run_packs_avx512,
    run_tet_packs_avx512,
    "AVX-512F and DQ"
);

/// Runs one kernel's packs in order, adding each lane's forces; a failed pack is rerun by
/// the scalar kernel (kernel-order elements from `offset`) for its error.
pub(super) fn run<K, E, S, L, const N: usize>(
    packs: &[Batch<K, L, N>],
    scalar: &[E],
    offset: usize,
    laws: &[MaterialLaw<S>],
    u: &[[S; 3]],
    f: &mut [[S; 3]],
) -> Result<(), PhysicsError>
where
    K: LaneKernel<S, L, N>,
    E: HexElement<S>,
    S: Real,
    L: HostLanes<S, N>,
{
    if u.len() != f.len() {
        return Err(PhysicsError::BadIndex {
            element: offset as u32,
        });
    }
    let mut from = 0;
    loop {
        let rest = packs.get(from..).unwrap_or(&[]);
        let mut add = |n: usize, v: [S; 3]| {
            if let Some(d) = f.get_mut(n) {
                for i in 0..3 {
                    d[i] += v[i];
                }
            }
        };
        let failed = run_with(rest, u, &mut add);
        let Some(j) = failed else { return Ok(()) };
        // The scalar kernel on the failed pack's elements: the error, named as the scalar
        // loop names it (or, should the scalar kernel pass, the pack's forces).
        let b = &packs[from + j];
        let end = (b.first + b.active).min(scalar.len());
        let elems = scalar.get(b.first..end).unwrap_or(&[]);
        accumulate_internal_forces(elems, (offset + b.first) as u32, laws, u, f)?;
        from += j + 1;
    }
}

/// The packs in order, each lane's forces handed to `scatter(node, force)` in the
/// scalar loop's order; the index of the first pack that fails (nothing of it handed
/// out), if any.
#[inline(always)]
fn run_packs_body<K, S, L, const N: usize>(
    packs: &[Batch<K, L, N>],
    u: &[[S; 3]],
    scatter: &mut impl FnMut(usize, [S; 3]),
) -> Option<usize>
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    for (k, b) in packs.iter().enumerate() {
        let r = b.kernel.lane_forces(
            &b.law,
            &b.nodes,
            b.active,
            u,
            #[inline(always)]
            |_, n, v| scatter(n, v),
        );
        if r.is_err() {
            return Some(k);
        }
    }
    None
}

/// [`run_packs_body`] compiled with AVX.
///
/// # Safety
/// The CPU must have AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn run_packs_avx<K, S, L, const N: usize>(
    packs: &[Batch<K, L, N>],
    u: &[[S; 3]],
    scatter: &mut impl FnMut(usize, [S; 3]),
) -> Option<usize>
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    run_packs_body(packs, u, scatter)
}

/// [`run_packs_body`] compiled with AVX-512.
///
/// # Safety
/// The CPU must have AVX-512F and AVX-512DQ.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,avx512f,avx512dq")]
unsafe fn run_packs_avx512<K, S, L, const N: usize>(
    packs: &[Batch<K, L, N>],
    u: &[[S; 3]],
    scatter: &mut impl FnMut(usize, [S; 3]),
) -> Option<usize>
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    run_packs_body(packs, u, scatter)
}

/// [`run_packs_body`] for the portable lanes, compiled for several instruction sets.
#[multiversion(targets(
    "x86_64+avx512f+avx512vl+avx2+avx",
    "x86_64+avx2+avx",
    "x86_64+avx",
    "aarch64+neon"
))]
fn run_packs<K, S, L, const N: usize>(
    packs: &[Batch<K, L, N>],
    u: &[[S; 3]],
    scatter: &mut impl FnMut(usize, [S; 3]),
) -> Option<usize>
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    run_packs_body(packs, u, scatter)
}

/// [`run_tet_packs_body`] compiled with AVX.
///
/// # Safety
/// The CPU must have AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn run_tet_packs_avx<S: Real, L: LaneReal<S, N>, const N: usize>(
    packs: &[TetPack<L, N>],
    pass: &mut TetPass<'_, S>,
    u: &[[S; 3]],
) -> Option<usize> {
    run_tet_packs_body(packs, pass, u)
}

/// [`run_tet_packs_body`] compiled with AVX-512.
///
/// # Safety
/// The CPU must have AVX-512F and AVX-512DQ.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,avx512f,avx512dq")]
unsafe fn run_tet_packs_avx512<S: Real, L: LaneReal<S, N>, const N: usize>(
    packs: &[TetPack<L, N>],
    pass: &mut TetPass<'_, S>,
    u: &[[S; 3]],
) -> Option<usize> {
    run_tet_packs_body(packs, pass, u)
}

/// [`run_tet_packs_body`] for the portable lanes, compiled for several instruction sets.
#[multiversion(targets(
    "x86_64+avx512f+avx512vl+avx2+avx",
    "x86_64+avx2+avx",
    "x86_64+avx",
    "aarch64+neon"
))]
fn run_tet_packs<S: Real, L: LaneReal<S, N>, const N: usize>(
    packs: &[TetPack<L, N>],
    pass: &mut TetPass<'_, S>,
    u: &[[S; 3]],
) -> Option<usize> {
    run_tet_packs_body(packs, pass, u)
}
