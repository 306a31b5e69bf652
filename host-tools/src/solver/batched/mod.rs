//! The host's element loop, batched: the scalar elements ([`Elements`]) packed `N` at a
//! time into lanes, each pack run by the firmware's own kernel code ([`LaneKernel`]). The
//! lanes are chosen at run time ([`Isa::detect`]): AVX-512 registers (8 f64, 16 f32) where
//! the CPU has AVX-512F and DQ, else AVX registers (4 f64, 8 f32), else [`Lanes`] arrays
//! (4 f64, 8 f32) compiled for the best instruction set the CPU has (AVX-512, AVX2, AVX,
//! NEON, or the baseline).
//!
//! Bits: every lane performs the scalar kernel's operations in the same order (the kernels
//! are generic over [`pe_firmware::physics::Real`]), and the forces of a batch are added
//! lane by lane, each element's nodes in the scalar kernel's order, and the batches in
//! kernel order, so the nodal forces are those of the scalar loop
//! ([`Elements::internal_forces`]), which are a one-board machine's. No fused multiply-add
//! is formed (Rust never contracts), whatever the target.
//!
//! A batch takes consecutive elements (kernel order) of one kernel whose laws are of one
//! kind; a batch with fewer than `N` elements (at a kernel's end, or where the law kind
//! changes) repeats its last element in the spare lanes and drops their forces. When a
//! batch fails (an inverted element in some lane, a bad index), its elements are run again
//! by the scalar kernel, one by one, which names the element and its Jacobian exactly as
//! the scalar loop would.

use std::any::Any;
use std::ops::Range;

use multiversion::multiversion;
use pe_firmware::physics::explicit::accumulate_internal_forces;
use pe_firmware::physics::{
    HexBox, HexCuboid, HexElement, HexFull, HexReduced, LaneKernel, LaneReal, Lanes, MaterialLaw,
    Pack, PhysicsError, Real,
};

use super::team::Team;
use crate::problem::elements::Elements;

#[cfg(target_arch = "x86_64")]
mod avx;
pub mod board;

/// Up to `N` consecutive elements of one kernel, packed.
pub struct Batch<K, L, const N: usize> {
    pub kernel: K,
    pub law: MaterialLaw<L>,
    pub nodes: [[u32; 8]; N],
    /// Lanes that hold elements (the rest repeat the last one).
    pub active: usize,
    /// Kernel-order index (within its kernel's list) of lane 0's element.
    pub first: usize,
}

/// Packs `elements` (laws indexed by material) `N` at a time, in order.
fn pack<E, S, L, const N: usize>(
    elements: &[E],
    laws: &[MaterialLaw<S>],
) -> Result<Vec<Batch<E::Packed, L, N>>, PhysicsError>
where
    S: Real,
    L: LaneReal<S, N>,
    E: HexElement<S> + Pack<S, L, N>,
    MaterialLaw<S>: Pack<S, L, N, Packed = MaterialLaw<L>>,
{
    let law_of = |k: usize| {
        elements
            .get(k)
            .and_then(|e| laws.get(e.material()))
            .ok_or(PhysicsError::BadIndex { element: k as u32 })
    };
    // The laws of elements `first..` (the last repeated after `end`), packed.
    let laws_of = |first: usize, end: usize| -> Result<Option<MaterialLaw<L>>, PhysicsError> {
        let mut ls = [law_of(first)?; N];
        for (l, v) in ls.iter_mut().enumerate() {
            *v = law_of((first + l).min(end - 1))?;
        }
        Ok(<MaterialLaw<S> as Pack<S, L, N>>::pack(ls))
    };
    let mut out = Vec::with_capacity(elements.len().div_ceil(N));
    let mut first = 0;
    while first < elements.len() {
        // The longest run (at most N) whose laws pack together.
        let mut end = first + 1;
        while end < elements.len() && end - first < N && laws_of(first, end + 1)?.is_some() {
            end += 1;
        }
        let law = laws_of(first, end)?.ok_or(PhysicsError::BadIndex {
            element: first as u32,
        })?;
        let pick: [&E; N] = core::array::from_fn(|l| &elements[(first + l).min(end - 1)]);
        let kernel = E::pack(pick).ok_or(PhysicsError::BadIndex {
            element: first as u32,
        })?;
        out.push(Batch {
            kernel,
            law,
            nodes: pick.map(|e| *e.nodes()),
            active: end - first,
            first,
        });
        first = end;
    }
    Ok(out)
}

