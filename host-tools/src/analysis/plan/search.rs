//! The greedy search: the model held so far ([`Held`]), each choice run and measured
//! against the reference ([`Search`]), and the steps that change the resolution (a coarser
//! level, a coarsened voxel mesh, fewer contact pairs) and prune the domain. The steps
//! that trim the contact surfaces and change the solver settings are `trim.rs` and
//! `settings.rs`.

use std::path::Path;

use anyhow::Result;

use super::array::array_figures;
use super::compare::{errors, View};
use super::{prune, settings, trace, trim, Reduced, Row, Trace, PRUNE_BISECTIONS, PRUNE_FRACTIONS};
use crate::compile::partition::Machine;
use crate::mesh::Mesh;
use crate::problem::{NodeKind, Problem};
use crate::scene::Scene;

/// The model the search holds: a scene on a full mesh, or a pruned one.
#[derive(Clone)]
pub(super) enum Model {
    Full { scene: Box<Scene> },
    Pruned(Box<Reduced>),
}

/// The model accepted so far: its problem, the trace of its run and how its field is read
/// at the reference's nodes.
pub(super) struct Held {
    pub model: Model,
    pub problem: Problem,
    pub trace: Trace,
    pub view: View,
}

impl Held {
    /// The scene of a model nothing has pruned yet (the scene as given, or on a coarsened
    /// mesh of its own), which pruning starts from; `None` once pruned or trimmed.
    pub(super) fn unpruned_scene(&self) -> Option<Scene> {
        match &self.model {
            Model::Full { scene } => Some((**scene).clone()),
            Model::Pruned(r) if r.fraction.is_none() && r.coarsened => Some(r.scene.clone()),
            Model::Pruned(_) => None,
        }
    }
}

/// The search's context.
pub(super) struct Search<'a> {
    pub name: &'a str,
    pub dir: &'a Path,
    pub reference: Trace,
    pub ref_mesh: Mesh,
    pub watched: Vec<usize>,
    pub machine: Machine,
    pub profile: &'a pe_firmware::profile::BoardProfile,
    pub budget: f64,
    pub rows: Vec<Row>,
}

impl<'a> Search<'a> {
    /// Runs the reference (`p_ref`, the scene as given), the search's first row.
    pub(super) fn start(
        name: &'a str,
        dir: &'a Path,
        p_ref: &Problem,
        watch: &[String],
        machine: Machine,
        profile: &'a pe_firmware::profile::BoardProfile,
        budget: f64,
    ) -> Result<Search<'a>> {
        let driven = prune::driven_nodes(p_ref, watch)?;
        let watched = watched_nodes(p_ref, &driven);
        eprintln!("plan: reference: {} elements", p_ref.mesh.cells.len());
        let reference = trace::run(p_ref, &format!("{name} [reference]"))?;
        let mut s = Search {
            name,
            dir,
            reference,
            ref_mesh: p_ref.mesh.clone(),
            watched,
            machine,
            profile,
            budget,
            rows: Vec::new(),
        };
        let ref_row = s.row(
            "reference (the scene as given)",
            p_ref,
            &s.reference,
            &View::Same,
        )?;
        s.rows.push(ref_row);
        Ok(s)
    }

    pub(super) fn row(&self, choice: &str, p: &Problem, t: &Trace, view: &View) -> Result<Row> {
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
        let within = force.is_none_or(|f| f.worst() <= self.budget) && disp <= self.budget;
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
            tool_force_err_rel: force.map(|f| f.worst()),
            tool_force_haptic_err_rel: force.map(|f| f.haptic),
            tool_force_graphics_err_rel: force.map(|f| f.graphics),
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
    pub(super) fn not_run(&mut self, choice: &str, mesh: &Mesh, p: Option<&Problem>, why: String) {
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
            tool_force_haptic_err_rel: None,
            tool_force_graphics_err_rel: None,
            displacement_err_rel: f64::NAN,
            compared_nodes: 0,
            note: why,
        });
    }

    /// Runs `p`, measures it, records the row; the trace when it is accepted.
    pub(super) fn try_model(
        &mut self,
        choice: &str,
        p: &Problem,
        view: &View,
    ) -> Result<Option<Trace>> {
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

/// The greedy search: level, pruning, settings.
pub(super) fn search(
    s: &mut Search<'_>,
    held: &mut Held,
    scene: &Scene,
    watch: &[String],
) -> Result<()> {
    // 1. Resolution: a coarser built-in level.
    try_levels(s, held, scene)?;
    // 1a. Resolution of a user mesh: a voxel mesh coarsened 2x, again while it passes.
    if scene.mesh.builtin.is_none() {
        try_coarsen(s, held, scene)?;
    }
    // 1b. Contact pairs the scene's quantities do not need (a pair that never touches, or
    // whose force the budget can do without), before the pilot run pruning reads.
    drop_pairs(s, held)?;
    // 2. Pruning: the first fraction that passes, then bisected (geometric mean) towards
    // the last that failed.
    try_pruning(s, held, watch)?;
    // 2b. Contact surfaces trimmed to what came near the tool or the other surface.
    trim::try_trims(s, held, watch)?;
    // 3. Solver settings on the model held.
    settings::try_settings(s, held)
}

/// Resolution of a built-in scene: the coarser levels, coarsest first; the first that
/// passes is held.
fn try_levels(s: &mut Search<'_>, held: &mut Held, scene: &Scene) -> Result<()> {
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
    Ok(())
}

/// Pruning the held model (when nothing has pruned it yet): the first of
/// [`PRUNE_FRACTIONS`] that passes, then [`PRUNE_BISECTIONS`] bisections (geometric mean)
/// towards the last that failed.
fn try_pruning(s: &mut Search<'_>, held: &mut Held, watch: &[String]) -> Result<()> {
    let Some(sc) = held.unpruned_scene() else {
        return Ok(());
    };
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
    Ok(())
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

/// The held model pruned at fraction `f` of the motion and energy of its run, measured
/// (`tried`: the element counts tried before, a repeat is not run again).
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
