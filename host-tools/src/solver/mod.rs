//! The serial reference solver: one thread, the whole mesh, the shared physics kernels.
//! Every parallel run (board-sim, the board array) is compared with it.

use std::time::Instant;

use anyhow::{anyhow, Result};
use pe_firmware::image::Precision;
use pe_firmware::physics::contact::{
    build_candidates, check_travel, evaluate_pairs, evaluate_tools, Candidate, ContactModel,
    ContactStats,
};
use pe_firmware::physics::explicit::{update_node, NodeMove};
use pe_firmware::physics::{CentralDifference, MaterialLaw, PhysicsError, Real};
use serde::Serialize;

use crate::problem::elements::Elements;
use crate::problem::frequency;
use crate::problem::{NodeKind, Problem};

/// Serial explicit model in scalar type `T`.
pub struct Model<'p, T> {
    pub problem: &'p Problem,
    pub elements: Elements<T>,
    pub laws: Vec<MaterialLaw<T>>,
    pub dt_s: f64,
    pub cd: CentralDifference<T>,
    /// `C / m_inertial` per node.
    pub gain: Vec<T>,
    /// Gravity force per node (true mass), N.
    pub gravity_force: Vec<[T; 3]>,
    pub u: Vec<[T; 3]>,
    pub u_prev: Vec<[T; 3]>,
    pub f_int: Vec<[T; 3]>,
    pub f_ext: Vec<[T; 3]>,
    /// Steps taken so far.
    pub step: u64,
    /// Time (s) and step at which the current `dt_s` took effect: the state is at
    /// `time_base_s + (step − step_base) · dt_s` (exactly `step · dt` until `dt` changes).
    pub time_base_s: f64,
    pub step_base: u64,
    /// Kinetic energy at the previous step's time (J), from the central velocity.
    pub kinetic_energy: f64,
    /// Sum over prescribed (and fixed) nodes of `f_int − f_ext`: the force the constraints
    /// exert on the tissue at the last step, N (for the built-in scene: the probe push).
    pub reaction_prescribed: [f64; 3],
    pub reaction_fixed: [f64; 3],
    /// Contact state (None: the scene has no contact).
    pub contact: Option<ContactState>,
}

/// The serial solver's contact state: the tables, the search and the forces of the last step.
pub struct ContactState {
    pub run: crate::problem::contact::ContactRun,
    pub candidates: Vec<Candidate>,
    /// Contact-node positions at the last check.
    pub at_check: Vec<[f64; 3]>,
    /// Contact force per contact node at the last step (N).
    pub force: Vec<[f64; 3]>,
    /// Force of the tissue on each tool at the last step (N).
    pub tool_force: Vec<[f64; 3]>,
    pub stats: ContactStats,
    /// Checks done and the most candidates any check found.
    pub checks: u64,
    pub candidates_max: usize,
    /// Deepest penetration over the run (m).
    pub max_depth_m: f64,
}

impl ContactState {
    fn new(problem: &Problem, dt_s: f64) -> Option<ContactState> {
        let setup = problem.contact.as_ref()?;
        let ms = problem.solver.mass_scaling;
        let inertial: Vec<f64> = problem.mass.iter().map(|m| m * ms).collect();
        let run = setup.for_step(&problem.mesh, &inertial, dt_s);
        let n = run.nodes.len();
        let tools = run.tools.len();
        Some(ContactState {
            run,
            candidates: Vec::new(),
            at_check: vec![[0.0; 3]; n],
            force: vec![[0.0; 3]; n],
            tool_force: vec![[0.0; 3]; tools],
            stats: ContactStats::default(),
            checks: 0,
            candidates_max: 0,
            max_depth_m: 0.0,
        })
    }