/// A model's elements packed for one lane type.
enum Packs<L, const N: usize> {
    Reduced {
        general: Vec<Batch<HexReduced<L>, L, N>>,
        boxes: Vec<Batch<HexBox<L>, L, N>>,
        cuboids: Vec<Batch<HexCuboid<L>, L, N>>,
    },
    Full(Vec<Batch<HexFull<L>, L, N>>),
}

impl<L, const N: usize> Packs<L, N> {
    fn build<S: Real>(elements: &Elements<S>, laws: &[MaterialLaw<S>]) -> Result<Self, PhysicsError>
    where
        L: LaneReal<S, N>,
    {
        Ok(match elements {
            Elements::Reduced {
                general,
                boxes,
                cuboids,
                ..
            } => Packs::Reduced {
                general: pack(general, laws)?,
                boxes: pack(boxes, laws)?,
                cuboids: pack(cuboids, laws)?,
            },
            Elements::Full(v) => Packs::Full(pack(v, laws)?),
        })
    }
}

/// The batched element loop of a model in scalar type `T`.
pub trait ElementLoop<T: Real>: Send + Sync {
    /// Adds the internal forces at `u` into `f` (`f` as long as `u`): the bits of
    /// [`Elements::internal_forces`], and its errors.
    fn internal_forces(
        &self,
        elements: &Elements<T>,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError>;
    /// What runs: the lane type ("f64x4 avx", ...).
    fn describe(&self) -> String;
    /// How `parts` threads share the elements ([`Plan`]); None (the default) when this
    /// loop has no packs to share.
    fn plan(&self, _parts: usize, _node_count: usize) -> Option<Plan> {
        None
    }
    /// The internal forces at `u` added into `f` (zero on entry) by the plan's blocks on
    /// `team`, with the bits of [`Self::internal_forces`]; false when a pack fails or
    /// the plan does not fit (the caller zeroes `f` and runs [`Self::internal_forces`]
    /// for the error). The default, for a loop without a plan, is false.
    fn parallel_forces(
        &self,
        _plan: &Plan,
        _kept: &mut [Vec<[T; 3]>],
        _team: &Team,
        _u: &[[T; 3]],
        _f: &mut [[T; 3]],
    ) -> bool {
        false
    }
}

/// A block's runs of packs of one kernel list, in order: each a pack index range and
/// whether it checks who owns each node.
type Runs = Vec<(Range<usize>, bool)>;

/// Elements shared among threads with the scalar loop's bits. The elements (kernel order)
/// are cut into blocks of whole packs; a node belongs to the first block that touches
/// it. Each block's thread adds its forces straight into the nodes it owns (in element
/// order: no earlier block touches them), and keeps its forces on other nodes aside, in
/// order; these are added after all blocks finished, block by block (in parallel over the
/// owners: each owner's nodes take their kept forces in block order, then in the order
/// they were produced). So every node sums its elements' forces from zero in kernel
/// order, as one thread does.
///
/// A pack all of whose nodes its block owns (most of them) adds its forces without
/// asking who owns each node: only the runs of packs that touch an earlier block's node
/// pay that check.
pub struct Plan {
    /// Per block, the runs of packs of each kernel list (general, parallelepipeds,
    /// cuboids; full integration uses the first), in order: each a pack index range and
    /// whether a pack of it touches a node the block does not own.
    blocks: Vec<[Runs; 3]>,
    /// Owning block of each node (`u16::MAX`: no element).
    owner: Vec<u16>,
    /// Per block, the nodes of its forces kept aside, in the order it produces them.
    aside: Vec<Vec<u32>>,
    /// Per owning block, the kept forces on its nodes as (block, index in `aside[block]`),
    /// in block order, then in the order each block produced them.
    aside_by_owner: Vec<Vec<(u32, u32)>>,
}

impl Plan {
    /// The blocks' packs, and how many of them are in runs that check each node's owner
    /// (runs touching a node another block owns): `(checked, all)`.
    pub fn checked_packs(&self) -> (usize, usize) {
        let runs = self.blocks.iter().flatten().flatten();
        runs.fold((0, 0), |(c, a), (r, shared)| {
            (c + if *shared { r.len() } else { 0 }, a + r.len())
        })
    }

