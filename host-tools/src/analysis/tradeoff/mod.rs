//! `pe tradeoff`: what each solver choice costs and what it buys, for one scene.
//!
//! The scene runs over a grid of configurations: the full precision × integration cross
//! around a baseline (the scene's own settings), then one factor at a time: hourglass
//! coefficient, dt safety factor, mesh level (when the mesh can be generated at several
//! levels) and mass scaling. Each run is timed (host ns per element-step, steps, wall time,
//! real-time factor) and compared with the reference configuration, the most accurate one:
//! f64, full integration, the finest level in the grid, dt safety 0.5, no mass scaling.
//!
//! Errors against the reference, at the end of the scene's duration:
//! * nodal displacement, max and RMS over the configuration's nodes. On the reference's own
//!   mesh node by node; on another level the reference field is interpolated (trilinear
//!   shape functions of the reference cell holding the node, found by inverting the cell
//!   map), and nodes farther than a quarter cell outside the reference mesh are left out
//!   (`compared_nodes` says how many were compared);
//! * the scene's quantity of interest: the force of the tissue on the first tool
//!   (`tool_force_n`) when the scene has tools, otherwise the force the prescribed nodes
//!   exert on the tissue (`prescribed_reaction_n`) when it prescribes motion, otherwise the
//!   mean displacement of the tip face (the nodes at the largest x): error is the norm of the
//!   vector difference over the reference's norm;
//! * energy: stored plus kinetic energy at the end, relative to the reference's.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};
use pe_firmware::image::{Integration, Precision};
use pe_firmware::physics::HourglassControl;
use pe_firmware::profile::BoardProfile;
use serde::Serialize;

use crate::geom::norm;
use crate::mesh::Mesh;
use crate::problem::{NodeKind, Problem};
use crate::scene::Scene;
use crate::solver;

mod interpolate;
mod report;

pub use interpolate::Interpolator;
pub use report::*;

/// Where the board column comes from, on a board of `profile`.
pub fn board_note(profile: &BoardProfile) -> String {
    format!(
        "instructions per element-step of a whole board step (elements, gather/scatter, node updates; `pe_firmware::profile::MEASURED_COST`, measured under QEMU with `scripts/board-cost.sh`), and the board real-time factor at {} MHz ({}) taking one instruction per cycle, for the whole scene on one board",
        profile.clock_hz as f64 / 1e6,
        profile.name
    )
}

/// One configuration of the grid.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Config {
    /// Which factor this row varies from the baseline ("baseline", "precision×integration",
    /// "hourglass", "dt_safety", "level", "mass_scaling", "reference").
    pub varied: String,
    #[serde(serialize_with = "crate::scene::settings::precision_text::serialize")]
    pub precision: Precision,
    #[serde(serialize_with = "crate::scene::settings::integration_text::serialize")]
    pub integration: Integration,
    #[serde(serialize_with = "crate::scene::settings::hourglass_text::serialize")]
    pub hourglass: HourglassControl,
    pub dt_safety: f64,
    pub level: String,
    pub mass_scaling: f64,
}

impl Config {
    pub fn label(&self) -> String {
        format!(
            "{} {} hg{} s{} {} ms{}",
            self.precision,
            self.integration,
            self.hourglass,
            self.dt_safety,
            self.level,
            self.mass_scaling
        )
    }

    fn same_run(&self, o: &Config) -> bool {
        // The hourglass coefficient does nothing under full integration.
        self.precision == o.precision
            && self.integration == o.integration
            && (self.integration == Integration::Full || self.hourglass == o.hourglass)
            && self.dt_safety == o.dt_safety
            && self.level == o.level
            && self.mass_scaling == o.mass_scaling
    }
}

/// One measured row (the CSV's columns, in order).
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub varied: String,
    #[serde(serialize_with = "crate::scene::settings::precision_text::serialize")]
    pub precision: Precision,
    #[serde(serialize_with = "crate::scene::settings::integration_text::serialize")]
    pub integration: Integration,
    #[serde(serialize_with = "crate::scene::settings::hourglass_text::serialize")]
    pub hourglass: HourglassControl,
    pub dt_safety: f64,
    pub level: String,
    pub mass_scaling: f64,
    pub elements: usize,
    pub nodes: usize,
    pub dt_s: f64,
    pub steps: u64,
    pub simulated_s: f64,
    pub wall_s: f64,
    pub host_ns_per_element_step: f64,
    pub real_time_factor: f64,
    /// Instructions per element-step of a whole board step and the board real-time factor
    /// ([`board_note`]), as text: "552 (board RTF 0.123)".
    pub board_instructions_per_element_step: String,
    pub compared_nodes: usize,
    pub u_err_max_m: f64,
    pub u_err_rms_m: f64,
    /// Errors over the reference's largest displacement.
    pub u_err_max_rel: f64,
    pub u_err_rms_rel: f64,
    pub qoi: String,
    pub qoi_value: f64,
    pub qoi_err_rel: f64,
    pub energy_j: f64,
    pub energy_err_rel: f64,
    /// On the Pareto front of (wall s per simulated s, u_err_rms_rel).
    pub pareto: bool,
}