    /// Contact forces at the state `u` (step `step`, time `t`), the same sequence of
    /// operations the board runtime performs for the nodes it owns.
    fn evaluate<T: Real>(
        &mut self,
        problem: &Problem,
        u: &[[T; 3]],
        step: u64,
        t: f64,
    ) -> Result<(), PhysicsError> {
        let run = &self.run;
        let m = ContactModel {
            nodes: &run.nodes,
            faces: &run.faces,
            pairs: &run.pairs,
            tools: &run.tools,
        };
        let pos = |c: usize| {
            let n = &run.nodes[c];
            let d = u[n.global as usize];
            Some(core::array::from_fn(|i| n.reference[i] + d[i].to_f64()))
        };
        let p = run.params;
        if step.is_multiple_of(p.check_interval_steps.max(1) as u64) {
            for (c, x) in self.at_check.iter_mut().enumerate() {
                *x = pos(c).unwrap_or([0.0; 3]);
            }
            if !run.pairs.is_empty() {
                // Search into the room the last check needed; grow and search again only
                // when this one needs more.
                let cap = self.candidates.capacity().max(self.candidates.len());
                self.candidates.resize(cap, Candidate::default());
                let n = match build_candidates(&m, pos, p.candidate_margin_m, &mut self.candidates)
                {
                    Ok(n) => n,
                    Err(needed) => {
                        self.candidates.resize(needed, Candidate::default());
                        build_candidates(&m, pos, p.candidate_margin_m, &mut self.candidates)
                            .unwrap_or(needed)
                    }
                };
                self.candidates.truncate(n);
                self.candidates_max = self.candidates_max.max(n);
            }
            self.checks += 1;
        }
        check_travel(
            &m,
            pos,
            &self.at_check,
            |_| true,
            p.pair_surfaces,
            p.travel_max_m,
        )?;
        self.force.iter_mut().for_each(|f| *f = [0.0; 3]);
        self.tool_force.iter_mut().for_each(|f| *f = [0.0; 3]);
        self.stats = ContactStats::default();
        let capsules: Vec<_> = run
            .tools
            .iter()
            .map(|tl| tl.capsule.translated(problem.paths[tl.path as usize].at(t)))
            .collect();
        evaluate_tools(
            &m,
            &capsules,
            pos,
            |_| true,
            p.tolerance_m,
            &mut self.force,
            &mut self.tool_force,
            &mut self.stats,
        )?;
        evaluate_pairs(
            &m,
            &self.candidates,
            pos,
            |_| true,
            p.tolerance_m,
            &mut self.force,
            &mut self.stats,
        )?;
        self.max_depth_m = self.max_depth_m.max(self.stats.max_depth_m);
        Ok(())
    }
}

/// A step failure with the step number.
#[derive(Debug)]
pub struct StepError {
    pub step: u64,
    pub error: PhysicsError,
}

impl std::fmt::Display for StepError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "step {}: {}", self.step, self.error)
    }
}
impl std::error::Error for StepError {}

impl<'p, T: Real> Model<'p, T> {
    pub fn new(problem: &'p Problem, dt_s: f64) -> Self {
        let n = problem.mesh.nodes.len();
        let cd = CentralDifference::<T>::new(dt_s, problem.solver.damping);
        let gain = problem
            .mass
            .iter()
            .map(|m| cd.gain(m * problem.solver.mass_scaling))
            .collect();
        let gravity_force = problem
            .mass
            .iter()
            .map(|m| problem.gravity.map(|g| T::from_f64(g * m)))
            .collect();
        Model {
            problem,
            elements: Elements::build(problem),
            laws: problem.laws.iter().map(|l| l.cast::<T>()).collect(),
            dt_s,
            cd,
            gain,
            gravity_force,
            u: vec![[T::ZERO; 3]; n],
            u_prev: vec![[T::ZERO; 3]; n],
            f_int: vec![[T::ZERO; 3]; n],
            f_ext: vec![[T::ZERO; 3]; n],
            step: 0,
            time_base_s: 0.0,
            step_base: 0,
            kinetic_energy: 0.0,
            reaction_prescribed: [0.0; 3],
            reaction_fixed: [0.0; 3],
            contact: ContactState::new(problem, dt_s),
        }
    }

    pub fn time_s(&self) -> f64 {
        self.time_base_s + (self.step - self.step_base) as f64 * self.dt_s
    }

    /// Changes the time step mid-run. The central difference keeps the half-step velocity
    /// `v = (u − u_prev)/dt` in its history, so the previous state is rescaled to keep it:
    /// `u_prev := u − (dt_new/dt_old)(u − u_prev)`; the update coefficients and the per-node
    /// gains are rebuilt for the new step.
    pub fn set_dt(&mut self, dt_new: f64) {
        let r = dt_new / self.dt_s;
        for (u, up) in self.u.iter().zip(self.u_prev.iter_mut()) {
            *up = core::array::from_fn(|i| {
                let (a, b) = (u[i].to_f64(), up[i].to_f64());
                T::from_f64(a - r * (a - b))
            });
        }
        self.time_base_s = self.time_s();
        self.step_base = self.step;
        self.dt_s = dt_new;
        self.cd = CentralDifference::<T>::new(dt_new, self.problem.solver.damping);
        let ms = self.problem.solver.mass_scaling;
        let cd = self.cd;
        self.gain = self.problem.mass.iter().map(|m| cd.gain(m * ms)).collect();
    }

