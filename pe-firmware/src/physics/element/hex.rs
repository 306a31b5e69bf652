//! The 8-node hexahedron's geometry: natural coordinates, faces, shape-function gradients,
//! and [`ReferenceHex`], everything an element kind's record is built from, computed once in
//! `f64` from the initial configuration. Node order is the Gmsh/VTK hexahedron order.

use super::super::real::Real;
use super::super::tensor::{self, Mat3};
use super::super::vec3;

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
    let (e1, e2) = (vec3::sub(a, c), vec3::sub(b, c));
    core::array::from_fn(|i| [e1[i], e2[i], up[i]])
}

impl ReferenceHex {
    /// The reference data of the cell whose corners (Gmsh order) are at `x`, or why it
    /// cannot be used: a coordinate that is not finite, a corner folded or collapsed
    /// ([`corner_check`]), a Gauss point whose Jacobian is not clearly positive
    /// ([`GaussIntegration::of`]). Each step below is a function of its own.
    pub fn new(x: &[[f64; 3]; 8]) -> Result<Self, GeometryError> {
        if x.iter().flatten().any(|v| !v.is_finite()) {
            return Err(GeometryError::NonFiniteCoordinate);
        }
        let prism = is_prism(x);
        let min_scaled_jacobian = corner_check(x, prism)?;
        let gauss = GaussIntegration::of(x, gauss_zero_scale(x, prism))?;
        let mean_gradients = gauss.mean_gradients();
        let (hourglass, hourglass_geometry) = hourglass_vectors(x, &mean_gradients);
        let parallelepiped = is_parallelepiped(x, &hourglass_geometry);
        Ok(ReferenceHex {
            volume: gauss.volume,
            mean_gradients,
            hourglass,
            hourglass_geometry,
            gauss_gradients: gauss.gradients,
            gauss_volumes: gauss.volumes,
            characteristic_length: gauss.volume / largest_face_area(x),
            min_scaled_jacobian,
            parallelepiped,
            cuboid: parallelepiped && has_diagonal_basis(&mean_gradients),
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
}

/// A prism stored as a degenerate hexahedron: corner 3 on corner 2 and 7 on 6 (the form
/// explicit codes use for wedges).
fn is_prism(x: &[[f64; 3]; 8]) -> bool {
    x[3] == x[2] && x[7] == x[6]
}

/// The corners' Jacobians: a zero-length edge (a collapsed cell) or a strongly negative
/// scaled Jacobian (a folded cell) is refused; returns the smallest scaled Jacobian. A
/// slightly negative corner value with positive Gauss-point values is a valid, if
/// distorted, cell (the MacNeal-Harder patch has one), so the hard test is at the Gauss
/// points ([`GaussIntegration::of`]). A prism ([`is_prism`]) has no hexahedral corners 2, 3,
/// 6, 7: there the prism's own corner is checked, the triangle's two edges and the
/// vertical edge.
fn corner_check(x: &[[f64; 3]; 8], prism: bool) -> Result<f64, GeometryError> {
    let mut min_scaled_jacobian = f64::INFINITY;
    for (a, corner) in NODE_XI.iter().enumerate() {
        let jm = match (prism, a) {
            (true, 2 | 3) => prism_corner(x[0], x[1], x[2], vec3::sub(x[6], x[2])),
            (true, 6 | 7) => prism_corner(x[4], x[5], x[6], vec3::sub(x[6], x[2])),
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
    Ok(min_scaled_jacobian)
}

/// The scale for "zero" at the Gauss points: the cube of the shortest edge, over 8 (a
/// prism's collapsed edges 2-3 and 6-7 are not edges).
fn gauss_zero_scale(x: &[[f64; 3]; 8], prism: bool) -> f64 {
    let mut m = f64::INFINITY;
    for f in FACES {
        for k in 0..4 {
            let e = vec3::norm(vec3::sub(x[f[k]], x[f[(k + 1) % 4]]));
            if !(prism && e == 0.0) {
                m = m.min(e);
            }
        }
    }
    m * m * m / 8.0
}

/// The 2x2x2 Gauss integration of the cell: at each point `g` the gradients `∂N_a/∂X` and
/// the weight `w_g det J_g`, and over the cell the volume and `∫ ∂N_a/∂X dV`.
struct GaussIntegration {
    volume: f64,
    /// `Σ_g det J_g ∂N_a/∂X` per node `a`.
    gradient_integrals: [[f64; 3]; 8],
    gradients: [[[f64; 3]; 8]; 8],
    volumes: [f64; 8],
}

impl GaussIntegration {
    /// The integration of the cell at `x`; a Jacobian not above `MIN_SCALED_JACOBIAN ·
    /// zero` at a Gauss point is refused.
    fn of(x: &[[f64; 3]; 8], zero: f64) -> Result<Self, GeometryError> {
        let g = 1.0 / libm::sqrt(3.0);
        let mut out = GaussIntegration {
            volume: 0.0,
            gradient_integrals: [[0.0; 3]; 8],
            gradients: [[[0.0; 3]; 8]; 8],
            volumes: [0.0; 8],
        };
        for (gp, xi_n) in NODE_XI.iter().enumerate() {
            let xi = [g * xi_n[0], g * xi_n[1], g * xi_n[2]];
            let dn = natural_gradients(xi);
            let jm = jacobian(x, &dn);
            let d = tensor::det(&jm);
            if !(d > MIN_SCALED_JACOBIAN * zero) {
                return Err(GeometryError::NonPositiveJacobian { at: xi, det_j: d });
            }
            let jinv = tensor::inverse(&jm, d);
            for a in 0..8 {
                // ∂N_a/∂X_i = Σ_j ∂N_a/∂ξ_j (J⁻¹)_ji
                let grad: [f64; 3] = core::array::from_fn(|i| {
                    dn[a][0] * jinv[0][i] + dn[a][1] * jinv[1][i] + dn[a][2] * jinv[2][i]
                });
                out.gradients[gp][a] = grad;
                for i in 0..3 {
                    out.gradient_integrals[a][i] += grad[i] * d;
                }
            }
            out.volumes[gp] = d;
            out.volume += d;
        }
        Ok(out)
    }

    /// The uniform gradients `B_a = (1/V) ∫ ∂N_a/∂X dV`.
    fn mean_gradients(&self) -> [[f64; 3]; 8] {
        core::array::from_fn(|a| {
            core::array::from_fn(|i| self.gradient_integrals[a][i] / self.volume)
        })
    }
}

/// The hourglass shape vectors `Γ_aα = h_aα − γ_α · B_a` and the hourglass geometry
/// `γ_α = Σ_b h_bα X_b`.
fn hourglass_vectors(
    x: &[[f64; 3]; 8],
    mean_gradients: &[[f64; 3]; 8],
) -> ([[f64; 4]; 8], [[f64; 3]; 4]) {
    let h = hourglass_base();
    let mut hourglass = [[0.0; 4]; 8];
    let mut hourglass_geometry = [[0.0; 3]; 4];
    for alpha in 0..4 {
        let mut hx = [0.0; 3];
        for b in 0..8 {
            for i in 0..3 {
                hx[i] += h[alpha][b] * x[b][i];
            }
        }
        for a in 0..8 {
            hourglass[a][alpha] = h[alpha][a] - vec3::dot(hx, mean_gradients[a]);
        }
        hourglass_geometry[alpha] = hx;
    }
    (hourglass, hourglass_geometry)
}

/// Whether every hourglass geometry vector is below [`PARALLELEPIPED_TOLERANCE`] times the
/// cell's size `Σ_j |Σ_a ξ_aj X_a|` (see [`ReferenceHex::is_parallelepiped`]).
fn is_parallelepiped(x: &[[f64; 3]; 8], hourglass_geometry: &[[f64; 3]; 4]) -> bool {
    let size: f64 = (0..3)
        .map(|j| {
            let e: [f64; 3] =
                core::array::from_fn(|i| (0..8).map(|a| NODE_XI[a][j] * x[a][i]).sum());
            vec3::norm(e)
        })
        .sum();
    let gamma_max = hourglass_geometry
        .iter()
        .map(|g| vec3::norm(*g))
        .fold(0.0, f64::max);
    gamma_max <= PARALLELEPIPED_TOLERANCE * size
}

/// Whether the gradient basis `b_j` of the uniform gradients is diagonal to round-off
/// (every off-diagonal `|b_ji|` at most [`PARALLELEPIPED_TOLERANCE`] times the largest
/// `|b_jj|`): with [`is_parallelepiped`], the cuboid kernel's choice
/// ([`ReferenceHex::is_cuboid`]).
fn has_diagonal_basis(mean_gradients: &[[f64; 3]; 8]) -> bool {
    let b = basis_of(&corner_moments(mean_gradients));
    let diag = (0..3).map(|j| libm::fabs(b[j][j])).fold(0.0, f64::max);
    let off = (0..3)
        .flat_map(|j| (0..3).filter(move |&i| i != j).map(move |i| (j, i)))
        .map(|(j, i)| libm::fabs(b[j][i]))
        .fold(0.0, f64::max);
    off <= PARALLELEPIPED_TOLERANCE * diag
}

/// The largest face area, each face's `|d1 × d2| / 2` over its diagonals (for the
/// characteristic length `V₀ / A_max`).
fn largest_face_area(x: &[[f64; 3]; 8]) -> f64 {
    let mut area_max: f64 = 0.0;
    for face in FACES {
        let d1 = vec3::sub(x[face[2]], x[face[0]]);
        let d2 = vec3::sub(x[face[3]], x[face[1]]);
        area_max = area_max.max(0.5 * vec3::norm(vec3::cross(d1, d2)));
    }
    area_max
}

/// The gradient basis `b_j = β_{ξ,η,ζ}` among the corner moments `β_k` (masks 1..=7).
pub(super) fn basis_of(beta: &[[f64; 3]; 7]) -> Mat3<f64> {
    [beta[0], beta[1], beta[3]]
}

pub(super) fn cast2<T: Real, const N: usize, const M: usize>(a: &[[f64; N]; M]) -> [[T; N]; M] {
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
