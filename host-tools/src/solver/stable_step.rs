//! The stable step of the deformed state, element by element, the way explicit codes
//! track it: cheap enough to run every few steps, so `dt` comes down before an
//! instability rather than after.
//!
//! For a one-point hexahedron with lumped mass, Flanagan and Belytschko (1981) bound the
//! highest frequency of the element by
//!
//! `ω_e² ≤ 8 c² Σ_a |∂N_a/∂x|² = 8 c² tr G'`, `G' = Σ_a (F⁻ᵀ B_a)(F⁻ᵀ B_a)ᵀ`,
//!
//! with `F⁻ᵀ B_a` the current uniform gradients (`B_a` the reference ones) and `c` the current
//! dilatational wave speed. The sum weighs the three directions alike, while an element
//! flattened in one direction vibrates mostly across it; the tracker uses
//! `8 c² (tr G' + γ max_i G'_ii) / (1 + γ/3)`, still an upper bound (`max_i G'_ii ≥ tr G'/3`)
//! and equal to the sum for a cube ([`DIRECTIONAL_WEIGHT`]). With `ρ = ρ₀/J`, `ρ c² = M(J)` the spatial
//! P-wave modulus of the law about the current state:
//!
//! * neo-Hookean `μ/2 (I₁−3) − μ ln J + λ/2 (ln J)²`: material part `λ + 2μ − 2λ ln J`;
//! * decoupled laws with `U(J)` and shear modulus `μ`: `J (J U'' − U' + 4/3 μ̄)` with
//!   `μ̄ = μ J^(−5/3) I₁/3` (`U = κ/2 (J−1)²`: `J U'' − U' = κ`; `U = κ/2 (ln J)²`:
//!   `κ (1 − 2 ln J)/J`);
//!
//! plus the initial-stress (geometric) part, the largest principal Kirchhoff stress when in
//! tension, bounded by `μ (I₁ − 3)⁺ + (J p)⁺` (`p` the pressure part; exact in uniaxial
//! strain). Under uniaxial strain `s` the sum is `∂τ/∂ln s − 2τ + τ⁺`, the longitudinal
//! wave modulus of the stressed solid. `ln J` is bounded by `1 − 1/J ≤ ln J ≤ J − 1`, each
//! side where it raises the modulus (no logarithm per element; second order in `J − 1`).
//!
//! By Irons' theorem the mesh's highest frequency is at most the largest element's, so
//! `2 / max_e ω_e` is a lower bound on the critical step of the uniform-strain part. The
//! hourglass stiffness and the boundary conditions move the true value away from it by a
//! factor fixed by the mesh: the tracker is calibrated against the power iteration at rest
//! (`κ = dt_crit(0) · max_e ω_e(0) / 2`) and reports `κ · 2 / max_e ω_e(t)`; a power
//! iteration about the deformed state (`dt_recheck_interval`) can only lower `κ`.
//!
//! Cost: about 200 flops per element per check, against about 800 for a step's element
//! kernel; at the default interval it is a few percent of a step (measured in the run
//! report's `dt_tracking_s`).

use pe_firmware::physics::element::hex::deformation_gradient;
use pe_firmware::physics::{tensor, vec3, MaterialLaw, Real, Volumetric};

use crate::problem::Problem;

/// What a check found: the critical step about the current state and the cell that sets it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackedStep {
    pub dt_critical_s: f64,
    pub limiting_cell: usize,
}

/// Element-by-element bound on the critical step of the deformed state of `problem`.
pub struct StableStepTracker<'p> {
    problem: &'p Problem,
    /// Per cell, what a bound reads, side by side (one pass over a compact array: the
    /// gradients read from the problem's reference cells, about 2 KiB apart, made a check
    /// take 17% of a `pe solve` of the seed's box at the default interval, now 8%).
    cells: Vec<TrackedCell>,
    /// `1 / (ρ₀ · mass_scaling)` per material.
    inverse_density: Vec<f64>,
    /// `κ`: the critical step at rest over the uncalibrated bound at rest.
    pub calibration: f64,
}

/// What the tracker keeps of a cell.
#[derive(Clone, Copy, Debug)]
struct TrackedCell {
    /// The uniform gradients `B_a` (1/m), the reference cell's, in its eight slots
    /// ([`crate::problem::CellReference::slot_gradients`]).
    gradients: [[f64; 3]; 8],
    /// `G = Σ_a B_a B_aᵀ` (a tetrahedron's halved for its quarter masses:
    /// [`crate::problem::CellReference::frequency_products`]).
    products: [[f64; 3]; 3],
}

/// `γ`: the weight of the stiffest direction in the element's size measure (see the module
/// doc). With `γ = 0` (the plain Flanagan-Belytschko sum) the calibrated bound came out 9%
/// above a fresh power estimate at 50% uniaxial compression (unsafe at dt_safety 0.99);
/// measured ratios tracked/fresh, compression and sagging cantilever: `γ = 0` 1.09/0.84,
/// `γ = 1` 0.95/0.79, `γ = 2` 0.88/0.76 (`pe stability --only compression` and
/// `--only sagging`).
pub const DIRECTIONAL_WEIGHT: f64 = 1.0;

