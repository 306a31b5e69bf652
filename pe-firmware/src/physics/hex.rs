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

use super::material::{MaterialLaw, NonPositiveJacobian};
use super::real::Real;
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
    /// See [`Self::is_parallelepiped`].
    parallelepiped: bool,
}

/// Relative size of the hourglass geometry under which a cell is a parallelepiped: the
/// [`HexBox`] kernel then differs from the general one by about this (relative), below f64
/// round-off of the forces.
pub const PARALLELEPIPED_TOLERANCE: f64 = 1e-13;

/// Scaled Jacobian threshold under which a cell is refused as degenerate.
pub const MIN_SCALED_JACOBIAN: f64 = 1e-6;

impl ReferenceHex {
    pub fn new(x: &[[f64; 3]; 8]) -> Result<Self, GeometryError> {
        if x.iter().flatten().any(|v| !v.is_finite()) {
            return Err(GeometryError::NonFiniteCoordinate);
        }
        // Corners: a zero-length edge (collapsed cell) or a strongly negative scaled
        // Jacobian (a folded cell) is refused. A slightly negative corner value with
        // positive Gauss-point values is a valid, if distorted, cell (the MacNeal-Harder
        // patch has one), so the hard test is at the Gauss points below.
        let mut min_scaled_jacobian = f64::INFINITY;
        for corner in NODE_XI {
            let jm = jacobian(x, &natural_gradients(corner));
            let d = tensor::det(&jm);
            let cols: [f64; 3] = core::array::from_fn(|j| {
                libm::sqrt(jm[0][j] * jm[0][j] + jm[1][j] * jm[1][j] + jm[2][j] * jm[2][j])
            });
            let scale = cols[0] * cols[1] * cols[2];
            if !(scale > 0.0) || d < -0.2 * scale {
                return Err(GeometryError::NonPositiveJacobian {
                    at: corner,
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
                    m = m.min(tensor::norm(&tensor::sub(&x[f[k]], &x[f[(k + 1) % 4]])));
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
        Ok(ReferenceHex {
            volume,
            mean_gradients,
            hourglass,
            hourglass_geometry,
            gauss_gradients,
            gauss_volumes,
            characteristic_length: volume / area_max,
            min_scaled_jacobian,
            parallelepiped: gamma_max <= PARALLELEPIPED_TOLERANCE * size,
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

    /// The gradient basis `b_j = (1/8) Σ_a ξ_aj B_a` (rows, 1/m): on a parallelepiped
    /// `B_a = Σ_j ξ_aj b_j` exactly.
    pub fn gradient_basis(&self) -> Mat3<f64> {
        core::array::from_fn(|j| {
            core::array::from_fn(|i| {
                (0..8)
                    .map(|a| NODE_XI[a][j] * self.mean_gradients[a][i])
                    .sum::<f64>()
                    / 8.0
            })
        })
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
            gradients: cast2(&self.mean_gradients),
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
}

/// Node (Gmsh order) at binary corner `p = b_ξ + 2 b_η + 4 b_ζ` (`b = 1` where the
/// natural coordinate is +1).
const CORNER: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];

/// Corner masks of the linear fields ξ, η, ζ and of the hourglass base vectors
/// `h_α` = ξη, ηζ, ζξ, ξηζ ([`hourglass_base`] order).
const LINEAR: [usize; 3] = [1, 2, 4];
const HOURGLASS: [usize; 4] = [3, 6, 5, 7];

/// Corner transform (a Walsh-Hadamard transform, 24 additions per component):
/// `c_k = Σ_a (Π_{j ∈ k} ξ_aj) v_a` for every mask `k` of the natural axes. `c_0` is the sum,
/// `c_LINEAR[j]` the linear moments `Σ_a ξ_aj v_a`, `c_HOURGLASS[α]` the hourglass moments
/// `Σ_a h_aα v_a`.
#[inline(always)]
fn corner_transform<T: Real>(v: &[[T; 3]; 8]) -> [[T; 3]; 8] {
    let mut w: [[T; 3]; 8] = core::array::from_fn(|p| v[CORNER[p]]);
    for bit in [1, 2, 4] {
        for p in 0..8 {
            if p & bit == 0 {
                let (lo, hi) = (w[p], w[p | bit]);
                for i in 0..3 {
                    w[p][i] = lo[i] + hi[i];
                    w[p | bit][i] = hi[i] - lo[i];
                }
            }
        }
    }
    w
}

/// The transpose of [`corner_transform`]: nodal vectors `f_a = Σ_k (Π_{j ∈ k} ξ_aj) c_k`
/// (Gmsh order) from moments `c` (24 additions per component).
#[inline(always)]
fn corner_synthesis<T: Real>(mut w: [[T; 3]; 8]) -> [[T; 3]; 8] {
    for bit in [4, 2, 1] {
        for p in 0..8 {
            if p & bit == 0 {
                let (s, d) = (w[p], w[p | bit]);
                for i in 0..3 {
                    w[p][i] = s[i] - d[i];
                    w[p | bit][i] = s[i] + d[i];
                }
            }
        }
    }
    let mut out = [[T::ZERO; 3]; 8];
    for p in 0..8 {
        out[CORNER[p]] = w[p];
    }
    out
}

/// One-point (reduced) element with hourglass control, any hexahedron (the general kernel).
///
/// With the displacement gradient `H = Σ_a u_a ⊗ B_a` (`F = I + H`) and the hourglass
/// moments `c_α = Σ_a h_aα u_a` from the [`corner_transform`], the hourglass displacements
/// are `q_α = Σ_a Γ_aα u_a = c_α − H γ_α`, and the forces
/// `f_a = (V₀ P − M) B_a + Σ_α h_aα Q_α` with `Q_α = k q_α`, `M = Σ_α Q_α ⊗ γ_α`: the
/// hourglass control costs two corner transforms and two 3x3x4 products instead of
/// `Γ` (8x4) products per component.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexReduced<T> {
    pub connectivity: Connectivity,
    pub volume: T,
    pub gradients: [[T; 3]; 8],
    /// `γ_α = Σ_b h_bα X_b` (m), see [`ReferenceHex::hourglass_geometry`].
    pub hourglass_geometry: [[T; 3]; 4],
    pub hourglass_stiffness: T,
}

impl<T: Real> HexReduced<T> {
    /// `H = Σ_a u_a ⊗ B_a` and the hourglass displacements `q_α = c_α − H γ_α`.
    #[inline(always)]
    fn strain_and_modes(&self, u: &[[T; 3]; 8]) -> (Mat3<T>, [[T; 3]; 4]) {
        let mut h = [[T::ZERO; 3]; 3];
        for a in 0..8 {
            for i in 0..3 {
                for j in 0..3 {
                    h[i][j] += u[a][i] * self.gradients[a][j];
                }
            }
        }
        let c = corner_transform(u);
        let q = core::array::from_fn(|alpha| {
            let g = &self.hourglass_geometry[alpha];
            let m = &c[HOURGLASS[alpha]];
            core::array::from_fn(|i| m[i] - (h[i][0] * g[0] + h[i][1] * g[1] + h[i][2] * g[2]))
        });
        (h, q)
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

impl<T: Real> HexElement<T> for HexReduced<T> {
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
        let (h, q) = self.strain_and_modes(u);
        let p = law.first_piola_kirchhoff(&plus_identity(h))?;
        let k = self.hourglass_stiffness;
        let big_q: [[T; 3]; 4] = core::array::from_fn(|alpha| q[alpha].map(|v| k * v));
        // V₀ P − Σ_α Q_α ⊗ γ_α
        let pm: Mat3<T> = core::array::from_fn(|i| {
            core::array::from_fn(|j| {
                let mut m = self.volume * p[i][j];
                for alpha in 0..4 {
                    m -= big_q[alpha][i] * self.hourglass_geometry[alpha][j];
                }
                m
            })
        });
        let mut moments = [[T::ZERO; 3]; 8];
        for alpha in 0..4 {
            moments[HOURGLASS[alpha]] = big_q[alpha];
        }
        let mut out = corner_synthesis(moments);
        for a in 0..8 {
            let g = &self.gradients[a];
            for i in 0..3 {
                out[a][i] += pm[i][0] * g[0] + pm[i][1] * g[1] + pm[i][2] * g[2];
            }
        }
        Ok(out)
    }
    fn energy(&self, law: &MaterialLaw<T>, u: &[[T; 3]; 8]) -> Result<T, NonPositiveJacobian> {
        let (h, q) = self.strain_and_modes(u);
        let w = law.strain_energy_density(&plus_identity(h))? * self.volume;
        let qq: T = q.iter().flatten().fold(T::ZERO, |s, v| s + *v * *v);
        Ok(w + T::from_f64(0.5) * self.hourglass_stiffness * qq)
    }
}

/// One-point element on a parallelepiped (an affine image of the cube: the seed's
/// undistorted element), the cheap kernel. There `B_a = Σ_j ξ_aj b_j` and `Γ = h`, so with
/// the moments `c = ` [`corner_transform`]`(u)`:
/// `F = I + Σ_j c_j ⊗ b_j` (27 products instead of 72),
/// `f = ` [`corner_synthesis`] of `(P V₀ b_j)` on the linear moments and `k c_α` on the
/// hourglass ones: the gradients and the hourglass vectors cost additions only.
/// To round-off it gives the general kernel's forces ([`HexReduced`]) on the same cell.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexBox<T> {
    pub connectivity: Connectivity,
    /// `b_j` (1/m), see [`ReferenceHex::gradient_basis`].
    pub basis: [[T; 3]; 3],
    /// `V₀ b_j` (m²).
    pub basis_volume: [[T; 3]; 3],
    pub volume: T,
    pub hourglass_stiffness: T,
}

impl<T: Real> HexBox<T> {
    /// `F = I + Σ_j c_j ⊗ b_j` and the moments.
    #[inline(always)]
    fn deformation(&self, u: &[[T; 3]; 8]) -> (Mat3<T>, [[T; 3]; 8]) {
        let c = corner_transform(u);
        let b = &self.basis;
        let (c0, c1, c2) = (&c[LINEAR[0]], &c[LINEAR[1]], &c[LINEAR[2]]);
        let h: Mat3<T> = core::array::from_fn(|i| {
            core::array::from_fn(|j| c0[i] * b[0][j] + c1[i] * b[1][j] + c2[i] * b[2][j])
        });
        (plus_identity(h), c)
    }
}

impl<T: Real> HexElement<T> for HexBox<T> {
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
        let (f, c) = self.deformation(u);
        let p = law.first_piola_kirchhoff(&f)?;
        let k = self.hourglass_stiffness;
        let mut moments = [[T::ZERO; 3]; 8];
        for (j, bv) in self.basis_volume.iter().enumerate() {
            moments[LINEAR[j]] =
                core::array::from_fn(|i| p[i][0] * bv[0] + p[i][1] * bv[1] + p[i][2] * bv[2]);
        }
        for m in HOURGLASS {
            moments[m] = c[m].map(|v| k * v);
        }
        Ok(corner_synthesis(moments))
    }
    fn energy(&self, law: &MaterialLaw<T>, u: &[[T; 3]; 8]) -> Result<T, NonPositiveJacobian> {
        let (f, c) = self.deformation(u);
        let w = law.strain_energy_density(&f)? * self.volume;
        let qq: T = HOURGLASS
            .iter()
            .flat_map(|&m| c[m])
            .fold(T::ZERO, |s, v| s + v * v);
        Ok(w + T::from_f64(0.5) * self.hourglass_stiffness * qq)
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
    #[inline]
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
