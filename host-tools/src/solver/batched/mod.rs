//! The host's element loop, batched: the scalar elements ([`Elements`]) packed `N` at a
//! time into [`Lanes`] (4 lanes in f64, 8 in f32), each pack run by the firmware's own
//! kernel code ([`LaneKernel`]), compiled for the best instruction set the CPU has
//! (AVX-512, AVX2, AVX, NEON, or the baseline) and chosen at run time.
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
    HexBox, HexElement, HexFull, HexReduced, LaneKernel, LaneReal, Lanes, MaterialLaw, Pack,
    PhysicsError, Real,
};

use crate::problem::elements::Elements;

#[cfg(target_arch = "x86_64")]
mod avx;

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
enum Packs<S: Real, L: LaneReal<S, N>, const N: usize> {
    Reduced {
        general: Vec<Batch<HexReduced<L>, L, N>>,
        boxes: Vec<Batch<HexBox<L>, L, N>>,
    },
    Full(Vec<Batch<HexFull<L>, L, N>>),
    #[allow(dead_code)]
    Scalar(core::marker::PhantomData<S>),
}

impl<S: Real, L: LaneReal<S, N>, const N: usize> Packs<S, L, N> {
    fn build(elements: &Elements<S>, laws: &[MaterialLaw<S>]) -> Result<Self, PhysicsError> {
        Ok(match elements {
            Elements::Reduced { general, boxes, .. } => Packs::Reduced {
                general: pack(general, laws)?,
                boxes: pack(boxes, laws)?,
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
    /// About `parts` ranges of kernel-order elements covering all of them, each a whole
    /// number of packs.
    fn ranges(&self, parts: usize) -> Vec<Range<usize>>;
    /// Each element's nodal forces of the elements `range` (from [`Self::ranges`]) into
    /// `out` (one entry per element, nodes in [`Incidence`] order); false when a pack
    /// fails (the caller then runs [`Self::internal_forces`] for the error).
    fn element_forces(&self, range: Range<usize>, u: &[[T; 3]], out: &mut [[[T; 3]; 8]]) -> bool;
    /// Which element slots add into each node, in the order the scalar loop adds them.
    fn incidence(&self) -> &Incidence;
}

/// For each node, the element slots (`8 · element + slot`, kernel order) whose forces
/// add into it, in kernel order: summing them from zero in this order gives the scalar
/// loop's bits (each element adds once to each of its nodes).
pub struct Incidence {
    start: Vec<u32>,
    slots: Vec<u32>,
}

impl Incidence {
    /// `nodes[e]` in slot order, for the kernel-order elements.
    fn build(nodes: impl Iterator<Item = [u32; 8]>, node_count: usize) -> Incidence {
        let nodes: Vec<[u32; 8]> = nodes.collect();
        let mut count = vec![0u32; node_count + 1];
        for e in &nodes {
            for &n in e {
                if let Some(c) = count.get_mut(n as usize + 1) {
                    *c += 1;
                }
            }
        }
        for k in 1..count.len() {
            count[k] += count[k - 1];
        }
        let start = count.clone();
        let mut slots = vec![0u32; *count.last().unwrap_or(&0) as usize];
        for (e, ns) in nodes.iter().enumerate() {
            for (k, &n) in ns.iter().enumerate() {
                if let Some(at) = count.get_mut(n as usize) {
                    if let Some(s) = slots.get_mut(*at as usize) {
                        *s = (8 * e + k) as u32;
                    }
                    *at += 1;
                }
            }
        }
        Incidence { start, slots }
    }

    /// Node `n`'s internal force: its slots of `forces` summed from zero in order.
    #[inline]
    pub fn gather<T: Real>(&self, n: usize, forces: &[[[T; 3]; 8]]) -> [T; 3] {
        let mut f = [T::ZERO; 3];
        let (a, b) = (self.start[n] as usize, self.start[n + 1] as usize);
        for &s in &self.slots[a..b] {
            let v = forces[s as usize / 8][s as usize % 8];
            for i in 0..3 {
                f[i] += v[i];
            }
        }
        f
    }
}

/// Which instruction set a [`Batched`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// 256-bit AVX registers (x86-64 with AVX, detected at run time).
    Avx,
    /// Plain arrays of lanes, compiled for the best SIMD the CPU has (AVX-512, AVX2,
    /// AVX, NEON, baseline) and chosen at run time; any target.
    Portable,
}

impl Isa {
    /// The best this CPU runs.
    pub fn detect() -> Isa {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx") {
            return Isa::Avx;
        }
        Isa::Portable
    }
}

/// The batched elements of a model in scalar type `T`.
pub struct Batched<T: Real>(Box<dyn ElementLoop<T>>);

struct Loop<S: Real, L: LaneReal<S, N>, const N: usize> {
    packs: Packs<S, L, N>,
    isa: Isa,
    incidence: Incidence,
    /// Kernel-order index of the first element of each kernel list.
    offsets: [usize; 2],
}

impl<S: Real, L: LaneReal<S, N>, const N: usize> Loop<S, L, N> {
    fn new(packs: Packs<S, L, N>, isa: Isa, elements: &Elements<S>) -> Self {
        fn order<K: LaneKernel<S, L, N>, S: Real, L: LaneReal<S, N>, const N: usize>(
            _: &[Batch<K, L, N>],
        ) -> [usize; 8] {
            K::SCATTER_ORDER
        }
        let max_node = |v: &mut dyn Iterator<Item = [u32; 8]>| {
            v.flat_map(|n| n).max().map_or(0, |m| m as usize + 1)
        };
        let (incidence, offsets) = match (&packs, elements) {
            (
                Packs::Reduced { general, boxes },
                Elements::Reduced {
                    general: g,
                    boxes: b,
                    ..
                },
            ) => {
                let (og, ob) = (order(general), order(boxes));
                let all = g
                    .iter()
                    .map(|e| og.map(|a| e.nodes()[a]))
                    .chain(b.iter().map(|e| ob.map(|a| e.nodes()[a])));
                let n = max_node(&mut all.clone());
                (Incidence::build(all, n), [0, g.len()])
            }
            (Packs::Full(p), Elements::Full(v)) => {
                let o = order(p);
                let all = v.iter().map(|e| o.map(|a| e.nodes()[a]));
                let n = max_node(&mut all.clone());
                (Incidence::build(all, n), [0, v.len()])
            }
            _ => (Incidence::build(core::iter::empty(), 0), [0, 0]),
        };
        Loop {
            packs,
            isa,
            incidence,
            offsets,
        }
    }
}

impl<T: Real> Batched<T> {
    /// Packs the elements for `isa` ([`Isa::detect`] for the best), 4 lanes in f64 and 8
    /// in f32 (one 256-bit register); any other scalar type runs the scalar loop.
    pub fn build(
        elements: &Elements<T>,
        laws: &[MaterialLaw<T>],
        isa: Isa,
    ) -> Result<Self, PhysicsError> {
        fn boxed<T: Real, S: Real, L: LaneReal<S, N>, const N: usize>(
            elements: &dyn Any,
            laws: &dyn Any,
            isa: Isa,
        ) -> Option<Result<Box<dyn ElementLoop<T>>, PhysicsError>>
        where
            Loop<S, L, N>: ElementLoop<S>,
        {
            let e = elements.downcast_ref::<Elements<S>>()?;
            let l = laws.downcast_ref::<Vec<MaterialLaw<S>>>()?;
            let b: Box<dyn ElementLoop<S>> = match Packs::<S, L, N>::build(e, l) {
                Ok(packs) => Box::new(Loop::new(packs, isa, e)),
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
        let found = match isa {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx => boxed::<T, f64, avx::F64x4, 4>(e, l, isa)
                .or_else(|| boxed::<T, f32, avx::F32x8, 8>(e, l, isa)),
            _ => boxed::<T, f64, Lanes<f64, 4>, 4>(e, l, Isa::Portable)
                .or_else(|| boxed::<T, f32, Lanes<f32, 8>, 8>(e, l, Isa::Portable)),
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
    fn ranges(&self, _: usize) -> Vec<Range<usize>> {
        Vec::new()
    }
    fn element_forces(&self, _: Range<usize>, _: &[[T; 3]], _: &mut [[[T; 3]; 8]]) -> bool {
        false
    }
    fn incidence(&self) -> &Incidence {
        static EMPTY: Incidence = Incidence {
            start: Vec::new(),
            slots: Vec::new(),
        };
        &EMPTY
    }
}

impl<S: Real, L: LaneReal<S, N>, const N: usize> ElementLoop<S> for Loop<S, L, N> {
    fn internal_forces(
        &self,
        elements: &Elements<S>,
        laws: &[MaterialLaw<S>],
        u: &[[S; 3]],
        f: &mut [[S; 3]],
    ) -> Result<(), PhysicsError> {
        let isa = self.isa;
        let r = match (&self.packs, elements) {
            (
                Packs::Reduced { general, boxes },
                Elements::Reduced {
                    general: g,
                    boxes: b,
                    ..
                },
            ) => run(general, g, 0, laws, u, f, isa)
                .and_then(|()| run(boxes, b, g.len(), laws, u, f, isa)),
            (Packs::Full(p), Elements::Full(v)) => run(p, v, 0, laws, u, f, isa),
            _ => return elements.internal_forces(laws, u, f),
        };
        r.map_err(|e| elements.in_mesh(e))
    }
    fn describe(&self) -> String {
        let isa = match self.isa {
            Isa::Avx => "avx",
            Isa::Portable => "portable",
        };
        format!("{}x{N} {isa}", S::NAME)
    }
    fn ranges(&self, parts: usize) -> Vec<Range<usize>> {
        // Pack boundaries in kernel order, then about equal shares of packs.
        let mut ends = Vec::new();
        let mut push = |firsts: &mut dyn Iterator<Item = usize>| ends.extend(firsts);
        match &self.packs {
            Packs::Reduced { general, boxes } => {
                push(&mut general.iter().map(|b| b.first + b.active));
                push(&mut boxes.iter().map(|b| self.offsets[1] + b.first + b.active));
            }
            Packs::Full(p) => push(&mut p.iter().map(|b| b.first + b.active)),
            Packs::Scalar(_) => {}
        }
        let parts = parts.clamp(1, ends.len().max(1));
        let mut out = Vec::with_capacity(parts);
        let mut from = 0;
        for k in 1..=parts {
            let Some(&end) = ends.get((k * ends.len()).div_ceil(parts).saturating_sub(1)) else {
                break;
            };
            if end > from {
                out.push(from..end);
                from = end;
            }
        }
        out
    }
    fn element_forces(&self, range: Range<usize>, u: &[[S; 3]], out: &mut [[[S; 3]; 8]]) -> bool {
        let isa = self.isa;
        let within = |offset: usize, first: usize, active: usize| {
            offset + first >= range.start && offset + first + active <= range.end
        };
        match &self.packs {
            Packs::Reduced { general, boxes } => {
                let (og, ob) = (self.offsets[0], self.offsets[1]);
                let g: Vec<&Batch<_, L, N>> = general
                    .iter()
                    .filter(|b| within(og, b.first, b.active))
                    .collect();
                let b: Vec<&Batch<_, L, N>> = boxes
                    .iter()
                    .filter(|b| within(ob, b.first, b.active))
                    .collect();
                forces_of(&g, og, range.start, u, out, isa)
                    && forces_of(&b, ob, range.start, u, out, isa)
            }
            Packs::Full(p) => {
                let f: Vec<&Batch<_, L, N>> =
                    p.iter().filter(|b| within(0, b.first, b.active)).collect();
                forces_of(&f, 0, range.start, u, out, isa)
            }
            Packs::Scalar(_) => false,
        }
    }
    fn incidence(&self) -> &Incidence {
        &self.incidence
    }
}

/// The packs' per-element forces into `out` (element `offset + first + l` at
/// `out[offset + first + l − base]`); false when one fails.
fn forces_of<K, S, L, const N: usize>(
    packs: &[&Batch<K, L, N>],
    offset: usize,
    base: usize,
    u: &[[S; 3]],
    out: &mut [[[S; 3]; 8]],
    isa: Isa,
) -> bool
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    match isa {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `run`.
        Isa::Avx => unsafe { forces_avx(packs, offset, base, u, out) },
        _ => forces_portable(packs, offset, base, u, out),
    }
}

#[inline(always)]
fn forces_body<K, S, L, const N: usize>(
    packs: &[&Batch<K, L, N>],
    offset: usize,
    base: usize,
    u: &[[S; 3]],
    out: &mut [[[S; 3]; 8]],
) -> bool
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    for b in packs {
        let at = (offset + b.first).wrapping_sub(base);
        let Some(dst) = out.get_mut(at..at + b.active) else {
            return false;
        };
        let mut k = 0;
        let r = b
            .kernel
            .lane_forces(&b.law, &b.nodes, b.active, u, |l, _, v| {
                if let Some(d) = dst.get_mut(l) {
                    d[k % 8] = v;
                }
                k += 1;
            });
        if r.is_err() {
            return false;
        }
    }
    true
}

/// [`forces_body`] compiled with AVX.
///
/// # Safety
/// The CPU must have AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn forces_avx<K, S, L, const N: usize>(
    packs: &[&Batch<K, L, N>],
    offset: usize,
    base: usize,
    u: &[[S; 3]],
    out: &mut [[[S; 3]; 8]],
) -> bool
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    forces_body(packs, offset, base, u, out)
}

#[multiversion(targets(
    "x86_64+avx512f+avx512vl+avx2+avx",
    "x86_64+avx2+avx",
    "x86_64+avx",
    "aarch64+neon"
))]
fn forces_portable<K, S, L, const N: usize>(
    packs: &[&Batch<K, L, N>],
    offset: usize,
    base: usize,
    u: &[[S; 3]],
    out: &mut [[[S; 3]; 8]],
) -> bool
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    forces_body(packs, offset, base, u, out)
}

