//! Finite elements, one file per element kind.
//!
//! Everything geometric is computed once from the initial (reference) configuration `X`:
//!
//! * **Uniform (mean) gradient** of Flanagan and Belytschko (1981):
//!   `B_a = (1/V) ∫_V ∂N_a/∂X dV`, evaluated exactly by 2x2x2 Gauss quadrature (the integrand
//!   `∂N_a/∂X · det J` is at most quadratic in each natural coordinate). With it the
//!   one-point element reproduces any linear displacement field exactly on distorted meshes
//!   (the patch test), unlike gradients taken at the centroid.
//! * Reduced (one-point) internal force, the seed's eq. 6: `f_a = V₀ F S B_a`, with
//!   `F = I + Σ_a u_a ⊗ B_a`.
//! * **Hourglass control against the initial configuration** (the seed's eq. 7; Joldes et al.):
//!   `Γ_aα = h_aα − (Σ_b h_bα X_b) · B_a` for the four hourglass base vectors `h_α`; the force
//!   `f_a = k Σ_α Γ_aα (Σ_b Γ_bα · u_b)` depends on the current displacement only, so nothing
//!   accumulates and a load cycle returns to rest. `Γ` is orthogonal to every linear field, so
//!   rigid motions and uniform strains give zero hourglass force. The stiffness is
//!   `k = κ_hg G V Σ_a |B_a|² / 8` with `G = 2μ` (see [`MaterialLaw::hourglass_modulus`])
//!   and `κ_hg` the scene's `hourglass` coefficient. Scaling by the shear rather than the
//!   dilatational modulus keeps nearly incompressible materials from locking in bending
//!   (with `λ + 2μ` a ν = 0.499 beam came out 27 times too stiff; measured).
//! * **Full 2x2x2 Gauss integration** as the accurate alternative: `f_a = Σ_g w_g det J_g P_g B_ga`
//!   (no hourglass control needed).
//!
//! Rooms: [`hex`] the hexahedron's geometry and its reference data ([`ReferenceHex`]),
//! [`kernel`] what every kind implements ([`Element`], [`HexElement`], [`LaneKernel`]),
//! `corner` the corner basis of the one-point kernels; one file per kind: [`HexReduced`]
//! (any cell), [`HexBox`] (parallelepipeds), [`HexCuboid`] (axis-aligned cuboids),
//! [`HexFull`] (full integration), each with its lane packing ([`crate::physics::Pack`]);
//! here the registry: the user's choice [`Integration`] and the kinds, [`ElementKind`].
//! Tetrahedra: [`tet`] the linear tetrahedron's geometry and kernel ([`ReferenceTet`],
//! [`Tet4`]), [`tet_pressure`] its element loop, plain or with averaged nodal pressure
//! (T4ANP, [`TetLoop`]); they run on the host (`pe solve`), not yet on the boards.
//!
//! **A new element kind** is a file here plus its registrations. The file holds the record
//! (serialised, its [`Connectivity`] first) and its four implementations: [`Element`] (its
//! `KIND` and the record built from the cell's reference data), [`HexElement`] (the scalar
//! kernel the board runs), [`LaneKernel`] and [`crate::physics::Pack`] (the host's lanes,
//! the same operations in the same order). It registers: a variant of [`ElementKind`] and
//! its row in each of its tables (`name`, `integration`, `table`, and the per-cell choice
//! [`ElementKind::of`]); its measured instruction cost, a figure of
//! [`crate::profile::MEASURED_COST`] and its arm of
//! [`crate::profile::FirmwareCost::element_step`] (`scripts/board-cost.sh` measures it); if it
//! is an integration's general record, an arm of [`crate::with_element_types`] (and the
//! board crate's feature); if it takes an element table of its own (a kind with its own
//! cells, such as a tetrahedron), [`ElementKind::TABLES`] and that table's section in the
//! image ([`crate::image::Counts`], [`crate::image::codec::transcode`] and `validate`), in
//! the board's storage ([`crate::runtime::storage`]) and in the batch loops
//! ([`crate::runtime::BatchSlices`], the host's `problem::elements` and `solver::batched`).

use serde::{Deserialize, Serialize};

mod corner;
pub mod hex;
mod hex_box;
mod hex_cuboid;
mod hex_full;
mod hex_reduced;
pub mod hourglass;
pub mod kernel;
pub mod tet;
pub mod tet_lanes;
pub mod tet_pressure;

