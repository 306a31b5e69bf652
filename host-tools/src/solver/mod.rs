//! The serial reference solver: the whole mesh, the shared physics kernels, on one thread
//! or several with the same bits. Every parallel run (board-sim, the board array) is
//! compared with it.

use anyhow::{anyhow, Result};
use pe_firmware::physics::contact::{
    contact_step, Candidate, ContactError, ContactModel, ContactStats, ContactWork, FaceGeometries,
    FaceGeometry, QuadBounds,
};
use pe_firmware::physics::{CentralDifference, MaterialLaw, PhysicsError, Pose, Real};

use crate::problem::curves::Curves;
use crate::problem::elements::Elements;
use crate::problem::Problem;
use crate::subnormals::FlushGuard;
use crate::team;

/// The batched element loop lives with the elements it packs ([`crate::problem::batched`]);
/// re-exported here for the solver's users (board-sim's boards).
pub use crate::problem::batched;

mod monitor;
mod nodes;
mod run;
pub mod settle;
pub mod stable_step;

pub use monitor::{DtChange, DtMonitor, Energies};
pub use run::{
    describe_step_error, run, run_threads, run_typed, run_typed_with, run_with_poses,
    ContactReport, Observer, PoseSchedule, RunOutput, RunReport, StepState, Stepper,
};

/// Serial explicit model in scalar type `T`.
pub struct Model<'p, T: Real> {
    pub problem: &'p Problem,
    pub elements: Elements<T>,
    /// The elements packed for the batched kernel ([`batched`]), which computes the
    /// scalar loop's bits faster; `None` runs the scalar loop (a model whose packing
    /// failed names the bad element at its first step).
    pub batched: Option<batched::Batched<T>>,
    pub laws: Vec<MaterialLaw<T>>,
    pub dt_s: f64,
    pub cd: CentralDifference<T>,
    /// `C / m_inertial` per node, once per component (`3 n` values).
    pub gain: Vec<T>,
    /// `0.5 · m · mass_scaling` per node (kinetic energy `Σ ke_mass v²`), kg.
    ke_mass: Vec<f64>,
    /// Gravity force per node (true mass), N.
    gravity_force: Vec<[T; 3]>,
    pub u: Vec<[T; 3]>,
    /// The last step's increment `du = u_n − u_{n−1}`: the central difference's state
    /// besides `u` (it runs in increment form, [`CentralDifference`]).
    pub du: Vec<[T; 3]>,
    /// Internal forces: summed by the element phase, consumed (and zeroed, ready for the
    /// next step) by the node update.
    pub f_int: Vec<[T; 3]>,
    /// Whether `f_int` is all zeros (the node update zeroed it; false after a failed step).
    f_int_zero: bool,
    /// External forces: gravity, plus loads and contact at the nodes in `f_ext_dirty`.
    pub f_ext: Vec<[T; 3]>,
    /// Nodes whose `f_ext` differs from gravity (loads, contact), restored each step.
    f_ext_dirty: Vec<usize>,
    /// The distinct ramps of the loads and gravity ([`Problem::ramp_curves`]), each
    /// evaluated once per step.
    ramps: Curves<1>,
    /// The prescribed paths' values at the step's `t_{n+1}`, evaluated once per step.
    path_at: Vec<[T; 3]>,
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
    /// Threads of the parallel solver ([`Model::set_threads`]); None: one thread.
    team: Option<team::Team>,
    /// How the threads share the elements, and each block's forces kept aside.
    plan: Option<batched::Plan>,
    kept: Vec<Vec<[T; 3]>>,
}

/// Nodes per block of the node update: the unit of the parallel node phase, and of the
/// kinetic-energy and reaction sums (summed per block, then block by block), so the
/// figures are the same whatever the thread count. Small enough that two threads share
/// the seed box's 2541 nodes evenly (2048 split them 2048 to 493: `pe bench`, f64, two
/// threads, 23.8 -> 21.5 ns per element-step on an AMD EPYC with AVX2 lanes).
const NODE_BLOCK: usize = 512;

