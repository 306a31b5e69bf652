//! The problem's hexahedra as the physics kernels take them, in scalar type `T`: reduced
//! or full integration as the scene asks.

use pe_firmware::image::Integration;
use pe_firmware::physics::explicit::{accumulate_internal_forces, stored_energy};
use pe_firmware::physics::{HexElement, HexFull, HexReduced, MaterialLaw, PhysicsError, Real};

use crate::problem::Problem;

/// Elements of one integration kind.
pub enum Elements<T> {
    Reduced(Vec<HexReduced<T>>),
    Full(Vec<HexFull<T>>),
}

impl<T: Real> Elements<T> {
    pub fn build(p: &Problem) -> Self {
        let cells = p.mesh.cells.iter().zip(&p.reference).zip(&p.cell_material);
        if p.solver.integration == Integration::Full {
            Elements::Full(cells.map(|((c, r), m)| r.full(*c, *m)).collect())
        } else {
            Elements::Reduced(
                cells
                    .map(|((c, r), m)| {
                        let modulus = p.laws[*m as usize].hourglass_modulus();
                        r.reduced(*c, *m, modulus, p.solver.hourglass)
                    })
                    .collect(),
            )
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Elements::Reduced(v) => v.len(),
            Elements::Full(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn internal_forces(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        match self {
            Elements::Reduced(v) => accumulate_internal_forces(v, 0, laws, u, f),
            Elements::Full(v) => accumulate_internal_forces(v, 0, laws, u, f),
        }
    }

    pub fn stored_energy(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
    ) -> Result<f64, PhysicsError> {
        match self {
            Elements::Reduced(v) => stored_energy(v, laws, u),
            Elements::Full(v) => stored_energy(v, laws, u),
        }
    }

    /// Nodes of element `e`.
    pub fn nodes(&self, e: usize) -> [u32; 8] {
        match self {
            Elements::Reduced(v) => *v[e].nodes(),
            Elements::Full(v) => *v[e].nodes(),
        }
    }
}
