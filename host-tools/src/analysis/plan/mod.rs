//! `pe plan`: the cheapest model of a scene whose error against the full model stays within
//! an accuracy budget on the scene's quantities of interest, proved by running both.
//!
//! The reference is the scene as given (its mesh, level and solver settings). The
//! quantities of interest, sampled at [`trace::SAMPLES`] fixed times over the scene's
//! duration:
//! * the force of the tissue on each tool, averaged over each sample window (see
//!   [`trace::Trace::tool_force`]): error `max_k |F_k − F_ref,k| / max_k |F_ref,k|`, the
//!   worst tool;
//! * the displacement of the touched surfaces (the nodes of every contact surface, the
//!   loaded nodes and any `--watch` node set; every node when the scene has none of them):
//!   error `max_{t,n} |u − u_ref| / max_{t,n} |u_ref|`. A node the model no longer
//!   simulates counts as not moving; on another mesh level the model's field is
//!   interpolated at the reference's nodes (those more than a quarter cell outside it are
//!   left out, and counted).
//!
//! The search is greedy, every step measured against the reference with everything
//! accepted before it, and a choice is accepted only when both errors stay within the
//! budget:
//! 1. resolution: a coarser built-in level (the coarsest that passes), or a voxel mesh
//!    coarsened 2x while it passes ([`crate::mesh::coarsen`]; the model's field read at
//!    the reference's nodes as for a level), then the model
//!    without each contact pair in turn (with the surfaces nothing else names): a pair that
//!    never touches costs every step for nothing;
//! 2. pruning: the elements whose motion and stored energy in the current model's run stay
//!    below a fraction of the largest (tried from 10% down to 0.01%; the first that passes
//!    is bisected towards the one before it), see [`prune`];
//! 3. contact surfaces cut down to the faces with a node that came within half (then one)
//!    longest face diagonal of a tool or of the paired surface in the current model's run
//!    (contact costs per surface node every step);
//! 4. solver settings: a longer step where the pruned model allows one (with contact,
//!    first keeping the contact stiffness, see [`PENALTY_MAX`]), mass scaling 16, then 4
//!    (the step grows by its root), then f32.
//!
//! The model found is written as `DIR/scene.toml` and `DIR/mesh.msh`, read back and run
//! again: the report's final error is that run's. Costs are element-steps per simulated
//! second (the model's cost on any machine), and from the schedule compiler on the target's
//! (or a 4x4x4) array: boards needed at 10 kHz and bytes exchanged per step.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use pe_firmware::image::Precision;
use serde::Serialize;

use crate::compile::partition::Machine;
use crate::geom::norm;
use crate::mesh::Mesh;
use crate::problem::{NodeKind, Problem};
use crate::scene::Scene;

pub mod prune;
mod report;
pub mod trace;

pub use prune::{CellKind, Reduced};
pub use trace::Trace;

/// What the plan must reach beside the budget.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// The cheapest model within the budget, nothing more.
    Cheapest,
    /// `pe solve` at a real-time factor of at least 1 on this machine.
    RealTime,
    /// The schedule compiler's verdict "keeps real time" on this array.
    Boards(Machine),
}

impl std::str::FromStr for Target {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Target> {
        match s {
            "cheapest" => Ok(Target::Cheapest),
            "real-time" => Ok(Target::RealTime),
            _ => match s.strip_prefix("boards=") {
                Some(m) => Ok(Target::Boards(
                    Machine::parse(m).map_err(|e| anyhow::anyhow!("--target {s:?}: {e}"))?,
                )),
                None => bail!(
                    "--target {s:?}: expected real-time, boards=XxYxZ (e.g. boards=4x4x4) or cheapest"
                ),
            },
        }
    }
}

/// `--budget`: "2%" or "0.02" as a fraction.
pub fn parse_budget(s: &str) -> Result<f64> {
    let (num, scale) = match s.trim().strip_suffix('%') {
        Some(n) => (n, 0.01),
        None => (s.trim(), 1.0),
    };
    match num.trim().parse::<f64>() {
        Ok(v) if v >= 0.0 && v.is_finite() => Ok(v * scale),
        _ => bail!("--budget {s:?}: expected a percentage such as 2% (or a fraction such as 0.02), at least 0"),
    }
}

/// Options of `pe plan`.
#[derive(Clone, Debug)]
pub struct Options {
    /// Largest relative error accepted on each quantity of interest (0.02 = 2%).
    pub budget_rel: f64,
    pub target: Target,
    /// Node sets of the mesh whose displacement is a quantity of interest too.
    pub watch: Vec<String>,
    /// Board profile the array's costs are computed for.
    pub profile: String,
}

/// One measured model: a row of the report.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// What this row tries ("reference", "level coarse", "prune below 1% of max |u|", ...).
    pub choice: String,
    /// Accepted into the plan (the reference and the final model are always "true").
    pub accepted: bool,
    pub elements: usize,
    pub nodes: usize,
    pub precision: String,
    pub mass_scaling: f64,
    pub dt_s: f64,
    pub steps: u64,
    pub element_steps_per_sim_s: f64,
    /// On the array (the target's, else 4x4x4) with the profile: compute-only boards
    /// needed at 10 kHz, bytes over all links per step, and the compiler's verdict.
    pub boards_needed_at_10_khz: Option<usize>,
    pub bytes_per_step: Option<usize>,
    pub array_keeps_real_time: Option<bool>,
    /// Wall time of the run on this machine, and simulated over wall time: the sampled
    /// runs record every step (slower than `pe solve`); the final model is timed as `pe
    /// solve` runs it (every core, no observer).
    pub host_wall_s: f64,
    pub host_real_time_factor: f64,
    /// Relative errors against the reference (0 for the reference).
    pub tool_force_err_rel: Option<f64>,
    pub displacement_err_rel: f64,
    /// Reference nodes the displacement error covers.
    pub compared_nodes: usize,
    /// Why it was refused (empty when accepted).
    pub note: String,
}

