//! Watching a run's stability: the critical step re-estimated during the run, the highest
//! frequency of the linearised model, and the energy terms.

use anyhow::{anyhow, Result};
use pe_firmware::physics::Real;
use serde::Serialize;

use super::Model;
use crate::problem::{frequency, Problem};

/// Re-estimates the critical step during a run (`[solver] dt_recheck_interval`).
pub struct DtMonitor {
    interval: Option<u64>,
    iterations: usize,
    /// Warm start of the power iteration: the last dominant mode.
    vector: Option<Vec<[f64; 3]>>,
    pub dt_critical_initial_s: f64,
    pub dt_critical_min_s: f64,
    pub rechecks: u64,
    pub reductions: u64,
}

impl DtMonitor {
    pub fn new(problem: &Problem, dt_critical_s: f64) -> Self {
        DtMonitor {
            interval: problem.solver.dt_recheck_interval,
            iterations: problem.solver.dt_recheck_iterations.max(1),
            vector: None,
            dt_critical_initial_s: dt_critical_s,
            dt_critical_min_s: dt_critical_s,
            rechecks: 0,
            reductions: 0,
        }
    }

    pub fn due(&self, step: u64) -> bool {
        self.interval.is_some_and(|n| step.is_multiple_of(n))
    }

    /// The critical step about the model's current state: `2/ω_max` by a warm-started
    /// power iteration, never above the initial critical step (which may be the smaller
    /// `L_e/c` estimate). Returns the step to continue with: `None` to keep `dt`, or a
    /// lower one (`adapt_dt`); without `adapt_dt`, a step above `dt_safety ×` the new
    /// critical step (explicit `dt`: above the critical step) is an error. 1% of slack
    /// absorbs the estimate's own noise.
    pub fn check<T: Real>(&mut self, model: &Model<'_, T>) -> Result<Option<f64>> {
        let p = model.problem;
        let mut v = self.vector.take().unwrap_or_else(|| model.start_vector());
        // A cold start needs more iterations to find the top of the spectrum.
        let iters = if self.rechecks == 0 {
            self.iterations.max(100)
        } else {
            self.iterations
        };
        let omega = model.max_frequency_from(&mut v, iters)?;
        self.vector = Some(v);
        self.rechecks += 1;
        let crit = if omega > 0.0 {
            (2.0 / omega).min(self.dt_critical_initial_s)
        } else {
            self.dt_critical_initial_s
        };
        self.dt_critical_min_s = self.dt_critical_min_s.min(crit);
        let safety = if p.solver.dt.is_some() {
            1.0
        } else {
            p.solver.dt_safety
        };
        if model.dt_s <= 1.01 * safety * crit {
            return Ok(None);
        }
        if p.solver.adapt_dt {
            self.reductions += 1;
            return Ok(Some(safety * crit));
        }
        anyhow::bail!(
            "step {}: t = {:.4e} s: the critical step about the deformed state has fallen to {crit:.4e} s ({:.3} of the {:.4e} s at rest); dt = {:.4e} s is above {safety} of it: the run would go unstable. Lower dt_safety, or set adapt_dt = true",
            model.step,
            model.time_s(),
            crit / self.dt_critical_initial_s,
            self.dt_critical_initial_s,
            model.dt_s
        )
    }
}

impl<'p, T: Real> Model<'p, T> {
    /// Highest angular frequency `ω_max` (rad/s) of the free nodes, linearised about the
    /// current state (see [`frequency::max_frequency_from`]).
    pub fn max_frequency(&self, iterations: usize) -> Result<f64> {
        let mut v = self.start_vector();
        self.max_frequency_from(&mut v, iterations)
    }

    /// Deterministic start vector of the power iteration, every free component excited.
    pub fn start_vector(&self) -> Vec<[f64; 3]> {
        frequency::start_vector(self.problem)
    }

    /// [`Model::max_frequency`] from the start vector `v` (warm start: the dominant mode of
    /// an earlier call); leaves the last iterate in `v` for the next call.
    pub fn max_frequency_from(&self, v: &mut Vec<[f64; 3]>, iterations: usize) -> Result<f64> {
        let state = frequency::Linearised {
            problem: self.problem,
            elements: &self.elements,
            laws: &self.laws,
            u: &self.u,
        };
        frequency::max_frequency_from(&state, v, iterations)
    }
}

/// Energy terms at the time of the previous state `u − du` (where the central velocity of
/// the last step is known), J.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Energies {
    pub kinetic: f64,
    pub stored: f64,
    /// `−Σ m g·u`.
    pub gravity: f64,
}

impl Energies {
    pub fn total(&self) -> f64 {
        self.kinetic + self.stored + self.gravity
    }
}

impl<'p, T: Real> Model<'p, T> {
    /// Energies at `t_{n}` after the step that produced `u_{n+1}`: the kinetic energy of
    /// the central velocity and the stored and gravity energy of `u_n`.
    pub fn energies(&self) -> Result<Energies> {
        let prev = self.previous_displacements();
        let prev_t: Vec<[T; 3]> = prev.iter().map(|u| u.map(T::from_f64)).collect();
        let stored = self
            .elements
            .stored_energy(&self.laws, &prev_t)
            .map_err(|e| anyhow!("{e}"))?;
        let g = self.problem.gravity;
        let gravity = prev
            .iter()
            .zip(&self.problem.mass)
            .map(|(u, m)| -m * (0..3).map(|i| g[i] * u[i]).sum::<f64>())
            .sum();
        Ok(Energies {
            kinetic: self.kinetic_energy,
            stored,
            gravity,
        })
    }
}
