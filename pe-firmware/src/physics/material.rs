//! Hyperelastic laws in Total Lagrangian form: the second Piola-Kirchhoff stress
//! `S = 2 ∂W/∂C` from the deformation gradient `F`, with `C = Fᵀ F`, `J = det F`.
//!
//! * Compressible neo-Hookean: `W = μ/2 (I₁ − 3) − μ ln J + λ/2 (ln J)²`,
//!   `S = μ (I − C⁻¹) + λ ln J C⁻¹`.
//! * Decoupled (nearly incompressible) neo-Hookean: `W = μ/2 (Ī₁ − 3) + κ/2 (J − 1)²`
//!   with `Ī₁ = J^(−2/3) I₁`.
//! * Mooney-Rivlin: `W = c₁₀ (Ī₁ − 3) + c₀₁ (Ī₂ − 3) + U(J)`, `Ī₂ = J^(−4/3) I₂`,
//!   `U = κ/2 (J − 1)²` ([`Volumetric::Quadratic`]) or `κ/2 (ln J)²` ([`Volumetric::Log`]):
//!   `S = 2c₁₀ J^(−2/3) (I − I₁/3 C⁻¹) + 2c₀₁ J^(−4/3) (I₁ I − C − 2/3 I₂ C⁻¹) + J U'(J) C⁻¹`.
//!
//! A law never panics: `J ≤ 0` (an inverted element) is returned as an error.

use serde::{Deserialize, Serialize};

use super::real::{array, Real};
use super::tensor::{self, Mat3};

/// Lamé parameters of small-strain elasticity, in Pa.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LameParameters<T> {
    pub mu: T,
    pub lambda: T,
}

impl LameParameters<f64> {
    /// From Young's modulus `E` (Pa) and Poisson's ratio `ν`:
    /// `μ = E / (2(1+ν))`, `λ = E ν / ((1+ν)(1−2ν))`.
    pub fn from_young_poisson(youngs_modulus: f64, poisson_ratio: f64) -> Self {
        let (e, nu) = (youngs_modulus, poisson_ratio);
        LameParameters {
            mu: e / (2.0 * (1.0 + nu)),
            lambda: e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        }
    }
    /// Bulk modulus `κ = λ + 2μ/3`.
    pub fn bulk_modulus(&self) -> f64 {
        self.lambda + 2.0 * self.mu / 3.0
    }
}

/// Volumetric energy `U(J)` of the decoupled laws.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Volumetric {
    /// `U = κ/2 (J − 1)²`
    Quadratic,
    /// `U = κ/2 (ln J)²`
    Log,
}

/// A hyperelastic law with its parameters (Pa).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum MaterialLaw<T> {
    NeoHookean(LameParameters<T>),
    NeoHookeanDecoupled {
        mu: T,
        kappa: T,
    },
    MooneyRivlin {
        c10: T,
        c01: T,
        kappa: T,
        volumetric: Volumetric,
    },
}

/// `J = det F ≤ 0`: the element is inverted (or degenerate) at this point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NonPositiveJacobian {
    pub jacobian: f64,
}

impl MaterialLaw<f64> {
    /// Convert the parameters to the solver's scalar type.
    pub fn cast<T: Real>(&self) -> MaterialLaw<T> {
        let c = T::from_f64;
        match *self {
            MaterialLaw::NeoHookean(l) => MaterialLaw::NeoHookean(LameParameters {
                mu: c(l.mu),
                lambda: c(l.lambda),
            }),
            MaterialLaw::NeoHookeanDecoupled { mu, kappa } => MaterialLaw::NeoHookeanDecoupled {
                mu: c(mu),
                kappa: c(kappa),
            },
            MaterialLaw::MooneyRivlin {
                c10,
                c01,
                kappa,
                volumetric,
            } => MaterialLaw::MooneyRivlin {
                c10: c(c10),
                c01: c(c01),
                kappa: c(kappa),
                volumetric,
            },
        }
    }

    /// Small-strain shear modulus μ (Pa).
    pub fn shear_modulus(&self) -> f64 {
        match *self {
            MaterialLaw::NeoHookean(l) => l.mu,
            MaterialLaw::NeoHookeanDecoupled { mu, .. } => mu,
            MaterialLaw::MooneyRivlin { c10, c01, .. } => 2.0 * (c10 + c01),
        }
    }

