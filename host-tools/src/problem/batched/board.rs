//! The batched kernel on one board of a machine (board-sim's boards): each batch of the
//! board's step program (x, y, z, inner) packed on its own, so the board's runtime computes
//! its element forces on the host's lanes ([`BatchForces`]) with the bits of the firmware's
//! scalar loop: the packs run the firmware's kernel code lane by lane and add each lane's
//! forces in the scalar loop's order (see the parent module); a failed pack is rerun by the
//! scalar kernel, which names the element as the board would.

use std::any::Any;
use std::ops::Range;

use pe_firmware::physics::{
    HexBox, HexCuboid, HexElement, HexFull, HexReduced, LaneKernel, Lanes, MaterialLaw, Pack,
    PhysicsError, Real,
};
use pe_firmware::runtime::{batch_range, BatchForces, BatchSlices, ScalarBatches};

use super::{pack, run, Batch, HostLanes, Isa};

/// Packs per batch of one kernel list.
type PerBatch<K, L, const N: usize> = Vec<Vec<Batch<K, L, N>>>;

/// One board's element batches, packed for the host's lanes (or the scalar loop where the
/// scalar type has no lane type).
pub struct BoardBatches<T, E> {
    lanes: Option<Box<dyn BatchForces<T, E> + Send + Sync>>,
    /// What runs ([`Self::describe`]).
    describe: String,
}

struct Packed<K, L, const N: usize> {
    general: PerBatch<K, L, N>,
    boxes: PerBatch<HexBox<L>, L, N>,
    cuboids: PerBatch<HexCuboid<L>, L, N>,
    /// Elements of each batch the packs hold (general, parallelepipeds, cuboids).
    counts: Vec<(usize, usize, usize)>,
}

impl<S, E, K, L, const N: usize> BatchForces<S, E> for Packed<K, L, N>
where
    S: Real,
    E: HexElement<S>,
    K: LaneKernel<S, L, N>,
    HexBox<L>: LaneKernel<S, L, N>,
    HexCuboid<L>: LaneKernel<S, L, N>,
    L: HostLanes<S, N>,
{
    fn batch_forces(
        &self,
        b: BatchSlices<'_, S, E>,
        laws: &[MaterialLaw<S>],
        u: &[[S; 3]],
        f: &mut [[S; 3]],
    ) -> Result<(), PhysicsError> {
        let i = b.index;
        let (Some(g), Some(x), Some(c), Some(&counts)) = (
            self.general.get(i),
            self.boxes.get(i),
            self.cuboids.get(i),
            self.counts.get(i),
        ) else {
            return ScalarBatches.batch_forces(b, laws, u, f);
        };
        if counts != (b.general.len(), b.boxes.len(), b.cuboids.len()) {
            // Not the batch these packs were made from: the scalar loop.
            return ScalarBatches.batch_forces(b, laws, u, f);
        }
        run(g, b.general, b.first_general as usize, laws, u, f)
            .and_then(|()| run(x, b.boxes, b.first_box as usize, laws, u, f))
            .and_then(|()| run(c, b.cuboids, b.first_cuboid as usize, laws, u, f))
    }
}

/// Adds `offset` to the element an error names.
fn offset_error(e: PhysicsError, offset: u32) -> PhysicsError {
    match e {
        PhysicsError::BadIndex { element } => PhysicsError::BadIndex {
            element: element + offset,
        },
        PhysicsError::InvertedElement { element, jacobian } => PhysicsError::InvertedElement {
            element: element + offset,
            jacobian,
        },
        e => e,
    }
}

/// The board's batches: `ends` are the step program's batch ends (`batch_ends`,
/// `box_batch_ends`, `cuboid_batch_ends` of the image's counts) into `general`, `boxes`
/// and `cuboids`.
pub struct BoardElements<'s, T, E> {
    pub general: &'s [E],
    pub boxes: &'s [HexBox<T>],
    pub cuboids: &'s [HexCuboid<T>],
    pub laws: &'s [MaterialLaw<T>],
    pub general_ends: [u32; 4],
    pub box_ends: [u32; 4],
    pub cuboid_ends: [u32; 4],
}

impl<T: Real, E> BoardElements<'_, T, E> {
    /// The element ranges of every batch (general, parallelepipeds, cuboids), checked
    /// against the lists.
    fn ranges(&self) -> Option<Vec<[Range<usize>; 3]>> {
        let cut = |ends: [u32; 4], len: usize| -> Option<Vec<Range<usize>>> {
            let rs: Vec<Range<usize>> = (0..4).map(|b| batch_range(ends, b)).collect();
            rs.iter()
                .all(|r| r.start <= r.end && r.end <= len)
                .then_some(rs)
        };
        let g = cut(self.general_ends, self.general.len())?;
        let b = cut(self.box_ends, self.boxes.len())?;
        let c = cut(self.cuboid_ends, self.cuboids.len())?;
        Some(
            g.into_iter()
                .zip(b)
                .zip(c)
                .map(|((g, b), c)| [g, b, c])
                .collect(),
        )
    }
}