/// How the scene's mesh varies with the level.
#[derive(Clone, Debug)]
pub enum Levels {
    /// The built-in anatomy at these levels (coarsest first).
    Builtin(Vec<String>),
    /// A generated box with its cells scaled by these factors (named "x0.5", "x1", "x2").
    Box(Vec<f64>),
    /// A mesh file: one level.
    Single,
}

/// Options of `pe tradeoff`.
#[derive(Clone, Debug)]
pub struct Options {
    /// Include the fine built-in level (slow) / a 4× box level.
    pub fine: bool,
    /// Baseline level of the built-in scene.
    pub level: Option<String>,
    /// The board whose clock gives the board real-time factor.
    pub profile: &'static BoardProfile,
}

fn level_names(levels: &Levels) -> Vec<String> {
    match levels {
        Levels::Builtin(v) => v.clone(),
        Levels::Box(f) => f.iter().map(|f| format!("x{f}")).collect(),
        Levels::Single => vec!["file".into()],
    }
}

/// The scene at a level.
fn scene_at(base: &Scene, levels: &Levels, level: &str) -> Result<Scene> {
    let mut s = base.clone();
    match levels {
        Levels::Builtin(_) => s.mesh.level = Some(level.into()),
        Levels::Box(_) => {
            let f: f64 = level
                .trim_start_matches('x')
                .parse()
                .with_context(|| format!("level {level}"))?;
            if let Some(g) = &mut s.mesh.generate {
                g.cells = g.cells.map(|c| ((c as f64 * f).round() as usize).max(1));
            }
        }
        Levels::Single => {}
    }
    Ok(s)
}

/// The grid: baseline, precision × integration, then one factor at a time, and the
/// reference, without duplicates. The baseline is the scene's own solver settings at
/// `base_level`.
pub fn grid(base: &Scene, levels: &Levels, base_level: &str) -> Vec<Config> {
    let s = &base.solver;
    let names = level_names(levels);
    let finest = names.last().cloned().unwrap_or_else(|| base_level.into());
    let b = Config {
        varied: "baseline".into(),
        precision: s.precision,
        integration: s.integration,
        hourglass: s.hourglass,
        dt_safety: s.dt_safety,
        level: base_level.into(),
        mass_scaling: s.mass_scaling,
    };
    let mut out: Vec<Config> = vec![Config {
        varied: "reference".into(),
        precision: Precision::F64,
        integration: Integration::Full,
        hourglass: s.hourglass,
        dt_safety: 0.5,
        level: finest,
        mass_scaling: 1.0,
    }];
    let mut push = |c: Config| {
        if !out.iter().any(|o| o.same_run(&c)) {
            out.push(c);
        }
    };
    push(b.clone());
    for p in [Precision::F64, Precision::F32] {
        for i in [Integration::Reduced, Integration::Full] {
            push(Config {
                varied: "precision×integration".into(),
                precision: p,
                integration: i,
                ..b.clone()
            });
        }
    }
    if b.integration == Integration::Reduced {
        let forms = [
            HourglassControl::Physical,
            HourglassControl::Scalar(0.05),
            HourglassControl::Scalar(0.1),
            HourglassControl::Scalar(0.2),
        ];
        for h in forms {
            push(Config {
                varied: "hourglass".into(),
                hourglass: h,
                ..b.clone()
            });
        }
    }
    for sf in [0.5, 0.9] {
        push(Config {
            varied: "dt_safety".into(),
            dt_safety: sf,
            ..b.clone()
        });
    }
    for l in names {
        push(Config {
            varied: "level".into(),
            level: l,
            ..b.clone()
        });
    }
    for m in [1.0, 4.0, 16.0] {
        push(Config {
            varied: "mass_scaling".into(),
            mass_scaling: m,
            ..b.clone()
        });
    }
    // Reference first in the run order (every error needs it), baseline next.
    out
}

