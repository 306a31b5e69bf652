//! The 8-node hexahedron in Total Lagrangian form.
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
//! Node order is the Gmsh/VTK hexahedron order.

use serde::{Deserialize, Serialize};

use super::lanes::LaneReal;
use super::material::{MaterialLaw, NonPositiveJacobian};
use super::real::{array, Real};
use super::tensor::{self, Mat3};

/// Natural coordinates of the eight nodes.
pub const NODE_XI: [[f64; 3]; 8] = [
    [-1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0],
    [1.0, 1.0, -1.0],
    [-1.0, 1.0, -1.0],
    [-1.0, -1.0, 1.0],
    [1.0, -1.0, 1.0],
    [1.0, 1.0, 1.0],
    [-1.0, 1.0, 1.0],
];

/// The six faces as node quadruples, ordered so the normal points out of the cell.
pub const FACES: [[usize; 4]; 6] = [
    [0, 3, 2, 1],
    [4, 5, 6, 7],
    [0, 1, 5, 4],
    [1, 2, 6, 5],
    [2, 3, 7, 6],
    [3, 0, 4, 7],
];

/// Hourglass base vectors `h_α`: ξη, ηζ, ζξ and ξηζ evaluated at the nodes.
pub fn hourglass_base() -> [[f64; 8]; 4] {
    core::array::from_fn(|alpha| {
        core::array::from_fn(|a| {
            let [x, y, z] = NODE_XI[a];
            match alpha {
                0 => x * y,
                1 => y * z,
                2 => z * x,
                _ => x * y * z,
            }
        })
    })
}

/// `∂N_a/∂ξ` at natural point `xi`.
pub fn natural_gradients(xi: [f64; 3]) -> [[f64; 3]; 8] {
    core::array::from_fn(|a| {
        let [xa, ya, za] = NODE_XI[a];
        let (p, q, r) = (1.0 + xa * xi[0], 1.0 + ya * xi[1], 1.0 + za * xi[2]);
        [0.125 * xa * q * r, 0.125 * ya * p * r, 0.125 * za * p * q]
    })
}

/// Corner moments `β_k = (1/8) Σ_a (Π_{j∈k} ξ_aj) g_a` of nodal vectors `g` (Gmsh order)
/// for the masks `k = 1..=7` (bit 0: ξ, bit 1: η, bit 2: ζ). For gradients (`Σ_a g_a = 0`)
/// `g_a = Σ_k (Π_{j∈k} ξ_aj) β_k`.
pub fn corner_moments(g: &[[f64; 3]; 8]) -> [[f64; 3]; 7] {
    core::array::from_fn(|m| {
        let k = m + 1;
        core::array::from_fn(|i| {
            (0..8)
                .map(|a| {
                    let sign: f64 = (0..3)
                        .filter(|j| k & (1 << j) != 0)
                        .map(|j| NODE_XI[a][j])
                        .product();
                    sign * g[a][i]
                })
                .sum::<f64>()
                / 8.0
        })
    })
}

/// Why a reference hexahedron cannot be used.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GeometryError {
    /// The Jacobian determinant is not positive at a Gauss point or a corner (inverted,
    /// degenerate or badly distorted cell); `at` is the natural point, `det_j` the value.
    NonPositiveJacobian { at: [f64; 3], det_j: f64 },
    /// A coordinate is NaN or infinite.
    NonFiniteCoordinate,
}

impl core::fmt::Display for GeometryError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            GeometryError::NonPositiveJacobian { at, det_j } => write!(
                f,
                "Jacobian determinant {det_j:.3e} <= 0 at natural point ({}, {}, {}): the cell is inverted or degenerate",
                at[0], at[1], at[2]
            ),
            GeometryError::NonFiniteCoordinate => write!(f, "a node coordinate is not finite"),
        }
    }
}

/// Jacobian `∂X/∂ξ` (`jm[i][j] = ∂X_i/∂ξ_j`) at natural point `xi`.
fn jacobian(x: &[[f64; 3]; 8], dn: &[[f64; 3]; 8]) -> Mat3<f64> {
    let mut jm = [[0.0; 3]; 3];
    for a in 0..8 {
        for i in 0..3 {
            for j in 0..3 {
                jm[i][j] += x[a][i] * dn[a][j];
            }
        }
    }
    jm
}

/// Reference-configuration data of one cell, computed in `f64`.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceHex {
    /// Initial volume `V₀` (m³).
    pub volume: f64,
    /// Uniform gradients `B_a` (1/m).
    pub mean_gradients: [[f64; 3]; 8],
    /// Hourglass shape vectors `Γ_aα = h_aα − γ_α · B_a`.
    pub hourglass: [[f64; 4]; 8],
    /// Hourglass geometry `γ_α = Σ_b h_bα X_b` (m): zero exactly when the cell is a
    /// parallelepiped (an affine image of the cube).
    pub hourglass_geometry: [[f64; 3]; 4],
    /// Gradients `∂N_a/∂X` at the 2x2x2 Gauss points and their weights `w_g det J_g` (m³).
    pub gauss_gradients: [[[f64; 3]; 8]; 8],
    pub gauss_volumes: [f64; 8],
    /// Characteristic length `L_e = V₀ / A_max` (largest face area), m.
    pub characteristic_length: f64,
    /// Smallest corner Jacobian scaled by the corner's edge lengths (1 for a cube).
    pub min_scaled_jacobian: f64,
    /// See [`Self::is_parallelepiped`] and [`Self::is_cuboid`].
    parallelepiped: bool,
    cuboid: bool,
}

/// Relative size of the hourglass geometry under which a cell is a parallelepiped: the
/// [`HexBox`] kernel then differs from the general one by about this (relative), below f64
/// round-off of the forces.
pub const PARALLELEPIPED_TOLERANCE: f64 = 1e-13;

/// Scaled Jacobian threshold under which a cell is refused as degenerate.
pub const MIN_SCALED_JACOBIAN: f64 = 1e-6;

/// The corner of a prism at `c` of its triangle `a b c` (counter-clockwise seen from the
/// other triangle), as a Jacobian whose columns are the edges `a − c`, `b − c` and the
/// prism's vertical edge `up` (from the bottom triangle to the top one): a positive
/// determinant for a well-shaped prism in either triangle.
fn prism_corner(a: [f64; 3], b: [f64; 3], c: [f64; 3], up: [f64; 3]) -> [[f64; 3]; 3] {
    let (e1, e2) = (tensor::sub(&a, &c), tensor::sub(&b, &c));
    core::array::from_fn(|i| [e1[i], e2[i], up[i]])
}

