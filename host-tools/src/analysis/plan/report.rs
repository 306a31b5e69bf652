//! The plan's outputs: `plan.md`, `plan.json` and `plan.png` (the full mesh's surface
//! coloured by what became of each element), and the console summary.

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use super::*;
use crate::output::render::{render_surface_png, CapsuleOverlay, SurfaceImage, View as Camera};

/// One measured model: a row of the report.
#[derive(Clone, Debug, Serialize, Deserialize)]
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
    /// Relative errors against the reference (0 for the reference). The tool force's is
    /// the worse of its errors over the 1 ms means a haptic loop feels and the 40 ms means a
    /// graphics frame shows (both given below); the budget holds on both.
    pub tool_force_err_rel: Option<f64>,
    pub tool_force_haptic_err_rel: Option<f64>,
    pub tool_force_graphics_err_rel: Option<f64>,
    pub displacement_err_rel: f64,
    /// Reference nodes the displacement error covers.
    pub compared_nodes: usize,
    /// Why it was refused (empty when accepted).
    pub note: String,
}

/// The whole plan (`DIR/plan.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
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
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BoardUse {
    pub board: [usize; 3],
    pub elements: usize,
    pub nodes: usize,
    pub runs: String,
}

fn pct(v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{:.3}%", 100.0 * v),
        Some(_) => "-".into(),
        None => "-".into(),
    }
}

fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map(|v| v.to_string()).unwrap_or_else(|| "-".into())
}

/// The markdown report.
pub fn to_markdown(r: &PlanReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Plan for {}\n", r.scene);
    let _ = writeln!(
        s,
        "Budget: {}% on each quantity of interest; target: {}; array figures for {} boards, profile {}.\n",
        100.0 * r.budget_rel,
        r.target,
        r.array,
        r.profile
    );
    let _ = writeln!(
        s,
        "Quantities of interest (sampled at {} times over the scene's duration):",
        r.samples
    );
    for q in &r.quantities {
        let _ = writeln!(s, "- {q}");
    }
    let f = &r.final_model;
    let _ = writeln!(
        s,
        "\n**Result: {}.** The written model (`scene.toml`, `mesh.msh`), read back and run: {} elements ({} pruned, {} nodes held at the cut), {}, mass scaling {}; tool-force error {} (over 1 ms means, as a haptic loop feels it: {}; over 40 ms means, as a graphics frame shows it: {}), displacement error {} ({} nodes compared). Cost {:.3e} element-steps per simulated second against the reference's {:.3e}: **{:.2}x fewer**.\n",
        if r.within_budget { "within the budget" } else { "the budget cannot be met; this is the best model found" },
        f.elements,
        r.pruned_elements,
        r.held_nodes,
        f.precision,
        f.mass_scaling,
        pct(f.tool_force_err_rel),
        pct(f.tool_force_haptic_err_rel),
        pct(f.tool_force_graphics_err_rel),
        pct(Some(f.displacement_err_rel)),
        f.compared_nodes,
        f.element_steps_per_sim_s,
        r.rows.first().map_or(0.0, |x| x.element_steps_per_sim_s),
        r.saving_factor
    );
    let _ = writeln!(
        s,
        "Target: {} — {}.\n",
        if r.target_met { "met" } else { "not met" },
        r.target_note
    );
    let _ = writeln!(s, "## Every choice, measured against the reference\n");
    let _ = writeln!(s, "Each row runs the model with everything accepted above it plus its own choice. Boards at 10 kHz and bytes per step come from the schedule compiler on {} ({}).\n", r.array, r.profile);
    let _ = writeln!(s, "| choice | accepted | elements | precision | mass scaling | dt (s) | element-steps per sim. s | boards at 10 kHz | bytes/step | array keeps real time | tool force err (1 ms / 40 ms means) | displacement err | note |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for x in r.rows.iter().chain(std::iter::once(&r.final_model)) {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {:.3e} | {:.3e} | {} | {} | {} | {} | {} | {} |",
            x.choice,
            if x.accepted { "yes" } else { "no" },
            x.elements,
            x.precision,
            x.mass_scaling,
            x.dt_s,
            x.element_steps_per_sim_s,
            opt(x.boards_needed_at_10_khz),
            opt(x.bytes_per_step),
            opt(x.array_keeps_real_time),
            force_cell(x),
            pct(Some(x.displacement_err_rel)),
            x.note
        );
    }
    if !r.boards.is_empty() {
        let _ = writeln!(s, "\n## What each board runs ({})\n", r.array);
        let _ = writeln!(s, "| board | elements | nodes | runs |");
        let _ = writeln!(s, "|---|---|---|---|");
        for b in &r.boards {
            let _ = writeln!(
                s,
                "| ({},{},{}) | {} | {} | {} |",
                b.board[0], b.board[1], b.board[2], b.elements, b.nodes, b.runs
            );
        }
    }
    let _ = writeln!(
        s,
        "\nNot varied: the hourglass coefficient (it changes accuracy, not cost), the contact check interval and the graphics rate (they do not change the element-steps; the graphics stream is not a quantity of interest). Host wall times are in plan.json."
    );
    s
}