/// The quantity of interest of a finished run: its name and vector value.
fn qoi(p: &Problem, out: &solver::RunOutput) -> (String, [f64; 3]) {
    if let Some(f) = out
        .report
        .contact
        .as_ref()
        .and_then(|c| c.tool_force_final_n.first())
    {
        return ("tool_force_n".into(), *f);
    }
    if p.node_kind
        .iter()
        .any(|k| matches!(k, NodeKind::Prescribed(_)))
    {
        return (
            "prescribed_reaction_n".into(),
            out.report.prescribed_reaction_n,
        );
    }
    let (lo, hi) = p.mesh.bounding_box();
    let tol = 1e-6 * (hi[0] - lo[0]).abs().max(1e-12);
    let tip: Vec<usize> = (0..p.mesh.nodes.len())
        .filter(|&n| p.mesh.nodes[n][0] >= hi[0] - tol)
        .collect();
    let mean = core::array::from_fn(|i| {
        tip.iter().map(|&n| out.displacements[n][i]).sum::<f64>() / tip.len().max(1) as f64
    });
    ("tip_mean_displacement_m".into(), mean)
}

/// What a run leaves for the comparison.
struct Done {
    row: Row,
    qoi: [f64; 3],
    u: Vec<[f64; 3]>,
    mesh: Mesh,
}

fn run_one(
    base: &Scene,
    dir: &Path,
    levels: &Levels,
    c: &Config,
    name: &str,
    profile: &BoardProfile,
) -> Result<Done> {
    let mut sc = scene_at(base, levels, &c.level)?;
    sc.solver.precision = c.precision;
    sc.solver.integration = c.integration;
    sc.solver.hourglass = c.hourglass;
    sc.solver.dt_safety = c.dt_safety;
    sc.solver.mass_scaling = c.mass_scaling;
    sc.solver.dt = None;
    let p = Problem::from_scene(&sc, dir)
        .with_context(|| format!("{name}: configuration {}", c.label()))?;
    let out = solver::run(&p, &format!("{name} [{}]", c.label()), &mut ())?;
    let (qname, q) = qoi(&p, &out);
    let r = &out.report;
    // Stored energy of the final state evaluated in f64 for every precision: in f32 the
    // strain energy of small strains cancels (W ~ ε² from terms ~ ε) and would measure the
    // evaluation instead of the run.
    let stored = crate::problem::elements::Elements::<f64>::build(&p)
        .stored_energy(&p.laws, &out.displacements)
        .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    let row = Row {
        varied: c.varied.clone(),
        precision: c.precision,
        integration: c.integration,
        hourglass: c.hourglass,
        dt_safety: c.dt_safety,
        level: c.level.clone(),
        mass_scaling: c.mass_scaling,
        elements: r.elements,
        nodes: r.nodes,
        dt_s: r.dt_s,
        steps: r.steps,
        simulated_s: r.simulated_s,
        wall_s: r.wall_s,
        host_ns_per_element_step: r.wall_s * 1e9 / (r.elements as f64 * r.steps as f64),
        real_time_factor: r.real_time_factor,
        board_instructions_per_element_step: {
            let c = pe_firmware::profile::measured_cost(c.precision, c.integration);
            let per_kernel = r.kernel_mix.map(|m| m * r.elements as f64);
            let step = c
                .step_cost()
                .step(per_kernel, r.nodes as f64, r.contact_nodes as f64);
            let step_s = step / profile.clock_hz as f64;
            format!("{} (board RTF {:.3})", c.step_per_element, r.dt_s / step_s)
        },
        compared_nodes: 0,
        u_err_max_m: 0.0,
        u_err_rms_m: 0.0,
        u_err_max_rel: 0.0,
        u_err_rms_rel: 0.0,
        qoi: qname,
        qoi_value: norm(q),
        qoi_err_rel: 0.0,
        energy_j: stored + r.kinetic_energy_final,
        energy_err_rel: 0.0,
        pareto: false,
    };
    Ok(Done {
        row,
        qoi: q,
        u: out.displacements,
        mesh: p.mesh,
    })
}

/// Fills the error columns of `d` against the reference run.
fn compare(d: &mut Done, reference: &Done, interp: &Interpolator<'_>) {
    let same_mesh = d.mesh.nodes == reference.mesh.nodes && d.mesh.cells == reference.mesh.cells;
    let umax = reference.u.iter().map(|u| norm(*u)).fold(0.0, f64::max);
    let (mut emax, mut sum2, mut count) = (0.0f64, 0.0, 0usize);
    for (n, x) in d.mesh.nodes.iter().enumerate() {
        let want = if same_mesh {
            Some(reference.u[n])
        } else {
            interp.at(&reference.u, *x)
        };
        if let Some(w) = want {
            let e = norm(core::array::from_fn(|i| d.u[n][i] - w[i]));
            emax = emax.max(e);
            sum2 += e * e;
            count += 1;
        }
    }
    let rms = (sum2 / count.max(1) as f64).sqrt();
    let r = &mut d.row;
    r.compared_nodes = count;
    r.u_err_max_m = emax;
    r.u_err_rms_m = rms;
    r.u_err_max_rel = emax / umax.max(1e-300);
    r.u_err_rms_rel = rms / umax.max(1e-300);
    r.qoi_err_rel = norm(core::array::from_fn(|i| d.qoi[i] - reference.qoi[i]))
        / norm(reference.qoi).max(1e-300);
    r.energy_err_rel =
        (r.energy_j - reference.row.energy_j).abs() / reference.row.energy_j.abs().max(1e-300);
}