impl ReferenceHex {
    pub fn new(x: &[[f64; 3]; 8]) -> Result<Self, GeometryError> {
        if x.iter().flatten().any(|v| !v.is_finite()) {
            return Err(GeometryError::NonFiniteCoordinate);
        }
        // Corners: a zero-length edge (collapsed cell) or a strongly negative scaled
        // Jacobian (a folded cell) is refused. A slightly negative corner value with
        // positive Gauss-point values is a valid, if distorted, cell (the MacNeal-Harder
        // patch has one), so the hard test is at the Gauss points below.
        //
        // A prism stored as a degenerate hexahedron (corner 3 on corner 2, 7 on 6, the form
        // explicit codes use for wedges) has no hexahedral corners 2, 3, 6, 7: there the
        // prism's own corner is checked, the triangle's two edges and the vertical edge.
        let prism = x[3] == x[2] && x[7] == x[6];
        let mut min_scaled_jacobian = f64::INFINITY;
        for (a, corner) in NODE_XI.iter().enumerate() {
            let jm = match (prism, a) {
                (true, 2 | 3) => prism_corner(x[0], x[1], x[2], tensor::sub(&x[6], &x[2])),
                (true, 6 | 7) => prism_corner(x[4], x[5], x[6], tensor::sub(&x[6], &x[2])),
                _ => jacobian(x, &natural_gradients(*corner)),
            };
            let d = tensor::det(&jm);
            let cols: [f64; 3] = core::array::from_fn(|j| {
                libm::sqrt(jm[0][j] * jm[0][j] + jm[1][j] * jm[1][j] + jm[2][j] * jm[2][j])
            });
            let scale = cols[0] * cols[1] * cols[2];
            if !(scale > 0.0) || d < -0.2 * scale {
                return Err(GeometryError::NonPositiveJacobian {
                    at: *corner,
                    det_j: d,
                });
            }
            min_scaled_jacobian = min_scaled_jacobian.min(d / scale);
        }
        // Scale for "zero" at the Gauss points: the cube of the shortest edge.
        let min_edge_scale = {
            let mut m = f64::INFINITY;
            for f in FACES {
                for k in 0..4 {
                    let e = tensor::norm(&tensor::sub(&x[f[k]], &x[f[(k + 1) % 4]]));
                    // A prism's collapsed edges (2-3, 6-7) are not edges.
                    if !(prism && e == 0.0) {
                        m = m.min(e);
                    }
                }
            }
            m * m * m / 8.0
        };
        let g = 1.0 / libm::sqrt(3.0);
        let mut volume = 0.0;
        let mut sum = [[0.0; 3]; 8];
        let mut gauss_gradients = [[[0.0; 3]; 8]; 8];
        let mut gauss_volumes = [0.0; 8];
        for (gp, xi_n) in NODE_XI.iter().enumerate() {
            let xi = [g * xi_n[0], g * xi_n[1], g * xi_n[2]];
            let dn = natural_gradients(xi);
            let jm = jacobian(x, &dn);
            let d = tensor::det(&jm);
            if !(d > MIN_SCALED_JACOBIAN * min_edge_scale) {
                return Err(GeometryError::NonPositiveJacobian { at: xi, det_j: d });
            }
            let jinv = tensor::inverse(&jm, d);
            for a in 0..8 {
                // ∂N_a/∂X_i = Σ_j ∂N_a/∂ξ_j (J⁻¹)_ji
                let grad: [f64; 3] = core::array::from_fn(|i| {
                    dn[a][0] * jinv[0][i] + dn[a][1] * jinv[1][i] + dn[a][2] * jinv[2][i]
                });
                gauss_gradients[gp][a] = grad;
                for i in 0..3 {
                    sum[a][i] += grad[i] * d;
                }
            }
            gauss_volumes[gp] = d;
            volume += d;
        }
        let mean_gradients: [[f64; 3]; 8] =
            core::array::from_fn(|a| core::array::from_fn(|i| sum[a][i] / volume));
        let h = hourglass_base();
        let mut hourglass = [[0.0; 4]; 8];
        let mut hourglass_geometry = [[0.0; 3]; 4];
        for alpha in 0..4 {
            // γ_α = Σ_b h_bα X_b
            let mut hx = [0.0; 3];
            for b in 0..8 {
                for i in 0..3 {
                    hx[i] += h[alpha][b] * x[b][i];
                }
            }
            for a in 0..8 {
                hourglass[a][alpha] = h[alpha][a] - tensor::dot(&hx, &mean_gradients[a]);
            }
            hourglass_geometry[alpha] = hx;
        }
        let size: f64 = (0..3)
            .map(|j| {
                let e: [f64; 3] =
                    core::array::from_fn(|i| (0..8).map(|a| NODE_XI[a][j] * x[a][i]).sum());
                tensor::norm(&e)
            })
            .sum();
        let gamma_max = hourglass_geometry
            .iter()
            .map(tensor::norm)
            .fold(0.0, f64::max);
        let mut area_max: f64 = 0.0;
        for face in FACES {
            let d1 = tensor::sub(&x[face[2]], &x[face[0]]);
            let d2 = tensor::sub(&x[face[3]], &x[face[1]]);
            area_max = area_max.max(0.5 * tensor::norm(&tensor::cross(&d1, &d2)));
        }
        let parallelepiped = gamma_max <= PARALLELEPIPED_TOLERANCE * size;
        let b = basis_of(&corner_moments(&mean_gradients));
        let diag = (0..3).map(|j| libm::fabs(b[j][j])).fold(0.0, f64::max);
        let off = (0..3)
            .flat_map(|j| (0..3).filter(move |&i| i != j).map(move |i| (j, i)))
            .map(|(j, i)| libm::fabs(b[j][i]))
            .fold(0.0, f64::max);
        Ok(ReferenceHex {
            volume,
            mean_gradients,
            hourglass,
            hourglass_geometry,
            gauss_gradients,
            gauss_volumes,
            characteristic_length: volume / area_max,
            min_scaled_jacobian,
            parallelepiped,
            cuboid: parallelepiped && off <= PARALLELEPIPED_TOLERANCE * diag,
        })
    }

    /// `Σ_a |B_a|²` (1/m²).
    pub fn gradient_norm_sq(&self) -> f64 {
        self.mean_gradients.iter().flatten().map(|v| v * v).sum()
    }

    /// Hourglass stiffness `k = κ_hg G V Σ|B_a|² / 8` (N/m).
    pub fn hourglass_stiffness(&self, hourglass_modulus: f64, hourglass_coefficient: f64) -> f64 {
        hourglass_coefficient * hourglass_modulus * self.volume * self.gradient_norm_sq() / 8.0
    }

    /// Whether the cell is a parallelepiped to round-off: every hourglass geometry vector
    /// `|γ_α| ≤` [`PARALLELEPIPED_TOLERANCE`] `· Σ_j |Σ_a ξ_aj X_a|` (the cell's size: its
    /// edge vectors, four times each, summed). Such a cell takes the [`HexBox`] kernel.
    pub fn is_parallelepiped(&self) -> bool {
        self.parallelepiped
    }

    /// Whether the cell is a rectangular cuboid aligned with the axes, to round-off: a
    /// parallelepiped ([`Self::is_parallelepiped`]) whose gradient basis is diagonal, every
    /// off-diagonal `|b_ji| ≤` [`PARALLELEPIPED_TOLERANCE`] `· max_j |b_jj|`. Such a cell
    /// takes the [`HexCuboid`] kernel (generated boxes, voxel meshes).
    pub fn is_cuboid(&self) -> bool {
        self.cuboid
    }

    /// The gradients' corner moments `β_k = (1/8) Σ_a (Π_{j∈k} ξ_aj) B_a` for the masks
    /// `k = 1..=7` (1/m): `B_a = Σ_k (Π_{j∈k} ξ_aj) β_k` (the corner basis is orthogonal,
    /// and `β_0 = Σ_a B_a / 8 = 0`).
    pub fn gradient_moments(&self) -> [[f64; 3]; 7] {
        corner_moments(&self.mean_gradients)
    }

    /// The gradient basis `b_j = β_{ξ,η,ζ}` (rows, 1/m): on a parallelepiped
    /// `B_a = Σ_j ξ_aj b_j` exactly (the other moments vanish).
    pub fn gradient_basis(&self) -> Mat3<f64> {
        basis_of(&self.gradient_moments())
    }

