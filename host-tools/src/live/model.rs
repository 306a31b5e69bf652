//! Which model `pe live` serves: the scene's full model where it keeps real time on this
//! machine, else the model `pe plan --target real-time` finds for it (`--plan DIR`).
//!
//! The full model is probed first: stepped unpaced on the session's threads for
//! [`PROBE_WALL_S`] of wall time (after [`WARM_UP_STEPS`] steps), from the scene's start,
//! its real-time factor measured. At `--min-rtf` or more (default 1.2: headroom for the
//! frames and the clients the session serves on the same cores) it is served. Below, the
//! plan in `DIR` is: `DIR/scene.toml` as `pe plan` wrote it, when `DIR/plan.json` says it
//! was planned for this scene; else it is planned there first (`pe plan SCENE --budget B
//! --target real-time -o DIR`: minutes, once). Its speed is probed too; a plan that still
//! cannot keep up is served all the same, and said so (the session then follows its
//! falling-behind policy). The page shows which model runs and why: the hello's and every
//! status's `model` line begins with `full model` or `planned model`.
//!
//! Without `--plan`, the full model is served, and a warning says how far from real time
//! it probed and how to get a plan.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

use super::solver_engine::solver_engine;
use crate::analysis::plan::{self, PlanReport, Target};
use crate::problem::Problem;
use crate::scene::Scene;

/// Wall time the probe steps a model for (s).
pub const PROBE_WALL_S: f64 = 1.0;
/// Steps before the probe's clock starts (caches, thread start-up).
pub const WARM_UP_STEPS: u64 = 20;

/// `pe live`'s model options.
#[derive(clap::Args, Debug, Clone)]
pub struct ModelArgs {
    /// Where `pe plan --target real-time -o DIR` wrote the model to serve when the full one
    /// cannot keep real time here; planned there first when it holds no plan for the scene.
    #[arg(long)]
    pub plan: Option<PathBuf>,
    /// The budget of a plan made here (as `pe plan --budget`).
    #[arg(long, default_value = "2%")]
    pub plan_budget: String,
    /// The real-time factor the full model must reach in the probe to be served.
    #[arg(long, default_value_t = 1.2, value_parser = crate::domain::positive)]
    pub min_rtf: f64,
}

/// The model a session serves.
pub struct Chosen {
    pub problem: Problem,
    /// The scene's name (for messages and records) and the command line that loads it
    /// (for the replay hint).
    pub name: String,
    pub scene_arg: String,
    /// What the page shows before the engine's own description: which model and why.
    pub note: String,
    pub planned: bool,
}

/// Chooses the model (see the module doc). `scene_arg` is how the command line named the
/// scene (`--builtin --level medium` or a path).
pub fn choose(
    scene: &Scene,
    dir: &Path,
    name: &str,
    scene_arg: &str,
    args: &ModelArgs,
    threads: usize,
) -> Result<Chosen> {
    if !(args.min_rtf >= 0.0 && args.min_rtf.is_finite()) {
        bail!("--min-rtf {}: a real-time factor >= 0", args.min_rtf);
    }
    let budget_rel = plan::parse_budget(&args.plan_budget)?;
    let full = Problem::from_scene(scene, dir).with_context(|| format!("scene {name}"))?;
    let rtf_full = probe_rtf(&full, name, threads)?;
    let full_chosen = |note: String| Chosen {
        problem: full,
        name: name.into(),
        scene_arg: scene_arg.into(),
        note,
        planned: false,
    };
    if rtf_full >= args.min_rtf {
        return Ok(full_chosen(format!(
            "full model (real-time factor {rtf_full:.2} here)"
        )));
    }
    let Some(plan_dir) = &args.plan else {
        eprintln!(
            "warning: the full model probed at real-time factor {rtf_full:.2} here (below --min-rtf {}): the session will fall behind; `--plan DIR` serves the model `pe plan --target real-time` finds instead",
            args.min_rtf
        );
        return Ok(full_chosen(format!(
            "full model (real-time factor {rtf_full:.2} here: behind real time; no --plan)"
        )));
    };
    let report = match read_plan(plan_dir, name)? {
        Some(r) => {
            eprintln!(
                "{name}: the full model probed at real-time factor {rtf_full:.2} here: serving the plan in {}",
                plan_dir.display()
            );
            r
        }
        None => {
            eprintln!(
                "{name}: the full model probed at real-time factor {rtf_full:.2} here: planning a model for real time into {} (pe plan --budget {} --target real-time; once)",
                plan_dir.display(),
                args.plan_budget
            );
            let opts = plan::Options {
                budget_rel,
                target: Target::RealTime,
                watch: vec![],
                profile: pe_firmware::profile::PE_BOARD.name.into(),
            };
            plan::run(scene, dir, name, &opts, plan_dir)?
        }
    };
    let path = plan_dir.join("scene.toml");
    let planned_scene = Scene::from_file(&path)?;
    let problem = Problem::from_scene(&planned_scene, plan_dir)
        .with_context(|| format!("the planned scene {}", path.display()))?;
    let rtf = probe_rtf(&problem, &path.display().to_string(), threads)?;
    let behind = if rtf < 1.0 { ": still behind" } else { "" };
    let force = report
        .final_model
        .tool_force_haptic_err_rel
        .map_or(String::new(), |e| {
            format!(", tool force within {:.2}% on 1 ms means", 100.0 * e)
        });
    Ok(Chosen {
        name: path.display().to_string(),
        scene_arg: path.display().to_string(),
        note: format!(
            "planned model (pe plan, budget {:.3}%{force}; real-time factor {rtf:.2} here{behind}; the full model: {rtf_full:.2})",
            100.0 * report.budget_rel
        ),
        problem,
        planned: true,
    })
}

/// The plan `DIR` holds for the scene `name` (`DIR/plan.json` read back as `pe plan` wrote
/// it, and its `scene.toml`), or `None` when it holds none (no such files: a plan is made
/// there). A plan for another scene is refused rather than overwritten.
pub fn read_plan(dir: &Path, name: &str) -> Result<Option<PlanReport>> {
    let (json, toml) = (dir.join("plan.json"), dir.join("scene.toml"));
    if !json.exists() && !toml.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&json).with_context(|| {
        format!(
            "{}: a plan's scene.toml without its plan.json",
            dir.display()
        )
    })?;
    let report: PlanReport = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a plan `pe plan` wrote", json.display()))?;
    if report.scene != name {
        bail!(
            "{}: a plan for {}, not {name} (give another --plan DIR)",
            json.display(),
            report.scene
        );
    }
    if !toml.exists() {
        bail!("{}: the plan's scene.toml is missing", dir.display());
    }
    Ok(Some(report))
}

/// `problem`'s real-time factor here: simulated over wall time while stepped unpaced for
/// [`PROBE_WALL_S`] after [`WARM_UP_STEPS`] steps.
pub fn probe_rtf(problem: &Problem, name: &str, threads: usize) -> Result<f64> {
    let mut engine = solver_engine(problem, name, threads, "")?;
    for _ in 0..WARM_UP_STEPS {
        engine.step()?;
    }
    let (start, t0) = (Instant::now(), engine.time_s());
    let wall = Duration::from_secs_f64(PROBE_WALL_S);
    while start.elapsed() < wall {
        engine.step()?;
    }
    Ok((engine.time_s() - t0) / start.elapsed().as_secs_f64())
}
