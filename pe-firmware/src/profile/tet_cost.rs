//! The tetrahedron's cost on the board, and the patch it is measured on.
//!
//! The boards do not run tetrahedra yet (`pe compile` refuses them); their kernels are the
//! shared code ([`crate::physics::TetLoop`]), so their cost is measured already: the board
//! bench `pe-board-tet-bench` (`scripts/board-cost.sh`, under QEMU with an exact instruction
//! counter) runs the loops of [`TetSample`] and prints the instruction counts and a digest
//! of the forces' bits, which the host recomputes from the same sample
//! (`tests/tests/board_cost.rs`: the same bits, and [`MEASURED_TET_COST`] not stale).

use crate::image::Precision;
use crate::physics::element::tet::kuhn;
use crate::physics::element::{add_nodal_volumes, Scratch};
use crate::physics::{LameParameters, MaterialLaw, Real, ReferenceTet, Tet4, TetLoop, TetPressure};

/// Cells per side of the sample cube.
pub const SAMPLE_CELLS: usize = 3;
/// Its nodes, `(n+1)³`.
pub const SAMPLE_NODES: usize = kuhn::node_count(SAMPLE_CELLS);
/// Its tetrahedra, `6n³`.
pub const SAMPLE_TETS: usize = kuhn::tet_count(SAMPLE_CELLS);
/// Side of a cell (m).
const CELL_M: f64 = 0.01;

/// A deformed patch of tetrahedra: a 3 cm cube of `SAMPLE_TETS` Kuhn tetrahedra (inner
/// nodes moved by a third of a cell), nearly incompressible neo-Hookean tissue (E = 3 kPa,
/// ν = 0.49), under the displacement field `u(X)` of [`Self::displacement`] (strains of a
/// few percent, `J` differing from element to element, so the material law takes its
/// general path and the nodal pressures differ from the elements').
pub struct TetSample<T> {
    pub tets: [Tet4<T>; SAMPLE_TETS],
    pub laws: [MaterialLaw<T>; 1],
    /// `V_n` (m³).
    pub nodal_volume: [T; SAMPLE_NODES],
    /// `u` (m).
    pub u: [[T; 3]; SAMPLE_NODES],
}

/// Why the sample could not be built (a change to the patch's geometry would show here,
/// never on a board as a panic).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleError;

impl<T: Real> TetSample<T> {
    /// The sample, every reference quantity computed in `f64` and then cast to `T`, as
    /// the compiler does for an image.
    pub fn new() -> Result<Self, SampleError> {
        let mut x = [[0.0; 3]; SAMPLE_NODES];
        let mut t = [[0u32; 4]; SAMPLE_TETS];
        kuhn::nodes(SAMPLE_CELLS, CELL_M, 1.0 / 3.0, &mut x).ok_or(SampleError)?;
        kuhn::tetrahedra(SAMPLE_CELLS, &x, &mut t).ok_or(SampleError)?;
        let mut tets = [Tet4 {
            nodes: [0; 4],
            material: 0,
            volume: T::ZERO,
            gradients: [[T::ZERO; 3]; 3],
        }; SAMPLE_TETS];
        for (record, nodes) in tets.iter_mut().zip(&t) {
            let r = ReferenceTet::new(&nodes.map(|a| x[a as usize])).map_err(|_| SampleError)?;
            *record = r.record(*nodes, 0);
        }
        let mut nodal_volume = [T::ZERO; SAMPLE_NODES];
        add_nodal_volumes(&tets, &mut nodal_volume);
        let law = MaterialLaw::NeoHookean(LameParameters::from_young_poisson(3.0e3, 0.49));
        Ok(TetSample {
            tets,
            laws: [law.cast()],
            nodal_volume,
            u: x.map(|p| Self::displacement(p).map(T::from_f64)),
        })
    }

    /// `u(X)` (m) at `X` (m), with `ξ = X / 3 cm`: a quadratic field, `L · (0.04 ξ_y ξ_z +
    /// 0.03 ξ_x², −0.05 ξ_x ξ_z + 0.02 ξ_y², 0.03 ξ_x ξ_y − 0.04 ξ_z²)`.
    pub fn displacement(x: [f64; 3]) -> [f64; 3] {
        let l = SAMPLE_CELLS as f64 * CELL_M;
        let [a, b, c] = x.map(|v| v / l);
        [
            l * (0.04 * b * c + 0.03 * a * a),
            l * (-0.05 * a * c + 0.02 * b * b),
            l * (0.03 * a * b - 0.04 * c * c),
        ]
    }

    /// The loop over the sample's tetrahedra in `form`.
    pub fn tet_loop(&self, form: TetPressure) -> TetLoop<'_, T> {
        TetLoop {
            tets: &self.tets,
            first: 0,
            laws: &self.laws,
            form,
            nodal_volume: &self.nodal_volume,
        }
    }

    /// The internal forces (N) of the sample's tetrahedra in `form`, into `f` (zeroed
    /// first): what the board bench measures and the host recomputes.
    pub fn forces(
        &self,
        form: TetPressure,
        f: &mut [[T; 3]; SAMPLE_NODES],
    ) -> Result<(), crate::physics::PhysicsError> {
        let mut ratio = [T::ZERO; SAMPLE_NODES];
        let mut pressure = [T::ZERO; SAMPLE_NODES];
        *f = [[T::ZERO; 3]; SAMPLE_NODES];
        let scratch = Scratch {
            ratio: &mut ratio,
            pressure: &mut pressure,
        };
        self.tet_loop(form).accumulate(scratch, &self.u, f)
    }
}

/// FNV-1a (64 bits) over the bits of every component of `f`, each widened to `f64`
/// (exact for `f32`): equal digests are equal forces, bit for bit.
pub fn digest<T: Real>(f: &[[T; 3]]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for v in f.iter().flatten() {
        for byte in v.to_f64().to_bits().to_le_bytes() {
            h ^= u64::from(byte);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// Executed instructions per tetrahedron of the board's loops, measured on [`TetSample`]
/// (`scripts/board-cost.sh`). Instructions, not cycles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TetCost {
    pub precision: Precision,
    /// One tetrahedron's internal forces, plain T4 (the kernel alone: `F`, stress, forces).
    pub kernel_per_tet: u32,
    /// Per tetrahedron of the plain loop ([`TetPressure::Element`]): kernel, gathering
    /// displacements, scattering forces.
    pub plain_per_tet_step: u32,
    /// Per tetrahedron of the T4ANP loop ([`TetPressure::Nodal`]): the nodal passes
    /// (`J_n`, `p_n`), then the isochoric stress with the mean nodal pressure, gathering
    /// and scattering. On one board: a partition adds the exchange of the partial nodal
    /// sums.
    pub nodal_per_tet_step: u32,
}

/// The measured table (scripts/board-cost.sh, run by CI: a test fails when a figure here is
/// more than 3% off the measurement; update it from that script's output).
pub const MEASURED_TET_COST: [TetCost; 2] = [
    TetCost {
        precision: Precision::F64,
        kernel_per_tet: 285,
        plain_per_tet_step: 340,
        nodal_per_tet_step: 475,
    },
    TetCost {
        precision: Precision::F32,
        kernel_per_tet: 221,
        plain_per_tet_step: 278,
        nodal_per_tet_step: 423,
    },
];

/// The measured cost of the tetrahedra in `precision`.
pub fn measured_tet_cost(precision: Precision) -> TetCost {
    match precision {
        Precision::F64 => MEASURED_TET_COST[0],
        Precision::F32 => MEASURED_TET_COST[1],
    }
}