    /// One-point element with hourglass stiffness `k = κ_hg G V Σ|B_a|² / 8` (the general
    /// kernel).
    pub fn reduced<T: Real>(
        &self,
        nodes: [u32; 8],
        material: u16,
        hourglass_modulus: f64,
        hourglass_coefficient: f64,
    ) -> HexReduced<T> {
        let k = self.hourglass_stiffness(hourglass_modulus, hourglass_coefficient);
        HexReduced {
            connectivity: Connectivity { nodes, material },
            volume: T::from_f64(self.volume),
            gradient_moments: cast2(&self.gradient_moments()),
            hourglass_geometry: cast2(&self.hourglass_geometry),
            hourglass_stiffness: T::from_f64(k),
        }
    }

    /// The parallelepiped kernel's record (meaningful when [`Self::is_parallelepiped`]):
    /// the gradient basis `b_j`, the same scaled by `V₀`, and `k`.
    pub fn parallelepiped<T: Real>(
        &self,
        nodes: [u32; 8],
        material: u16,
        hourglass_modulus: f64,
        hourglass_coefficient: f64,
    ) -> HexBox<T> {
        let k = self.hourglass_stiffness(hourglass_modulus, hourglass_coefficient);
        let b = self.gradient_basis();
        HexBox {
            connectivity: Connectivity { nodes, material },
            basis: cast2(&b),
            basis_volume: core::array::from_fn(|j| {
                core::array::from_fn(|i| T::from_f64(b[j][i] * self.volume))
            }),
            volume: T::from_f64(self.volume),
            hourglass_stiffness: T::from_f64(k),
        }
    }

    /// The cuboid kernel's record (meaningful when [`Self::is_cuboid`]): the diagonal of
    /// the gradient basis `d_j = b_jj`, the same scaled by `V₀`, and `k`.
    pub fn cuboid<T: Real>(
        &self,
        nodes: [u32; 8],
        material: u16,
        hourglass_modulus: f64,
        hourglass_coefficient: f64,
    ) -> HexCuboid<T> {
        let k = self.hourglass_stiffness(hourglass_modulus, hourglass_coefficient);
        let b = self.gradient_basis();
        HexCuboid {
            connectivity: Connectivity { nodes, material },
            scale: core::array::from_fn(|j| T::from_f64(b[j][j])),
            scale_volume: core::array::from_fn(|j| T::from_f64(b[j][j] * self.volume)),
            volume: T::from_f64(self.volume),
            hourglass_stiffness: T::from_f64(k),
        }
    }

    /// Fully integrated (2x2x2) element.
    pub fn full<T: Real>(&self, nodes: [u32; 8], material: u16) -> HexFull<T> {
        HexFull {
            connectivity: Connectivity { nodes, material },
            gauss: core::array::from_fn(|g| GaussPoint {
                gradients: cast2(&self.gauss_gradients[g]),
                volume: T::from_f64(self.gauss_volumes[g]),
            }),
        }
    }
}

/// The gradient basis `b_j = β_{ξ,η,ζ}` among the corner moments `β_k` (masks 1..=7).
fn basis_of(beta: &[[f64; 3]; 7]) -> Mat3<f64> {
    [beta[0], beta[1], beta[3]]
}

fn cast2<T: Real, const N: usize, const M: usize>(a: &[[f64; N]; M]) -> [[T; N]; M] {
    core::array::from_fn(|i| core::array::from_fn(|j| T::from_f64(a[i][j])))
}

/// Deformation gradient `F = I + Σ_a u_a ⊗ g_a` (`F_iJ = δ_iJ + Σ_a u_ai g_aJ`).
#[inline(always)]
pub fn deformation_gradient<T: Real>(u: &[[T; 3]; 8], g: &[[T; 3]; 8]) -> Mat3<T> {
    let mut f = tensor::identity::<T>();
    for a in 0..8 {
        for i in 0..3 {
            for j in 0..3 {
                f[i][j] += u[a][i] * g[a][j];
            }
        }
    }
    f
}

/// Adds `vol · P g_a` to every nodal force, `P` the first Piola-Kirchhoff stress.
#[inline(always)]
fn add_stress_forces<T: Real>(out: &mut [[T; 3]; 8], p: &Mat3<T>, g: &[[T; 3]; 8], vol: T) {
    let mut p = *p;
    for row in p.iter_mut() {
        for v in row.iter_mut() {
            *v *= vol;
        }
    }
    for a in 0..8 {
        for i in 0..3 {
            out[a][i] += p[i][0] * g[a][0] + p[i][1] * g[a][1] + p[i][2] * g[a][2];
        }
    }
}

/// What every element kind shares: its nodes (local indices, reference order) and its
/// material. (Serialised inline: an element record's bytes start with these fields.)
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Connectivity {
    pub nodes: [u32; 8],
    pub material: u16,
}

/// An element that turns nodal displacements into internal nodal forces.
pub trait HexElement<T: Real> {
    fn connectivity(&self) -> &Connectivity;
    #[inline(always)]
    fn nodes(&self) -> &[u32; 8] {
        &self.connectivity().nodes
    }
    #[inline(always)]
    fn material(&self) -> usize {
        self.connectivity().material as usize
    }
    /// Internal nodal forces for the element's nodal displacements `u` (reference order).
    fn internal_forces(
        &self,
        law: &MaterialLaw<T>,
        u: &[[T; 3]; 8],
    ) -> Result<[[T; 3]; 8], NonPositiveJacobian>;
    /// Stored energy (J): strain energy plus hourglass energy.
    fn energy(&self, law: &MaterialLaw<T>, u: &[[T; 3]; 8]) -> Result<T, NonPositiveJacobian>;
    /// Gathers the element's displacements from `u`, computes its internal forces and adds
    /// them into `f` (the element loop's body; a kernel may fuse the three). The per-node
    /// values added are bit for bit those of [`Self::internal_forces`].
    #[inline(always)]
    fn accumulate(
        &self,
        law: &MaterialLaw<T>,
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), KernelFault> {
        let nodes = checked_nodes(self.nodes(), u.len().min(f.len()))?;
        let ue = nodes.map(|n| u[n]);
        let fe = self
            .internal_forces(law, &ue)
            .map_err(KernelFault::Inverted)?;
        for (a, &n) in nodes.iter().enumerate() {
            for i in 0..3 {
                f[n][i] += fe[a][i];
            }
        }
        Ok(())
    }
}

/// Why [`HexElement::accumulate`] failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum KernelFault {
    /// `J ≤ 0`.
    Inverted(NonPositiveJacobian),
    /// A node index outside the displacement or force array.
    BadIndex,
}

/// The element's node indices as `usize`, all checked against `len` (one comparison each,
/// before any access).
#[inline(always)]
fn checked_nodes(nodes: &[u32; 8], len: usize) -> Result<[usize; 8], KernelFault> {
    let mut max = 0;
    for &n in nodes {
        max = max.max(n);
    }
    if (max as usize) < len {
        Ok(nodes.map(|n| n as usize))
    } else {
        Err(KernelFault::BadIndex)
    }
}

/// Node (Gmsh order) at binary corner `p = b_ξ + 2 b_η + 4 b_ζ` (`b = 1` where the
/// natural coordinate is +1).
const CORNER: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];