    /// Small-strain bulk modulus κ (Pa).
    pub fn bulk_modulus(&self) -> f64 {
        match *self {
            MaterialLaw::NeoHookean(l) => l.bulk_modulus(),
            MaterialLaw::NeoHookeanDecoupled { kappa, .. } => kappa,
            MaterialLaw::MooneyRivlin { kappa, .. } => kappa,
        }
    }

    /// Modulus `G = 2μ` that scales the hourglass stiffness (equal to `λ + 2μ` at ν = 0,
    /// and finite as ν → 0.5, so the hourglass control does not lock).
    pub fn hourglass_modulus(&self) -> f64 {
        2.0 * self.shear_modulus()
    }

    /// P-wave (dilatational) modulus `M = κ + 4μ/3 = λ + 2μ` (Pa): sets the wave speed
    /// `c = √(M/ρ)` and the hourglass stiffness.
    pub fn dilatational_modulus(&self) -> f64 {
        self.bulk_modulus() + 4.0 / 3.0 * self.shear_modulus()
    }
}

impl<T: Real> MaterialLaw<T> {
    /// Second Piola-Kirchhoff stress `S(F)`.
    #[inline(always)]
    pub fn second_piola_kirchhoff(&self, f: &Mat3<T>) -> Result<Mat3<T>, NonPositiveJacobian> {
        let j = tensor::det(f);
        if !(j > T::ZERO) {
            return Err(NonPositiveJacobian {
                jacobian: j.to_f64(),
            });
        }
        let c = tensor::gram(f);
        let det_c = j * j;
        let c_inv = tensor::inverse_symmetric(&c, det_c);
        let mut s = [[T::ZERO; 3]; 3];
        match *self {
            MaterialLaw::NeoHookean(LameParameters { mu, lambda }) => {
                let b = lambda * j.ln() - mu;
                for i in 0..3 {
                    for k in 0..3 {
                        s[i][k] = b * c_inv[i][k];
                    }
                    s[i][i] += mu;
                }
            }
            MaterialLaw::NeoHookeanDecoupled { mu, kappa } => {
                // S = μ J^(-2/3) (I - I1/3 C⁻¹) + κ (J-1) J C⁻¹
                let j23 = inv_j_two_thirds(j);
                let i1 = tensor::trace(&c);
                let a = mu * j23;
                let b = kappa * (j - T::ONE) * j - a * i1 / T::from_i32(3);
                for i in 0..3 {
                    for k in 0..3 {
                        s[i][k] = b * c_inv[i][k];
                    }
                    s[i][i] += a;
                }
            }
            MaterialLaw::MooneyRivlin {
                c10,
                c01,
                kappa,
                volumetric,
            } => {
                let j23 = inv_j_two_thirds(j);
                let j43 = j23 * j23;
                let i1 = tensor::trace(&c);
                let i2 = half_i2(&c, i1);
                let two = T::from_i32(2);
                let third = T::ONE / T::from_i32(3);
                let a1 = two * c10 * j23;
                let a2 = two * c01 * j43;
                let vol = match volumetric {
                    Volumetric::Quadratic => kappa * (j - T::ONE) * j,
                    Volumetric::Log => kappa * j.ln(),
                };
                // coefficient of C⁻¹
                let b = vol - a1 * i1 * third - a2 * two * third * i2;
                for i in 0..3 {
                    for k in 0..3 {
                        s[i][k] = b * c_inv[i][k] - a2 * c[i][k];
                    }
                    s[i][i] += a1 + a2 * i1;
                }
            }
        }
        Ok(s)
    }

    /// First Piola-Kirchhoff stress `P = F S(F)`, what the element kernels need, with the
    /// neo-Hookean laws in closed form through the cofactor matrix `cof F = J F⁻ᵀ` (no `C`,
    /// no `C⁻¹`): `P = μ F + ((λ ln J − μ)/J) cof F` (compressible),
    /// `P = a F + ((κ (J−1) J − a I₁/3)/J) cof F` with `a = μ J^(−2/3)`, `I₁ = F : F`
    /// (decoupled); Mooney-Rivlin as `F S`.
    #[inline(always)]
    pub fn first_piola_kirchhoff(&self, f: &Mat3<T>) -> Result<Mat3<T>, NonPositiveJacobian> {
        let (a, b_over_j, cof) = match *self {
            MaterialLaw::MooneyRivlin { .. } => {
                let s = self.second_piola_kirchhoff(f)?;
                return Ok(tensor::mul(f, &s));
            }
            MaterialLaw::NeoHookean(LameParameters { mu, lambda }) => {
                let (cof, j) = positive_cofactor(f)?;
                (mu, (lambda * j.ln() - mu) / j, cof)
            }
            MaterialLaw::NeoHookeanDecoupled { mu, kappa } => {
                let (cof, j) = positive_cofactor(f)?;
                let a = mu * inv_j_two_thirds(j);
                let i1 = tensor::ddot(f, f);
                let b = kappa * (j - T::ONE) * j - a * i1 / T::from_i32(3);
                (a, b / j, cof)
            }
        };
        Ok(f_and_cofactor(a, f, b_over_j, &cof))
    }

