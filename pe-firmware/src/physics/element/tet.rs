//! The 4-node linear tetrahedron (T4): constant strain, exact integration by one point.
//!
//! Node order is Gmsh's and VTK's: the first three nodes seen from the fourth run
//! counter-clockwise, so `6V = (X₁ − X₀) · ((X₂ − X₀) × (X₃ − X₀)) > 0`.
//!
//! * Gradients `B_a = ∂N_a/∂X`, constant over the cell: with the edge matrix
//!   `E = [X₁ − X₀, X₂ − X₀, X₃ − X₀]` (columns), `B_1..B_3` are the rows of `E⁻¹` and
//!   `B_0 = −(B_1 + B_2 + B_3)`. The record keeps `B_1..B_3`.
//! * Deformation gradient `F = I + Σ_{a=1..3} (u_a − u_0) ⊗ B_a` (`= I + Σ_a u_a ⊗ B_a`).
//! * Internal force `f_a = V P B_a` for `a = 1..3` and `f_0 = −(f_1 + f_2 + f_3)`, with
//!   `P` the first Piola-Kirchhoff stress. A constant-strain element reproduces every
//!   linear displacement field exactly and has no hourglass modes, but with a nearly
//!   incompressible law its volumetric term locks (one `J` per element, about as many
//!   constraints as degrees of freedom): [`super::tet_pressure`] averages it over the nodes
//!   (T4ANP).
//! * Stable step: `L_e = 1 / √(Σ_a |B_a|²)` ([`ReferenceTet::characteristic_length`]).
//!   With lumped masses `ρV/4`, `ω²_max ≤ 4 (λ + 2μ) Σ_a |B_a|² / ρ` (the largest
//!   eigenvalue of `V Bᵀ D B` is at most `V (λ + 2μ) Σ_a |B_a|²` for an isotropic `D`
//!   whose largest eigenvalue on a unit strain is `λ + 2μ` along the volumetric mode), so
//!   `Δt_crit = 2/ω_max ≥ L_e / c`; checked against the element's eigenvalues in the tests
//!   (equality as `ν → 0.5`).

use serde::{Deserialize, Serialize};

use super::super::material::{MaterialLaw, NonPositiveJacobian};
use super::super::real::{array, Real};
use super::super::tensor::{self, Mat3};
use super::super::vec3;
use super::hex::GeometryError;
use super::kernel::KernelFault;
use super::MIN_SCALED_JACOBIAN;

/// Reference-configuration data of one tetrahedron, computed in `f64`.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceTet {
    /// Initial volume `V₀` (m³).
    pub volume: f64,
    /// Gradients `B_a` (1/m), all four.
    pub gradients: [[f64; 3]; 4],
    /// `L_e = 1/√(Σ_a |B_a|²)` (m): `L_e / c` is at most the element's critical step.
    pub characteristic_length: f64,
    /// The smallest corner Jacobian scaled by its three edges' lengths (`√2/2` at every
    /// corner of a regular tetrahedron; 1 at the right-angled corner of a corner cube).
    pub min_scaled_jacobian: f64,
}

impl ReferenceTet {
    /// The reference data of the tetrahedron whose nodes (Gmsh order) are at `x`, or why it
    /// cannot be used: a coordinate that is not finite, or a corner whose scaled Jacobian is
    /// below [`MIN_SCALED_JACOBIAN`] (inverted, flat or collapsed).
    pub fn new(x: &[[f64; 3]; 4]) -> Result<Self, GeometryError> {
        if x.iter().flatten().any(|v| !v.is_finite()) {
            return Err(GeometryError::NonFiniteCoordinate);
        }
        let e = [1, 2, 3].map(|a| vec3::sub(x[a], x[0]));
        let det = vec3::dot(e[0], vec3::cross(e[1], e[2]));
        let min_scaled_jacobian = min_scaled_jacobian(x, det);
        if !(min_scaled_jacobian >= MIN_SCALED_JACOBIAN) {
            return Err(GeometryError::NonPositiveJacobian {
                at: [0.25; 3],
                det_j: det,
            });
        }
        // Rows of E⁻¹ (E's columns the edges): the cofactors over det.
        let b1 = vec3::scale(vec3::cross(e[1], e[2]), 1.0 / det);
        let b2 = vec3::scale(vec3::cross(e[2], e[0]), 1.0 / det);
        let b3 = vec3::scale(vec3::cross(e[0], e[1]), 1.0 / det);
        let b0 = vec3::scale(vec3::add(vec3::add(b1, b2), b3), -1.0);
        let gradients = [b0, b1, b2, b3];
        let norm_sq: f64 = gradients.iter().flatten().map(|v| v * v).sum();
        Ok(ReferenceTet {
            volume: det / 6.0,
            gradients,
            characteristic_length: 1.0 / libm::sqrt(norm_sq),
            min_scaled_jacobian,
        })
    }

    /// The record of this cell in scalar type `T`, with its nodes and material.
    pub fn record<T: Real>(&self, nodes: [u32; 4], material: u16) -> Tet4<T> {
        Tet4 {
            nodes,
            material,
            volume: T::from_f64(self.volume),
            gradients: array(|a| array(|j| T::from_f64(self.gradients[a + 1][j]))),
        }
    }
}