/// The whole plan (`DIR/plan.json`).
#[derive(Clone, Debug, Serialize)]
pub struct PlanReport {
    pub scene: String,
    pub budget_rel: f64,
    pub target: String,
    pub array: String,
    pub profile: String,
    /// What the errors measure.
    pub quantities: Vec<String>,
    pub samples: usize,
    pub rows: Vec<Row>,
    /// The written model, read back from `DIR/scene.toml` and run.
    pub final_model: Row,
    pub within_budget: bool,
    /// Reference cost over the final model's, in element-steps per simulated second.
    pub saving_factor: f64,
    pub target_met: bool,
    pub target_note: String,
    /// Per board of the final model on the array: elements, nodes, contact nodes, loads.
    pub boards: Vec<BoardUse>,
    pub pruned_elements: usize,
    pub held_nodes: usize,
    pub files: Vec<String>,
}

/// What one board runs in the final model.
#[derive(Clone, Debug, Serialize)]
pub struct BoardUse {
    pub board: [usize; 3],
    pub elements: usize,
    pub nodes: usize,
    pub runs: String,
}

/// How a candidate's field is read at the reference's nodes.
#[derive(Clone)]
enum View {
    /// The reference's own mesh, every node simulated.
    Same,
    /// The reference's mesh pruned: reference node → model node (None: not simulated).
    Pruned(Vec<Option<u32>>),
    /// Another mesh (level), maybe pruned: that level's full mesh and its node → model node.
    Level {
        mesh: Mesh,
        node_map: Option<Vec<Option<u32>>>,
    },
}

impl View {
    /// The same view after pruning the model it reads with `map` (model node → pruned).
    fn then_pruned(&self, map: &[Option<u32>]) -> View {
        let compose = |m: Option<&Vec<Option<u32>>>| -> Vec<Option<u32>> {
            match m {
                None => map.to_vec(),
                Some(m) => m.iter().map(|o| o.and_then(|k| map[k as usize])).collect(),
            }
        };
        match self {
            View::Same => View::Pruned(map.to_vec()),
            View::Pruned(m) => View::Pruned(compose(Some(m))),
            View::Level { mesh, node_map } => View::Level {
                mesh: mesh.clone(),
                node_map: Some(compose(node_map.as_ref())),
            },
        }
    }
}

/// The errors of `cand` (read through `view`) against `reference` on `watched` nodes.
fn errors(
    reference: &Trace,
    ref_mesh: &Mesh,
    watched: &[usize],
    cand: &Trace,
    view: &View,
) -> (Option<f64>, f64, usize) {
    let force = (!reference.tool_force.is_empty()).then(|| {
        reference
            .tool_force
            .iter()
            .zip(&cand.tool_force)
            .map(|(r, c)| {
                let scale = r.iter().map(|f| norm(*f)).fold(0.0, f64::max);
                let e = r
                    .iter()
                    .zip(c)
                    .map(|(a, b)| norm(core::array::from_fn(|i| a[i] - b[i])))
                    .fold(0.0, f64::max);
                e / scale.max(1e-300)
            })
            .fold(0.0, f64::max)
    });
    let interp_mesh = match view {
        View::Level { mesh, .. } => Some(crate::analysis::tradeoff::Interpolator::new(mesh)),
        _ => None,
    };
    let (mut emax, mut umax, mut compared) = (0.0f64, 0.0f64, vec![false; watched.len()]);
    for (s, ur) in reference.u.iter().enumerate() {
        let uc = &cand.u[s];
        let expanded: Option<Vec<[f64; 3]>> = match view {
            View::Level {
                mesh,
                node_map: Some(m),
            } => Some(
                (0..mesh.nodes.len())
                    .map(|n| m[n].map(|k| uc[k as usize]).unwrap_or([0.0; 3]))
                    .collect(),
            ),
            _ => None,
        };
        for (w, &n) in watched.iter().enumerate() {
            let got = match view {
                View::Same => Some(uc[n]),
                View::Pruned(m) => Some(m[n].map(|k| uc[k as usize]).unwrap_or([0.0; 3])),
                View::Level { .. } => interp_mesh
                    .as_ref()
                    .and_then(|i| i.at(expanded.as_deref().unwrap_or(uc), ref_mesh.nodes[n])),
            };
            umax = umax.max(norm(ur[n]));
            if let Some(g) = got {
                compared[w] = true;
                emax = emax.max(norm(core::array::from_fn(|i| g[i] - ur[n][i])));
            }
        }
    }
    (
        force,
        emax / umax.max(1e-300),
        compared.iter().filter(|&&c| c).count(),
    )
}

/// The model the search holds: a scene on a full mesh, or a pruned one.
#[derive(Clone)]
enum Model {
    Full { scene: Box<Scene> },
    Pruned(Box<Reduced>),
}