    /// Strain energy density `W(F)` per unit reference volume (J/m³).
    pub fn strain_energy_density(&self, f: &Mat3<T>) -> Result<T, NonPositiveJacobian> {
        let j = tensor::det(f);
        if !(j > T::ZERO) {
            return Err(NonPositiveJacobian {
                jacobian: j.to_f64(),
            });
        }
        let c = tensor::gram(f);
        let i1 = tensor::trace(&c);
        let three = T::from_i32(3);
        let half = T::from_f64(0.5);
        Ok(match *self {
            MaterialLaw::NeoHookean(LameParameters { mu, lambda }) => {
                let lj = j.ln();
                half * mu * (i1 - three) - mu * lj + half * lambda * lj * lj
            }
            MaterialLaw::NeoHookeanDecoupled { mu, kappa } => {
                let d = j - T::ONE;
                half * mu * (inv_j_two_thirds(j) * i1 - three) + half * kappa * d * d
            }
            MaterialLaw::MooneyRivlin {
                c10,
                c01,
                kappa,
                volumetric,
            } => {
                let j23 = inv_j_two_thirds(j);
                let i2 = half_i2(&c, i1);
                let u = match volumetric {
                    Volumetric::Quadratic => (j - T::ONE) * (j - T::ONE),
                    Volumetric::Log => j.ln() * j.ln(),
                };
                c10 * (j23 * i1 - three) + c01 * (j23 * j23 * i2 - three) + half * kappa * u
            }
        })
    }
}

/// The split of a law into its isochoric part and its volumetric energy `U(J)`, for
/// elements that take the pressure from elsewhere than the element's own `J` (the
/// tetrahedron's averaged nodal pressure, [`crate::physics::element::tet_pressure`]):
/// `W(F) = W_iso(F) + U(J)` and `P(F) = P_iso(F) + U'(J) cof F`, where the volumetric
/// term is the one with the bulk parameter (`λ` of the compressible neo-Hookean law,
/// `κ` of the decoupled ones), the term that locks a linear element as `ν → 0.5`.
impl<T: Real> MaterialLaw<T> {
    /// The law without its volumetric term (`λ = 0` or `κ = 0`): `W_iso`, `P_iso`.
    pub fn isochoric(&self) -> MaterialLaw<T> {
        match *self {
            MaterialLaw::NeoHookean(LameParameters { mu, .. }) => {
                MaterialLaw::NeoHookean(LameParameters {
                    mu,
                    lambda: T::ZERO,
                })
            }
            MaterialLaw::NeoHookeanDecoupled { mu, .. } => {
                MaterialLaw::NeoHookeanDecoupled { mu, kappa: T::ZERO }
            }
            MaterialLaw::MooneyRivlin {
                c10,
                c01,
                volumetric,
                ..
            } => MaterialLaw::MooneyRivlin {
                c10,
                c01,
                kappa: T::ZERO,
                volumetric,
            },
        }
    }

    /// `P = P_iso(F) + p cof F`: the isochoric part's first Piola-Kirchhoff stress and a
    /// given pressure `p` (Pa; T4ANP's mean nodal pressure), with one cofactor and no
    /// logarithm: `P = μ F + (p − μ/J) cof F` (compressible neo-Hookean at `λ = 0`),
    /// `P = a F + (p − a I₁/(3J)) cof F` with `a = μ J^(−2/3)` (decoupled), `F S_iso +
    /// p cof F` (Mooney-Rivlin). Refused unless `J > 0`.
    #[inline(always)]
    pub fn isochoric_stress_with_pressure(
        &self,
        f: &Mat3<T>,
        p: T,
    ) -> Result<Mat3<T>, NonPositiveJacobian> {
        let (a, b_over_j, cof) = match *self {
            MaterialLaw::MooneyRivlin { .. } => {
                let s = self.isochoric().second_piola_kirchhoff(f)?;
                let fs = tensor::mul(f, &s);
                let cof = tensor::cofactor(f);
                return Ok(array(
                    #[inline(always)]
                    |i| {
                        array(
                            #[inline(always)]
                            |k| fs[i][k] + p * cof[i][k],
                        )
                    },
                ));
            }
            MaterialLaw::NeoHookean(LameParameters { mu, .. }) => {
                let (cof, j) = positive_cofactor(f)?;
                (mu, p - mu / j, cof)
            }
            MaterialLaw::NeoHookeanDecoupled { mu, .. } => {
                let (cof, j) = positive_cofactor(f)?;
                let a = mu * inv_j_two_thirds(j);
                let i1 = tensor::ddot(f, f);
                (a, p - a * i1 / T::from_i32(3) / j, cof)
            }
        };
        Ok(f_and_cofactor(a, f, b_over_j, &cof))
    }