/// The console summary.
pub fn summary(r: &PlanReport) -> String {
    let f = &r.final_model;
    let mut s = format!(
        "plan for {}: {} — {} elements of {} ({} pruned), {}, mass scaling {}; tool-force error {}, displacement error {} (budget {}%); {:.2}x fewer element-steps per simulated second\n",
        r.scene,
        if r.within_budget { "within the budget" } else { "budget NOT met (best model found)" },
        f.elements,
        r.rows.first().map_or(0, |x| x.elements),
        r.pruned_elements,
        f.precision,
        f.mass_scaling,
        pct(f.tool_force_err_rel),
        pct(Some(f.displacement_err_rel)),
        100.0 * r.budget_rel,
        r.saving_factor
    );
    let _ = writeln!(
        s,
        "  target {}: {}",
        if r.target_met { "met" } else { "not met" },
        r.target_note
    );
    let _ = write!(s, "  wrote {}", r.files.join(", "));
    s
}

/// Writes plan.md, plan.json and plan.png; returns the report with its file list.
pub(super) fn write(
    mut r: PlanReport,
    held: &Held,
    reduced: &Reduced,
    out: &Path,
) -> Result<PlanReport> {
    r.files = super::files(out)
        .iter()
        .map(|p| p.display().to_string())
        .collect();
    let png = out.join("plan.png");
    picture(held, reduced, &png, &r.scene)?;
    let md = out.join("plan.md");
    crate::output::file::write_atomic(&md, to_markdown(&r))?;
    let js = out.join("plan.json");
    crate::output::file::write_atomic(&js, serde_json::to_string_pretty(&r)?)?;
    Ok(r)
}

/// The held model's full mesh (before pruning), each boundary face coloured by its
/// element's kind.
fn picture(held: &Held, reduced: &Reduced, path: &Path, name: &str) -> Result<()> {
    let full_mesh = &reduced.full_mesh;
    let faces = full_mesh.boundary_faces_with_cells();
    let mut positions = Vec::with_capacity(4 * faces.len());
    let mut quads = Vec::with_capacity(faces.len());
    let mut groups = Vec::with_capacity(faces.len());
    let mut values = Vec::with_capacity(4 * faces.len());
    for (q, c) in &faces {
        let kind = reduced
            .cell_kind
            .get(*c as usize)
            .copied()
            .unwrap_or(CellKind::Kept);
        let k = positions.len() as u32;
        for &n in q {
            positions.push(full_mesh.nodes[n as usize]);
            values.push(kind as u8 as f64);
        }
        quads.push([k, k + 1, k + 2, k + 3]);
        groups.push(kind as u8);
    }
    let tools: Vec<CapsuleOverlay> = held
        .problem
        .contact
        .as_ref()
        .map(|c| {
            c.tools
                .iter()
                .map(|t| CapsuleOverlay {
                    a: t.capsule.a,
                    b: t.capsule.b,
                    radius_m: t.capsule.radius_m,
                })
                .collect()
        })
        .unwrap_or_default();
    let title = format!("{name}: 0 pruned, 1 kept, 2 held at the cut, 3 tool/contact/load");
    render_surface_png(
        path,
        &SurfaceImage {
            positions: &positions,
            quads: &quads,
            quad_groups: &groups,
            node_values: &values,
            value_label: "element kind",
            value_scale: 1.0,
            tools: &tools,
            title: &title,
            view: Camera {
                azimuth_deg: -60.0,
                elevation_deg: 30.0,
            },
            size_px: (1200, 900),
        },
    )
}

/// A row's tool-force error cell: the 1 ms and 40 ms means' errors ("-" without tools).
fn force_cell(x: &Row) -> String {
    match (x.tool_force_haptic_err_rel, x.tool_force_graphics_err_rel) {
        (Some(h), Some(g)) => format!("{} / {}", pct(Some(h)), pct(Some(g))),
        _ => pct(x.tool_force_err_rel),
    }
}