pub use hex::{
    corner_moments, deformation_gradient, hourglass_base, natural_gradients, GeometryError,
    ReferenceHex, FACES, MIN_SCALED_JACOBIAN, NODE_XI, PARALLELEPIPED_TOLERANCE,
};
pub use hex_box::HexBox;
pub use hex_cuboid::HexCuboid;
pub use hex_full::{GaussPoint, HexFull};
pub use hex_reduced::HexReduced;
pub use hourglass::{FramedStiffness, HourglassControl, ModeStiffness};
pub use kernel::{Connectivity, Element, HexElement, Hourglass, KernelFault, LaneKernel};
pub use tet::{ReferenceTet, Tet4};
pub use tet_pressure::{add_nodal_volumes, Scratch, TetLoop, TetPressure};

/// The element choice a scene makes (`integration = "reduced" | "full"` in its solver
/// settings) and an image's header records: which kinds ([`ElementKind::integration`]) the
/// compiler may choose from for a cell. The user-facing setting; the kinds are the kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Integration {
    Reduced,
    Full,
}

impl Integration {
    /// The name scenes, manifests and reports use: "reduced" | "full".
    pub const fn name(self) -> &'static str {
        match self {
            Integration::Reduced => "reduced",
            Integration::Full => "full",
        }
    }
}

impl core::fmt::Display for Integration {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// The element kinds, one file each: the registry every table below is written in, and the
/// key of the records ([`Element::KIND`]), the image's element tables, the compiler's choice
/// per cell ([`ElementKind::of`]) and the firmware cost table
/// ([`crate::profile::FirmwareCost::element_step`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ElementKind {
    /// Any hexahedron, one-point with hourglass control ([`HexReduced`]).
    HexReduced,
    /// A parallelepiped to round-off ([`HexBox`]).
    HexBox,
    /// An axis-aligned rectangular cuboid to round-off ([`HexCuboid`]).
    HexCuboid,
    /// Any hexahedron, fully integrated ([`HexFull`]).
    HexFull,
}

impl ElementKind {
    pub const ALL: [ElementKind; 4] = [
        ElementKind::HexReduced,
        ElementKind::HexBox,
        ElementKind::HexCuboid,
        ElementKind::HexFull,
    ];

    /// Element tables of an image (and of a board's storage): each holds one kind, and a
    /// batch runs them in table order.
    pub const TABLES: usize = 3;

    pub const fn name(self) -> &'static str {
        match self {
            ElementKind::HexReduced => "general hexahedron",
            ElementKind::HexBox => "parallelepiped",
            ElementKind::HexCuboid => "cuboid",
            ElementKind::HexFull => "fully integrated hexahedron",
        }
    }

    /// The element choice the kind belongs to.
    pub const fn integration(self) -> Integration {
        match self {
            ElementKind::HexReduced | ElementKind::HexBox | ElementKind::HexCuboid => {
                Integration::Reduced
            }
            ElementKind::HexFull => Integration::Full,
        }
    }

    /// The element table the kind's records take in an image of its integration: 0 the
    /// general one (the image's element record type), 1 the parallelepipeds, 2 the cuboids.
    pub const fn table(self) -> usize {
        match self {
            ElementKind::HexReduced | ElementKind::HexFull => 0,
            ElementKind::HexBox => 1,
            ElementKind::HexCuboid => 2,
        }
    }

    /// The kind table `table` of an image of `integration` holds (`None`: the table stays
    /// empty there).
    pub const fn in_table(integration: Integration, table: usize) -> Option<ElementKind> {
        let mut k = 0;
        while k < ElementKind::ALL.len() {
            let kind = ElementKind::ALL[k];
            if kind.integration() as u8 == integration as u8 && kind.table() == table {
                return Some(kind);
            }
            k += 1;
        }
        None
    }

    /// The kind a cell whose reference data is `r` takes under `integration`: the cheapest
    /// kernel that gives the general one's forces on it (to round-off; see
    /// [`ReferenceHex::is_parallelepiped`] and [`ReferenceHex::is_cuboid`]).
    pub fn of(r: &ReferenceHex, integration: Integration) -> ElementKind {
        match integration {
            Integration::Full => ElementKind::HexFull,
            Integration::Reduced if r.is_cuboid() => ElementKind::HexCuboid,
            Integration::Reduced if r.is_parallelepiped() => ElementKind::HexBox,
            Integration::Reduced => ElementKind::HexReduced,
        }
    }
}

impl core::fmt::Display for ElementKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}