/// Corner masks of the linear fields ξ, η, ζ and of the hourglass base vectors
/// `h_α` = ξη, ηζ, ζξ, ξηζ ([`hourglass_base`] order).
const LINEAR: [usize; 3] = [1, 2, 4];
const HOURGLASS: [usize; 4] = [3, 6, 5, 7];

/// Corner transform of one component (a Walsh-Hadamard transform, 24 additions):
/// `c_k = Σ_p (Π_{j ∈ k} ξ_pj) v_p` for every mask `k` of the natural axes, `v` in corner
/// order. `c_0` is the sum, `c_LINEAR[j]` the linear moments `Σ ξ_j v`, `c_HOURGLASS[α]`
/// the hourglass moments `Σ h_α v`. The corner basis is orthogonal: `Σ_p v_p w_p =
/// (1/8) Σ_k c_k(v) c_k(w)`.
#[inline(always)]
fn transform8<T: Real>(mut w: [T; 8]) -> [T; 8] {
    for bit in [1, 2, 4] {
        for p in 0..8 {
            if p & bit == 0 {
                let (lo, hi) = (w[p], w[p | bit]);
                w[p] = lo + hi;
                w[p | bit] = hi - lo;
            }
        }
    }
    w
}

/// The transpose of [`transform8`] for moments whose sum `c_0` is zero (those of the
/// corner-basis kernels' forces: a gradient's corner values sum to zero), corner 0
/// negated: `[-v_0, v_1, .., v_7]` with `v_p = Σ_{k ≠ 0} (Π_{j ∈ k} ξ_pj) c_k`; `w[0]` is
/// not read. The butterflies of the full transpose (three stages of `s ∓ d` over the
/// bits 4, 2, 1) with the zero folded in: the first stage's pair `(0, 4)` gives `∓c_4`
/// without an addition, and the sign carried to corner 0 is left to the caller (it
/// subtracts), so 22 additions instead of 24. Each value is the full transpose's to the
/// bit (negation is exact and `a + (−b) = a − b`), except that the full one turns a
/// zero's sign where it adds `0 ± 0`.
#[inline(always)]
fn synthesis8_mean_free<T: Real>(c: [T; 8]) -> [T; 8] {
    // Stage bit 4: (0, 4) gives (−c_4, c_4); the others s ∓ d.
    let (a1, a5) = (c[1] - c[5], c[1] + c[5]);
    let (a2, a6) = (c[2] - c[6], c[2] + c[6]);
    let (a3, a7) = (c[3] - c[7], c[3] + c[7]);
    // Stage bit 2: (0, 2) is (−c_4 − a2, −c_4 + a2) = (−t, a2 − c_4), t = c_4 + a2.
    let t = c[4] + a2;
    let b2 = a2 - c[4];
    let (b1, b3) = (a1 - a3, a1 + a3);
    let (b4, b6) = (c[4] - a6, c[4] + a6);
    let (b5, b7) = (a5 - a7, a5 + a7);
    // Stage bit 1: (0, 1) is (−t − b1, −t + b1) = (−(t + b1), b1 − t).
    [
        t + b1,
        b1 - t,
        b2 - b3,
        b2 + b3,
        b4 - b5,
        b4 + b5,
        b6 - b7,
        b6 + b7,
    ]
}

/// Where a reduced kernel reads displacements and puts forces, by corner (binary order)
/// and component: the element's own arrays ([`HexElement::internal_forces`]) or the
/// board's, fused with the gather and scatter ([`HexElement::accumulate`]). Both see the
/// same values, so both give the same bits.
trait Corners<T> {
    fn get(&self, p: usize, i: usize) -> T;
    /// Adds `v` to the force at corner `p` (all three components at once: one lookup of
    /// the node per corner).
    fn add(&mut self, p: usize, v: [T; 3]);
    /// Subtracts `v` from the force at corner `p` (adds `−v`, to the bit).
    fn sub(&mut self, p: usize, v: [T; 3]);
    /// Adds `v` to component `i` of the force at corner `p`.
    fn add_one(&mut self, p: usize, i: usize, v: T);
    /// Subtracts `v` from component `i` of the force at corner `p`.
    fn sub_one(&mut self, p: usize, i: usize, v: T);
}

/// A kernel in the corner basis: reads the displacements from and adds the forces to
/// `corners` (each corner's force added once).
trait CornerKernel<T: Real> {
    fn kernel(
        &self,
        law: &MaterialLaw<T>,
        corners: &mut impl Corners<T>,
    ) -> Result<(), NonPositiveJacobian>;
}