struct Held {
    model: Model,
    problem: Problem,
    trace: Trace,
    view: View,
}

impl Held {
    /// The scene of a model nothing has pruned yet (the scene as given, or on a coarsened
    /// mesh of its own), which pruning starts from; `None` once pruned or trimmed.
    fn unpruned_scene(&self) -> Option<Scene> {
        match &self.model {
            Model::Full { scene } => Some((**scene).clone()),
            Model::Pruned(r) if r.fraction.is_none() && r.coarsened => Some(r.scene.clone()),
            Model::Pruned(_) => None,
        }
    }
}

/// A problem on an array, from the schedule compiler.
struct ArrayFigures {
    boards_needed_at_10_khz: usize,
    bytes_per_step: usize,
    keeps_real_time: bool,
    /// Why not, from the compiler's verdict.
    reasons: Vec<String>,
    boards: Vec<BoardUse>,
}

/// Array figures of a problem: boards needed at 10 kHz, bytes per step, real time, and
/// each board's use.
fn array_figures(
    p: &Problem,
    machine: Machine,
    profile: &pe_firmware::profile::BoardProfile,
) -> Result<ArrayFigures> {
    // The schedule `pe compile` would make (the better of the two balances).
    let (plan, images, other) = crate::compile::plan_for_real_time(p, machine, profile)?;
    let mut r = crate::compile::report("plan", p, &plan, &images, profile)?;
    r.balance_other = other;
    let boards = plan
        .boards
        .iter()
        .zip(&r.boards)
        .map(|(b, s)| {
            let contact = p.contact.as_ref().map_or(0, |c| {
                c.node_globals
                    .iter()
                    .filter(|n| b.nodes.binary_search(n).is_ok())
                    .count()
            });
            let loads = p
                .loads
                .iter()
                .filter(|l| b.nodes.binary_search(&l.node).is_ok())
                .count();
            let mut runs = vec![format!("{} elements", s.elements)];
            if contact > 0 {
                runs.push(format!("contact on {contact} nodes"));
            }
            if loads > 0 {
                runs.push(format!("loads on {loads} nodes"));
            }
            if s.elements == 0 {
                runs = vec!["idle (no element)".into()];
            }
            BoardUse {
                board: s.board,
                elements: s.elements,
                nodes: s.nodes,
                runs: runs.join(", "),
            }
        })
        .collect();
    Ok(ArrayFigures {
        boards_needed_at_10_khz: r.capacity.boards_needed_at_10_khz,
        bytes_per_step: r.bytes_per_step_total,
        keeps_real_time: r.real_time.keeps_real_time,
        reasons: r.real_time.reasons.clone(),
        boards,
    })
}

/// The search's context.
struct Search<'a> {
    name: &'a str,
    dir: &'a Path,
    reference: Trace,
    ref_mesh: Mesh,
    watched: Vec<usize>,
    machine: Machine,
    profile: &'a pe_firmware::profile::BoardProfile,
    budget: f64,
    rows: Vec<Row>,
}

impl Search<'_> {
    fn row(&self, choice: &str, p: &Problem, t: &Trace, view: &View) -> Result<Row> {
        let (force, disp, compared) =
            errors(&self.reference, &self.ref_mesh, &self.watched, t, view);
        let (boards, bytes, rt) = match array_figures(p, self.machine, self.profile) {
            Ok(a) => (
                Some(a.boards_needed_at_10_khz),
                Some(a.bytes_per_step),
                Some(a.keeps_real_time),
            ),
            Err(_) => (None, None, None),
        };
        let within = force.is_none_or(|f| f <= self.budget) && disp <= self.budget;
        Ok(Row {
            choice: choice.into(),
            accepted: within,
            elements: t.elements,
            nodes: t.nodes,
            precision: p.solver.precision.name().into(),
            mass_scaling: p.solver.mass_scaling,
            dt_s: t.dt_s,
            steps: t.steps,
            element_steps_per_sim_s: t.element_steps_per_sim_s,
            boards_needed_at_10_khz: boards,
            bytes_per_step: bytes,
            array_keeps_real_time: rt,
            host_wall_s: t.wall_s,
            host_real_time_factor: t.simulated_s / t.wall_s.max(1e-12),
            tool_force_err_rel: force,
            displacement_err_rel: disp,
            compared_nodes: compared,
            note: if within {
                String::new()
            } else {
                format!("over the budget of {:.3}%", 100.0 * self.budget)
            },
        })
    }

    /// Records a choice that did not run to the end (or was not run), and why: its mesh,
    /// and the settings of its problem when it has one.
    fn not_run(&mut self, choice: &str, mesh: &Mesh, p: Option<&Problem>, why: String) {
        self.rows.push(Row {
            choice: choice.into(),
            accepted: false,
            elements: mesh.cells.len(),
            nodes: mesh.nodes.len(),
            precision: p.map_or(String::new(), |p| p.solver.precision.name().into()),
            mass_scaling: p.map_or(0.0, |p| p.solver.mass_scaling),
            dt_s: p.map_or(0.0, |p| p.time_step.dt_s),
            steps: 0,
            element_steps_per_sim_s: 0.0,
            boards_needed_at_10_khz: None,
            bytes_per_step: None,
            array_keeps_real_time: None,
            host_wall_s: 0.0,
            host_real_time_factor: 0.0,
            tool_force_err_rel: None,
            displacement_err_rel: f64::NAN,
            compared_nodes: 0,
            note: why,
        });
    }

    /// Runs `p`, measures it, records the row; the trace when it is accepted.
    fn try_model(&mut self, choice: &str, p: &Problem, view: &View) -> Result<Option<Trace>> {
        eprintln!("plan: {choice}: {} elements", p.mesh.cells.len());
        let t = match trace::run(p, &format!("{} [{choice}]", self.name)) {
            Ok(t) => t,
            Err(e) => {
                self.not_run(choice, &p.mesh, Some(p), format!("the run failed: {e:#}"));
                return Ok(None);
            }
        };
        let row = self.row(choice, p, &t, view)?;
        let ok = row.accepted;
        self.rows.push(row);
        Ok(ok.then_some(t))
    }
}