/// Packs a board's batches with lane type `L` when `T` is `S` and `E` is `ES`.
fn packed<T, E, S, ES, L, const N: usize>(
    board: &BoardElements<'_, T, E>,
) -> Option<Result<BoardBatches<T, E>, PhysicsError>>
where
    T: Real + 'static,
    E: Copy + 'static,
    S: Real + 'static,
    ES: HexElement<S> + Pack<S, L, N> + Copy + 'static,
    ES::Packed: LaneKernel<S, L, N> + Send + Sync + 'static,
    HexBox<S>: Pack<S, L, N, Packed = HexBox<L>>,
    HexBox<L>: LaneKernel<S, L, N> + Send + Sync,
    HexCuboid<S>: Pack<S, L, N, Packed = HexCuboid<L>>,
    HexCuboid<L>: LaneKernel<S, L, N> + Send + Sync,
    MaterialLaw<S>: Pack<S, L, N, Packed = MaterialLaw<L>>,
    MaterialLaw<L>: Send + Sync,
    L: HostLanes<S, N> + Send + Sync + 'static,
{
    let general = board.general.to_vec();
    let boxes = board.boxes.to_vec();
    let cuboids = board.cuboids.to_vec();
    let laws = board.laws.to_vec();
    let general = (&general as &dyn Any).downcast_ref::<Vec<ES>>()?;
    let boxes = (&boxes as &dyn Any).downcast_ref::<Vec<HexBox<S>>>()?;
    let cuboids = (&cuboids as &dyn Any).downcast_ref::<Vec<HexCuboid<S>>>()?;
    let laws = (&laws as &dyn Any).downcast_ref::<Vec<MaterialLaw<S>>>()?;
    let Some(ranges) = board.ranges() else {
        return Some(Err(PhysicsError::BadIndex { element: 0 }));
    };
    let mut p = Packed::<ES::Packed, L, N> {
        general: Vec::new(),
        boxes: Vec::new(),
        cuboids: Vec::new(),
        counts: Vec::new(),
    };
    let (general_count, box_count) = (general.len() as u32, boxes.len() as u32);
    for [g, b, c] in ranges {
        let packs = pack::<ES, S, L, N>(&general[g.clone()], laws)
            .map_err(|e| offset_error(e, g.start as u32));
        let box_packs = pack::<HexBox<S>, S, L, N>(&boxes[b.clone()], laws)
            .map_err(|e| offset_error(e, general_count + b.start as u32));
        let cuboid_packs = pack::<HexCuboid<S>, S, L, N>(&cuboids[c.clone()], laws)
            .map_err(|e| offset_error(e, general_count + box_count + c.start as u32));
        match (packs, box_packs, cuboid_packs) {
            (Ok(x), Ok(y), Ok(z)) => {
                p.general.push(x);
                p.boxes.push(y);
                p.cuboids.push(z);
                p.counts.push((g.len(), b.len(), c.len()));
            }
            (Err(e), _, _) | (_, Err(e), _) | (_, _, Err(e)) => return Some(Err(e)),
        }
    }
    let b: Box<dyn BatchForces<S, ES> + Send + Sync> = Box::new(p);
    // S is T and ES is E here: the downcasts above succeeded.
    let any: Box<dyn Any> = Box::new(b);
    let lanes = any
        .downcast::<Box<dyn BatchForces<T, E> + Send + Sync>>()
        .ok()?;
    Some(Ok(BoardBatches {
        lanes: Some(*lanes),
        describe: L::ISA.describe_lanes::<S, N>(),
    }))
}

impl<T: Real + 'static, E: HexElement<T> + Copy + 'static> BoardBatches<T, E> {
    /// Packs `board`'s batches for `isa` ([`Isa::detect`] for the best): 4 lanes in f64,
    /// 8 in f32 (8 and 16 on AVX-512), reduced (general, parallelepiped and cuboid kernels) or full integration; any
    /// other scalar or element type runs the scalar loop.
    pub fn build(board: &BoardElements<'_, T, E>, isa: Isa) -> Result<Self, PhysicsError> {
        type Red<S> = HexReduced<S>;
        type Full<S> = HexFull<S>;
        let isa = isa.or_portable();
        let found = match isa {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx => {
                use super::avx::{F32x8, F64x4};
                packed::<T, E, f64, Red<f64>, F64x4, 4>(board)
                    .or_else(|| packed::<T, E, f64, Full<f64>, F64x4, 4>(board))
                    .or_else(|| packed::<T, E, f32, Red<f32>, F32x8, 8>(board))
                    .or_else(|| packed::<T, E, f32, Full<f32>, F32x8, 8>(board))
            }
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => {
                use super::avx::{F32x16, F64x8};
                packed::<T, E, f64, Red<f64>, F64x8, 8>(board)
                    .or_else(|| packed::<T, E, f64, Full<f64>, F64x8, 8>(board))
                    .or_else(|| packed::<T, E, f32, Red<f32>, F32x16, 16>(board))
                    .or_else(|| packed::<T, E, f32, Full<f32>, F32x16, 16>(board))
            }
            _ => packed::<T, E, f64, Red<f64>, Lanes<f64, 4>, 4>(board)
                .or_else(|| packed::<T, E, f64, Full<f64>, Lanes<f64, 4>, 4>(board))
                .or_else(|| packed::<T, E, f32, Red<f32>, Lanes<f32, 8>, 8>(board))
                .or_else(|| packed::<T, E, f32, Full<f32>, Lanes<f32, 8>, 8>(board)),
        };
        found.unwrap_or_else(|| Ok(Self::scalar()))
    }

    /// The firmware's scalar loop.
    pub fn scalar() -> Self {
        BoardBatches {
            lanes: None,
            describe: format!("{} scalar", T::NAME),
        }
    }

    /// What runs: the lane type ("f64x4 avx", ...) or "f64 scalar".
    pub fn describe(&self) -> &str {
        &self.describe
    }
}

impl<T: Real, E: HexElement<T>> BatchForces<T, E> for BoardBatches<T, E> {
    fn batch_forces(
        &self,
        b: BatchSlices<'_, T, E>,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        match &self.lanes {
            Some(l) => l.batch_forces(b, laws, u, f),
            None => ScalarBatches.batch_forces(b, laws, u, f),
        }
    }
}
