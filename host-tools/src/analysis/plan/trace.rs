//! What one run of a candidate model leaves for the comparison: its quantities of interest
//! sampled at fixed times, each node's largest displacement over the run (the pilot's
//! motion), and its cost.
//!
//! Displacements are sampled at `t_k = duration · k / SAMPLES`, `k = 1..=SAMPLES`, linearly
//! interpolated between the two steps around `t_k`. Tool forces are averaged over the
//! windows their consumers sample at: every millisecond (the haptic loop, [`HAPTIC_WINDOW_S`])
//! and every 40 ms (the graphics, [`GRAPHICS_WINDOW_S`]), each window `(t_{k-1}, t_k]`. Runs
//! with different steps are so compared at the same times, not at the same step numbers.

use anyhow::Result;

use crate::geom::norm;
use crate::problem::Problem;
use crate::solver::{self, Observer, StepState};

/// Sample times per run.
pub const SAMPLES: usize = 40;

/// The haptic loop's period: it feels the mean force over each millisecond (s).
pub const HAPTIC_WINDOW_S: f64 = 1e-3;

/// The graphics' period: a frame shows the mean force over its 40 ms (s).
pub const GRAPHICS_WINDOW_S: f64 = 0.04;

/// The ends of the windows of width `window_s` over `(0, duration_s]`: `k · window_s` while
/// below the end, then the end (a last, shorter window when the duration is not a multiple).
pub fn window_ends(duration_s: f64, window_s: f64) -> Vec<f64> {
    let n = (duration_s / window_s - 1e-9).ceil().max(1.0) as usize;
    (1..=n)
        .map(|k| (k as f64 * window_s).min(duration_s))
        .collect()
}

/// One run's samples and figures.
#[derive(Clone, Debug)]
pub struct Trace {
    /// Sample times (s).
    pub times_s: Vec<f64>,
    /// Displacement of every node of the run's mesh at each sample: `u[sample][node]`.
    pub u: Vec<Vec<[f64; 3]>>,
    /// Force of the tissue on each tool, the mean over each millisecond (the haptic
    /// loop's): `tool_force_haptic[tool][window]` (N). A penalty contact's force rings step
    /// to step; the window mean is the force a haptic or graphics loop running slower than
    /// the solver sees, and compares runs whose steps differ.
    pub tool_force_haptic: Vec<Vec<[f64; 3]>>,
    /// The same over each 40 ms (a graphics frame's).
    pub tool_force_graphics: Vec<Vec<[f64; 3]>>,
    pub tool_names: Vec<String>,
    /// Largest |u| of each node over every step of the run (m).
    pub motion_m: Vec<f64>,
    /// Largest stored energy of each cell over the samples (J), evaluated in f64.
    pub energy_j: Vec<f64>,
    pub elements: usize,
    pub nodes: usize,
    pub steps: u64,
    pub dt_s: f64,
    pub simulated_s: f64,
    pub wall_s: f64,
    /// Element-steps per simulated second: the model's cost, whatever the machine.
    pub element_steps_per_sim_s: f64,
}

/// Records every step's displacements around the sample times and each node's motion.
struct Recorder {
    times_s: Vec<f64>,
    next: usize,
    prev: Option<(f64, Vec<[f64; 3]>)>,
    u: Vec<Vec<[f64; 3]>>,
    step_times_s: Vec<f64>,
    motion_m: Vec<f64>,
}

impl Observer for Recorder {
    fn after_step(&mut self, _step: u64, time_s: f64, _total: u64, state: &dyn StepState) {
        let u = state.displacements();
        self.step_times_s.push(time_s);
        for (m, d) in self.motion_m.iter_mut().zip(&u) {
            *m = m.max(norm(*d));
        }
        while self.next < self.times_s.len() && self.times_s[self.next] <= time_s {
            let t = self.times_s[self.next];
            let sample = match &self.prev {
                Some((t0, u0)) if time_s > *t0 => {
                    let w = (t - t0) / (time_s - t0);
                    u0.iter()
                        .zip(&u)
                        .map(|(a, b)| core::array::from_fn(|i| a[i] + w * (b[i] - a[i])))
                        .collect()
                }
                _ => u.clone(),
            };
            self.u.push(sample);
            self.next += 1;
        }
        self.prev = Some((time_s, u));
    }
}

/// The mean of the series `v` (one value per step, at `step_times_s`) over each window
/// `(t_{k-1}, t_k]` of `times_s` (`t_0 = 0`); a window without a step takes the value of
/// the first step after it.
fn window_means(step_times_s: &[f64], v: &[[f64; 3]], times_s: &[f64]) -> Vec<[f64; 3]> {
    let mut out = Vec::with_capacity(times_s.len());
    let mut k = 0;
    for &t in times_s {
        let (mut sum, mut n) = ([0.0; 3], 0usize);
        while k < v.len() && step_times_s[k] <= t {
            for i in 0..3 {
                sum[i] += v[k][i];
            }
            n += 1;
            k += 1;
        }
        out.push(if n > 0 {
            sum.map(|x| x / n as f64)
        } else {
            v.get(k).or(v.last()).copied().unwrap_or([0.0; 3])
        });
    }
    out
}

/// Runs `problem` to its end and samples it.
pub fn run(problem: &Problem, name: &str) -> Result<Trace> {
    let dt = problem.time_step.dt_s;
    let duration = problem.steps(dt) as f64 * dt;
    let times_s: Vec<f64> = (1..=SAMPLES)
        .map(|k| duration * k as f64 / SAMPLES as f64)
        .collect();
    let mut rec = Recorder {
        times_s: times_s.clone(),
        next: 0,
        prev: None,
        u: Vec::new(),
        step_times_s: Vec::new(),
        motion_m: vec![0.0; problem.mesh.nodes.len()],
    };
    let out = solver::run(problem, name, &mut rec)?;
    // The last sample may fall a rounding error after the last step.
    while rec.u.len() < times_s.len() {
        rec.u.push(out.displacements.clone());
    }
    let tools = out
        .report
        .contact
        .as_ref()
        .map(|c| c.tools.clone())
        .unwrap_or_default();
    let per_step = |t: usize| -> Vec<[f64; 3]> {
        out.tool_force
            .iter()
            .skip(t)
            .step_by(tools.len().max(1))
            .copied()
            .collect()
    };
    let means = |window_s: f64| -> Vec<Vec<[f64; 3]>> {
        let ends = window_ends(duration, window_s);
        (0..tools.len())
            .map(|t| window_means(&rec.step_times_s, &per_step(t), &ends))
            .collect()
    };
    let (tool_force_haptic, tool_force_graphics) =
        (means(HAPTIC_WINDOW_S), means(GRAPHICS_WINDOW_S));
    let elements = crate::problem::elements::Elements::<f64>::build(problem);
    let mut energy_j = vec![0.0f64; problem.mesh.cells.len()];
    for u in &rec.u {
        let w = elements
            .cell_energies(&problem.laws, u)
            .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
        for (m, x) in energy_j.iter_mut().zip(w) {
            *m = m.max(x);
        }
    }
    let r = &out.report;
    Ok(Trace {
        energy_j,
        times_s,
        u: rec.u,
        tool_force_haptic,
        tool_force_graphics,
        tool_names: tools,
        motion_m: rec.motion_m,
        elements: r.elements,
        nodes: r.nodes,
        steps: r.steps,
        dt_s: r.dt_s,
        simulated_s: r.simulated_s,
        wall_s: r.wall_s,
        element_steps_per_sim_s: r.elements as f64 * r.steps as f64 / r.simulated_s,
    })
}