    /// The number of blocks.
    pub fn blocks(&self) -> usize {
        self.blocks.len()
    }

    /// Room for each block's forces kept aside.
    pub fn kept_buffers<T>(&self) -> Vec<Vec<[T; 3]>> {
        self.aside
            .iter()
            .map(|a| Vec::with_capacity(a.len()))
            .collect()
    }
}

/// The force array, written by several threads at nodes each owns alone.
struct SharedForces<T>(*mut [T; 3], usize);

// SAFETY: threads only write through it at nodes their block owns (a node has one owner),
// and nothing reads the array until they have all finished (`Plan`).
unsafe impl<T: Send> Sync for SharedForces<T> {}

impl<T: Real> SharedForces<T> {
    /// The same array, for another closure to own.
    fn copy(&self) -> Self {
        SharedForces(self.0, self.1)
    }

    /// Adds `v` at node `n`.
    ///
    /// # Safety
    /// Only the block that owns `n` calls this for `n`, while no one else accesses it.
    #[inline(always)]
    unsafe fn add(&self, n: usize, v: [T; 3]) {
        if n < self.1 {
            // SAFETY: in bounds (checked), and exclusive to this thread (the caller).
            let d = unsafe { &mut *self.0.add(n) };
            for i in 0..3 {
                d[i] += v[i];
            }
        }
    }
}

/// Which instruction set a [`Batched`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// 256-bit AVX registers (x86-64 with AVX, detected at run time).
    Avx,
    /// 512-bit AVX-512 registers, 8 f64 or 16 f32 lanes (x86-64 with AVX-512F and DQ,
    /// detected at run time).
    Avx512,
    /// Plain arrays of lanes, compiled for the best SIMD the CPU has (AVX-512, AVX2,
    /// AVX, NEON, baseline) and chosen at run time; any target.
    Portable,
}

impl Isa {
    /// `N` lanes of `S` on this instruction set: "f64x4 avx", "f32x8 portable".
    fn describe_lanes<S: Real, const N: usize>(self) -> String {
        let isa = match self {
            Isa::Avx => "avx",
            Isa::Avx512 => "avx512",
            Isa::Portable => "portable",
        };
        format!("{}x{N} {isa}", S::NAME)
    }

    /// The best this CPU runs: the widest registers it has.
    pub fn detect() -> Isa {
        Isa::available().last().copied().unwrap_or(Isa::Portable)
    }

    /// The best this CPU runs with registers of at most 256 bits (AVX, else the portable
    /// lanes): for loops over small batches, such as a board's (the built-in scene on
    /// 4x4x4 boards gives each board about 31 elements, cut into up to twelve lists by
    /// batch and kernel), where the 8 f64 or 16 f32 lanes of AVX-512 would mostly be the
    /// padding a short pack repeats.
    pub fn detect_narrow() -> Isa {
        Isa::Avx.or_portable()
    }

    /// `self` if this CPU runs it, else [`Isa::Portable`]: the lane types of an instruction
    /// set are only ever built after this check (the `avx` module's safety).
    pub fn or_portable(self) -> Isa {
        if Isa::available().contains(&self) {
            self
        } else {
            Isa::Portable
        }
    }

    /// Every instruction set this CPU runs, narrowest first (the portable lanes always).
    pub fn available() -> Vec<Isa> {
        let mut v = vec![Isa::Portable];
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx") {
                v.push(Isa::Avx);
            }
            if has!("avx") && has!("avx512f") && has!("avx512dq") {
                v.push(Isa::Avx512);
            }
        }
        v
    }
}

