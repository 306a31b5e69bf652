//! The serial reference solver: one thread, the whole mesh, the shared physics kernels.
//! Every parallel run (board-sim, the board array) is compared with it.

use std::time::Instant;

use anyhow::{anyhow, Result};
use pe_firmware::physics::explicit::{accumulate_internal_forces, stored_energy};
use pe_firmware::physics::{
    CentralDifference, HexElement, HexFull, HexReduced, MaterialLaw, PhysicsError, Real,
};
use serde::Serialize;

use crate::problem::{NodeKind, Problem};

/// Elements of one integration kind.
pub enum Elements<T> {
    Reduced(Vec<HexReduced<T>>),
    Full(Vec<HexFull<T>>),
}

impl<T: Real> Elements<T> {
    pub fn build(p: &Problem) -> Self {
        let cells = p.mesh.cells.iter().zip(&p.reference).zip(&p.cell_material);
        if p.solver.integration == "full" {
            Elements::Full(cells.map(|((c, r), m)| r.full(*c, *m)).collect())
        } else {
            Elements::Reduced(
                cells
                    .map(|((c, r), m)| {
                        let modulus = p.laws[*m as usize].hourglass_modulus();
                        r.reduced(*c, *m, modulus, p.solver.hourglass)
                    })
                    .collect(),
            )
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Elements::Reduced(v) => v.len(),
            Elements::Full(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn internal_forces(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        match self {
            Elements::Reduced(v) => accumulate_internal_forces(v, 0, laws, u, f),
            Elements::Full(v) => accumulate_internal_forces(v, 0, laws, u, f),
        }
    }

    pub fn stored_energy(
        &self,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
    ) -> Result<f64, PhysicsError> {
        match self {
            Elements::Reduced(v) => stored_energy(v, laws, u),
            Elements::Full(v) => stored_energy(v, laws, u),
        }
    }

    /// Nodes of element `e`.
    pub fn nodes(&self, e: usize) -> [u32; 8] {
        match self {
            Elements::Reduced(v) => *v[e].nodes(),
            Elements::Full(v) => *v[e].nodes(),
        }
    }
}

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
    /// Steps taken so far; the state is at time `step · dt`.
    pub step: u64,
    /// Kinetic energy at the previous step's time (J), from the central velocity.
    pub kinetic_energy: f64,
    /// Sum over prescribed (and fixed) nodes of `f_int − f_ext`: the force the constraints
    /// exert on the tissue at the last step, N (for the built-in scene: the probe push).
    pub reaction_prescribed: [f64; 3],
    pub reaction_fixed: [f64; 3],
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
            kinetic_energy: 0.0,
            reaction_prescribed: [0.0; 3],
            reaction_fixed: [0.0; 3],
        }
    }

    pub fn time_s(&self) -> f64 {
        self.step as f64 * self.dt_s
    }