/// `6V` over the product of a corner's three edge lengths, smallest over the corners (the
/// sign of `6V` kept: negative for an inverted cell).
fn min_scaled_jacobian(x: &[[f64; 3]; 4], det: f64) -> f64 {
    let mut min = f64::INFINITY;
    for a in 0..4 {
        let mut lengths = 1.0;
        for b in 0..4 {
            if b != a {
                lengths *= vec3::norm(vec3::sub(x[b], x[a]));
            }
        }
        let scaled = if lengths > 0.0 { det / lengths } else { 0.0 };
        if !(scaled >= min) {
            min = scaled;
        }
    }
    min
}

/// One tetrahedron as the kernels take it: nodes (local indices, Gmsh order), material,
/// `V₀` and the gradients `B_1..B_3` (`B_0 = −(B_1 + B_2 + B_3)`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tet4<T> {
    pub nodes: [u32; 4],
    pub material: u16,
    pub volume: T,
    /// `B_1..B_3` (1/m).
    pub gradients: [[T; 3]; 3],
}

impl<T: Real> Tet4<T> {
    /// `F = I + Σ_{a=1..3} (u_a − u_0) ⊗ B_a`.
    #[inline(always)]
    pub fn deformation_gradient(&self, u: &[[T; 3]; 4]) -> Mat3<T> {
        // Plain loops and always-inlined closures (not `map`), so the lanes' operations
        // stay inline in the host's batched loop (see `real::array`).
        let d: [[T; 3]; 3] = array(
            #[inline(always)]
            |a| vec3::sub(u[a + 1], u[0]),
        );
        let b = &self.gradients;
        let mut f: Mat3<T> = array(
            #[inline(always)]
            |i| {
                array(
                    #[inline(always)]
                    |j| d[0][i] * b[0][j] + d[1][i] * b[1][j],
                )
            },
        );
        for (i, row) in f.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v += d[2][i] * b[2][j];
            }
            row[i] += T::ONE;
        }
        f
    }

    /// The nodal forces of a stress `P`: `f_a = V P B_a` (`a = 1..3`), `f_0 = −Σ f_a`.
    #[inline(always)]
    pub fn forces_of_stress(&self, p: &Mat3<T>) -> [[T; 3]; 4] {
        let v = self.volume;
        let g: [[T; 3]; 3] = array(
            #[inline(always)]
            |a| {
                let b = &self.gradients[a];
                array(
                    #[inline(always)]
                    |i| v * (p[i][0] * b[0] + p[i][1] * b[1] + p[i][2] * b[2]),
                )
            },
        );
        let f0 = array(
            #[inline(always)]
            |i| -(g[0][i] + g[1][i] + g[2][i]),
        );
        [f0, g[0], g[1], g[2]]
    }

    /// Internal nodal forces of the plain T4 at its nodal displacements `u`.
    #[inline(always)]
    pub fn internal_forces(
        &self,
        law: &MaterialLaw<T>,
        u: &[[T; 3]; 4],
    ) -> Result<[[T; 3]; 4], NonPositiveJacobian> {
        let f = self.deformation_gradient(u);
        let p = law.first_piola_kirchhoff(&f)?;
        Ok(self.forces_of_stress(&p))
    }

    /// Strain energy `V W(F)` (J) of the plain T4.
    pub fn energy(&self, law: &MaterialLaw<T>, u: &[[T; 3]; 4]) -> Result<T, NonPositiveJacobian> {
        let f = self.deformation_gradient(u);
        Ok(self.volume * law.strain_energy_density(&f)?)
    }

    /// The element's node indices as `usize`, each checked against `len`.
    #[inline(always)]
    pub fn checked_nodes(&self, len: usize) -> Result<[usize; 4], KernelFault> {
        let max = self.nodes.iter().copied().max().unwrap_or(0);
        if (max as usize) < len {
            Ok(self.nodes.map(|n| n as usize))
        } else {
            Err(KernelFault::BadIndex)
        }
    }

    /// The element's displacements gathered from `u` (`nodes` from [`Self::checked_nodes`]).
    #[inline(always)]
    pub fn gather(nodes: &[usize; 4], u: &[[T; 3]]) -> [[T; 3]; 4] {
        nodes.map(|n| u[n])
    }

    /// `J = det F` of the element at `u` (its nodes checked by the caller).
    #[inline(always)]
    pub fn volume_ratio(&self, ue: &[[T; 3]; 4]) -> T {
        tensor::det(&self.deformation_gradient(ue))
    }

    /// T4ANP's share of the element's current volume for each of its nodes, `V J / 4`
    /// (m³), refused unless `J > 0`.
    #[inline(always)]
    pub fn volume_weight(&self, ue: &[[T; 3]; 4]) -> Result<T, NonPositiveJacobian> {
        let j = self.volume_ratio(ue);
        if !(j > T::ZERO) {
            return Err(NonPositiveJacobian {
                jacobian: j.to_f64(),
            });
        }
        Ok(T::from_f64(0.25) * self.volume * j)
    }
}

pub mod kuhn;
#[cfg(test)]
mod tests;
