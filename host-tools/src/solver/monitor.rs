//! Watching a run's stability: the critical step tracked during the run, the highest
//! frequency of the linearised model, and the energy terms.

use anyhow::{anyhow, Result};
use pe_firmware::physics::Real;
use serde::Serialize;

use super::stable_step::{StableStepTracker, TrackedStep};
use super::Model;
use crate::problem::{frequency, Problem};

/// One change of `dt` during a run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct DtChange {
    pub step: u64,
    pub time_s: f64,
    pub dt_s: f64,
    /// The critical step found about the state at that step, and the cell setting it.
    pub dt_critical_s: f64,
    pub cell: usize,
}

/// Watches the critical step during a run: the element-by-element bound every
/// `dt_track_interval` steps ([`StableStepTracker`]), and the power iteration every
/// `dt_recheck_interval` steps, which can only lower the tracker's calibration.
pub struct DtMonitor<'p> {
    track_interval: u64,
    tracker: Option<StableStepTracker<'p>>,
    interval: Option<u64>,
    iterations: usize,
    adapt: bool,
    has_contact: bool,
    /// Warm start of the power iteration: the last dominant mode.
    vector: Option<Vec<[f64; 3]>>,
    pub dt_critical_initial_s: f64,
    pub dt_critical_min_s: f64,
    /// Element bounds and power iterations done, and how many checks lowered `dt`.
    pub tracks: u64,
    pub rechecks: u64,
    pub reductions: u64,
    /// Wall time spent in the checks (s).
    pub wall_s: f64,
    pub history: Vec<DtChange>,
    /// The tracker's calibration at rest (0 without tracking).
    pub calibration_initial: f64,
    /// The last element bound: step and critical step.
    last_tracked: Option<(u64, f64)>,
}

/// Whether a check that finds `dt` too large lowers it (`adapt_dt`; by default yes, except
/// with contact, whose penalty follows from the step: the run stops instead).
pub fn adapts(problem: &Problem) -> bool {
    problem.solver.adapt_dt.unwrap_or(problem.contact.is_none())
}

impl<'p> DtMonitor<'p> {
    pub fn new(problem: &'p Problem, dt_critical_s: f64) -> Self {
        let s = &problem.solver;
        // A forced step (`force_dt`) is the user's on purpose: not tracked.
        let track = s.dt_track_interval > 0 && !s.force_dt;
        let tracker = track.then(|| StableStepTracker::new(problem));
        DtMonitor {
            calibration_initial: tracker.as_ref().map_or(0.0, |t| t.calibration),
            track_interval: s.dt_track_interval,
            tracker,
            interval: s.dt_recheck_interval,
            iterations: s.dt_recheck_iterations.max(1),
            adapt: adapts(problem),
            has_contact: problem.contact.is_some(),
            vector: None,
            dt_critical_initial_s: dt_critical_s,
            dt_critical_min_s: dt_critical_s,
            tracks: 0,
            rechecks: 0,
            reductions: 0,
            wall_s: 0.0,
            history: Vec::new(),
            last_tracked: None,
        }
    }

    /// The tracker's calibration now (0 without tracking).
    pub fn calibration(&self) -> f64 {
        self.tracker.as_ref().map_or(0.0, |t| t.calibration)
    }

    fn track_due(&self, step: u64) -> bool {
        self.tracker.is_some() && step.is_multiple_of(self.track_interval.max(1))
    }

    fn recheck_due(&self, step: u64) -> bool {
        self.interval.is_some_and(|n| step.is_multiple_of(n))
    }

    pub fn due(&self, step: u64) -> bool {
        self.track_due(step) || self.recheck_due(step)
    }

    /// The element tracker's critical step about the model's state now, if tracking.
    pub fn tracked<T: Real>(&self, model: &Model<'_, T>) -> Option<TrackedStep> {
        let t = self.tracker.as_ref()?;
        Some(t.bound(&model.u, model.team.as_ref()))
    }

