//! `pe plan`: the cheapest model of a scene whose error against the full model stays within
//! an accuracy budget on the scene's quantities of interest, proved by running both.
//!
//! The reference is the scene as given (its mesh, level and solver settings). The
//! quantities of interest, sampled at [`trace::SAMPLES`] fixed times over the scene's
//! duration:
//! * the force of the tissue on each tool at the rates its consumers sample it: averaged
//!   over each millisecond (the haptic loop, [`trace::Trace::tool_force_haptic`]) and over
//!   each 40 ms (a graphics frame, [`trace::Trace::tool_force_graphics`]); error
//!   `max_k |F_k − F_ref,k| / max_k |F_ref,k|` over the windows, the worst tool, and the
//!   budget holds on both rates;
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

use crate::compile::partition::Machine;
use crate::problem::Problem;
use crate::scene::Scene;

mod array;
mod compare;
pub mod prune;
mod report;
mod search;
mod settings;
pub mod trace;
mod trim;

use array::{array_figures, ArrayFigures};
use compare::View;
pub use prune::{CellKind, Reduced};
pub use report::{BoardUse, PlanReport, Row};
use search::{search, Held, Model, Search};
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
        Ok(v) if scale == 1.0 && v >= 1.0 && v.is_finite() => bail!(
            "--budget {s:?}: a fraction of {v} is {}%: write {v}% for {v} percent (or a fraction below 1 such as 0.02)",
            v * 100.0
        ),
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
    let profile = pe_firmware::profile::BoardProfile::by_name(&opts.profile)
        .map_err(|e| anyhow::anyhow!("--profile: {e}"))?;
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
    let mut s = Search::start(
        name,
        dir,
        &p_ref,
        &opts.watch,
        machine,
        profile,
        opts.budget_rel,
    )?;
    let mut held = Held {
        model: Model::Full {
            scene: Box::new(scene.clone()),
        },
        problem: p_ref.clone(),
        trace: s.reference.clone(),
        view: View::Same,
    };
    if opts.budget_rel > 0.0 {
        search(&mut s, &mut held, &scene, &opts.watch)?;
    }
    let reduced = found_model(&held, &opts.watch)?;
    let (p_final, final_model, within_budget) =
        write_and_rerun(&s, &held, &reduced, opts.budget_rel, out)?;
    let (target_met, target_note, boards) =
        target_verdict(opts.target, &p_final, &final_model, within_budget, profile)?;
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

/// The model the search found, as the reduced model it is written as (a full model
/// rewritten on its own mesh file, nothing pruned).
fn found_model(held: &Held, watch: &[String]) -> Result<Reduced> {
    Ok(match &held.model {
        Model::Pruned(r) => (**r).clone(),
        Model::Full { scene: sc, .. } => {
            let d = prune::driven_nodes(&held.problem, watch)?;
            let pilot = prune::Pilot {
                motion_m: &held.trace.motion_m,
                energy_j: &held.trace.energy_j,
            };
            prune::prune(&held.problem, sc, pilot, &d, None)?
        }
    })
}

/// The model found, written under `out`, read back and run: its problem, its row (the
/// host's figures timed as `pe solve` runs it) and whether it is within the budget.
fn write_and_rerun(
    s: &Search<'_>,
    held: &Held,
    reduced: &Reduced,
    budget_rel: f64,
    out: &Path,
) -> Result<(Problem, Row, bool)> {
    let name = s.name;
    let header = format!(
        "# Written by `pe plan` from {name}: the cheapest model found within a budget of {}% (see plan.md).\n",
        100.0 * budget_rel
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
    Ok((p_final, final_model, within_budget))
}

/// Whether the final model meets the target, why (or why not), and, for an array, what
/// each of its boards runs.
fn target_verdict(
    target: Target,
    p_final: &Problem,
    final_model: &Row,
    within_budget: bool,
    profile: &pe_firmware::profile::BoardProfile,
) -> Result<(bool, String, Vec<BoardUse>)> {
    Ok(match target {
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
            } = array_figures(p_final, m, profile)?;
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
    })
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
        // A bare number of 1 or more is a budget of 100% or more: surely a percentage
        // without its sign.
        let e = parse_budget("2").expect_err("2").to_string();
        assert!(e.contains("200%") && e.contains("write 2%"), "{e}");
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