/// The serial solver's contact state: the tables, the search and the forces of the last step.
pub struct ContactState {
    pub run: crate::problem::contact::ContactRun,
    /// The room for the candidates (grown when a check needs more) and how many of them
    /// the last check kept (all it found: this solver applies every contact).
    candidates: Vec<Candidate>,
    kept: usize,
    /// The faces the candidates name (bit `f % 32` of word `f / 32`), and each face's
    /// geometry at the current step (refreshed every step for those faces).
    faces_used: Vec<u32>,
    geometry: Vec<Option<FaceGeometry>>,
    /// The candidate search's boxes, one per contact face (its scratch).
    search_boxes: Vec<QuadBounds>,
    /// Contact-node positions at the last check.
    pub at_check: Vec<[f64; 3]>,
    /// Contact force per contact node at the last step (N).
    pub force: Vec<[f64; 3]>,
    /// Force of the tissue on each tool at the last step (N).
    pub tool_force: Vec<[f64; 3]>,
    /// A pose per tool that replaces its scripted path from the step it was set on (a live
    /// session's or a replay's; `None`: the path).
    pub live_pose: Vec<Option<Pose>>,
    pub stats: ContactStats,
    /// Checks done and the most candidates any check found.
    pub checks: u64,
    pub candidates_max: usize,
    /// Deepest penetration over the run (m).
    pub max_depth_m: f64,
    /// Wall time spent in contact evaluations so far (s): `pe bench`'s contact figure.
    pub evaluate_s: f64,
}

impl ContactState {
    fn new(problem: &Problem, dt_s: f64) -> Option<ContactState> {
        let setup = problem.contact.as_ref()?;
        let ms = problem.solver.mass_scaling;
        let inertial: Vec<f64> = problem.mass.iter().map(|m| m * ms).collect();
        let run = setup.for_step(&problem.mesh, &inertial, dt_s);
        let n = run.nodes.len();
        let tools = run.tools.len();
        let faces = run.faces.len();
        Some(ContactState {
            run,
            candidates: Vec::new(),
            kept: 0,
            faces_used: vec![0; faces.div_ceil(32)],
            geometry: vec![None; faces],
            search_boxes: vec![QuadBounds::default(); faces],
            at_check: vec![[0.0; 3]; n],
            force: vec![[0.0; 3]; n],
            tool_force: vec![[0.0; 3]; tools],
            live_pose: vec![None; tools],
            stats: ContactStats::default(),
            checks: 0,
            candidates_max: 0,
            max_depth_m: 0.0,
            evaluate_s: 0.0,
        })
    }

