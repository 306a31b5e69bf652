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

use pe_firmware::physics::{LaneReal, Lanes, MaterialLaw, PhysicsError, Real};

use crate::problem::elements::{Elements, Hexahedra};
use crate::team::Team;

#[cfg(target_arch = "x86_64")]
mod avx;
pub mod board;
mod isa;
mod lanes;
mod pack;
mod parallel;
mod tets;

pub use isa::Isa;
pub use lanes::HostLanes;
use lanes::{run, run_with};
pub use pack::Batch;
use pack::{pack, Packs};
pub use parallel::Plan;

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
    /// Adds the tetrahedra's internal forces at `u` into `f` (after the hexahedra's, on
    /// this thread): the bits and errors of [`Tetrahedra::add_forces`]. The default runs
    /// the scalar loop.
    ///
    /// [`Tetrahedra::add_forces`]: crate::problem::elements::Tetrahedra::add_forces
    fn tet_forces(
        &self,
        elements: &Elements<T>,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        elements.tets.add_forces(laws, u, f)
    }
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

/// The batched elements of a model in scalar type `T`.
pub struct Batched<T: Real>(Box<dyn ElementLoop<T>>);

struct Loop<L, const N: usize> {
    packs: Packs<L, N>,
    tets: Vec<pe_firmware::physics::element::tet_lanes::TetPack<L, N>>,
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
            let built = Packs::<L, N>::build(e, l)
                .and_then(|packs| Ok((packs, tets::pack_tets(&e.tets.records, l)?)));
            let b: Box<dyn ElementLoop<S>> = match built {
                Ok((packs, tets)) => Box::new(Loop { packs, tets }),
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
        let r = match (&self.packs, &elements.hexes) {
            (
                Packs::Reduced {
                    general,
                    boxes,
                    cuboids,
                },
                Hexahedra::Reduced {
                    general: g,
                    boxes: b,
                    cuboids: c,
                    ..
                },
            ) => run(general, g, 0, laws, u, f)
                .and_then(|()| run(boxes, b, g.len(), laws, u, f))
                .and_then(|()| run(cuboids, c, g.len() + b.len(), laws, u, f)),
            (Packs::Full(p), Hexahedra::Full { records: v, .. }) => run(p, v, 0, laws, u, f),
            _ => return elements.internal_forces(laws, u, f),
        };
        r.map_err(|e| elements.hexes.in_mesh(e))?;
        // The tetrahedra after every hexahedron, as the scalar loop runs them.
        self.tet_forces(elements, laws, u, f)
    }
    fn tet_forces(
        &self,
        elements: &Elements<S>,
        laws: &[MaterialLaw<S>],
        u: &[[S; 3]],
        f: &mut [[S; 3]],
    ) -> Result<(), PhysicsError> {
        tets::run_tets(&self.tets, &elements.tets, laws, u, f)
    }
    fn describe(&self) -> String {
        L::ISA.describe_lanes::<S, N>()
    }
    fn plan(&self, parts: usize, node_count: usize) -> Option<Plan> {
        self.plan_blocks::<S>(parts, node_count)
    }

    fn parallel_forces(
        &self,
        plan: &Plan,
        kept: &mut [Vec<[S; 3]>],
        team: &Team,
        u: &[[S; 3]],
        f: &mut [[S; 3]],
    ) -> bool {
        self.plan_forces::<S>(plan, kept, team, u, f)
    }
}