/// [`HexElement::internal_forces`] of a corner-basis kernel: the kernel on the element's
/// own arrays (Gmsh order), through [`Global`] with the nodes `0..8`, so the element's
/// forces are the board's to the bit.
#[inline(always)]
fn local_forces<T: Real>(
    u: &[[T; 3]; 8],
    kernel: impl FnOnce(&mut Global<'_, T>) -> Result<(), NonPositiveJacobian>,
) -> Result<[[T; 3]; 8], NonPositiveJacobian> {
    let mut f = [[T::ZERO; 3]; 8];
    kernel(&mut Global::of_element(u, &mut f))?;
    Ok(f)
}

/// [`HexElement::accumulate`] of a corner-basis kernel: the kernel on the board's arrays.
#[inline(always)]
fn global_forces<T: Real>(
    nodes: &[u32; 8],
    u: &[[T; 3]],
    f: &mut [[T; 3]],
    kernel: impl FnOnce(&mut Global<'_, T>) -> Result<(), NonPositiveJacobian>,
) -> Result<(), KernelFault> {
    let mut g = Global::new(nodes, u, f)?;
    kernel(&mut g).map_err(KernelFault::Inverted)
}

/// The board's arrays at the element's nodes: [`Global::new`] checks every node against
/// both arrays (equal lengths), so the force additions below always land.
struct Global<'a, T> {
    /// Displacement of each corner (binary order).
    u: [&'a [T; 3]; 8],
    f: &'a mut [[T; 3]],
    /// Node of each corner (binary order).
    at: [usize; 8],
}

impl<'a, T: Real> Global<'a, T> {
    #[inline(always)]
    fn new(nodes: &[u32; 8], u: &'a [[T; 3]], f: &'a mut [[T; 3]]) -> Result<Self, KernelFault> {
        if u.len() != f.len() {
            return Err(KernelFault::BadIndex);
        }
        let at = CORNER.map(|a| nodes[a] as usize);
        let get = |p: usize| u.get(at[p]).ok_or(KernelFault::BadIndex);
        let u = [
            get(0)?,
            get(1)?,
            get(2)?,
            get(3)?,
            get(4)?,
            get(5)?,
            get(6)?,
            get(7)?,
        ];
        Ok(Global { u, f, at })
    }

    /// An element's own arrays (Gmsh order), as the board's arrays of its 8 nodes
    /// `0..8`: nothing to check.
    #[inline(always)]
    fn of_element(u: &'a [[T; 3]; 8], f: &'a mut [[T; 3]; 8]) -> Self {
        Global {
            u: CORNER.map(|a| &u[a]),
            f,
            at: CORNER,
        }
    }
}

impl<T: Real> Corners<T> for Global<'_, T> {
    #[inline(always)]
    fn get(&self, p: usize, i: usize) -> T {
        self.u[p][i]
    }
    #[inline(always)]
    fn add_one(&mut self, p: usize, i: usize, v: T) {
        // Always in range (see `Global::new`).
        if let Some(d) = self.f.get_mut(self.at[p]) {
            d[i] += v;
        }
    }
    #[inline(always)]
    fn sub_one(&mut self, p: usize, i: usize, v: T) {
        // Always in range (see `Global::new`).
        if let Some(d) = self.f.get_mut(self.at[p]) {
            d[i] -= v;
        }
    }
    #[inline(always)]
    fn add(&mut self, p: usize, v: [T; 3]) {
        // Always in range (see `Global::new`).
        if let Some(d) = self.f.get_mut(self.at[p]) {
            for i in 0..3 {
                d[i] += v[i];
            }
        }
    }
    #[inline(always)]
    fn sub(&mut self, p: usize, v: [T; 3]) {
        // Always in range (see `Global::new`).
        if let Some(d) = self.f.get_mut(self.at[p]) {
            for i in 0..3 {
                d[i] -= v[i];
            }
        }
    }
}

/// The corner moments of component `i` of the displacements ([`transform8`]).
#[inline(always)]
fn moments_of<T: Real>(c: &impl Corners<T>, i: usize) -> [T; 8] {
    transform8(array(
        #[inline(always)]
        |p| c.get(p, i),
    ))
}

/// Adds the nodal vectors of the moments `m[i]` (component `i`, `m[i][0]` zero and not
/// read: see [`synthesis8_mean_free`]) to the corners.
#[inline(always)]
fn add_synthesis<T: Real>(c: &mut impl Corners<T>, m: [[T; 8]; 3]) {
    let v: [[T; 8]; 3] = array(
        #[inline(always)]
        |i| synthesis8_mean_free(m[i]),
    );
    c.sub(0, [v[0][0], v[1][0], v[2][0]]);
    for p in 1..8 {
        c.add(p, [v[0][p], v[1][p], v[2][p]]);
    }
}

/// Adds the nodal values of the moments `m` of component `i` (`m[0]` zero and not read:
/// see [`synthesis8_mean_free`]) to the corners' forces, one component at a time.
#[inline(always)]
fn add_synthesis_of_component<T: Real>(c: &mut impl Corners<T>, i: usize, m: [T; 8]) {
    let v = synthesis8_mean_free(m);
    c.sub_one(0, i, v[0]);
    for p in 1..8 {
        c.add_one(p, i, v[p]);
    }
}

/// `v`, computed here and kept in memory until it is used (on the board; elsewhere `v`
/// itself): an optimisation barrier that changes no value. A reduced kernel's hourglass
/// moments are computed with `F` but used only after the material law; without it, LLVM
/// sinks their last butterfly stage past the law's branches and keeps that stage's 18
/// inputs live across the law instead of the 12 moments, spilling them. Measured on the
/// Cortex-M7 (exact instruction counts, the bench of `scripts/board-cost.sh`), per
/// element-step: cuboid kernel f64 595 -> 589, f32 516 -> 489; general kernel f32 842 ->
/// 815 (f64 unchanged). The parallelepiped kernel is faster without it (f64 688 against
/// 711), so it does not use it.
#[inline(always)]
fn kept_in_memory<T>(v: T) -> T {
    #[cfg(target_arch = "arm")]
    {
        core::hint::black_box(v)
    }
    #[cfg(not(target_arch = "arm"))]
    {
        v
    }
}

/// `I + H`.
#[inline(always)]
fn plus_identity<T: Real>(mut h: Mat3<T>) -> Mat3<T> {
    for (i, row) in h.iter_mut().enumerate() {
        row[i] += T::ONE;
    }
    h
}

/// The corner masks 1..=7 (`c_0` of a gradient is zero: gradients sum to zero).
const MASKS: [usize; 7] = [1, 2, 3, 4, 5, 6, 7];

/// One-point (reduced) element with hourglass control, any hexahedron (the general kernel),
/// in the corner basis.
///
/// The gradients are kept as their corner moments `β_k = (1/8) Σ_a (Π_{j∈k} ξ_aj) B_a`, so
/// `B_a = Σ_k (Π ξ_a) β_k` and, with the displacement moments `c_k` ([`transform8`]),
/// `H = Σ_a u_a ⊗ B_a = Σ_k c_k ⊗ β_k` (`F = I + H`). The hourglass displacements are
/// `q_α = Σ_a Γ_aα u_a = c_α − H γ_α` (`c_α` the hourglass moments, `γ_α = Σ_b h_bα X_b`),
/// and the forces `f_a = Σ_k (Π ξ_a) m_k`: the synthesis of the moments
/// `m_k = (V₀ P − M) β_k (+ Q_α on the hourglass masks)`, with `Q_α = k q_α` and
/// `M = Σ_α Q_α ⊗ γ_α`. Gathering, the transforms and scattering are fused
/// ([`HexElement::accumulate`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexReduced<T> {
    pub connectivity: Connectivity,
    pub volume: T,
    /// `β_k` for the masks 1..=7 (1/m).
    pub gradient_moments: [[T; 3]; 7],
    /// `γ_α = Σ_b h_bα X_b` (m), see [`ReferenceHex::hourglass_geometry`].
    pub hourglass_geometry: [[T; 3]; 4],
    pub hourglass_stiffness: T,
}

impl<T: Real> HexReduced<T> {
    /// `F = I + H` and the hourglass displacements `q_α`, one displacement component (row
    /// of `H`) at a time: with [`Real::FORCES_BY_COMPONENT`], each component's `q_α` with
    /// its row, otherwise all `q_α` after `H` (the same values; the shape the board's
    /// compiler serves best).
    #[inline(always)]
    fn deformation(&self, corners: &impl Corners<T>) -> (Mat3<T>, [[T; 3]; 4]) {
        let mut h = [[T::ZERO; 3]; 3];
        let mut q = [[T::ZERO; 3]; 4];
        if T::FORCES_BY_COMPONENT {
            for i in 0..3 {
                let c = moments_of(corners, i);
                h[i] = self.gradient_row(&c);
                for alpha in 0..4 {
                    q[alpha][i] = self.hourglass_displacement(c[HOURGLASS[alpha]], &h[i], alpha);
                }
            }
        } else {
            let mut hg = [[T::ZERO; 4]; 3];
            for i in 0..3 {
                let c = moments_of(corners, i);
                h[i] = self.gradient_row(&c);
                hg[i] = array(
                    #[inline(always)]
                    |a| c[HOURGLASS[a]],
                );
            }
            q = array(
                #[inline(always)]
                |alpha| {
                    array(
                        #[inline(always)]
                        |i| self.hourglass_displacement(hg[i][alpha], &h[i], alpha),
                    )
                },
            );
        }
        (plus_identity(h), q)
    }

    /// A row of `H`: `Σ_k c_k β_k` over the displacement moments `c` of one component.
    #[inline(always)]
    fn gradient_row(&self, c: &[T; 8]) -> [T; 3] {
        let beta = &self.gradient_moments;
        array(
            #[inline(always)]
            |j| {
                let mut s = c[MASKS[0]] * beta[0][j];
                for k in 1..7 {
                    s += c[MASKS[k]] * beta[k][j];
                }
                s
            },
        )
    }

    /// One component of `q_α = c_α − H γ_α`, from that component's `c_α` and row of `H`.
    #[inline(always)]
    fn hourglass_displacement(&self, c_alpha: T, h_row: &[T; 3], alpha: usize) -> T {
        let g = &self.hourglass_geometry[alpha];
        c_alpha - (h_row[0] * g[0] + h_row[1] * g[1] + h_row[2] * g[2])
    }

