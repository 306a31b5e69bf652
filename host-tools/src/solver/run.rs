//! Running a problem to its end: the loop around [`Model::advance`], the observer, the
//! run report, and step errors in the mesh's own words.

use std::time::Instant;

use anyhow::{anyhow, Result};
use pe_firmware::image::Precision;
use pe_firmware::physics::{PhysicsError, Pose, Real};
use serde::Serialize;

use super::{DtMonitor, Model, StepError};
use crate::geom::norm;
use crate::problem::Problem;

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
    /// Fraction of the elements that take each hexahedral kernel (general,
    /// parallelepiped, cuboid); the rest are tetrahedra.
    pub kernel_mix: [f64; 3],
    /// Tetrahedra among the elements (`[solver] tetrahedron` chooses their form).
    #[serde(default)]
    pub tetrahedra: usize,
    pub nodes: usize,
    /// Nodes on a contact surface.
    pub contact_nodes: usize,
    pub wall_s: f64,
    /// Solver threads, and the element kernel that ran ("f64x4 avx", ...).
    pub threads: usize,
    pub kernel: String,
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
    /// Smallest critical step found during the run (element tracking and re-checks), s;
    /// the initial one when both are off.
    pub dt_critical_min_s: f64,
    /// Element-by-element bounds (`dt_track_interval`) and power re-checks
    /// (`dt_recheck_interval`) done, and how many checks lowered `dt`.
    pub dt_tracks: u64,
    pub dt_rechecks: u64,
    pub dt_reductions: u64,
    /// Wall time of those checks (s) and its share of the run's wall time.
    pub dt_tracking_s: f64,
    pub dt_tracking_fraction: f64,
    /// The element tracker's calibration `κ` at rest and at the end (lowered only by a
    /// power re-check that found a smaller critical step); 0 when tracking is off.
    pub dt_calibration_initial: f64,
    pub dt_calibration_final: f64,
    /// Every change of `dt`: step, time, new step, the critical step found and its cell.
    pub dt_history: Vec<super::DtChange>,
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

impl RunReport {
    /// The console summary of `pe solve`: steps, speed, largest displacement and kinetic
    /// energy; the reaction of the prescribed nodes when there are any
    /// (`prescribed_nodes`), and each tool's force at the end and its peak when the scene
    /// has tools.
    pub fn console_summary(&self, prescribed_nodes: usize) -> String {
        let r = self;
        let mut s = format!(
            "{} steps in {:.2} s on {} thread(s), {} kernel: {:.3e} element-steps/s, real-time factor {:.3}; max |u| = {:.4e} m at node {}; KE = {:.3e} J",
            r.steps, r.wall_s, r.threads, r.kernel, r.element_steps_per_s, r.real_time_factor,
            r.max_displacement, r.max_displacement_node, r.kinetic_energy_final
        );
        if r.dt_reductions > 0 {
            s += &format!(
                "\n  dt lowered {} times as the stable step shrank under deformation: {:.4e} s at rest, {:.4e} s at the end (smallest critical step {:.4e} s; tracking took {:.1}% of the run)",
                r.dt_reductions,
                r.dt_s,
                r.dt_final_s,
                r.dt_critical_min_s,
                100.0 * r.dt_tracking_fraction
            );
        }
        if prescribed_nodes > 0 {
            let f = r.prescribed_reaction_n;
            s += &format!(
                "\n  prescribed reaction ({prescribed_nodes} prescribed nodes on the tissue, at the end) = [{:.4e}, {:.4e}, {:.4e}] N",
                f[0], f[1], f[2]
            );
        }
        if let Some(c) = &r.contact {
            for (k, name) in c.tools.iter().enumerate() {
                let f = c.tool_force_final_n.get(k).copied().unwrap_or([0.0; 3]);
                let peak = c.tool_force_peak_n.get(k).copied().unwrap_or(0.0);
                s += &format!(
                    "\n  tool {name:?}: force of the tissue at the end [{:.4e}, {:.4e}, {:.4e}] N (|F| = {:.4e} N), peak |F| = {peak:.4e} N",
                    f[0], f[1], f[2], norm(f)
                );
            }
        }
        s
    }
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
    fn after_step(&mut self, step: u64, time_s: f64, steps_total: u64, state: &dyn StepState);
    /// The run starts again from rest at step `dt_s` (`pe solve` settling its step,
    /// [`super::settle`]): outputs begun are begun again.
    fn restart(&mut self, _dt_s: f64) -> Result<()> {
        Ok(())
    }
}

impl Observer for () {
    fn after_step(&mut self, _: u64, _: f64, _: u64, _: &dyn StepState) {}
}