/// The batched elements of a model in scalar type `T`.
pub struct Batched<T: Real>(Box<dyn ElementLoop<T>>);

struct Loop<L, const N: usize> {
    packs: Packs<L, N>,
}

impl<T: Real> Batched<T> {
    /// Packs the elements for `isa` ([`Isa::detect`] for the best): 4 lanes in f64 and 8
    /// in f32 (one 256-bit register or the portable arrays), 8 and 16 on AVX-512; any other
    /// scalar type runs the scalar loop. An `isa` this CPU does not run
    /// ([`Isa::available`]) takes the portable lanes.
    pub fn build(
        elements: &Elements<T>,
        laws: &[MaterialLaw<T>],
        isa: Isa,
    ) -> Result<Self, PhysicsError> {
        fn boxed<T: Real, S: Real, L: LaneReal<S, N>, const N: usize>(
            elements: &dyn Any,
            laws: &dyn Any,
        ) -> Option<Result<Box<dyn ElementLoop<T>>, PhysicsError>>
        where
            Loop<L, N>: ElementLoop<S>,
        {
            let e = elements.downcast_ref::<Elements<S>>()?;
            let l = laws.downcast_ref::<Vec<MaterialLaw<S>>>()?;
            let b: Box<dyn ElementLoop<S>> = match Packs::<L, N>::build(e, l) {
                Ok(packs) => Box::new(Loop { packs }),
                Err(err) => return Some(Err(err)),
            };
            // S is T here: the downcasts above succeeded.
            let any: Box<dyn Any> = Box::new(b);
            any.downcast::<Box<dyn ElementLoop<T>>>()
                .ok()
                .map(|b| Ok(*b))
        }
        let laws = laws.to_vec();
        let (e, l): (&dyn Any, &dyn Any) = (elements, &laws);
        let isa = isa.or_portable();
        let found = match isa {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx => boxed::<T, f64, avx::F64x4, 4>(e, l)
                .or_else(|| boxed::<T, f32, avx::F32x8, 8>(e, l)),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => boxed::<T, f64, avx::F64x8, 8>(e, l)
                .or_else(|| boxed::<T, f32, avx::F32x16, 16>(e, l)),
            _ => boxed::<T, f64, Lanes<f64, 4>, 4>(e, l)
                .or_else(|| boxed::<T, f32, Lanes<f32, 8>, 8>(e, l)),
        };
        match found {
            Some(b) => Ok(Batched(b?)),
            None => Ok(Batched(Box::new(ScalarLoop))),
        }
    }

    pub fn internal_forces(
        &self,
        elements: &Elements<T>,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        self.0.internal_forces(elements, laws, u, f)
    }

    pub fn describe(&self) -> String {
        self.0.describe()
    }

    pub fn element_loop(&self) -> &dyn ElementLoop<T> {
        self.0.as_ref()
    }
}

/// The scalar loop, for scalar types without a lane type.
struct ScalarLoop;

impl<T: Real> ElementLoop<T> for ScalarLoop {
    fn internal_forces(
        &self,
        elements: &Elements<T>,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        elements.internal_forces(laws, u, f)
    }
    fn describe(&self) -> String {
        format!("{} scalar", T::NAME)
    }
}