    /// Row `i` of `V₀ P − Σ_α Q_α ⊗ γ_α`.
    #[inline(always)]
    fn stress_row(&self, p: &Mat3<T>, big_q: &[[T; 3]; 4], i: usize) -> [T; 3] {
        array(
            #[inline(always)]
            |j| {
                let mut m = self.volume * p[i][j];
                for alpha in 0..4 {
                    m -= big_q[alpha][i] * self.hourglass_geometry[alpha][j];
                }
                m
            },
        )
    }

    /// The force moments of component `i` from its stress row: `row · β_k`, plus `Q_α` on
    /// the hourglass masks.
    #[inline(always)]
    fn force_moments(&self, row: &[T; 3], big_q: &[[T; 3]; 4], i: usize) -> [T; 8] {
        let mut m = [T::ZERO; 8];
        for (k, b) in self.gradient_moments.iter().enumerate() {
            m[MASKS[k]] = row[0] * b[0] + row[1] * b[1] + row[2] * b[2];
        }
        for alpha in 0..4 {
            m[HOURGLASS[alpha]] += big_q[alpha][i];
        }
        m
    }
}

impl<T: Real> CornerKernel<T> for HexReduced<T> {
    #[inline(always)]
    fn kernel(
        &self,
        law: &MaterialLaw<T>,
        corners: &mut impl Corners<T>,
    ) -> Result<(), NonPositiveJacobian> {
        let (f, q) = self.deformation(corners);
        let k = self.hourglass_stiffness;
        let big_q: [[T; 3]; 4] = array(
            #[inline(always)]
            |alpha| {
                array(
                    #[inline(always)]
                    |i| k * q[alpha][i],
                )
            },
        );
        let big_q = kept_in_memory(big_q);
        let p = law.first_piola_kirchhoff(&f)?;
        let rows: Mat3<T> = array(
            #[inline(always)]
            |i| self.stress_row(&p, &big_q, i),
        );
        if T::FORCES_BY_COMPONENT {
            for i in 0..3 {
                add_synthesis_of_component(corners, i, self.force_moments(&rows[i], &big_q, i));
            }
        } else {
            let m = array(
                #[inline(always)]
                |i| self.force_moments(&rows[i], &big_q, i),
            );
            add_synthesis(corners, m);
        }
        Ok(())
    }
}

/// One-point element on a parallelepiped (an affine image of the cube: the seed's
/// undistorted element), the cheap kernel: the general kernel ([`HexReduced`]) where the
/// hourglass geometry `γ` and the gradient moments off the linear masks vanish, so
/// `F = I + Σ_j c_j ⊗ b_j` (27 products instead of 63), `Γ = h` (`q_α = c_α`), and the
/// forces are the synthesis of `(P V₀ b_j)` on the linear masks and `k c_α` on the
/// hourglass ones. To round-off it gives the general kernel's forces on the same cell.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexBox<T> {
    pub connectivity: Connectivity,
    /// `b_j = β_LINEAR[j]` (1/m), see [`ReferenceHex::gradient_basis`].
    pub basis: [[T; 3]; 3],
    /// `V₀ b_j` (m²).
    pub basis_volume: [[T; 3]; 3],
    pub volume: T,
    pub hourglass_stiffness: T,
}

impl<T: Real> HexBox<T> {
    /// `F = I + Σ_j c_j ⊗ b_j` and the hourglass moments `c_α` (`hg[i][α]`), one
    /// displacement component (row of `F`) at a time.
    #[inline(always)]
    fn deformation(&self, corners: &impl Corners<T>) -> (Mat3<T>, [[T; 4]; 3]) {
        let b = &self.basis;
        let mut h = [[T::ZERO; 3]; 3];
        let mut hg = [[T::ZERO; 4]; 3];
        for i in 0..3 {
            let c = moments_of(corners, i);
            let (c0, c1, c2) = (c[LINEAR[0]], c[LINEAR[1]], c[LINEAR[2]]);
            h[i] = array(
                #[inline(always)]
                |j| c0 * b[0][j] + c1 * b[1][j] + c2 * b[2][j],
            );
            hg[i] = array(
                #[inline(always)]
                |a| c[HOURGLASS[a]],
            );
        }
        (plus_identity(h), hg)
    }
}

impl<T: Real> CornerKernel<T> for HexBox<T> {
    #[inline(always)]
    fn kernel(
        &self,
        law: &MaterialLaw<T>,
        corners: &mut impl Corners<T>,
    ) -> Result<(), NonPositiveJacobian> {
        let (f, hg) = self.deformation(corners);
        let p = law.first_piola_kirchhoff(&f)?;
        let k = self.hourglass_stiffness;
        // Each component's moments written out in the loop, not by a closure: a closure
        // cannot be marked `inline(always)` here, and one left out of line keeps the
        // host's SIMD lanes out of their registers (see `real::array`).
        for i in 0..3 {
            let row = &p[i];
            let mut m = [T::ZERO; 8];
            for (j, bv) in self.basis_volume.iter().enumerate() {
                m[LINEAR[j]] = row[0] * bv[0] + row[1] * bv[1] + row[2] * bv[2];
            }
            for alpha in 0..4 {
                m[HOURGLASS[alpha]] = k * hg[i][alpha];
            }
            add_synthesis_of_component(corners, i, m);
        }
        Ok(())
    }
}

/// [`HexElement`] of a corner-basis kernel whose `deformation` gives `F` and the hourglass
/// displacements (`q_α` of the general kernel, the moments `c_α` of the parallelepiped and
/// cuboid ones): the same energy and the same fused loop.
macro_rules! corner_element {
    ($kernel:ident) => {
        impl<T: Real> HexElement<T> for $kernel<T> {
            #[inline(always)]
            fn connectivity(&self) -> &Connectivity {
                &self.connectivity
            }
            #[inline]
            fn internal_forces(
                &self,
                law: &MaterialLaw<T>,
                u: &[[T; 3]; 8],
            ) -> Result<[[T; 3]; 8], NonPositiveJacobian> {
                local_forces(u, |c| self.kernel(law, c))
            }
            fn energy(
                &self,
                law: &MaterialLaw<T>,
                u: &[[T; 3]; 8],
            ) -> Result<T, NonPositiveJacobian> {
                let mut unused = [[T::ZERO; 3]; 8];
                let (f, hg) = self.deformation(&Global::of_element(u, &mut unused));
                let w = law.strain_energy_density(&f)? * self.volume;
                let qq: T = hg.iter().flatten().fold(T::ZERO, |s, v| s + *v * *v);
                Ok(w + T::from_f64(0.5) * self.hourglass_stiffness * qq)
            }
            #[inline(always)]
            fn accumulate(
                &self,
                law: &MaterialLaw<T>,
                u: &[[T; 3]],
                f: &mut [[T; 3]],
            ) -> Result<(), KernelFault> {
                global_forces(self.nodes(), u, f, |c| self.kernel(law, c))
            }
        }
    };
}

corner_element!(HexReduced);
corner_element!(HexBox);

