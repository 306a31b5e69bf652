//! The highest natural frequency of a problem's mesh, linearised about a state: power
//! iteration on `M⁻¹K`. It sets the stability limit `2/ω_max` of the central difference.

use anyhow::{anyhow, Result};
use pe_firmware::physics::{MaterialLaw, Real};

use crate::problem::elements::Elements;
use crate::problem::{NodeKind, Problem};

/// The mesh in one state: its elements and laws in scalar `T` and the displacements `u`.
pub struct Linearised<'a, T> {
    pub problem: &'a Problem,
    pub elements: &'a Elements<T>,
    pub laws: &'a [MaterialLaw<T>],
    pub u: &'a [[T; 3]],
}

/// Deterministic start vector of the power iteration, every free component excited.
pub fn start_vector(problem: &Problem) -> Vec<[f64; 3]> {
    problem
        .node_kind
        .iter()
        .enumerate()
        .map(|(k, kind)| {
            core::array::from_fn(|i| {
                if *kind == NodeKind::Free {
                    (((k * 3 + i) as f64) * 0.7548776662).fract() - 0.5
                } else {
                    0.0
                }
            })
        })
        .collect()
}

/// Highest angular frequency `ω_max` (rad/s) of the free nodes, linearised about `state`,
/// by power iteration on `M⁻¹K` (`K v` by a central difference of the internal forces)
/// from the start vector `v` (warm start: the dominant mode of an earlier call); leaves
/// the last iterate in `v` for the next call. The stable central-difference step is
/// `2/ω_max` (undamped). Costs about two force evaluations per iteration.
pub fn max_frequency_from<T: Real>(
    state: &Linearised<'_, T>,
    v: &mut Vec<[f64; 3]>,
    iterations: usize,
) -> Result<f64> {
    let problem = state.problem;
    let n = state.u.len();
    let free: Vec<bool> = problem
        .node_kind
        .iter()
        .map(|k| *k == NodeKind::Free)
        .collect();
    let m: Vec<f64> = problem
        .mass
        .iter()
        .map(|m| m * problem.solver.mass_scaling)
        .collect();
    if v.len() != n {
        *v = start_vector(problem);
    }
    let scale = problem
        .reference
        .iter()
        .map(|r| r.characteristic_length)
        .fold(f64::INFINITY, f64::min);
    // The finite-difference probe must stand well above the scalar's resolution of the
    // displacements: 1e-7 of the smallest element in f64, 1e-3 in f32 (ε_f32 ≈ 6e-8).
    let low_precision = T::from_f64(1.0 + 1e-10).to_f64() == 1.0;
    let eps = if low_precision { 1e-3 } else { 1e-7 } * scale;
    let mut lambda = 0.0;
    let mut fp = vec![[T::ZERO; 3]; n];
    let mut fm = vec![[T::ZERO; 3]; n];
    for _ in 0..iterations {
        let norm = v
            .iter()
            .zip(&m)
            .map(|(a, mm)| mm * (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]))
            .sum::<f64>()
            .sqrt();
        if !(norm > 0.0) {
            // No free node (or a lost vector): no mode to limit the step.
            return Ok(0.0);
        }
        v.iter_mut()
            .for_each(|a| a.iter_mut().for_each(|x| *x /= norm));
        let up: Vec<[T; 3]> = state
            .u
            .iter()
            .zip(v.iter())
            .map(|(u, d)| core::array::from_fn(|i| T::from_f64(u[i].to_f64() + eps * d[i])))
            .collect();
        let um: Vec<[T; 3]> = state
            .u
            .iter()
            .zip(v.iter())
            .map(|(u, d)| core::array::from_fn(|i| T::from_f64(u[i].to_f64() - eps * d[i])))
            .collect();
        fp.iter_mut().for_each(|f| *f = [T::ZERO; 3]);
        fm.iter_mut().for_each(|f| *f = [T::ZERO; 3]);
        state
            .elements
            .internal_forces(state.laws, &up, &mut fp)
            .map_err(|e| anyhow!("{e}"))?;
        state
            .elements
            .internal_forces(state.laws, &um, &mut fm)
            .map_err(|e| anyhow!("{e}"))?;
        let mut vkv = 0.0;
        let mut w = vec![[0.0; 3]; n];
        for k in 0..n {
            if !free[k] {
                continue;
            }
            for i in 0..3 {
                let kv = (fp[k][i].to_f64() - fm[k][i].to_f64()) / (2.0 * eps);
                vkv += v[k][i] * kv;
                w[k][i] = kv / m[k];
            }
        }
        lambda = vkv; // v is M-normalised: Rayleigh quotient
        *v = w;
    }
    Ok(lambda.max(0.0).sqrt())
}