/// The state after a step, computed only when an observer asks for it.
pub trait StepState {
    /// Displacement of every node (m).
    fn displacements(&self) -> Vec<[f64; 3]>;
    /// Velocity of every node (m/s): the central difference's `(u_n − u_{n−1})/dt` over the
    /// last step.
    fn velocities(&self) -> Vec<[f64; 3]>;
}

impl<T: Real> StepState for Model<'_, T> {
    fn displacements(&self) -> Vec<[f64; 3]> {
        Model::displacements(self)
    }
    fn velocities(&self) -> Vec<[f64; 3]> {
        Model::velocities(self)
    }
}

/// Runs the problem to its end in its scene's precision, on this thread.
pub fn run(problem: &Problem, name: &str, observer: &mut dyn Observer) -> Result<RunOutput> {
    run_threads(problem, name, observer, 1)
}

/// [`run`] on `threads` threads: the same bits whatever the count.
pub fn run_threads(
    problem: &Problem,
    name: &str,
    observer: &mut dyn Observer,
    threads: usize,
) -> Result<RunOutput> {
    run_with_poses(problem, name, observer, threads, PoseSchedule::default())
}

/// [`run_threads`] with tool poses applied at the steps `poses` names (a recorded live
/// session replayed: the same bits as the session).
pub fn run_with_poses(
    problem: &Problem,
    name: &str,
    observer: &mut dyn Observer,
    threads: usize,
    poses: PoseSchedule,
) -> Result<RunOutput> {
    match problem.solver.precision {
        Precision::F32 => run_typed_with::<f32>(problem, name, observer, threads, poses),
        Precision::F64 => run_typed_with::<f64>(problem, name, observer, threads, poses),
    }
}

/// Tool poses to apply, each before the step it names: `(step, tool, pose)`, in step order.
#[derive(Clone, Debug, Default)]
pub struct PoseSchedule {
    pub poses: Vec<(u64, usize, Pose)>,
}

/// A run's step sequence, one step at a time: the poses due, the step, and the critical
/// step's tracking (which may lower `dt`). `pe solve`, its replays and live sessions all
/// step through it, so they compute the same bits.
pub struct Stepper<'p, T: Real> {
    pub model: Model<'p, T>,
    pub monitor: DtMonitor<'p>,
    /// The step count the run ends at (`u64::MAX`: open-ended, a live session); follows
    /// `dt` when the scene gives a duration.
    pub steps: u64,
    name: String,
    poses: PoseSchedule,
    next_pose: usize,
}

impl<'p, T: Real> Stepper<'p, T> {
    /// The problem at rest, at its time step, on `threads` threads.
    pub fn new(problem: &'p Problem, name: &str, threads: usize) -> Result<Self> {
        let (dt, dt_crit) = (
            problem.time_step.dt_s,
            problem.time_step.critical.dt_critical_s,
        );
        let mut model = Model::<T>::new(problem, dt);
        model.set_threads(threads)?;
        Ok(Stepper {
            model,
            monitor: DtMonitor::new(problem, dt_crit),
            steps: problem.steps(dt),
            name: name.to_string(),
            poses: PoseSchedule::default(),
            next_pose: 0,
        })
    }

    /// Poses to apply before the steps they name (replaces any schedule not yet applied).
    pub fn schedule(&mut self, poses: PoseSchedule) {
        self.poses = poses;
        self.next_pose = 0;
    }

    /// Sets `tool`'s pose from the next step on. Err: the scene has no such tool.
    pub fn set_pose(&mut self, tool: usize, pose: Pose) -> Result<()> {
        let slot = self
            .model
            .contact
            .as_mut()
            .and_then(|c| c.live_pose.get_mut(tool))
            .ok_or_else(|| anyhow!("{}: no tool {tool}", self.name))?;
        *slot = Some(pose);
        Ok(())
    }

    /// One step: the scheduled poses due, the step, then the critical step's check.
    pub fn step(&mut self) -> Result<()> {
        while let Some(&(at, tool, pose)) = self.poses.poses.get(self.next_pose) {
            if at > self.model.step {
                break;
            }
            self.set_pose(tool, pose)?;
            self.next_pose += 1;
        }
        let problem = self.model.problem;
        if let Err(e) = self.model.advance() {
            return Err(anyhow!(
                "{}: {}{}",
                self.name,
                describe_step_error(problem, &e),
                instability_note(&self.monitor, &self.model)
            ));
        }
        if self.monitor.due(self.model.step) && self.model.step < self.steps {
            let name = &self.name;
            if let Some(dt_new) = self
                .monitor
                .check(&self.model)
                .map_err(|e| anyhow!("{name}: {e}"))?
            {
                self.model.set_dt(dt_new);
                if problem.solver.steps.is_none() && self.steps != u64::MAX {
                    let left = problem.solver.duration.unwrap_or(1.0) - self.model.time_s();
                    self.steps = self.model.step + (left / dt_new).ceil().max(0.0) as u64;
                }
            }
        }
        Ok(())
    }
}