/// Cells per parallel task: large enough that the split costs nothing.
const CHUNK: usize = 1024;

impl<'p> StableStepTracker<'p> {
    /// The tracker of `problem`, calibrated so that it gives the problem's critical step
    /// (`time_step.critical`) at rest.
    pub fn new(problem: &'p Problem) -> Self {
        let ms = problem.solver.mass_scaling;
        let mut t = StableStepTracker {
            problem,
            cells: problem
                .reference
                .iter()
                .map(|r| TrackedCell {
                    gradients: r.slot_gradients(),
                    products: r.frequency_products(),
                })
                .collect(),
            inverse_density: problem.densities.iter().map(|r| 1.0 / (r * ms)).collect(),
            calibration: 1.0,
        };
        let zero = vec![[0.0f64; 3]; problem.mesh.nodes.len()];
        let at_rest = t.bound(&zero, None).dt_critical_s;
        let dt0 = problem.time_step.critical.dt_critical_s;
        if at_rest.is_finite() && at_rest > 0.0 && dt0.is_finite() {
            t.calibration = dt0 / at_rest;
        }
        t
    }

    /// `ω_e²` bound of cell `e` at displacements `u` (see the module doc); zero for an
    /// inverted cell, which the element phase reports as such.
    fn omega_sq<T: Real>(&self, e: usize, u: &[[T; 3]]) -> f64 {
        let p = self.problem;
        let cell = &p.mesh.cells[e];
        let ua: [[f64; 3]; 8] = core::array::from_fn(|a| {
            let v = u.get(cell[a] as usize).copied().unwrap_or([T::ZERO; 3]);
            v.map(|x| x.to_f64())
        });
        let Some(tracked) = self.cells.get(e) else {
            return 0.0;
        };
        let f = deformation_gradient(&ua, &tracked.gradients);
        // F⁻ᵀ = cof F / J, J = det F (along the first row).
        let c = tensor::cofactor(&f);
        let jac = vec3::dot(f[0], c[0]);
        if !(jac > 0.0) {
            return 0.0;
        }
        // Σ_a |F⁻ᵀ B_a|² = Σ_a |cof F · B_a|² / J² = tr(cof F · G · cof Fᵀ) / J², with
        // G = Σ_a B_a B_aᵀ.
        let gg = &tracked.products;
        let (mut s, mut dmax) = (0.0, 0.0f64);
        for row in &c {
            let cg: [f64; 3] =
                core::array::from_fn(|j| row[0] * gg[0][j] + row[1] * gg[1][j] + row[2] * gg[2][j]);
            let d = cg[0] * row[0] + cg[1] * row[1] + cg[2] * row[2];
            s += d;
            dmax = dmax.max(d);
        }
        s = (s + DIRECTIONAL_WEIGHT * dmax) / (1.0 + DIRECTIONAL_WEIGHT / 3.0);
        s /= jac * jac;
        let m = p.cell_material[e] as usize;
        let modulus = wave_modulus(&p.laws[m], jac, tensor::ddot(&f, &f));
        8.0 * modulus * self.inverse_density[m] * s
    }

    /// The calibrated critical step about displacements `u` (`κ · 2 / max_e ω_e`), on
    /// `team`'s threads when given (the maximum does not depend on the split).
    pub fn bound<T: Real>(&self, u: &[[T; 3]], team: Option<&super::team::Team>) -> TrackedStep {
        let chunk_max = |k: usize| {
            let (lo, hi) = (
                k * CHUNK,
                ((k + 1) * CHUNK).min(self.problem.mesh.cells.len()),
            );
            (lo..hi)
                .map(|e| (self.omega_sq(e, u), e))
                .fold((0.0f64, 0usize), |a, b| if b.0 > a.0 { b } else { a })
        };
        let chunks = self.problem.mesh.cells.len().div_ceil(CHUNK);
        let pick = |a: (f64, usize), b: (f64, usize)| {
            if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                b
            } else {
                a
            }
        };
        let (w2, cell) = match team {
            Some(t) if chunks > 1 => t.map(chunks, chunk_max).into_iter().fold((0.0, 0), pick),
            _ => (0..chunks).map(chunk_max).fold((0.0, 0), pick),
        };
        let dt = if w2 > 0.0 {
            self.calibration * 2.0 / w2.sqrt()
        } else {
            f64::INFINITY
        };
        TrackedStep {
            dt_critical_s: dt,
            limiting_cell: cell,
        }
    }
}