impl<S: Real, L: HostLanes<S, N>, const N: usize> ElementLoop<S> for Loop<L, N> {
    fn internal_forces(
        &self,
        elements: &Elements<S>,
        laws: &[MaterialLaw<S>],
        u: &[[S; 3]],
        f: &mut [[S; 3]],
    ) -> Result<(), PhysicsError> {
        let r = match (&self.packs, elements) {
            (
                Packs::Reduced {
                    general,
                    boxes,
                    cuboids,
                },
                Elements::Reduced {
                    general: g,
                    boxes: b,
                    cuboids: c,
                    ..
                },
            ) => run(general, g, 0, laws, u, f)
                .and_then(|()| run(boxes, b, g.len(), laws, u, f))
                .and_then(|()| run(cuboids, c, g.len() + b.len(), laws, u, f)),
            (Packs::Full(p), Elements::Full(v)) => run(p, v, 0, laws, u, f),
            _ => return elements.internal_forces(laws, u, f),
        };
        r.map_err(|e| elements.in_mesh(e))
    }
    fn describe(&self) -> String {
        L::ISA.describe_lanes::<S, N>()
    }
    fn plan(&self, parts: usize, node_count: usize) -> Option<Plan> {
        let lists: [Vec<([[u32; 8]; N], usize)>; 3] = match &self.packs {
            Packs::Reduced {
                general,
                boxes,
                cuboids,
            } => [listed(general), listed(boxes), listed(cuboids)],
            Packs::Full(p) => [listed(p), Vec::new(), Vec::new()],
        };
        // Packs in kernel order as (list, index), cut into `parts` runs of about equal
        // element counts.
        let order: Vec<(usize, usize)> = (0..3)
            .flat_map(|k| (0..lists[k].len()).map(move |i| (k, i)))
            .collect();
        let parts = parts
            .clamp(1, order.len().max(1))
            .min(u16::MAX as usize - 1);
        let elements: usize = order.iter().map(|&(k, i)| lists[k][i].1).sum();
        let mut blocks: Vec<[Runs; 3]> = vec![[Vec::new(), Vec::new(), Vec::new()]; parts];
        let mut owner = vec![u16::MAX; node_count];
        let mut aside = vec![Vec::new(); parts];
        let (mut done, mut block) = (0, 0);
        for &(k, i) in &order {
            let (nodes, active) = &lists[k][i];
            while block + 1 < parts && done * parts >= (block + 1) * elements {
                block += 1;
            }
            let kept_before = aside[block].len();
            for at in nodes.iter().take(*active) {
                for &n in at {
                    match owner.get_mut(n as usize) {
                        Some(o) if *o == u16::MAX => *o = block as u16,
                        Some(o) if *o == block as u16 => {}
                        Some(_) => aside[block].push(n),
                        None => return None,
                    }
                }
            }
            let shared = aside[block].len() > kept_before;
            let runs = &mut blocks[block][k];
            match runs.last_mut() {
                Some((r, s)) if *s == shared && r.end == i => r.end = i + 1,
                _ => runs.push((i..i + 1, shared)),
            }
            done += active;
        }
        let mut aside_by_owner = vec![Vec::new(); parts];
        for (b, nodes) in aside.iter().enumerate() {
            for (i, &n) in nodes.iter().enumerate() {
                let o = *owner.get(n as usize)? as usize;
                aside_by_owner.get_mut(o)?.push((b as u32, i as u32));
            }
        }
        Some(Plan {
            blocks,
            owner,
            aside,
            aside_by_owner,
        })
    }