/// Marks the Pareto front of (cost = wall s per simulated s, error = u_err_rms_rel) among
/// the rows other than the reference: a row is on it when no other row is at most as costly
/// and at most as wrong, and better in one of the two.
pub fn mark_pareto(rows: &mut [Row]) {
    let pts: Vec<(f64, f64, bool)> = rows
        .iter()
        .map(|r| {
            (
                1.0 / r.real_time_factor,
                r.u_err_rms_rel,
                r.varied == "reference",
            )
        })
        .collect();
    for (k, r) in rows.iter_mut().enumerate() {
        let (c, e, is_ref) = pts[k];
        r.pareto = !is_ref
            && !pts.iter().enumerate().any(|(j, &(cj, ej, rj))| {
                j != k && !rj && cj <= c && ej <= e && (cj < c || ej < e)
            });
    }
}

/// The scene and its levels: the built-in levels, the box factors, or one file level.
pub fn levels_of(scene: &Scene, opts: &Options) -> (Levels, String) {
    if scene.mesh.builtin.is_some() {
        let base = opts
            .level
            .clone()
            .or_else(|| scene.mesh.level.clone())
            .unwrap_or_else(|| "medium".into());
        let mut v = vec!["coarse".to_string(), "medium".to_string()];
        if opts.fine || base == "fine" {
            v.push("fine".into());
        }
        (Levels::Builtin(v), base)
    } else if scene.mesh.generate.is_some() {
        let mut f = vec![0.5, 1.0, 2.0];
        if opts.fine {
            f.push(4.0);
        }
        (Levels::Box(f), "x1".into())
    } else {
        (Levels::Single, "file".into())
    }
}

/// Runs the grid and returns the rows (reference first).
pub fn run(
    scene: &Scene,
    dir: &Path,
    name: &str,
    opts: &Options,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<Row>> {
    let mut scene = scene.clone();
    // The grid changes dt: hold the simulated time, not the step count, fixed.
    Problem::hold_duration(&mut scene, dir)?;
    let (levels, base_level) = levels_of(&scene, opts);
    let configs = grid(&scene, &levels, &base_level);
    let mut done: Vec<Done> = Vec::new();
    for (k, c) in configs.iter().enumerate() {
        progress(&format!("[{}/{}] {}", k + 1, configs.len(), c.label()));
        done.push(run_one(&scene, dir, &levels, c, name, opts.profile)?);
    }
    let Some((reference, rest)) = done.split_first_mut() else {
        bail!("empty grid");
    };
    let interp = Interpolator::new(&reference.mesh);
    let umax = reference.u.iter().map(|u| norm(*u)).fold(0.0, f64::max);
    reference.row.compared_nodes = reference.mesh.nodes.len();
    for d in rest.iter_mut() {
        compare(d, reference, &interp);
    }
    if !(umax > 0.0) {
        progress("warning: the reference does not move; relative errors are meaningless");
    }
    let mut rows: Vec<Row> = done.into_iter().map(|d| d.row).collect();
    mark_pareto(&mut rows);
    Ok(rows)
}

/// `pe tradeoff`: runs the grid, writes DIR/tradeoff.csv, .md and .png, prints the table.
pub fn run_cli(scene: &Scene, dir: &Path, name: &str, opts: &Options, out: &Path) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let rows = run(scene, dir, name, opts, &mut |s| eprintln!("{s}"))?;
    let csv = out.join("tradeoff.csv");
    crate::output::file::write_atomic(&csv, to_csv(&rows)?)?;
    let md = to_markdown(&rows, name, opts.profile);
    let mdp = out.join("tradeoff.md");
    crate::output::file::write_atomic(&mdp, &md)?;
    let png = out.join("tradeoff.png");
    plot(&rows, &png, &format!("error against cost: {name}"))?;
    println!("{md}");
    println!(
        "wrote {}, {}, {}",
        csv.display(),
        mdp.display(),
        png.display()
    );
    Ok(())
}
