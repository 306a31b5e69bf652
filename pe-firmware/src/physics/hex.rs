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
    /// Hourglass shape vectors `Γ_aα`.
    pub hourglass: [[f64; 4]; 8],
    /// Gradients `∂N_a/∂X` at the 2x2x2 Gauss points and their weights `w_g det J_g` (m³).
    pub gauss_gradients: [[[f64; 3]; 8]; 8],
    pub gauss_volumes: [f64; 8],
    /// Characteristic length `L_e = V₀ / A_max` (largest face area), m.
    pub characteristic_length: f64,
    /// Smallest corner Jacobian scaled by the corner's edge lengths (1 for a cube).
    pub min_scaled_jacobian: f64,
}

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
        for alpha in 0..4 {
            // (Σ_b h_bα X_b)
            let mut hx = [0.0; 3];
            for b in 0..8 {
                for i in 0..3 {
                    hx[i] += h[alpha][b] * x[b][i];
                }
            }
            for a in 0..8 {
                hourglass[a][alpha] = h[alpha][a] - tensor::dot(&hx, &mean_gradients[a]);
            }
        }
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
            gauss_gradients,
            gauss_volumes,
            characteristic_length: volume / area_max,
            min_scaled_jacobian,
        })
    }

    /// `Σ_a |B_a|²` (1/m²).
    pub fn gradient_norm_sq(&self) -> f64 {
        self.mean_gradients.iter().flatten().map(|v| v * v).sum()
    }

    /// One-point element with hourglass stiffness `k = κ_hg G V Σ|B_a|² / 8`.
    pub fn reduced<T: Real>(
        &self,
        nodes: [u32; 8],
        material: u16,
        hourglass_modulus: f64,
        hourglass_coefficient: f64,
    ) -> HexReduced<T> {
        let k =
            hourglass_coefficient * hourglass_modulus * self.volume * self.gradient_norm_sq() / 8.0;
        HexReduced {
            connectivity: Connectivity { nodes, material },
            volume: T::from_f64(self.volume),
            gradients: cast2(&self.mean_gradients),
            hourglass: cast2(&self.hourglass),
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

/// Adds `vol · P g_a` to every nodal force, `P = F S` the first Piola-Kirchhoff stress.
#[inline(always)]
fn add_stress_forces<T: Real>(
    out: &mut [[T; 3]; 8],
    f: &Mat3<T>,
    s: &Mat3<T>,
    g: &[[T; 3]; 8],
    vol: T,
) {
    let mut p = tensor::mul(f, s);
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

/// One-point (reduced) element with hourglass control.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexReduced<T> {
    pub connectivity: Connectivity,
    pub volume: T,
    pub gradients: [[T; 3]; 8],
    pub hourglass: [[T; 4]; 8],
    pub hourglass_stiffness: T,
}

impl<T: Real> HexReduced<T> {
    /// Hourglass generalised displacements `q_α = Σ_b Γ_bα · u_b` (one per direction).
    #[inline(always)]
    fn hourglass_modes(&self, u: &[[T; 3]; 8]) -> [[T; 3]; 4] {
        let mut q = [[T::ZERO; 3]; 4];
        for b in 0..8 {
            for alpha in 0..4 {
                let gam = self.hourglass[b][alpha];
                for i in 0..3 {
                    q[alpha][i] += gam * u[b][i];
                }
            }
        }
        q
    }
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
        let f = deformation_gradient(u, &self.gradients);
        let s = law.second_piola_kirchhoff(&f)?;
        let mut out = [[T::ZERO; 3]; 8];
        add_stress_forces(&mut out, &f, &s, &self.gradients, self.volume);
        let mut q = self.hourglass_modes(u);
        for qa in q.iter_mut() {
            for v in qa.iter_mut() {
                *v *= self.hourglass_stiffness;
            }
        }
        for a in 0..8 {
            for alpha in 0..4 {
                let gam = self.hourglass[a][alpha];
                for i in 0..3 {
                    out[a][i] += gam * q[alpha][i];
                }
            }
        }
        Ok(out)
    }
    fn energy(&self, law: &MaterialLaw<T>, u: &[[T; 3]; 8]) -> Result<T, NonPositiveJacobian> {
        let f = deformation_gradient(u, &self.gradients);
        let w = law.strain_energy_density(&f)? * self.volume;
        let q = self.hourglass_modes(u);
        let qq: T = q.iter().flatten().fold(T::ZERO, |s, v| s + *v * *v);
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
            let s = law.second_piola_kirchhoff(&f)?;
            add_stress_forces(&mut out, &f, &s, &gp.gradients, gp.volume);
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