    /// The pressure-like derivative `U'(J)` (Pa): `λ ln J / J` (compressible neo-Hookean),
    /// `κ (J − 1)` (quadratic), `κ ln J / J` (logarithmic). `J > 0` is the caller's.
    #[inline(always)]
    pub fn volumetric_pressure(&self, j: T) -> T {
        match *self {
            MaterialLaw::NeoHookean(LameParameters { lambda, .. }) => lambda * j.ln() / j,
            MaterialLaw::NeoHookeanDecoupled { kappa, .. }
            | MaterialLaw::MooneyRivlin {
                kappa,
                volumetric: Volumetric::Quadratic,
                ..
            } => kappa * (j - T::ONE),
            MaterialLaw::MooneyRivlin {
                kappa,
                volumetric: Volumetric::Log,
                ..
            } => kappa * j.ln() / j,
        }
    }

    /// The volumetric energy density `U(J)` (J/m³): `λ/2 (ln J)²`, `κ/2 (J − 1)²` or
    /// `κ/2 (ln J)²`.
    pub fn volumetric_energy(&self, j: T) -> T {
        let half = T::from_f64(0.5);
        match *self {
            MaterialLaw::NeoHookean(LameParameters { lambda, .. }) => {
                half * lambda * j.ln() * j.ln()
            }
            MaterialLaw::NeoHookeanDecoupled { kappa, .. }
            | MaterialLaw::MooneyRivlin {
                kappa,
                volumetric: Volumetric::Quadratic,
                ..
            } => half * kappa * (j - T::ONE) * (j - T::ONE),
            MaterialLaw::MooneyRivlin {
                kappa,
                volumetric: Volumetric::Log,
                ..
            } => half * kappa * j.ln() * j.ln(),
        }
    }
}

/// The cofactor matrix `cof F = J F⁻ᵀ` and `J = det F`, refused unless `J > 0`.
#[inline(always)]
fn positive_cofactor<T: Real>(f: &Mat3<T>) -> Result<(Mat3<T>, T), NonPositiveJacobian> {
    let cof = tensor::cofactor(f);
    let j = f[0][0] * cof[0][0] + f[0][1] * cof[0][1] + f[0][2] * cof[0][2];
    if !(j > T::ZERO) {
        return Err(NonPositiveJacobian {
            jacobian: j.to_f64(),
        });
    }
    Ok((cof, j))
}

/// `a F + c cof F`: the neo-Hookean laws' first Piola-Kirchhoff stress.
#[inline(always)]
fn f_and_cofactor<T: Real>(a: T, f: &Mat3<T>, c: T, cof: &Mat3<T>) -> Mat3<T> {
    array(
        #[inline(always)]
        |i| {
            array(
                #[inline(always)]
                |k| a * f[i][k] + c * cof[i][k],
            )
        },
    )
}

/// `J^(−2/3)`.
#[inline(always)]
fn inv_j_two_thirds<T: Real>(j: T) -> T {
    let r = j.cbrt();
    T::ONE / (r * r)
}

/// Second invariant `I₂ = ½ (I₁² − tr C²)`.
#[inline(always)]
fn half_i2<T: Real>(c: &Mat3<T>, i1: T) -> T {
    let trc2 = tensor::ddot(c, c);
    T::from_f64(0.5) * (i1 * i1 - trc2)
}

/// Cauchy stress `σ = J⁻¹ F S Fᵀ` (for reports and tests).
pub fn cauchy_stress<T: Real>(f: &Mat3<T>, s: &Mat3<T>) -> Mat3<T> {
    let j = tensor::det(f);
    let fs = tensor::mul(f, s);
    let ft = tensor::transpose(f);
    let mut sigma = tensor::mul(&fs, &ft);
    for row in sigma.iter_mut() {
        for v in row.iter_mut() {
            *v = *v / j;
        }
    }
    sigma
}
