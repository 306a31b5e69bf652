//! Packing: a kernel's elements `N` at a time into lanes, runs of one law kind each.

use pe_firmware::physics::{
    HexBox, HexCuboid, HexElement, HexFull, HexReduced, LaneReal, MaterialLaw, Pack, PhysicsError,
    Real,
};

use crate::problem::elements::{Elements, Hexahedra};

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
pub(super) fn pack<E, S, L, const N: usize>(
    elements: &[E],
    laws: &[MaterialLaw<S>],
) -> Result<Vec<Batch<E::Packed, L, N>>, PhysicsError>
where
    S: Real,
    L: LaneReal<S, N>,
    E: HexElement<S> + Pack<S, L, N>,
    MaterialLaw<S>: Pack<S, L, N, Packed = MaterialLaw<L>>,
{
    pack_runs(
        elements,
        laws,
        |e| e.material(),
        |pick, law, active, first| {
            Some(Batch {
                kernel: E::pack(pick)?,
                law,
                nodes: pick.map(|e| *e.nodes()),
                active,
                first,
            })
        },
    )
}

/// Splits `items` (laws indexed by `material`) into runs of at most `N` consecutive items
/// whose laws pack together (one kind), in order, and makes each run's pack with
/// `make(lanes, law, active, first)`: the lanes hold the run's items, the last repeated
/// after `active`. An item whose material has no law, or a run `make` refuses, is
/// [`PhysicsError::BadIndex`] naming it (the run's first).
pub(super) fn pack_runs<X, S, L, P, const N: usize>(
    items: &[X],
    laws: &[MaterialLaw<S>],
    material: impl Fn(&X) -> usize,
    make: impl Fn([&X; N], MaterialLaw<L>, usize, usize) -> Option<P>,
) -> Result<Vec<P>, PhysicsError>
where
    S: Real,
    L: LaneReal<S, N>,
    MaterialLaw<S>: Pack<S, L, N, Packed = MaterialLaw<L>>,
{
    let law_of = |k: usize| {
        items
            .get(k)
            .and_then(|x| laws.get(material(x)))
            .ok_or(PhysicsError::BadIndex { element: k as u32 })
    };
    // The laws of items `first..` (the last repeated after `end`), packed.
    let laws_of = |first: usize, end: usize| -> Result<Option<MaterialLaw<L>>, PhysicsError> {
        let mut ls = [law_of(first)?; N];
        for (l, v) in ls.iter_mut().enumerate() {
            *v = law_of((first + l).min(end - 1))?;
        }
        Ok(<MaterialLaw<S> as Pack<S, L, N>>::pack(ls))
    };
    let mut out = Vec::with_capacity(items.len().div_ceil(N));
    let mut first = 0;
    while first < items.len() {
        // The longest run (at most N) whose laws pack together.
        let mut end = first + 1;
        while end < items.len() && end - first < N && laws_of(first, end + 1)?.is_some() {
            end += 1;
        }
        let bad = PhysicsError::BadIndex {
            element: first as u32,
        };
        let law = laws_of(first, end)?.ok_or(bad)?;
        let pick: [&X; N] = core::array::from_fn(|l| &items[(first + l).min(end - 1)]);
        out.push(make(pick, law, end - first, first).ok_or(bad)?);
        first = end;
    }
    Ok(out)
}

/// A model's elements packed for one lane type.
pub(super) enum Packs<L, const N: usize> {
    Reduced {
        general: Vec<Batch<HexReduced<L>, L, N>>,
        boxes: Vec<Batch<HexBox<L>, L, N>>,
        cuboids: Vec<Batch<HexCuboid<L>, L, N>>,
    },
    Full(Vec<Batch<HexFull<L>, L, N>>),
}

impl<L, const N: usize> Packs<L, N> {
    pub(super) fn build<S: Real>(
        elements: &Elements<S>,
        laws: &[MaterialLaw<S>],
    ) -> Result<Self, PhysicsError>
    where
        L: LaneReal<S, N>,
    {
        Ok(match &elements.hexes {
            Hexahedra::Reduced {
                general,
                boxes,
                cuboids,
                ..
            } => Packs::Reduced {
                general: pack(general, laws)?,
                boxes: pack(boxes, laws)?,
                cuboids: pack(cuboids, laws)?,
            },
            Hexahedra::Full { records: v, .. } => Packs::Full(pack(v, laws)?),
        })
    }
}