    /// External forces at time `t`: gravity plus ramped loads plus contact (in that order,
    /// as the board runtime adds them).
    fn external_forces(&mut self, t: f64) -> Result<(), PhysicsError> {
        self.f_ext.copy_from_slice(&self.gravity_force);
        for l in &self.problem.loads {
            let s = l.ramp.as_ref().map(|r| r.at(t)[0]).unwrap_or(1.0);
            for i in 0..3 {
                self.f_ext[l.node as usize][i] += T::from_f64(l.force[i] * s);
            }
        }
        if let Some(c) = self.contact.as_mut() {
            c.evaluate(self.problem, &self.u, self.step, t)?;
            for (node, f) in c.run.nodes.iter().zip(&c.force) {
                let e = &mut self.f_ext[node.global as usize];
                for i in 0..3 {
                    e[i] += T::from_f64(f[i]);
                }
            }
        }
        Ok(())
    }

    /// One central-difference step from `t_n` to `t_{n+1}`.
    pub fn advance(&mut self) -> Result<(), StepError> {
        let t = self.time_s();
        let t_next = t + self.dt_s;
        let step = self.step;
        self.f_int.iter_mut().for_each(|f| *f = [T::ZERO; 3]);
        self.elements
            .internal_forces(&self.laws, &self.u, &mut self.f_int)
            .map_err(|error| StepError { step, error })?;
        self.external_forces(t)
            .map_err(|error| StepError { step, error })?;
        let inv_2dt = 1.0 / (2.0 * self.dt_s);
        let limit = self.problem.solver.speed_limit;
        let ms = self.problem.solver.mass_scaling;
        let mut ke = 0.0;
        let mut rp = [0.0; 3];
        let mut rf = [0.0; 3];
        for n in 0..self.u.len() {
            let (f_ext, f_int) = (self.f_ext[n], self.f_int[n]);
            let reaction = |r: &mut [f64; 3]| {
                for i in 0..3 {
                    r[i] += (f_int[i] - f_ext[i]).to_f64();
                }
            };
            let mv = match self.problem.node_kind[n] {
                NodeKind::Free => NodeMove::Free {
                    gain: self.gain[n],
                    residual: core::array::from_fn(|i| f_ext[i] - f_int[i]),
                },
                NodeKind::Fixed => {
                    reaction(&mut rf);
                    NodeMove::Held([T::ZERO; 3])
                }
                NodeKind::Prescribed(k) => {
                    reaction(&mut rp);
                    NodeMove::Held(self.problem.paths[k as usize].at(t_next).map(T::from_f64))
                }
            };
            let (u, u_prev) = (&mut self.u[n], &mut self.u_prev[n]);
            let v2 = update_node(&self.cd, u, u_prev, mv, inv_2dt, limit, n as u32)
                .map_err(|error| StepError { step, error })?;
            ke += 0.5 * self.problem.mass[n] * ms * v2;
        }
        self.kinetic_energy = ke;
        self.reaction_prescribed = rp;
        self.reaction_fixed = rf;
        self.step += 1;
        Ok(())
    }

    /// Stored (strain + hourglass) energy at the current state, J.
    pub fn stored_energy(&self) -> Result<f64> {
        self.elements
            .stored_energy(&self.laws, &self.u)
            .map_err(|e| anyhow!("{e}"))
    }

    /// Displacements as `f64`.
    pub fn displacements(&self) -> Vec<[f64; 3]> {
        self.u.iter().map(|u| u.map(|v| v.to_f64())).collect()
    }
}