/// [`run_threads`] in the scalar type `T`, whatever the scene's precision.
pub fn run_typed<T: Real>(
    problem: &Problem,
    name: &str,
    observer: &mut dyn Observer,
    threads: usize,
) -> Result<RunOutput> {
    run_typed_with::<T>(problem, name, observer, threads, PoseSchedule::default())
}

/// [`run_typed`] with tool poses applied at the steps `poses` names.
pub fn run_typed_with<T: Real>(
    problem: &Problem,
    name: &str,
    observer: &mut dyn Observer,
    threads: usize,
    poses: PoseSchedule,
) -> Result<RunOutput> {
    let (dt, dt_crit) = (
        problem.time_step.dt_s,
        problem.time_step.critical.dt_critical_s,
    );
    let mut stepper = Stepper::<T>::new(problem, name, threads)?;
    stepper.schedule(poses);
    let start = Instant::now();
    let mut tool_force = Vec::new();
    let mut peak: Vec<f64> = Vec::new();
    let mut pair_rel: f64 = 0.0;
    while stepper.model.step < stepper.steps {
        stepper.step()?;
        let (model, steps) = (&stepper.model, stepper.steps);
        if let Some(c) = &model.contact {
            tool_force.extend_from_slice(&c.tool_force);
            peak.resize(c.tool_force.len(), 0.0);
            for (p, f) in peak.iter_mut().zip(&c.tool_force) {
                *p = p.max(norm(*f));
            }
            for (s, m) in c.stats.pair_sum_n.iter().zip(&c.stats.pair_magnitude_n) {
                if *m > 0.0 {
                    pair_rel = pair_rel.max(norm(*s) / m);
                }
            }
        }
        observer.after_step(model.step, model.time_s(), steps, model);
    }
    let wall_s = start.elapsed().as_secs_f64();
    let Stepper {
        model,
        monitor,
        steps,
        ..
    } = stepper;
    let displacements = model.displacements();
    let (max_node, max_disp) = displacements
        .iter()
        .enumerate()
        .map(|(k, u)| (k, norm(*u)))
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
        kernel_mix: model
            .elements
            .hexes
            .per_kernel()
            .map(|n| n as f64 / elements.max(1) as f64),
        tetrahedra: model.elements.tets.len(),
        nodes: problem.mesh.nodes.len(),
        contact_nodes: problem.contact.as_ref().map_or(0, |c| c.node_globals.len()),
        wall_s,
        threads: model.threads(),
        kernel: model
            .batched
            .as_ref()
            .map_or_else(|| format!("{} scalar", T::NAME), |b| b.describe()),
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
        dt_tracks: monitor.tracks,
        dt_rechecks: monitor.rechecks,
        dt_reductions: monitor.reductions,
        dt_tracking_s: monitor.wall_s,
        dt_tracking_fraction: monitor.wall_s / wall_s.max(1e-12),
        dt_calibration_initial: monitor.calibration_initial,
        dt_calibration_final: monitor.calibration(),
        dt_history: monitor.history.clone(),
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

/// When a step failed: whether the step was unstable, from the element bound about the
/// last good state (`u` is still the state the failed step started from): ": an unstable
/// step: dt = … above the critical step … of the deformed state (cell …)", or nothing.
fn instability_note<T: Real>(monitor: &DtMonitor<'_>, model: &Model<'_, T>) -> String {
    let tracked = monitor.tracked(model).or_else(|| {
        // Tracking off: bound the step about the last good state once, now.
        Some(super::stable_step::StableStepTracker::new(model.problem).bound(&model.u, None))
    });
    match tracked {
        Some(t) if model.dt_s > t.dt_critical_s => format!(
            "\n  an unstable step: dt = {:.4e} s is above the critical step of the deformed state, {:.4e} s (cell {} sets it; {:.4e} s at rest); {}",
            model.dt_s,
            t.dt_critical_s,
            t.limiting_cell,
            monitor.dt_critical_initial_s,
            match model.problem.solver.dt_track_interval {
                0 => "dt_track_interval = 0 turned the tracking off: leave it at its default".to_string(),
                n => format!("the element bound ran every {n} steps (dt_track_interval): lower it or dt_safety"),
            }
        ),
        _ => String::new(),
    }
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