/// The nodes whose displacement is a quantity of interest: contact surfaces, loaded nodes
/// and watched sets (not prescribed ones: they move as told); every node if none.
fn watched_nodes(p: &Problem, driven: &[bool]) -> Vec<usize> {
    let w: Vec<usize> = (0..p.mesh.nodes.len())
        .filter(|&n| driven[n] && !matches!(p.node_kind[n], NodeKind::Prescribed(_)))
        .collect();
    if w.is_empty() {
        (0..p.mesh.nodes.len()).collect()
    } else {
        w
    }
}

/// Pruning tolerances, as fractions of the current model's largest motion, tried in order.
pub const PRUNE_FRACTIONS: [f64; 7] = [0.1, 0.03, 0.01, 3e-3, 1e-3, 3e-4, 1e-4];
/// Largest contact penalty fraction a longer step may raise β to (at dt_safety 0.9 the
/// stiffest mode leaves room for about 0.7).
pub const PENALTY_MAX: f64 = 0.6;
/// Bisections between the first fraction that passes and the one before it.
pub const PRUNE_BISECTIONS: usize = 2;
/// Mass scalings tried, in order.
pub const MASS_SCALINGS: [f64; 2] = [16.0, 4.0];

/// Finds the plan and writes it under `out`.
pub fn run(
    scene: &Scene,
    dir: &Path,
    name: &str,
    opts: &Options,
    out: &Path,
) -> Result<PlanReport> {
    if !(opts.budget_rel >= 0.0 && opts.budget_rel.is_finite()) {
        bail!(
            "--budget must be a percentage >= 0, got {}",
            100.0 * opts.budget_rel
        );
    }
    let profile = pe_firmware::profile::profile(&opts.profile)
        .with_context(|| format!("--profile {:?}: not a known board profile", opts.profile))?;
    let machine = match opts.target {
        Target::Boards(m) => m,
        _ => Machine::new([4, 4, 4]).expect("a machine of 1..16 boards per axis"),
    };
    let mut scene = scene.clone();
    // Candidates change dt: hold the simulated time fixed, not the step count.
    Problem::hold_duration(&mut scene, dir)?;
    scene.solver.dt = None;
    let p_ref = Problem::from_scene(&scene, dir).with_context(|| format!("scene {name}"))?;
    p_ref.print_notes();
    let driven = prune::driven_nodes(&p_ref, &opts.watch)?;
    let watched = watched_nodes(&p_ref, &driven);
    eprintln!("plan: reference: {} elements", p_ref.mesh.cells.len());
    let reference = trace::run(&p_ref, &format!("{name} [reference]"))?;
    let mut s = Search {
        name,
        dir,
        reference: reference.clone(),
        ref_mesh: p_ref.mesh.clone(),
        watched,
        machine,
        profile: &profile,
        budget: opts.budget_rel,
        rows: Vec::new(),
    };
    let ref_row = s.row(
        "reference (the scene as given)",
        &p_ref,
        &reference,
        &View::Same,
    )?;
    s.rows.push(ref_row);
    let mut held = Held {
        model: Model::Full {
            scene: Box::new(scene.clone()),
        },
        problem: p_ref.clone(),
        trace: reference,
        view: View::Same,
    };
    if opts.budget_rel > 0.0 {
        search(&mut s, &mut held, &scene, &opts.watch)?;
    }
    // The model found, written and read back.
    let reduced = match &held.model {
        Model::Pruned(r) => (**r).clone(),
        Model::Full { scene: sc, .. } => {
            let d = prune::driven_nodes(&held.problem, &opts.watch)?;
            let pilot = prune::Pilot {
                motion_m: &held.trace.motion_m,
                energy_j: &held.trace.energy_j,
            };
            prune::prune(&held.problem, sc, pilot, &d, None)?
        }
    };
    let header = format!(
        "# Written by `pe plan` from {name}: the cheapest model found within a budget of {}% (see plan.md).\n",
        100.0 * opts.budget_rel
    );
    reduced.write(out, &header)?;
    let written = out.join("scene.toml");
    let sc = Scene::from_file(&written)?;
    let p_final = Problem::from_scene(&sc, out)
        .with_context(|| format!("reading back {}", written.display()))?;
    if p_final.mesh.cells != reduced.mesh.cells || p_final.mesh.nodes != reduced.mesh.nodes {
        bail!(
            "internal: {} does not read back as the model planned",
            written.display()
        );
    }
    let t_final = trace::run(&p_final, &format!("{name} [planned, read back]"))?;
    // A pruned model's view already reads through its map; a full one is rewritten as is.
    let final_view = match &held.model {
        Model::Pruned(_) => held.view.clone(),
        Model::Full { .. } => held.view.then_pruned(&reduced.node_map),
    };
    let mut final_model = s.row(
        "the written model, read back and run",
        &p_final,
        &t_final,
        &final_view,
    )?;
    let within_budget = final_model.accepted;
    final_model.accepted = true;
    // The sampled runs record every step; the final model's speed is timed as `pe solve`
    // runs it: no observer, every core.
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let timed = crate::solver::run_threads(
        &p_final,
        &format!("{name} [planned, timed]"),
        &mut (),
        cores,
    )?;
    final_model.host_wall_s = timed.report.wall_s;
    final_model.host_real_time_factor = timed.report.real_time_factor;
    let (target_met, target_note, boards) = match opts.target {
        Target::Cheapest => (
            within_budget,
            "the cheapest model within the budget".into(),
            vec![],
        ),
        Target::RealTime => {
            let rtf = final_model.host_real_time_factor;
            (
                rtf >= 1.0,
                format!("`pe solve` on this machine: real-time factor {rtf:.2} (>= 1 needed)"),
                vec![],
            )
        }
        Target::Boards(m) => {
            let ArrayFigures {
                keeps_real_time: rt,
                reasons,
                boards,
                ..
            } = array_figures(&p_final, m, &profile)?;
            let note = if rt {
                format!(
                    "`pe compile --boards {m} --profile {}`: keeps real time",
                    profile.name
                )
            } else {
                format!(
                    "`pe compile --boards {m} --profile {}`: does not keep real time: {}",
                    profile.name,
                    reasons.join("; ")
                )
            };
            (rt, note, boards)
        }
    };
    let report = PlanReport {
        scene: name.into(),
        budget_rel: opts.budget_rel,
        target: match opts.target {
            Target::Cheapest => "cheapest".into(),
            Target::RealTime => "real-time".into(),
            Target::Boards(m) => format!("boards={m}"),
        },
        array: machine.to_string(),
        profile: profile.name.into(),
        quantities: quantities(&p_ref, &s.reference, &s.watched),
        samples: trace::SAMPLES,
        saving_factor: s.rows[0].element_steps_per_sim_s
            / final_model.element_steps_per_sim_s.max(1e-300),
        rows: s.rows,
        final_model,
        within_budget,
        target_met,
        target_note,
        boards,
        pruned_elements: reduced
            .cell_kind
            .iter()
            .filter(|k| **k == CellKind::Pruned)
            .count(),
        held_nodes: reduced.held_nodes,
        files: vec![],
    };
    let report = report::write(report, &held, &reduced, out)?;
    Ok(report)
}