/// What a run reports (`--report FILE.json`).
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    pub scene: String,
    pub precision: String,
    pub integration: String,
    pub steps: u64,
    pub dt_s: f64,
    pub dt_critical_s: f64,
    pub simulated_s: f64,
    pub elements: usize,
    pub nodes: usize,
    pub wall_s: f64,
    pub element_steps_per_s: f64,
    pub real_time_factor: f64,
    pub kinetic_energy_final: f64,
    pub stored_energy_final: f64,
    pub max_displacement: f64,
    pub max_displacement_node: u64,
    /// Force the prescribed nodes exert on the tissue at the end (N): the probe push.
    pub prescribed_reaction_n: [f64; 3],
    pub fixed_reaction_n: [f64; 3],
    /// Step at the end (differs from `dt_s` only when `adapt_dt` lowered it).
    pub dt_final_s: f64,
    /// Smallest critical step found by the re-checks (`dt_recheck_interval`), s; the
    /// initial one when re-checks are off.
    pub dt_critical_min_s: f64,
    /// Re-checks done and how many of them lowered `dt`.
    pub dt_rechecks: u64,
    pub dt_reductions: u64,
    /// Contact figures (absent without contact).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact: Option<ContactReport>,
}

/// What contact did over a run.
#[derive(Clone, Debug, Serialize)]
pub struct ContactReport {
    pub tools: Vec<String>,
    /// Force of the tissue on each tool at the end and the largest magnitude over the run (N).
    pub tool_force_final_n: Vec<[f64; 3]>,
    pub tool_force_peak_n: Vec<f64>,
    /// Deepest penetration over the run (m) and the scene's tolerance.
    pub max_penetration_m: f64,
    pub tolerance_m: f64,
    /// Largest |Σ forces of a pair| / Σ|forces| over the run (zero to round-off).
    pub pair_force_sum_rel_max: f64,
    pub check_interval_steps: u32,
    pub checks: u64,
    pub candidates_max: usize,
    pub active_contacts_final: u32,
}

/// Result of a run: final displacements (f64) and the report.
pub struct RunOutput {
    pub displacements: Vec<[f64; 3]>,
    pub report: RunReport,
    /// Per step, the force of the tissue on each tool (N): `tool_force[step · tools + t]`.
    pub tool_force: Vec<[f64; 3]>,
}

/// Called every step with the model's state after the step (for progress and frames).
pub trait Observer {
    fn after_step(
        &mut self,
        step: u64,
        time_s: f64,
        steps_total: u64,
        u: &dyn Fn() -> Vec<[f64; 3]>,
    );
}

impl Observer for () {
    fn after_step(&mut self, _: u64, _: f64, _: u64, _: &dyn Fn() -> Vec<[f64; 3]>) {}
}

/// Runs the problem to its end in its scene's precision.
pub fn run(problem: &Problem, name: &str, observer: &mut dyn Observer) -> Result<RunOutput> {
    match problem.solver.precision {
        Precision::F32 => run_typed::<f32>(problem, name, observer),
        Precision::F64 => run_typed::<f64>(problem, name, observer),
    }
}