    /// Contact forces at the state `u` (step `step`, time `t`): the board runtime's
    /// sequence ([`contact_step`]) with every contact node applied, the faces held as their
    /// geometry, and the room for candidates grown until a check's search fits.
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
        let check = step.is_multiple_of(p.check_interval_steps.max(1) as u64);
        let capsules: Vec<_> = run
            .tools
            .iter()
            .zip(&self.live_pose)
            .map(|(tl, live)| match live {
                Some(pose) => tl.capsule.posed(pose),
                None => tl.capsule.translated(problem.paths[tl.path as usize].at(t)),
            })
            .collect();
        let found = loop {
            let mut work = ContactWork {
                at_check: &mut self.at_check,
                candidates: &mut self.candidates,
                kept: &mut self.kept,
                faces_used: &mut self.faces_used,
                faces: FaceGeometries {
                    geometry: &mut self.geometry,
                    search_boxes: &mut self.search_boxes,
                },
                force: &mut self.force,
                tool_force: &mut self.tool_force,
                stats: &mut self.stats,
            };
            match contact_step(&m, &p, check, &capsules, pos, |_| true, &mut work, |_| {}) {
                Ok(found) => break found,
                // Room for what this check needs, and the step again.
                Err(ContactError::Candidates { needed }) => {
                    self.candidates.resize(needed, Candidate::default())
                }
                Err(ContactError::Physics(e)) => return Err(e),
            }
        };
        if check {
            self.checks += 1;
        }
        if let Some(n) = found {
            self.candidates_max = self.candidates_max.max(n);
        }
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
        let gain = Self::gains(problem, &cd);
        let ms = problem.solver.mass_scaling;
        let ke_mass = problem.mass.iter().map(|m| 0.5 * m * ms).collect();
        let gravity_force: Vec<[T; 3]> = problem
            .mass
            .iter()
            .map(|m| problem.gravity.map(|g| T::from_f64(g * m)))
            .collect();
        let elements = Elements::build(problem);
        let laws: Vec<MaterialLaw<T>> = problem.laws.iter().map(|l| l.cast::<T>()).collect();
        Model {
            problem,
            batched: batched::Batched::build(&elements, &laws, batched::Isa::detect()).ok(),
            elements,
            laws,
            dt_s,
            cd,
            gain,
            ke_mass,
            u: vec![[T::ZERO; 3]; n],
            du: vec![[T::ZERO; 3]; n],
            f_int: vec![[T::ZERO; 3]; n],
            f_int_zero: true,
            f_ext: gravity_force.clone(),
            gravity_force,
            f_ext_dirty: Vec::new(),
            ramps: problem.ramp_curves(),
            path_at: vec![[T::ZERO; 3]; problem.paths.len()],
            step: 0,
            time_base_s: 0.0,
            step_base: 0,
            kinetic_energy: 0.0,
            reaction_prescribed: [0.0; 3],
            reaction_fixed: [0.0; 3],
            contact: ContactState::new(problem, dt_s),
            team: None,
            plan: None,
            kept: Vec::new(),
        }
    }

    /// Runs on `threads` threads (1: this one): elements in blocks of packs
    /// ([`batched::Plan`]: each node's forces summed in the scalar loop's order), then the
    /// node update in blocks; the bits are those of one thread whatever the count.
    pub fn set_threads(&mut self, threads: usize) -> Result<()> {
        // One block per thread: where blocks meet, forces go through the owner check and
        // the kept-aside buffers, and the nodes' cache lines move between cores. Measured
        // (`pe bench --elements 20000`, f64, 2 threads over 1): 2 blocks a thread 1.74x,
        // 4 a thread 1.3x, 1 a thread 1.9x; the team's threads wait awake, so the
        // balance a spare block gave against a slow wake-up is not needed.
        self.plan = match (&self.batched, threads > 1) {
            (Some(b), true) => b.element_loop().plan(threads, self.u.len()),
            _ => None,
        };
        self.kept = self
            .plan
            .as_ref()
            .map_or_else(Vec::new, |p| p.kept_buffers());
        // The old team's threads end (joined on drop) before the new one's start.
        self.team = None;
        self.team = if threads > 1 {
            Some(team::Team::new(threads)?)
        } else {
            None
        };
        Ok(())
    }

    /// The threads the solver runs on.
    pub fn threads(&self) -> usize {
        self.team.as_ref().map_or(1, |t| t.threads())
    }

    /// Internal forces at `u` into `f_int`, on the team when there is one.
    fn element_phase(&mut self, team: Option<&team::Team>) -> Result<(), PhysicsError> {
        if !std::mem::replace(&mut self.f_int_zero, false) {
            self.f_int.iter_mut().for_each(|f| *f = [T::ZERO; 3]);
        }
        if let (Some(team), Some(b), Some(plan)) = (team, &self.batched, &self.plan) {
            let el = b.element_loop();
            if el.parallel_forces(plan, &mut self.kept, team, &self.u, &mut self.f_int) {
                // The tetrahedra after every hexahedron, on this thread.
                return el.tet_forces(&self.elements, &self.laws, &self.u, &mut self.f_int);
            }
            // A pack failed: the one-thread loop names the element.
            self.f_int.iter_mut().for_each(|f| *f = [T::ZERO; 3]);
        }
        match &self.batched {
            Some(b) => b.internal_forces(&self.elements, &self.laws, &self.u, &mut self.f_int),
            None => self
                .elements
                .internal_forces(&self.laws, &self.u, &mut self.f_int),
        }
    }

    pub fn time_s(&self) -> f64 {
        self.time_base_s + (self.step - self.step_base) as f64 * self.dt_s
    }

    /// Changes the time step mid-run. The central difference keeps the half-step velocity
    /// `v = du/dt` in its history, so the increment is rescaled to keep it:
    /// `du := (dt_new/dt_old) du`; the update coefficients and the per-node gains are
    /// rebuilt for the new step.
    pub fn set_dt(&mut self, dt_new: f64) {
        let r = dt_new / self.dt_s;
        for du in self.du.iter_mut() {
            *du = du.map(|d| T::from_f64(r * d.to_f64()));
        }
        self.time_base_s = self.time_s();
        self.step_base = self.step;
        self.dt_s = dt_new;
        self.cd = CentralDifference::<T>::new(dt_new, self.problem.solver.damping);
        self.gain = Self::gains(self.problem, &self.cd);
    }

    /// `C / m_inertial` per node, repeated for its three components.
    fn gains(problem: &Problem, cd: &CentralDifference<T>) -> Vec<T> {
        let ms = problem.solver.mass_scaling;
        let gain = |m: &f64| [cd.gain(m * ms); 3];
        problem.mass.iter().flat_map(gain).collect()
    }

    /// External forces at time `t`: gravity plus ramped loads plus contact (in that order,
    /// as the board runtime adds them).
    fn external_forces(&mut self, t: f64) -> Result<(), PhysicsError> {
        self.ramps.evaluate(t);
        let (f_ext, dirty) = (&mut self.f_ext, &mut self.f_ext_dirty);
        match self.ramps.value(self.problem.gravity_ramp_user()) {
            // Ramped gravity everywhere, `g · s(t)` in the nodes' precision (the boards'
            // product).
            Some([s]) => {
                let s = T::from_f64(s);
                dirty.clear();
                for (f, g) in f_ext.iter_mut().zip(&self.gravity_force) {
                    *f = g.map(|gi| gi * s);
                }
            }
            // Gravity everywhere: only the nodes given more last step need restoring.
            None => {
                for n in dirty.drain(..) {
                    f_ext[n] = self.gravity_force[n];
                }
            }
        }
        for (k, l) in self.problem.loads.iter().enumerate() {
            let s = self.ramps.value(k).map_or(1.0, |v| v[0]);
            let n = l.node as usize;
            dirty.push(n);
            for i in 0..3 {
                f_ext[n][i] += T::from_f64(l.force[i] * s);
            }
        }
        if let Some(c) = self.contact.as_mut() {
            let start = std::time::Instant::now();
            c.evaluate(self.problem, &self.u, self.step, t)?;
            c.evaluate_s += start.elapsed().as_secs_f64();
            for (node, f) in c.run.nodes.iter().zip(&c.force) {
                let n = node.global as usize;
                dirty.push(n);
                for i in 0..3 {
                    f_ext[n][i] += T::from_f64(f[i]);
                }
            }
        }
        Ok(())
    }

    /// One central-difference step from `t_n` to `t_{n+1}`: the element phase and the node
    /// update on the team's threads when there are several ([`team`]: they wait for the
    /// next phase awake), subnormals flushed as on the boards unless the problem keeps
    /// them ([`crate::subnormals`]).
    pub fn advance(&mut self) -> Result<(), StepError> {
        // The boards' floating-point rule for the step (the team's threads take the
        // caller's: [`team`]); the caller's mode is back when the step returns.
        let _mode = FlushGuard::enter(self.problem.subnormals);
        let team = self.team.take();
        let r = self.advance_inner(team.as_ref());
        self.team = team;
        r
    }

    fn advance_inner(&mut self, team: Option<&team::Team>) -> Result<(), StepError> {
        let t = self.time_s();
        let t_next = t + self.dt_s;
        let step = self.step;
        self.element_phase(team)
            .map_err(|error| StepError { step, error })?;
        self.external_forces(t)
            .map_err(|error| StepError { step, error })?;
        for (at, path) in self.path_at.iter_mut().zip(&self.problem.paths) {
            *at = path.at(t_next).map(T::from_f64);
        }
        let nodes = nodes::NodeStep {
            problem: self.problem,
            path_at: &self.path_at,
            cd: self.cd,
            gain: &self.gain,
            ke_mass: &self.ke_mass,
            f_ext: &self.f_ext,
            inv_2dt_per_s: 1.0 / (2.0 * self.dt_s),
            speed_limit_m_per_s: self.problem.solver.speed_limit,
        };
        let parts = self
            .u
            .chunks_mut(NODE_BLOCK)
            .zip(self.du.chunks_mut(NODE_BLOCK))
            .zip(self.f_int.chunks_mut(NODE_BLOCK))
            .enumerate()
            .map(|(k, ((u, du), f_int))| (k * NODE_BLOCK, u, du, f_int));
        let block = |(first, u, du, f_int): &mut (usize, &mut [[T; 3]], &mut _, &mut _)| {
            nodes.block(*first, u, du, f_int)
        };
        let sums: Vec<nodes::BlockSums> = match team {
            Some(team) => team.map_mut(&mut parts.collect::<Vec<_>>(), |_, p| block(p)),
            None => parts.map(|mut p| block(&mut p)).collect(),
        };
        let (mut ke, mut rp, mut rf) = (0.0, [0.0; 3], [0.0; 3]);
        for s in &sums {
            if let Some(error) = s.error {
                return Err(StepError { step, error });
            }
            ke += s.kinetic_energy;
            for i in 0..3 {
                rp[i] += s.reaction_prescribed[i];
                rf[i] += s.reaction_fixed[i];
            }
        }
        self.f_int_zero = true;
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

    /// Velocities as `f64` (m/s): the central difference's `du/dt = (u_n − u_{n−1})/dt`
    /// over the last step, the velocity at half a step before [`time_s`](Self::time_s)
    /// (zero at rest).
    pub fn velocities(&self) -> Vec<[f64; 3]> {
        self.du
            .iter()
            .map(|d| d.map(|v| v.to_f64() / self.dt_s))
            .collect()
    }

    /// The previous state `u_{n−1} = u_n − du`, as `f64`.
    pub fn previous_displacements(&self) -> Vec<[f64; 3]> {
        self.u
            .iter()
            .zip(&self.du)
            .map(|(u, d)| core::array::from_fn(|i| u[i].to_f64() - d[i].to_f64()))
            .collect()
    }
}