/// One-point element with hourglass control on a rectangular cuboid aligned with the axes
/// (the seed's undistorted element), in the corner basis: the [`HexBox`] kernel with a
/// diagonal gradient basis `b_j = d_j e_j`, so `F_ij = δ_ij + d_j c_j[i]` (9 products
/// instead of 27 and no sums) and the linear force moments are `m_j[i] = V₀ d_j P_ij`
/// (9 products instead of 27). The hourglass moments are [`HexBox`]'s (`q_α = c_α`). It
/// gives [`HexBox`]'s forces on the same cell to round-off (the terms it drops are the
/// basis's off-diagonal round-off, within 1e-13 of its diagonal; where they are exact zeros
/// it gives [`HexBox`]'s bits), and so the general kernel's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexCuboid<T> {
    pub connectivity: Connectivity,
    /// `d_j = b_jj` (1/m), see [`ReferenceHex::gradient_basis`].
    pub scale: [T; 3],
    /// `V₀ d_j` (m²).
    pub scale_volume: [T; 3],
    pub volume: T,
    pub hourglass_stiffness: T,
}

impl<T: Real> HexCuboid<T> {
    /// `F = I + [d_j c_j[i]]` and the hourglass moments `c_α` (`hg[i][α]`), one
    /// displacement component (row of `F`) at a time.
    #[inline(always)]
    fn deformation(&self, corners: &impl Corners<T>) -> (Mat3<T>, [[T; 4]; 3]) {
        let d = &self.scale;
        let mut h = [[T::ZERO; 3]; 3];
        let mut hg = [[T::ZERO; 4]; 3];
        for i in 0..3 {
            let c = moments_of(corners, i);
            h[i] = array(
                #[inline(always)]
                |j| c[LINEAR[j]] * d[j],
            );
            hg[i] = array(
                #[inline(always)]
                |a| c[HOURGLASS[a]],
            );
        }
        (plus_identity(h), hg)
    }
}

impl<T: Real> CornerKernel<T> for HexCuboid<T> {
    #[inline(always)]
    fn kernel(
        &self,
        law: &MaterialLaw<T>,
        corners: &mut impl Corners<T>,
    ) -> Result<(), NonPositiveJacobian> {
        let (f, hg) = self.deformation(corners);
        let k = self.hourglass_stiffness;
        // The hourglass moments' forces `k c_α` before the law, kept (see `kept_in_memory`).
        let khg: [[T; 4]; 3] = kept_in_memory(array(
            #[inline(always)]
            |i| {
                array(
                    #[inline(always)]
                    |alpha| k * hg[i][alpha],
                )
            },
        ));
        let p = law.first_piola_kirchhoff(&f)?;
        // Each component's moments written out in the loop (see `HexBox`'s kernel).
        for i in 0..3 {
            let row = &p[i];
            let mut m = [T::ZERO; 8];
            for j in 0..3 {
                m[LINEAR[j]] = row[j] * self.scale_volume[j];
            }
            for alpha in 0..4 {
                m[HOURGLASS[alpha]] = khg[i][alpha];
            }
            add_synthesis_of_component(corners, i, m);
        }
        Ok(())
    }
}

corner_element!(HexCuboid);

/// The kernel an element takes, chosen per element at compile time from its reference
/// geometry (reduced integration; full integration has only [`HexFull`]). The image holds
/// one table per kernel, and a batch runs them in this order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kernel {
    /// Any hexahedron ([`HexReduced`], or [`HexFull`] with full integration).
    General = 0,
    /// A parallelepiped to round-off ([`HexBox`]).
    Parallelepiped = 1,
    /// An axis-aligned rectangular cuboid to round-off ([`HexCuboid`]).
    Cuboid = 2,
}

impl Kernel {
    pub const ALL: [Kernel; 3] = [Kernel::General, Kernel::Parallelepiped, Kernel::Cuboid];

    pub fn name(self) -> &'static str {
        match self {
            Kernel::General => "general",
            Kernel::Parallelepiped => "parallelepiped",
            Kernel::Cuboid => "cuboid",
        }
    }
}

/// One Gauss point of a fully integrated element.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GaussPoint<T> {
    pub gradients: [[T; 3]; 8],
    /// `w_g det J_g` (m³).
    pub volume: T,
}

/// Fully integrated (2x2x2 Gauss) element.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexFull<T> {
    pub connectivity: Connectivity,
    pub gauss: [GaussPoint<T>; 8],
}

impl<T: Real> HexElement<T> for HexFull<T> {
    #[inline(always)]
    fn connectivity(&self) -> &Connectivity {
        &self.connectivity
    }
    #[inline(always)]
    fn internal_forces(
        &self,
        law: &MaterialLaw<T>,
        u: &[[T; 3]; 8],
    ) -> Result<[[T; 3]; 8], NonPositiveJacobian> {
        let mut out = [[T::ZERO; 3]; 8];
        for gp in &self.gauss {
            let f = deformation_gradient(u, &gp.gradients);
            let p = law.first_piola_kirchhoff(&f)?;
            add_stress_forces(&mut out, &p, &gp.gradients, gp.volume);
        }
        Ok(out)
    }
    fn energy(&self, law: &MaterialLaw<T>, u: &[[T; 3]; 8]) -> Result<T, NonPositiveJacobian> {
        let mut w = T::ZERO;
        for gp in &self.gauss {
            let f = deformation_gradient(u, &gp.gradients);
            w += law.strain_energy_density(&f)? * gp.volume;
        }
        Ok(w)
    }
}

/// `N` elements of one kernel run side by side ([`LaneReal`]): the host's batched element
/// loop. Every lane performs exactly the operations of the scalar kernel on its element,
/// in the same order, and the forces are handed out in the order the scalar
/// [`HexElement::accumulate`] adds them, so a caller that adds them in that order gets the
/// scalar loop's bits.
pub trait LaneKernel<S: Real, L: LaneReal<S, N>, const N: usize> {
    /// The element's nodes (Gmsh positions) in the order `scatter` receives them.
    const SCATTER_ORDER: [usize; 8];
    /// Internal forces of the batch's elements, whose nodes (Gmsh order) are `nodes[l]`,
    /// at the displacements `u`: `scatter(l, node, force)` is called for the lanes
    /// `l < active`, lane by lane, each lane's nodes in the scalar kernel's order.
    /// [`KernelFault::BadIndex`] when a node of any lane is outside `u`, before any
    /// computation; [`KernelFault::Inverted`] when `J ≤ 0` in some lane (which one is not
    /// said: run the scalar kernel on the batch's elements to find it), before any call to
    /// `scatter`.
    fn lane_forces(
        &self,
        law: &MaterialLaw<L>,
        nodes: &[[u32; 8]; N],
        active: usize,
        u: &[[S; 3]],
        scatter: impl FnMut(usize, usize, [S; 3]),
    ) -> Result<(), KernelFault>;
}

/// The batch's displacements, gathered (Gmsh order) and every index checked.
#[inline(always)]
fn gather_lanes<S: Real, L: LaneReal<S, N>, const N: usize>(
    nodes: &[[u32; 8]; N],
    u: &[[S; 3]],
) -> Result<[[L; 3]; 8], KernelFault> {
    L::gather_corners(u, nodes).ok_or(KernelFault::BadIndex)
}

/// Per corner and component, the lanes as an array.
#[inline(always)]
fn lanes_out<S: Real, L: LaneReal<S, N>, const N: usize>(f: &[[L; 3]; 8]) -> [[[S; N]; 3]; 8] {
    let mut out = [[[S::ZERO; N]; 3]; 8];
    for (o, v) in out.iter_mut().zip(f) {
        for (o, v) in o.iter_mut().zip(v) {
            *o = v.to_lanes();
        }
    }
    out
}