pub fn run_typed<T: Real>(
    problem: &Problem,
    name: &str,
    observer: &mut dyn Observer,
) -> Result<RunOutput> {
    let (dt, dt_crit) = problem.time_step()?;
    let mut steps = problem.steps(dt);
    let mut model = Model::<T>::new(problem, dt);
    let mut monitor = DtMonitor::new(problem, dt_crit);
    let start = Instant::now();
    let mut tool_force = Vec::new();
    let mut peak: Vec<f64> = Vec::new();
    let mut pair_rel: f64 = 0.0;
    while model.step < steps {
        model
            .advance()
            .map_err(|e| anyhow!("{name}: {}", describe_step_error(problem, &e)))?;
        if let Some(c) = &model.contact {
            tool_force.extend_from_slice(&c.tool_force);
            peak.resize(c.tool_force.len(), 0.0);
            for (p, f) in peak.iter_mut().zip(&c.tool_force) {
                *p = p.max((f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt());
            }
            for (s, m) in c.stats.pair_sum_n.iter().zip(&c.stats.pair_magnitude_n) {
                if *m > 0.0 {
                    pair_rel = pair_rel.max((s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt() / m);
                }
            }
        }
        if monitor.due(model.step) && model.step < steps {
            if let Some(dt_new) = monitor.check(&model).map_err(|e| anyhow!("{name}: {e}"))? {
                model.set_dt(dt_new);
                if problem.solver.steps.is_none() {
                    let left = problem.solver.duration.unwrap_or(1.0) - model.time_s();
                    steps = model.step + (left / dt_new).ceil().max(0.0) as u64;
                }
            }
        }
        let m = &model;
        observer.after_step(m.step, m.time_s(), steps, &|| m.displacements());
    }
    let wall_s = start.elapsed().as_secs_f64();
    let displacements = model.displacements();
    let (max_node, max_disp) = displacements
        .iter()
        .enumerate()
        .map(|(k, u)| (k, (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt()))
        .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    let elements = model.elements.len();
    let report = RunReport {
        scene: name.to_string(),
        precision: T::NAME.to_string(),
        integration: problem.solver.integration.name().to_string(),
        steps,
        dt_s: dt,
        dt_critical_s: dt_crit,
        simulated_s: model.time_s(),
        elements,
        nodes: problem.mesh.nodes.len(),
        wall_s,
        element_steps_per_s: (elements as f64 * steps as f64) / wall_s.max(1e-12),
        real_time_factor: model.time_s() / wall_s.max(1e-12),
        kinetic_energy_final: model.kinetic_energy,
        stored_energy_final: model.stored_energy()?,
        max_displacement: max_disp,
        max_displacement_node: problem.mesh.node_tags.get(max_node).copied().unwrap_or(0),
        prescribed_reaction_n: model.reaction_prescribed,
        fixed_reaction_n: model.reaction_fixed,
        dt_final_s: model.dt_s,
        dt_critical_min_s: monitor.dt_critical_min_s,
        dt_rechecks: monitor.rechecks,
        dt_reductions: monitor.reductions,
        contact: model.contact.as_ref().map(|c| ContactReport {
            tools: problem
                .contact
                .as_ref()
                .map(|s| s.tool_names.clone())
                .unwrap_or_default(),
            tool_force_final_n: c.tool_force.clone(),
            tool_force_peak_n: peak.clone(),
            max_penetration_m: c.max_depth_m,
            tolerance_m: c.run.params.tolerance_m,
            pair_force_sum_rel_max: pair_rel,
            check_interval_steps: c.run.params.check_interval_steps,
            checks: c.checks,
            candidates_max: c.candidates_max,
            active_contacts_final: c.stats.active,
        }),
    };
    Ok(RunOutput {
        displacements,
        report,
        tool_force,
    })
}

/// A step failure in words a user can act on: the step and time, and the mesh's own name
/// (tag) and position of the node, or the nodes of the element.
pub fn describe_step_error(problem: &Problem, e: &StepError) -> String {
    let tag = |n: u32| {
        problem
            .mesh
            .node_tags
            .get(n as usize)
            .copied()
            .unwrap_or(n as u64 + 1)
    };
    let at = |n: u32| {
        problem
            .mesh
            .nodes
            .get(n as usize)
            .map(|p| format!(" at [{:.4e}, {:.4e}, {:.4e}] m", p[0], p[1], p[2]))
            .unwrap_or_default()
    };
    let detail = match e.error {
        PhysicsError::NonFinite { node }
        | PhysicsError::SpeedLimit { node, .. }
        | PhysicsError::Penetration { node, .. }
        | PhysicsError::ContactSpeedBound { node, .. } => {
            format!(
                " (node index {node} = mesh node tag {}{})",
                tag(node),
                at(node)
            )
        }
        PhysicsError::InvertedElement { element, .. } | PhysicsError::BadIndex { element } => {
            match problem.mesh.cells.get(element as usize) {
                Some(c) => format!(
                    " (element {element} = mesh cell {element}, nodes {:?}{})",
                    c.map(tag),
                    at(c[0]).replace(" at", ", first node at")
                ),
                None => String::new(),
            }
        }
        PhysicsError::BadContactIndex { .. } => String::new(),
    };
    format!("{e}{detail}")
}

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

/// Energy terms at the time of the previous state `u_prev` (where the central velocity of
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
        let stored = self
            .elements
            .stored_energy(&self.laws, &self.u_prev)
            .map_err(|e| anyhow!("{e}"))?;
        let g = self.problem.gravity;
        let gravity = self
            .u_prev
            .iter()
            .zip(&self.problem.mass)
            .map(|(u, m)| -m * (0..3).map(|i| g[i] * u[i].to_f64()).sum::<f64>())
            .sum();
        Ok(Energies {
            kinetic: self.kinetic_energy,
            stored,
            gravity,
        })
    }
}