    fn parallel_forces(
        &self,
        plan: &Plan,
        kept: &mut [Vec<[S; 3]>],
        team: &Team,
        u: &[[S; 3]],
        f: &mut [[S; 3]],
    ) -> bool {
        if kept.len() != plan.blocks.len() || plan.owner.len() != f.len() || u.len() != f.len() {
            return false;
        }
        let shared = SharedForces(f.as_mut_ptr(), f.len());
        let ok = team.map_mut(kept, |b, kept| {
            kept.clear();
            let Some(runs) = plan.blocks.get(b) else {
                return false;
            };
            // Plain copies (not references) in the closures, so the force stores, through
            // a raw pointer, do not make the loop reload them.
            let (owner, block) = (plan.owner.as_slice(), b as u16);
            let (own, mine) = (shared.copy(), shared.copy());
            let mut checked = move |n: usize, v: [S; 3]| {
                if owner.get(n) == Some(&block) {
                    // SAFETY: block `b` owns node `n` (see `Plan`).
                    unsafe { own.add(n, v) }
                } else {
                    kept.push(v);
                }
            };
            let mut owned = move |n: usize, v: [S; 3]| {
                // SAFETY: the plan found every node of these packs owned by block `b` (a
                // run not marked shared).
                unsafe { mine.add(n, v) }
            };
            match &self.packs {
                Packs::Reduced {
                    general,
                    boxes,
                    cuboids,
                } => {
                    run_runs(general, &runs[0], u, &mut checked, &mut owned)
                        && run_runs(boxes, &runs[1], u, &mut checked, &mut owned)
                        && run_runs(cuboids, &runs[2], u, &mut checked, &mut owned)
                }
                Packs::Full(p) => run_runs(p, &runs[0], u, &mut checked, &mut owned),
            }
        });
        if !ok.iter().all(|&k| k) {
            return false;
        }
        // The forces kept aside, each owner's on its nodes, block by block, each block's
        // in the order it produced them.
        if plan
            .aside
            .iter()
            .zip(kept.iter())
            .any(|(n, v)| n.len() != v.len())
        {
            return false;
        }
        let kept = &*kept;
        team.for_each(plan.aside_by_owner.len(), |o| {
            for &(b, i) in &plan.aside_by_owner[o] {
                let (b, i) = (b as usize, i as usize);
                let node = plan.aside.get(b).and_then(|a| a.get(i));
                let value = kept.get(b).and_then(|k| k.get(i));
                if let (Some(&n), Some(&v)) = (node, value) {
                    // SAFETY: node `n` is owned by this list's block (`Plan::plan` files a
                    // kept force under its node's owner), and no other list holds that
                    // block's nodes.
                    unsafe { shared.add(n as usize, v) }
                }
            }
        });
        true
    }
}

/// The runs of `packs` in order, each on [`run_with`] with `checked` (a run touching
/// nodes another block owns) or `owned`; false if a pack failed.
fn run_runs<K, S, L, const N: usize>(
    packs: &[Batch<K, L, N>],
    runs: &[(Range<usize>, bool)],
    u: &[[S; 3]],
    checked: &mut impl FnMut(usize, [S; 3]),
    owned: &mut impl FnMut(usize, [S; 3]),
) -> bool
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: HostLanes<S, N>,
{
    runs.iter().all(|(r, shared)| {
        let Some(p) = packs.get(r.clone()) else {
            return false;
        };
        if *shared {
            run_with(p, u, checked).is_none()
        } else {
            run_with(p, u, owned).is_none()
        }
    })
}

/// Each pack's nodes in scatter order (per lane) and its active count.
fn listed<K, S, L, const N: usize>(packs: &[Batch<K, L, N>]) -> Vec<([[u32; 8]; N], usize)>
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    packs
        .iter()
        .map(|b| (b.nodes.map(|at| K::SCATTER_ORDER.map(|a| at[a])), b.active))
        .collect()
}

/// [`run_packs_body`] on the lane type's instruction set ([`HostLanes::run_packs`]).
#[inline(always)]
fn run_with<K, S, L, const N: usize>(
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
}

/// The AVX (`avx`) and AVX-512 (`avx512`) lane types on their functions.
#[cfg(target_arch = "x86_64")]
macro_rules! host_lanes {
    ($lanes:ty, $s:ty, $n:expr, $isa:expr, $run:ident, $why:literal) => {
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
        }
    };
}
#[cfg(target_arch = "x86_64")]
host_lanes!(avx::F64x4, f64, 4, Isa::Avx, run_packs_avx, "AVX");
#[cfg(target_arch = "x86_64")]
host_lanes!(avx::F32x8, f32, 8, Isa::Avx, run_packs_avx, "AVX");
#[cfg(target_arch = "x86_64")]
host_lanes!(
    avx::F64x8,
    f64,
    8,
    Isa::Avx512,
    run_packs_avx512,
    "AVX-512F and DQ"
);
#[cfg(target_arch = "x86_64")]
host_lanes!(
    avx::F32x16,
    f32,
    16,
    Isa::Avx512,
    run_packs_avx512,
    "AVX-512F and DQ"
);

/// Runs one kernel's packs in order, adding each lane's forces; a failed pack is rerun by
/// the scalar kernel (kernel-order elements from `offset`) for its error.
fn run<K, E, S, L, const N: usize>(
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