    /// External forces at time `t`: gravity plus ramped loads.
    fn external_forces(&mut self, t: f64) {
        self.f_ext.copy_from_slice(&self.gravity_force);
        for l in &self.problem.loads {
            let s = l.ramp.as_ref().map(|r| r.at(t)[0]).unwrap_or(1.0);
            for i in 0..3 {
                self.f_ext[l.node as usize][i] += T::from_f64(l.force[i] * s);
            }
        }
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
        self.external_forces(t);
        let inv2dt = 1.0 / (2.0 * self.dt_s);
        let limit = self.problem.solver.speed_limit;
        let ms = self.problem.solver.mass_scaling;
        let mut ke = 0.0;
        let mut rp = [0.0; 3];
        let mut rf = [0.0; 3];
        for n in 0..self.u.len() {
            let next = match self.problem.node_kind[n] {
                NodeKind::Free => {
                    let r: [T; 3] = core::array::from_fn(|i| self.f_ext[n][i] - self.f_int[n][i]);
                    let next = self
                        .cd
                        .advance(&self.u[n], &self.u_prev[n], self.gain[n], &r);
                    if !next.iter().all(|v| v.is_finite()) {
                        return Err(StepError {
                            step,
                            error: PhysicsError::NonFinite { node: n as u32 },
                        });
                    }
                    next
                }
                NodeKind::Fixed => {
                    for i in 0..3 {
                        rf[i] += (self.f_int[n][i] - self.f_ext[n][i]).to_f64();
                    }
                    [T::ZERO; 3]
                }
                NodeKind::Prescribed(k) => {
                    for i in 0..3 {
                        rp[i] += (self.f_int[n][i] - self.f_ext[n][i]).to_f64();
                    }
                    self.problem.paths[k as usize].at(t_next).map(T::from_f64)
                }
            };
            let v: [f64; 3] =
                core::array::from_fn(|i| (next[i] - self.u_prev[n][i]).to_f64() * inv2dt);
            let v2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            if v2 > limit * limit {
                return Err(StepError {
                    step,
                    error: PhysicsError::SpeedLimit {
                        node: n as u32,
                        speed_m_per_s: v2.sqrt(),
                    },
                });
            }
            ke += 0.5 * self.problem.mass[n] * ms * v2;
            self.u_prev[n] = self.u[n];
            self.u[n] = next;
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
}

/// Result of a run: final displacements (f64) and the report.
pub struct RunOutput {
    pub displacements: Vec<[f64; 3]>,
    pub report: RunReport,
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
    match problem.solver.precision.as_str() {
        "f32" => run_typed::<f32>(problem, name, observer),
        _ => run_typed::<f64>(problem, name, observer),
    }
}

pub fn run_typed<T: Real>(
    problem: &Problem,
    name: &str,
    observer: &mut dyn Observer,
) -> Result<RunOutput> {
    let (dt, dt_crit) = problem.time_step()?;
    let steps = problem.steps(dt);
    let mut model = Model::<T>::new(problem, dt);
    let start = Instant::now();
    for _ in 0..steps {
        model.advance().map_err(|e| anyhow!("{name}: {e}"))?;
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
        integration: problem.solver.integration.clone(),
        steps,
        dt_s: dt,
        dt_critical_s: dt_crit,
        simulated_s: steps as f64 * dt,
        elements,
        nodes: problem.mesh.nodes.len(),
        wall_s,
        element_steps_per_s: (elements as f64 * steps as f64) / wall_s.max(1e-12),
        real_time_factor: steps as f64 * dt / wall_s.max(1e-12),
        kinetic_energy_final: model.kinetic_energy,
        stored_energy_final: model.stored_energy()?,
        max_displacement: max_disp,
        max_displacement_node: problem.mesh.node_tags.get(max_node).copied().unwrap_or(0),
        prescribed_reaction_n: model.reaction_prescribed,
        fixed_reaction_n: model.reaction_fixed,
    };
    Ok(RunOutput {
        displacements,
        report,
    })
}

impl<'p, T: Real> Model<'p, T> {
    /// Highest angular frequency `ω_max` (rad/s) of the free nodes, linearised about the
    /// current state, by power iteration on `M⁻¹K` (`K v` by a central difference of the
    /// internal forces). The stable central-difference step is `2/ω_max` (undamped).
    /// Costs about two force evaluations per iteration.
    pub fn max_frequency(&self, iterations: usize) -> Result<f64> {
        let n = self.u.len();
        let free: Vec<bool> = self
            .problem
            .node_kind
            .iter()
            .map(|k| *k == crate::problem::NodeKind::Free)
            .collect();
        let m: Vec<f64> = self
            .problem
            .mass
            .iter()
            .map(|m| m * self.problem.solver.mass_scaling)
            .collect();
        // Deterministic start with every component excited.
        let mut v: Vec<[f64; 3]> = (0..n)
            .map(|k| {
                core::array::from_fn(|i| {
                    if free[k] {
                        (((k * 3 + i) as f64) * 0.7548776662).fract() - 0.5
                    } else {
                        0.0
                    }
                })
            })
            .collect();
        let scale = self
            .problem
            .reference
            .iter()
            .map(|r| r.characteristic_length)
            .fold(f64::INFINITY, f64::min);
        let eps = 1e-7 * scale;
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
            v.iter_mut()
                .for_each(|a| a.iter_mut().for_each(|x| *x /= norm));
            let up: Vec<[T; 3]> = self
                .u
                .iter()
                .zip(&v)
                .map(|(u, d)| core::array::from_fn(|i| T::from_f64(u[i].to_f64() + eps * d[i])))
                .collect();
            let um: Vec<[T; 3]> = self
                .u
                .iter()
                .zip(&v)
                .map(|(u, d)| core::array::from_fn(|i| T::from_f64(u[i].to_f64() - eps * d[i])))
                .collect();
            fp.iter_mut().for_each(|f| *f = [T::ZERO; 3]);
            fm.iter_mut().for_each(|f| *f = [T::ZERO; 3]);
            self.elements
                .internal_forces(&self.laws, &up, &mut fp)
                .map_err(|e| anyhow!("{e}"))?;
            self.elements
                .internal_forces(&self.laws, &um, &mut fm)
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
            v = w;
        }
        Ok(lambda.max(0.0).sqrt())
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