/// A batch's corners for the corner-basis kernels: the gathered displacements and the
/// forces the kernel's synthesis produces (each corner written once).
struct LaneCorners<L> {
    u: [[L; 3]; 8],
    f: [[L; 3]; 8],
}

impl<L: Real> Corners<L> for LaneCorners<L> {
    #[inline(always)]
    fn get(&self, p: usize, i: usize) -> L {
        self.u[CORNER[p]][i]
    }
    /// [`add_synthesis`] adds to each corner once: a store, as the scalar kernel's
    /// addition into a zeroed array gives the same value (`0 + v = v`, up to the sign
    /// of a zero, which cannot change a later sum that starts from `+0`).
    #[inline(always)]
    fn add(&mut self, p: usize, v: [L; 3]) {
        self.f[p] = v;
    }
    /// As [`Corners::add`] of `−v` (`0 − v = −v` up to the sign of a zero).
    #[inline(always)]
    fn sub(&mut self, p: usize, v: [L; 3]) {
        self.f[p] = array(
            #[inline(always)]
            |i| -v[i],
        );
    }
    /// As [`Corners::add`], one component.
    #[inline(always)]
    fn add_one(&mut self, p: usize, i: usize, v: L) {
        self.f[p][i] = v;
    }
    /// As [`Corners::sub`], one component.
    #[inline(always)]
    fn sub_one(&mut self, p: usize, i: usize, v: L) {
        self.f[p][i] = -v;
    }
}

/// [`LaneKernel::lane_forces`] of a corner-basis kernel: gather, kernel, then the forces
/// lane by lane in binary corner order (the scalar [`Global`] scatter's order).
#[inline(always)]
fn lane_corner_forces<S: Real, L: LaneReal<S, N>, const N: usize>(
    kernel: &impl CornerKernel<L>,
    law: &MaterialLaw<L>,
    nodes: &[[u32; 8]; N],
    active: usize,
    u: &[[S; 3]],
    mut scatter: impl FnMut(usize, usize, [S; 3]),
) -> Result<(), KernelFault> {
    let mut c = LaneCorners {
        u: gather_lanes(nodes, u)?,
        f: [[L::ZERO; 3]; 8],
    };
    kernel.kernel(law, &mut c).map_err(KernelFault::Inverted)?;
    let f = lanes_out::<S, L, N>(&c.f);
    for (l, at) in nodes.iter().enumerate().take(active) {
        for p in 0..8 {
            scatter(
                l,
                at[CORNER[p]] as usize,
                [f[p][0][l], f[p][1][l], f[p][2][l]],
            );
        }
    }
    Ok(())
}

/// [`LaneKernel`] of the corner-basis kernels: [`lane_corner_forces`].
macro_rules! corner_lane_kernel {
    ($($kernel:ident),*) => {$(
        impl<S: Real, L: LaneReal<S, N>, const N: usize> LaneKernel<S, L, N> for $kernel<L> {
            const SCATTER_ORDER: [usize; 8] = CORNER;
            #[inline(always)]
            fn lane_forces(
                &self,
                law: &MaterialLaw<L>,
                nodes: &[[u32; 8]; N],
                active: usize,
                u: &[[S; 3]],
                scatter: impl FnMut(usize, usize, [S; 3]),
            ) -> Result<(), KernelFault> {
                lane_corner_forces(self, law, nodes, active, u, scatter)
            }
        }
    )*};
}

corner_lane_kernel!(HexReduced, HexBox, HexCuboid);

impl<S: Real, L: LaneReal<S, N>, const N: usize> LaneKernel<S, L, N> for HexFull<L> {
    const SCATTER_ORDER: [usize; 8] = [0, 1, 2, 3, 4, 5, 6, 7];
    /// Gmsh order, as the default [`HexElement::accumulate`].
    #[inline(always)]
    fn lane_forces(
        &self,
        law: &MaterialLaw<L>,
        nodes: &[[u32; 8]; N],
        active: usize,
        u: &[[S; 3]],
        mut scatter: impl FnMut(usize, usize, [S; 3]),
    ) -> Result<(), KernelFault> {
        let ue = gather_lanes(nodes, u)?;
        let fe = self
            .internal_forces(law, &ue)
            .map_err(KernelFault::Inverted)?;
        let fe = lanes_out::<S, L, N>(&fe);
        for (l, at) in nodes.iter().enumerate().take(active) {
            for (a, v) in fe.iter().enumerate() {
                scatter(l, at[a] as usize, [v[0][l], v[1][l], v[2][l]]);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The transpose of [`transform8`] with all 8 moments, three stages of `s ∓ d` over the
    /// bits 4, 2, 1 (the butterflies [`synthesis8_mean_free`] folds the zero into).
    fn full_synthesis(mut w: [f64; 8]) -> [f64; 8] {
        for bit in [4, 2, 1] {
            for p in 0..8 {
                if p & bit == 0 {
                    let (s, d) = (w[p], w[p | bit]);
                    w[p] = s - d;
                    w[p | bit] = s + d;
                }
            }
        }
        w
    }

    /// `Π_{j ∈ k} ξ_pj`: −1 for each axis of mask `k` on which corner `p` is at −1.
    fn sign(p: usize, k: usize) -> f64 {
        if (!p & k).count_ones() % 2 == 1 {
            -1.0
        } else {
            1.0
        }
    }

    /// Moments in [−1, 1) with `c_0 = 0`, from a fixed linear congruential sequence.
    fn moments(seed: u64) -> [f64; 8] {
        let mut x = seed;
        let mut c = [0.0; 8];
        for v in c.iter_mut().skip(1) {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *v = (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0;
        }
        c
    }

    /// The folded butterflies give the full transpose's bits (corner 0 negated), and both
    /// the transpose by its definition `v_p = Σ_k (Π_{j ∈ k} ξ_pj) c_k` to round-off
    /// (|v_p| ≤ 7, seven roundings of at most 2⁻⁵³·8 each: 1e-14 absolute).
    #[test]
    fn mean_free_synthesis_is_the_transpose_of_the_transform() {
        for seed in 1..200 {
            let c = moments(seed);
            let largest = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(
                largest > 0.1,
                "seed {seed}: moments {c:?} too small to tell"
            );
            let folded = synthesis8_mean_free(c);
            let full = full_synthesis(c);
            assert_eq!(folded.len(), full.len());
            assert_eq!((-folded[0]).to_bits(), full[0].to_bits(), "seed {seed}");
            for p in 1..8 {
                assert_eq!(
                    folded[p].to_bits(),
                    full[p].to_bits(),
                    "seed {seed}, corner {p}"
                );
            }
            for p in 0..8 {
                let direct: f64 = (1..8).map(|k| sign(p, k) * c[k]).sum();
                assert!(
                    (full[p] - direct).abs() <= 1e-14,
                    "seed {seed}, corner {p}: {} against {direct}",
                    full[p]
                );
            }
        }
        // And the transform it is the transpose of: synthesis of the transform is 8 times
        // the identity (the basis is orthogonal), on values whose sum is zero.
        let v = moments(7);
        let mut corners = full_synthesis(v);
        let mean = corners.iter().sum::<f64>() / 8.0;
        corners.iter_mut().for_each(|x| *x -= mean);
        let back = transform8(corners);
        let again = synthesis8_mean_free(back);
        for p in 0..8 {
            let got = if p == 0 { -again[0] } else { again[p] };
            assert!((got - 8.0 * corners[p]).abs() <= 1e-13, "corner {p}");
        }
    }
}