fn quantities(p: &Problem, t: &Trace, watched: &[usize]) -> Vec<String> {
    let mut q: Vec<String> = t
        .tool_names
        .iter()
        .map(|n| format!("force of the tissue on tool {n:?} over time"))
        .collect();
    let what = if watched.len() == p.mesh.nodes.len() {
        "every node (the scene has no contact surface, load or watched set)".to_string()
    } else {
        format!(
            "{} nodes of the contact surfaces, loads and watched sets",
            watched.len()
        )
    };
    q.push(format!("displacement over time of {what}"));
    q
}

/// Contact-surface margins tried, in longest face diagonals of the contact surfaces.
pub const TRIM_FACE_DIAMETERS: [f64; 2] = [0.5, 1.0];

/// Distance (m) from `x` to the capsule `a`–`b` of radius `r` (negative inside).
fn capsule_distance(x: [f64; 3], a: [f64; 3], b: [f64; 3], r: f64) -> f64 {
    let ab: [f64; 3] = core::array::from_fn(|i| b[i] - a[i]);
    let ax: [f64; 3] = core::array::from_fn(|i| x[i] - a[i]);
    let l2 = ab.iter().map(|v| v * v).sum::<f64>();
    let t = if l2 > 0.0 {
        (ax.iter().zip(&ab).map(|(p, q)| p * q).sum::<f64>() / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    norm(core::array::from_fn(|i| ax[i] - t * ab[i])) - r
}

/// The held model with each contact surface cut down to its faces with a node that came
/// within `k` longest face diagonals of a tool of the surface or of a node of the surface
/// it pairs with, at a sample of the held model's run (a face is kept whole: the other
/// side's nodes meet it anywhere on it); measured. None when it changes nothing or would
/// leave a surface without a face.
fn try_trim(s: &mut Search<'_>, held: &Held, watch: &[String], k: f64) -> Result<Option<Held>> {
    let p = &held.problem;
    let Some(c) = &p.contact else {
        return Ok(None);
    };
    let (mut r, view) = match (&held.model, held.unpruned_scene()) {
        (Model::Pruned(r), None) => ((**r).clone(), held.view.clone()),
        (_, Some(scene)) => {
            let d = prune::driven_nodes(p, watch)?;
            let pilot = prune::Pilot {
                motion_m: &held.trace.motion_m,
                energy_j: &held.trace.energy_j,
            };
            let r = prune::prune(p, &scene, pilot, &d, None)?;
            let v = held.view.then_pruned(&r.node_map);
            (r, v)
        }
        // (A full model is its scene: not reached.)
        (Model::Full { .. }, None) => return Ok(None),
    };
    let margin = k * c.face_diameter_max_m;
    let at = |n: usize, smp: usize| -> [f64; 3] {
        core::array::from_fn(|i| p.mesh.nodes[n][i] + held.trace.u[smp][n][i])
    };
    let nodes_of = |si: usize| -> Vec<usize> {
        let mut v: Vec<usize> = c.surfaces[si]
            .faces
            .iter()
            .flat_map(|(q, _)| q.iter().map(|&n| n as usize))
            .collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    let mut near = vec![f64::INFINITY; p.mesh.nodes.len()];
    for (si, _) in c.surfaces.iter().enumerate() {
        let mine = nodes_of(si);
        for smp in 0..held.trace.u.len() {
            let t = held.trace.times_s[smp];
            for tool in c.tools.iter().filter(|t| t.surface as usize == si) {
                let d = p.paths[tool.path as usize].at(t);
                let a: [f64; 3] = core::array::from_fn(|i| tool.capsule.a[i] + d[i]);
                let b: [f64; 3] = core::array::from_fn(|i| tool.capsule.b[i] + d[i]);
                for &n in &mine {
                    near[n] =
                        near[n].min(capsule_distance(at(n, smp), a, b, tool.capsule.radius_m));
                }
            }
            for pair in &c.pairs {
                let other = match (pair.a as usize, pair.b as usize) {
                    (a, b) if a == si => b,
                    (a, b) if b == si => a,
                    _ => continue,
                };
                let theirs: Vec<[f64; 3]> = nodes_of(other).iter().map(|&n| at(n, smp)).collect();
                for &n in &mine {
                    let x = at(n, smp);
                    for y in &theirs {
                        near[n] = near[n].min(norm(core::array::from_fn(|i| x[i] - y[i])));
                    }
                }
            }
        }
    }
    let mut dropped = 0usize;
    for (si, surf) in c.surfaces.iter().enumerate() {
        let kept: Vec<u32> = {
            let mut v: Vec<u32> = surf
                .faces
                .iter()
                .filter(|(q, _)| q.iter().any(|&n| near[n as usize] <= margin))
                .flat_map(|(q, _)| q.iter().copied())
                .collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        if kept.is_empty() {
            return Ok(None);
        }
        dropped += nodes_of(si).len() - kept.len();
        r.node_sets.insert(format!("plan_surface_{si}"), kept);
    }
    if dropped == 0 {
        return Ok(None);
    }
    let q = r.problem()?;
    let kept_nodes = q.contact.as_ref().map_or(0, |c| c.node_globals.len());
    let choice = format!(
        "contact surfaces cut to what came within {k} face diagonals ({:.2} mm) of a tool or the paired surface: {kept_nodes} contact nodes of {}",
        1e3 * margin,
        c.node_globals.len()
    );
    Ok(s.try_model(&choice, &q, &view)?.map(|t| Held {
        model: Model::Pruned(Box::new(r)),
        problem: q,
        trace: t,
        view,
    }))
}

/// What one pruning fraction gave.
enum Pruning {
    Passed(Box<Held>),
    Failed,
    /// The same elements as a fraction tried before.
    Same,
    /// Nothing to prune.
    Whole,
}

fn try_prune(
    s: &mut Search<'_>,
    held: &Held,
    sc: &Scene,
    driven: &[bool],
    f: f64,
    tried: &mut Vec<usize>,
) -> Result<Pruning> {
    let pilot = prune::Pilot {
        motion_m: &held.trace.motion_m,
        energy_j: &held.trace.energy_j,
    };
    let mut r = prune::prune(&held.problem, sc, pilot, driven, Some(f))?;
    let n = r.mesh.cells.len();
    if n >= held.problem.mesh.cells.len() {
        return Ok(Pruning::Whole);
    }
    if tried.contains(&n) {
        return Ok(Pruning::Same);
    }
    tried.push(n);
    // The step stays the model's: the contact penalty follows from it (the pruned mesh may
    // allow a longer one, tried with the settings).
    r.scene.solver.dt = Some(held.problem.time_step.dt_s);
    let p = r.problem()?;
    let view = held.view.then_pruned(&r.node_map);
    let choice = format!(
        "prune where motion and energy stay below {:.3}% of their largest: {n} elements, {} held nodes",
        100.0 * f,
        r.held_nodes
    );
    Ok(match s.try_model(&choice, &p, &view)? {
        Some(t) => Pruning::Passed(Box::new(Held {
            model: Model::Pruned(Box::new(r)),
            problem: p,
            trace: t,
            view,
        })),
        None => Pruning::Failed,
    })
}

/// The greedy search: level, pruning, settings.
fn search(s: &mut Search<'_>, held: &mut Held, scene: &Scene, watch: &[String]) -> Result<()> {
    // 1. Resolution: a coarser built-in level.
    if let Some(level) = scene.mesh.builtin.as_ref().and(scene.mesh.level.as_deref()) {
        let levels = ["coarse", "medium", "fine"];
        let at = levels.iter().position(|l| *l == level).unwrap_or(0);
        for lv in &levels[..at] {
            let mut sc = scene.clone();
            sc.mesh.level = Some((*lv).into());
            let p = Problem::from_scene(&sc, s.dir)?;
            let view = View::Level {
                mesh: p.mesh.clone(),
                node_map: None,
            };
            if let Some(t) = s.try_model(&format!("level {lv}"), &p, &view)? {
                *held = Held {
                    model: Model::Full {
                        scene: Box::new(sc),
                    },
                    problem: p,
                    trace: t,
                    view,
                };
                break;
            }
        }
    }
    // 1a. Resolution of a user mesh: a voxel mesh coarsened 2x, again while it passes.
    if scene.mesh.builtin.is_none() {
        try_coarsen(s, held, scene)?;
    }
    // 1b. Contact pairs the scene's quantities do not need (a pair that never touches, or
    // whose force the budget can do without), before the pilot run pruning reads.
    drop_pairs(s, held)?;
    // 2. Pruning: the first fraction that passes, then bisected (geometric mean) towards
    // the last that failed.
    if let Some(sc) = held.unpruned_scene() {
        let driven = prune::driven_nodes(&held.problem, watch)?;
        let mut tried: Vec<usize> = Vec::new();
        let mut failed: Option<f64> = None;
        let mut passed: Option<(f64, Box<Held>)> = None;
        for f in PRUNE_FRACTIONS {
            match try_prune(s, held, &sc, &driven, f, &mut tried)? {
                Pruning::Passed(h) => {
                    passed = Some((f, h));
                    break;
                }
                Pruning::Failed => failed = Some(f),
                Pruning::Same => {}
                Pruning::Whole => break,
            }
        }
        if let (Some(mut hi), Some((mut lo, _))) = (failed, passed.as_ref().map(|p| (p.0, ()))) {
            for _ in 0..PRUNE_BISECTIONS {
                let mid = (hi * lo).sqrt();
                match try_prune(s, held, &sc, &driven, mid, &mut tried)? {
                    Pruning::Passed(h) => {
                        lo = mid;
                        passed = Some((mid, h));
                    }
                    Pruning::Failed => hi = mid,
                    Pruning::Same | Pruning::Whole => break,
                }
            }
        }
        if let Some((_, h)) = passed {
            *held = *h;
        }
    }
    // 2b. Contact surfaces trimmed to what came near the tool or the other surface.
    if held.problem.contact.is_some() {
        for k in TRIM_FACE_DIAMETERS {
            if let Some(h) = try_trim(s, held, watch, k)? {
                *held = h;
                break;
            }
        }
    }
    // 3. Solver settings on the model held.
    type Tweak = Box<dyn Fn(&mut Scene)>;
    let mut tweaks: Vec<(String, Tweak)> = Vec::new();
    // A longer step where the model allows it. With contact, the penalty is a fraction β of
    // m/dt²: the first try keeps the contact stiffness (β grows with dt², up to
    // PENALTY_MAX), the second takes the model's own critical step with the scene's β.
    let (dt, ts) = (held.problem.time_step.dt_s, held.problem.time_step);
    let longest = held.problem.solver.dt_safety * ts.critical.dt_critical_s;
    if let Some(beta) = held.problem.contact.as_ref().map(|c| c.settings.penalty) {
        let dt_new = longest.min(dt * (PENALTY_MAX / beta).sqrt());
        if dt_new > 1.02 * dt {
            let beta_new = beta * (dt_new / dt).powi(2);
            tweaks.push((
                format!("a {:.2}x longer step, the contact stiffness kept (penalty {beta} -> {beta_new:.3})", dt_new / dt),
                Box::new(move |sc: &mut Scene| {
                    sc.solver.dt = Some(dt_new);
                    if let Some(c) = &mut sc.contact {
                        c.penalty = beta_new;
                    }
                }),
            ));
        }
    }
    if longest > 1.02 * dt {
        tweaks.push((
            "the step from the model's own critical step".to_string(),
            Box::new(|sc: &mut Scene| sc.solver.dt = None),
        ));
    }
    for m in MASS_SCALINGS {
        tweaks.push((
            format!("mass scaling {m}"),
            Box::new(move |sc: &mut Scene| {
                sc.solver.mass_scaling = m;
                sc.solver.dt = None;
            }),
        ));
    }
    tweaks.push((
        "precision f32".to_string(),
        Box::new(|sc: &mut Scene| sc.solver.precision = Precision::F32),
    ));
    let mut longer = false;
    let mut scaled = false;
    for (choice, apply) in tweaks {
        if scaled && choice.starts_with("mass") {
            continue;
        }
        let cur = match &held.model {
            Model::Full { scene, .. } => scene.solver.clone(),
            Model::Pruned(r) => r.scene.solver.clone(),
        };
        if choice == "precision f32" && cur.precision == Precision::F32 {
            continue;
        }
        if (choice.starts_with("the step") || choice.starts_with("a "))
            && (longer || cur.dt.is_none())
        {
            continue;
        }
        if choice.starts_with("mass") && cur.mass_scaling != 1.0 {
            continue;
        }
        let mut model = held.model.clone();
        let p = match &mut model {
            Model::Full { scene, .. } => {
                apply(scene);
                Problem::from_scene(scene, s.dir)?
            }
            Model::Pruned(r) => {
                apply(&mut r.scene);
                r.problem()?
            }
        };
        let view = held.view.clone();
        if let Some(t) = s.try_model(&choice, &p, &view)? {
            scaled |= choice.starts_with("mass");
            longer |= choice.starts_with("a ") || choice.starts_with("the step");
            *held = Held {
                model,
                problem: p,
                trace: t,
                view,
            };
        }
    }
    Ok(())
}

/// Resolution of a user mesh: a voxel mesh ([`crate::mesh::coarsen`]) coarsened 2x, and
/// again while the coarser model stays within the budget. Each try is a row, with what the
/// coarsening changed; a coarse mesh the scene cannot be set on (a node set it names left
/// empty) is a row that says so, not run.
fn try_coarsen(s: &mut Search<'_>, held: &mut Held, scene: &Scene) -> Result<()> {
    if !matches!(held.model, Model::Full { .. }) {
        return Ok(());
    }
    let mut mesh = held.problem.mesh.clone();
    while let Some(c) = crate::mesh::coarsen::coarsen(&mesh) {
        let choice = format!(
            "voxels coarsened 2x ({:.2} to {:.2} mm): {} elements of {}, volume {:.3}x ({} fine cells left out, {} added, {} loose coarse cells left out)",
            1e3 * c.h_fine_m,
            1e3 * c.h_coarse_m,
            c.mesh.cells.len(),
            mesh.cells.len(),
            c.volume_ratio(mesh.cells.len()),
            c.fine_cells_left_out,
            c.fine_cells_added,
            c.loose_cells_left_out
        );
        let r = Reduced::coarsened(scene, c.mesh.clone());
        let p = match r.problem() {
            Ok(p) => p,
            Err(e) => {
                s.not_run(
                    &choice,
                    &c.mesh,
                    None,
                    format!("the scene does not fit the coarse mesh: {e:#}"),
                );
                break;
            }
        };
        let view = View::Level {
            mesh: c.mesh.clone(),
            node_map: None,
        };
        let Some(t) = s.try_model(&choice, &p, &view)? else {
            break;
        };
        *held = Held {
            model: Model::Pruned(Box::new(r)),
            problem: p,
            trace: t,
            view,
        };
        mesh = c.mesh;
    }
    Ok(())
}

/// Tries the held model without each of its contact pairs (and the surfaces nothing else
/// names), one at a time, keeping each removal the budget allows.
fn drop_pairs(s: &mut Search<'_>, held: &mut Held) -> Result<()> {
    let Model::Full { scene } = &held.model else {
        return Ok(());
    };
    let mut i = 0;
    let mut sc = (**scene).clone();
    while i < sc.contact_pair.len() {
        let mut without = sc.clone();
        let [a, b] = without.contact_pair.remove(i).surfaces;
        drop_unused_surfaces(&mut without);
        let p = Problem::from_scene(&without, s.dir)?;
        let choice = format!("without the contact pair {a:?}-{b:?}");
        match s.try_model(&choice, &p, &held.view)? {
            Some(t) => {
                sc = without.clone();
                *held = Held {
                    model: Model::Full {
                        scene: Box::new(without),
                    },
                    problem: p,
                    trace: t,
                    view: held.view.clone(),
                };
            }
            None => i += 1,
        }
    }
    Ok(())
}

/// Removes the `[[surface]]`s no tool or contact pair names (their nodes would still be
/// contact nodes, paid for on every board that holds them), and `[contact]` with the last.
fn drop_unused_surfaces(sc: &mut Scene) {
    let used = |name: &str| {
        sc.tool.iter().any(|t| t.surface == name)
            || sc
                .contact_pair
                .iter()
                .any(|p| p.surfaces.iter().any(|s| s == name))
    };
    let keep: Vec<bool> = sc.surface.iter().map(|s| used(&s.name)).collect();
    let mut k = keep.iter();
    sc.surface.retain(|_| k.next().copied().unwrap_or(true));
    if sc.surface.is_empty() {
        sc.contact = None;
    }
}

/// `pe plan`: plans, writes `out/`, prints the summary.
pub fn run_cli(scene: &Scene, dir: &Path, name: &str, opts: &Options, out: &Path) -> Result<()> {
    let r = run(scene, dir, name, opts, out)?;
    println!("{}", report::summary(&r));
    Ok(())
}

/// Where `pe plan` writes its files.
pub fn files(out: &Path) -> Vec<PathBuf> {
    [
        "scene.toml",
        prune::MESH_FILE,
        "plan.md",
        "plan.json",
        "plan.png",
    ]
    .iter()
    .map(|f| out.join(f))
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budgets_read_as_percentages_or_fractions_and_bad_ones_are_named() {
        assert_eq!(parse_budget("2%").ok(), Some(0.02));
        assert_eq!(parse_budget("0.5 %").ok(), Some(0.005));
        assert_eq!(parse_budget("0.02").ok(), Some(0.02));
        assert_eq!(parse_budget("0").ok(), Some(0.0));
        for bad in ["-1%", "two", "nan", "inf%", ""] {
            let e = parse_budget(bad).expect_err(bad).to_string();
            assert!(e.contains("--budget"), "{bad}: {e}");
        }
    }

    #[test]
    fn targets_parse_and_bad_ones_are_named() {
        assert_eq!("real-time".parse::<Target>().ok(), Some(Target::RealTime));
        assert_eq!("cheapest".parse::<Target>().ok(), Some(Target::Cheapest));
        assert_eq!(
            "boards=2x3x4".parse::<Target>().ok(),
            Some(Target::Boards(
                Machine::new([2, 3, 4]).expect("a machine of 1..16 boards per axis")
            ))
        );
        for bad in ["boards", "boards=4x4", "fast"] {
            let e = bad.parse::<Target>().expect_err(bad).to_string();
            assert!(
                e.contains("--target") || e.contains("--boards"),
                "{bad}: {e}"
            );
        }
    }
}