    /// The critical step about the model's current state: the element bound
    /// ([`StableStepTracker`]) when due, and `2/ω_max` by a warm-started power iteration
    /// when due (never above the initial critical step, which may be the smaller `L_e/c`
    /// estimate); a power estimate below the tracker's lowers the tracker's calibration.
    /// Returns the step to continue with: `None` to keep `dt`, or `dt_safety ×` the new
    /// critical step when `dt` is above it (explicit `dt`: the critical step itself), with
    /// 1% of slack for the estimates' own noise, when adapting; without adapting, a step
    /// above the critical step itself (by the next check) is an error naming the step and
    /// the cell.
    pub fn check<T: Real>(&mut self, model: &Model<'_, T>) -> Result<Option<f64>> {
        let start = std::time::Instant::now();
        let r = self.check_inner(model);
        self.wall_s += start.elapsed().as_secs_f64();
        r
    }

    fn check_inner<T: Real>(&mut self, model: &Model<'_, T>) -> Result<Option<f64>> {
        let p = model.problem;
        let step = model.step;
        let mut tracked = None;
        if self.track_due(step) || self.recheck_due(step) {
            tracked = self.tracked(model);
            if tracked.is_some() {
                self.tracks += 1;
            }
        }
        let mut crit = tracked.map_or(f64::INFINITY, |t| t.dt_critical_s);
        let mut cell = tracked.map_or(0, |t| t.limiting_cell);
        // Look one interval ahead: where the bound is falling, assume it goes on falling
        // as fast until the next check (never below half of it), so `dt` comes down
        // before the state gets there.
        let mut ahead = crit;
        if let Some(t) = tracked {
            if let Some((s0, c0)) = self.last_tracked {
                if c0 > t.dt_critical_s && step > s0 {
                    let fall =
                        (c0 - t.dt_critical_s) * self.track_interval as f64 / (step - s0) as f64;
                    ahead = (t.dt_critical_s - fall).max(0.5 * t.dt_critical_s);
                }
            }
            self.last_tracked = Some((step, t.dt_critical_s));
        }
        if self.recheck_due(step) {
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
            let power = if omega > 0.0 {
                (2.0 / omega).min(self.dt_critical_initial_s)
            } else {
                self.dt_critical_initial_s
            };
            if let (Some(tr), Some(t)) = (self.tracker.as_mut(), tracked) {
                if power < t.dt_critical_s {
                    tr.calibration *= power / t.dt_critical_s;
                }
            }
            if power < crit {
                crit = power;
                ahead = ahead.min(power);
                cell = tracked.map_or(0, |t| t.limiting_cell);
            }
        }
        if !crit.is_finite() {
            return Ok(None);
        }
        self.dt_critical_min_s = self.dt_critical_min_s.min(crit);
        let safety = if p.solver.dt.is_some() {
            1.0
        } else {
            p.solver.dt_safety
        };
        if model.dt_s <= 1.01 * safety * ahead {
            return Ok(None);
        }
        // Not adapting, the safety margin may be eaten: stop only when dt would be above
        // the critical step itself by the next check.
        if !self.adapt && model.dt_s <= ahead {
            return Ok(None);
        }
        if self.adapt {
            self.reductions += 1;
            let dt = safety * ahead;
            self.history.push(DtChange {
                step,
                time_s: model.time_s(),
                dt_s: dt,
                dt_critical_s: crit,
                cell,
            });
            return Ok(Some(dt));
        }
        let why = if self.has_contact && p.solver.adapt_dt.is_none() {
            "with contact dt is not lowered during a run (the penalty follows from the step): lower dt_safety"
        } else {
            "lower dt_safety, or set adapt_dt = true"
        };
        anyhow::bail!(
            "step {step}: t = {:.4e} s: unstable step ahead: the critical step about the deformed state has fallen to {crit:.4e} s (falling to {ahead:.4e} s by the next check) ({:.3} of the {:.4e} s at rest; cell {cell} sets it) and dt = {:.4e} s is above it: the run would go unstable; {why}",
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
            batched: self.batched.as_ref(),
        };
        frequency::max_frequency_from(&state, v, iterations)
    }
}

impl<'p, T: Real> Model<'p, T> {
    /// Gravity at the last step's external forces (`t_n`): `[gravity] acceleration` times
    /// its ramp's factor then (m/s²).
    pub fn gravity_m_per_s2(&self) -> [f64; 3] {
        let s = self
            .ramps
            .value(self.problem.gravity_ramp_user())
            .map_or(1.0, |v| v[0]);
        self.problem.gravity.map(|g| g * s)
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
        let g = self.gravity_m_per_s2();
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