/// Runs one kernel's packs in order, adding each lane's forces; a failed pack is rerun by
/// the scalar kernel (kernel-order elements from `offset`) for its error.
fn run<K, E, S, L, const N: usize>(
    packs: &[Batch<K, L, N>],
    scalar: &[E],
    offset: usize,
    laws: &[MaterialLaw<S>],
    u: &[[S; 3]],
    f: &mut [[S; 3]],
    isa: Isa,
) -> Result<(), PhysicsError>
where
    K: LaneKernel<S, L, N>,
    E: HexElement<S>,
    S: Real,
    L: LaneReal<S, N>,
{
    if u.len() != f.len() {
        return Err(PhysicsError::BadIndex {
            element: offset as u32,
        });
    }
    let mut from = 0;
    loop {
        let rest = packs.get(from..).unwrap_or(&[]);
        let failed = match isa {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Isa::Avx` is only chosen where the CPU has AVX (`Isa::detect`, or a
            // caller that checked the same).
            Isa::Avx => unsafe { run_packs_avx(rest, u, f) },
            _ => run_packs(rest, u, f),
        };
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

/// The packs in order, each lane's forces added into `f`; the index of the first pack
/// that fails (nothing of it added), if any.
#[inline(always)]
fn run_packs_body<K, S, L, const N: usize>(
    packs: &[Batch<K, L, N>],
    u: &[[S; 3]],
    f: &mut [[S; 3]],
) -> Option<usize>
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    for (k, b) in packs.iter().enumerate() {
        let r = b
            .kernel
            .lane_forces(&b.law, &b.nodes, b.active, u, |_, n, v| {
                if let Some(d) = f.get_mut(n) {
                    for i in 0..3 {
                        d[i] += v[i];
                    }
                }
            });
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
    f: &mut [[S; 3]],
) -> Option<usize>
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    run_packs_body(packs, u, f)
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
    f: &mut [[S; 3]],
) -> Option<usize>
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    run_packs_body(packs, u, f)
}