/// `ρ₀ c²` of `law` about a state with `J = det F` and `I₁ = tr C` (see the module doc),
/// never below the shear modulus.
pub fn wave_modulus(law: &MaterialLaw<f64>, jac: f64, i1: f64) -> f64 {
    // ln J bounded without a logarithm, each bound on the side that raises the modulus:
    // 1 − 1/J ≤ ln J ≤ J − 1.
    let (ln_j_low, ln_j_high) = (1.0 - 1.0 / jac, jac - 1.0);
    // (material part, shear modulus, Kirchhoff pressure J p)
    let (m, mu, jp) = match *law {
        MaterialLaw::NeoHookean(l) => (
            l.lambda + 2.0 * l.mu - 2.0 * l.lambda * ln_j_low,
            l.mu,
            l.lambda * ln_j_high,
        ),
        MaterialLaw::NeoHookeanDecoupled { mu, kappa } => (
            decoupled(kappa, Volumetric::Quadratic, mu, jac, i1),
            mu,
            jac * kappa * (jac - 1.0),
        ),
        MaterialLaw::MooneyRivlin {
            c10,
            c01,
            kappa,
            volumetric,
        } => {
            let mu = 2.0 * (c10 + c01);
            let jp = match volumetric {
                Volumetric::Quadratic => jac * kappa * (jac - 1.0),
                Volumetric::Log => kappa * ln_j_high,
            };
            (decoupled(kappa, volumetric, mu, jac, i1), mu, jp)
        }
    };
    let geometric = (mu * (i1 - 3.0)).max(0.0) + jp.max(0.0);
    m.max(mu) + geometric
}

fn decoupled(kappa: f64, volumetric: Volumetric, mu: f64, jac: f64, i1: f64) -> f64 {
    let vol = match volumetric {
        Volumetric::Quadratic => kappa,
        Volumetric::Log => kappa * (1.0 - 2.0 * (1.0 - 1.0 / jac)) / jac,
    };
    let mu_bar = mu * jac.powf(-5.0 / 3.0) * i1 / 3.0;
    jac * (vol + 4.0 / 3.0 * mu_bar)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pe_firmware::physics::material::LameParameters;

    #[test]
    fn wave_modulus_at_rest_is_the_p_wave_modulus() {
        // At J = 1, I₁ = 3 every law's ρ₀c² is κ + 4μ/3 = λ + 2μ (the small-strain value).
        let l = LameParameters::from_young_poisson(5e3, 0.45);
        let (mu, kappa) = (l.mu, l.bulk_modulus());
        let p_wave = l.lambda + 2.0 * l.mu;
        assert!(p_wave > 1e4, "a non-trivial modulus: {p_wave}");
        let laws = [
            MaterialLaw::NeoHookean(l),
            MaterialLaw::NeoHookeanDecoupled { mu, kappa },
            MaterialLaw::MooneyRivlin {
                c10: mu / 4.0,
                c01: mu / 4.0,
                kappa,
                volumetric: Volumetric::Log,
            },
        ];
        for law in &laws {
            let m = wave_modulus(law, 1.0, 3.0);
            // Round-off only: the formulas are exact at rest.
            assert!(
                (m - p_wave).abs() <= 1e-12 * p_wave,
                "{law:?}: {m} vs {p_wave}"
            );
        }
    }

    #[test]
    fn neo_hookean_wave_modulus_in_uniaxial_strain() {
        // Uniaxial strain F = diag(s, 1, 1): the Kirchhoff stress is τ = μ(s² − 1) + λ ln s,
        // the spatial tangent along the stretch ∂τ/∂ln s − 2τ, and the stressed solid's
        // longitudinal modulus adds τ in tension (the bound drops it in compression, where
        // it lowers the frequency). The derivative by central difference.
        let l = LameParameters::from_young_poisson(5e3, 0.3);
        let tau = |s: f64| l.mu * (s * s - 1.0) + l.lambda * s.ln();
        for s in [0.6, 0.8, 1.0, 1.3, 1.6] {
            let h = 1e-5;
            let d = (tau(s * (1.0 + h)) - tau(s * (1.0 - h))) / ((1.0 + h).ln() - (1.0 - h).ln());
            let expected = d - 2.0 * tau(s) + tau(s).max(0.0);
            assert!(expected > l.mu, "a non-trivial modulus: {expected}");
            let m = wave_modulus(&MaterialLaw::NeoHookean(l), s, s * s + 2.0);
            // What the logarithm-free bounds of ln J add, second order in s − 1 and never
            // negative: 2λ (ln s − (1 − 1/s)), plus λ (s − 1 − ln s) in tension.
            let excess = 2.0 * l.lambda * (s.ln() - (1.0 - 1.0 / s))
                + if s > 1.0 {
                    l.lambda * (s - 1.0 - s.ln())
                } else {
                    0.0
                };
            assert!(
                excess >= 0.0 && excess <= 0.2 * expected,
                "s = {s}: {excess}"
            );
            // The finite difference's truncation error is O(h²) relative: 1e-7 is ample.
            assert!(
                (m - expected - excess).abs() <= 1e-7 * expected,
                "s = {s}: {m} vs {expected} + {excess}"
            );
        }
    }
}
