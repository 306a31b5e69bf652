//! Each mesh cell's reference geometry: a hexahedron's ([`ReferenceHex`], prisms included)
//! or a tetrahedron's ([`ReferenceTet`], a cell stored by
//! [`crate::mesh::tetrahedron_as_hexahedron`]), computed once in `f64` when the problem is
//! built, and what every consumer asks of either.

use pe_firmware::physics::{ReferenceHex, ReferenceTet};

/// The reference geometry of one mesh cell (a hexahedron's 2 KiB boxed, so a tetrahedral
/// mesh's cells take about 130 bytes each).
#[derive(Clone, Debug, PartialEq)]
pub enum CellReference {
    Hex(Box<ReferenceHex>),
    Tet(ReferenceTet),
}

impl CellReference {
    /// Initial volume `V₀` (m³).
    pub fn volume(&self) -> f64 {
        match self {
            CellReference::Hex(r) => r.volume,
            CellReference::Tet(r) => r.volume,
        }
    }

    /// `L_e` (m): `L_e / c` is the element's step estimate (`V/A_max` for a hexahedron,
    /// `1/√(Σ_a |B_a|²)` for a tetrahedron, each a bound on its own element's critical step).
    pub fn characteristic_length(&self) -> f64 {
        match self {
            CellReference::Hex(r) => r.characteristic_length,
            CellReference::Tet(r) => r.characteristic_length,
        }
    }

    /// The smallest scaled corner Jacobian (1 for a cube).
    pub fn min_scaled_jacobian(&self) -> f64 {
        match self {
            CellReference::Hex(r) => r.min_scaled_jacobian,
            CellReference::Tet(r) => r.min_scaled_jacobian,
        }
    }

    /// The hexahedron's data (None for a tetrahedron).
    pub fn hex(&self) -> Option<&ReferenceHex> {
        match self {
            CellReference::Hex(r) => Some(r.as_ref()),
            CellReference::Tet(_) => None,
        }
    }

    /// Its nodes' share of its mass: an eighth per hexahedral corner, a quarter per
    /// tetrahedral node (lumped mass), in the cell's eight slots (a tetrahedron's
    /// repeated slots share their node's quarter).
    pub fn mass_shares(&self) -> [f64; 8] {
        match self {
            CellReference::Hex(_) => [0.125; 8],
            CellReference::Tet(_) => [0.25, 0.25, 0.125, 0.125, 0.0625, 0.0625, 0.0625, 0.0625],
        }
    }

    /// The uniform gradients `B_a` in the cell's eight slots (1/m), such that
    /// `Σ_slots u ⊗ B = H` on the cell's stored nodes: a hexahedron's own; a tetrahedron's
    /// split evenly over its repeated slots.
    pub fn slot_gradients(&self) -> [[f64; 3]; 8] {
        match self {
            CellReference::Hex(r) => r.mean_gradients,
            CellReference::Tet(r) => {
                let g = &r.gradients;
                let part = |a: usize, s: f64| g[a].map(|v| v * s);
                [
                    g[0],
                    g[1],
                    part(2, 0.5),
                    part(2, 0.5),
                    part(3, 0.25),
                    part(3, 0.25),
                    part(3, 0.25),
                    part(3, 0.25),
                ]
            }
        }
    }

    /// `G = w Σ_a B_a B_aᵀ` over the element's nodes, with `w` its nodes' mass share over
    /// a hexahedron's (1 for a hexahedron, 1/2 for a tetrahedron: lumped masses `ρV/4`
    /// against `ρV/8`), so that `8 c² tr(F⁻ᵀ G F⁻¹)` bounds either element's `ω²`.
    pub fn frequency_products(&self) -> [[f64; 3]; 3] {
        let (g, w): (&[[f64; 3]], f64) = match self {
            CellReference::Hex(r) => (&r.mean_gradients, 1.0),
            CellReference::Tet(r) => (&r.gradients, 0.5),
        };
        core::array::from_fn(|i| {
            core::array::from_fn(|j| w * g.iter().map(|b| b[i] * b[j]).sum::<f64>())
        })
    }
}
