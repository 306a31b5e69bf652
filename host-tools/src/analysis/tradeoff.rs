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
//! * the scene's quantity of interest: the force the prescribed nodes exert on the tissue
//!   (the probe's push, `prescribed_reaction_n`) when the scene prescribes motion, otherwise
//!   the mean displacement of the tip face (the nodes at the largest x): error is the norm of
//!   the vector difference over the reference's norm;
//! * energy: stored plus kinetic energy at the end, relative to the reference's.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Serialize;

use crate::mesh::Mesh;
use crate::problem::{NodeKind, Problem};
use crate::scene::Scene;
use crate::solver;

/// Board instructions per element-step: not measured until the board firmware exists.
/// Where the board column comes from.
pub const BOARD_NOTE: &str = "instructions per element-step of a whole board step (elements, gather/scatter, node updates; `pe_firmware::profile::MEASURED_COST`, measured under QEMU with `scripts/board-cost.sh`), and the board real-time factor at 480 MHz taking one instruction per cycle, for the whole scene on one board";

/// One configuration of the grid.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Config {
    /// Which factor this row varies from the baseline ("baseline", "precision×integration",
    /// "hourglass", "dt_safety", "level", "mass_scaling", "reference").
    pub varied: String,
    pub precision: String,
    pub integration: String,
    pub hourglass: f64,
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
            && (self.integration == "full" || self.hourglass == o.hourglass)
            && self.dt_safety == o.dt_safety
            && self.level == o.level
            && self.mass_scaling == o.mass_scaling
    }
}

/// One measured row (the CSV's columns, in order).
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub varied: String,
    pub precision: String,
    pub integration: String,
    pub hourglass: f64,
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
    /// Empty until the board firmware reports instruction counts.
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
        precision: s.precision.clone(),
        integration: s.integration.clone(),
        hourglass: s.hourglass,
        dt_safety: s.dt_safety,
        level: base_level.into(),
        mass_scaling: s.mass_scaling,
    };
    let mut out: Vec<Config> = vec![Config {
        varied: "reference".into(),
        precision: "f64".into(),
        integration: "full".into(),
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
    for p in ["f64", "f32"] {
        for i in ["reduced", "full"] {
            push(Config {
                varied: "precision×integration".into(),
                precision: p.into(),
                integration: i.into(),
                ..b.clone()
            });
        }
    }
    if b.integration == "reduced" {
        for h in [0.05, 0.1, 0.2] {
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

/// Trilinear interpolation of a nodal field of `mesh` at arbitrary points.
pub struct Interpolator<'m> {
    mesh: &'m Mesh,
    lo: [f64; 3],
    h: [f64; 3],
    n: [usize; 3],
    bins: Vec<Vec<u32>>,
}

impl<'m> Interpolator<'m> {
    pub fn new(mesh: &'m Mesh) -> Self {
        let (lo, hi) = mesh.bounding_box();
        let k = ((mesh.cells.len() as f64).cbrt().ceil() as usize).max(1);
        let n = [k; 3];
        let h: [f64; 3] = core::array::from_fn(|i| ((hi[i] - lo[i]) / k as f64).max(1e-300));
        let mut bins = vec![Vec::new(); k * k * k];
        for c in 0..mesh.cells.len() {
            let x = mesh.cell_coords(c);
            let (mut a, mut b) = ([f64::MAX; 3], [f64::MIN; 3]);
            for p in &x {
                for i in 0..3 {
                    a[i] = a[i].min(p[i]);
                    b[i] = b[i].max(p[i]);
                }
            }
            // Pad by a quarter of the cell so nodes just outside still find it.
            let pad: [f64; 3] = core::array::from_fn(|i| 0.25 * (b[i] - a[i]));
            let r =
                |v: f64, i: usize| (((v - lo[i]) / h[i]).floor().max(0.0) as usize).min(n[i] - 1);
            for ix in r(a[0] - pad[0], 0)..=r(b[0] + pad[0], 0) {
                for iy in r(a[1] - pad[1], 1)..=r(b[1] + pad[1], 1) {
                    for iz in r(a[2] - pad[2], 2)..=r(b[2] + pad[2], 2) {
                        bins[ix + n[0] * (iy + n[1] * iz)].push(c as u32);
                    }
                }
            }
        }
        Interpolator {
            mesh,
            lo,
            h,
            n,
            bins,
        }
    }

    /// Natural coordinates of `p` in cell `c` (Newton on the trilinear map).
    fn natural(&self, c: usize, p: [f64; 3]) -> [f64; 3] {
        let x = self.mesh.cell_coords(c);
        let mut xi = [0.0; 3];
        for _ in 0..20 {
            let n = shape(xi);
            let g = pe_firmware::physics::hex::natural_gradients(xi);
            let mut r = [0.0; 3];
            let mut j = [[0.0; 3]; 3];
            for a in 0..8 {
                for i in 0..3 {
                    r[i] += n[a] * x[a][i];
                    for k in 0..3 {
                        j[i][k] += x[a][i] * g[a][k];
                    }
                }
            }
            let d: [f64; 3] = core::array::from_fn(|i| p[i] - r[i]);
            let Some(s) = solve3(j, d) else { break };
            for i in 0..3 {
                xi[i] += s[i];
            }
            if s.iter().map(|v| v.abs()).fold(0.0, f64::max) < 1e-12 {
                break;
            }
        }
        xi
    }

    /// The field `u` at `p`, or `None` when `p` lies more than a quarter cell outside the
    /// mesh (natural coordinate beyond ±1.5; inside that, the coordinates are clamped).
    pub fn at(&self, u: &[[f64; 3]], p: [f64; 3]) -> Option<[f64; 3]> {
        let b: [usize; 3] = core::array::from_fn(|i| {
            (((p[i] - self.lo[i]) / self.h[i]).floor().max(0.0) as usize).min(self.n[i] - 1)
        });
        let mut best: Option<(f64, usize, [f64; 3])> = None;
        for &c in &self.bins[b[0] + self.n[0] * (b[1] + self.n[1] * b[2])] {
            let xi = self.natural(c as usize, p);
            let out = xi.iter().map(|v| v.abs()).fold(0.0, f64::max);
            if !out.is_finite() {
                continue;
            }
            if best.is_none_or(|(o, _, _)| out < o) {
                best = Some((out, c as usize, xi));
            }
            if out <= 1.0 + 1e-9 {
                break;
            }
        }
        let (out, c, xi) = best?;
        if out > 1.5 {
            return None;
        }
        let n = shape(xi.map(|v| v.clamp(-1.0, 1.0)));
        let cell = self.mesh.cells[c];
        Some(core::array::from_fn(|i| {
            (0..8).map(|a| n[a] * u[cell[a] as usize][i]).sum()
        }))
    }
}

fn shape(xi: [f64; 3]) -> [f64; 8] {
    core::array::from_fn(|a| {
        let q = pe_firmware::physics::hex::NODE_XI[a];
        0.125 * (1.0 + q[0] * xi[0]) * (1.0 + q[1] * xi[1]) * (1.0 + q[2] * xi[2])
    })
}

fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    if !(det.abs() > 0.0) {
        return None;
    }
    let col = |k: usize| {
        let mut m = a;
        for i in 0..3 {
            m[i][k] = b[i];
        }
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    Some([col(0) / det, col(1) / det, col(2) / det])
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

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// What a run leaves for the comparison.
struct Done {
    row: Row,
    qoi: [f64; 3],
    u: Vec<[f64; 3]>,
    mesh: Mesh,
}

fn run_one(base: &Scene, dir: &Path, levels: &Levels, c: &Config, name: &str) -> Result<Done> {
    let mut sc = scene_at(base, levels, &c.level)?;
    sc.solver.precision = c.precision.clone();
    sc.solver.integration = c.integration.clone();
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
        precision: c.precision.clone(),
        integration: c.integration.clone(),
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
            use pe_firmware::image::{Integration, Precision};
            let p = if r.precision == "f32" {
                Precision::F32
            } else {
                Precision::F64
            };
            let i = if r.integration == "full" {
                Integration::Full
            } else {
                Integration::Reduced
            };
            let c = pe_firmware::profile::measured_cost(p, i);
            let step_s = c.step_instructions(r.elements, r.nodes)
                / pe_firmware::profile::PE_BOARD.clock_hz as f64;
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
    if scene.solver.duration.is_none() {
        // The grid changes dt: hold the simulated time, not the step count, fixed.
        let p = Problem::from_scene(&scene, dir)?;
        let (dt, _) = p.time_step()?;
        scene.solver.duration = Some(p.steps(dt) as f64 * dt);
    }
    scene.solver.steps = None;
    let (levels, base_level) = levels_of(&scene, opts);
    let configs = grid(&scene, &levels, &base_level);
    let mut done: Vec<Done> = Vec::new();
    for (k, c) in configs.iter().enumerate() {
        progress(&format!("[{}/{}] {}", k + 1, configs.len(), c.label()));
        done.push(run_one(&scene, dir, &levels, c, name)?);
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

fn csv_escape(s: &str) -> String {
    if s.contains(',') || s.contains('"') {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// The CSV: one row per configuration, a header naming every column.
pub fn to_csv(rows: &[Row]) -> Result<String> {
    let mut out = String::new();
    let header: Vec<String> = match serde_json::to_value(rows.first())? {
        serde_json::Value::Object(m) => m.keys().cloned().collect(),
        _ => vec![],
    };
    // serde_json's map is sorted; keep the struct's order instead.
    let order = [
        "varied",
        "precision",
        "integration",
        "hourglass",
        "dt_safety",
        "level",
        "mass_scaling",
        "elements",
        "nodes",
        "dt_s",
        "steps",
        "simulated_s",
        "wall_s",
        "host_ns_per_element_step",
        "real_time_factor",
        "board_instructions_per_element_step",
        "compared_nodes",
        "u_err_max_m",
        "u_err_rms_m",
        "u_err_max_rel",
        "u_err_rms_rel",
        "qoi",
        "qoi_value",
        "qoi_err_rel",
        "energy_j",
        "energy_err_rel",
        "pareto",
    ];
    debug_assert_eq!(header.len(), order.len());
    out.push_str(&order.join(","));
    out.push('\n');
    for r in rows {
        let v = serde_json::to_value(r)?;
        let cells: Vec<String> = order
            .iter()
            .map(|k| match &v[*k] {
                serde_json::Value::String(s) => csv_escape(s),
                serde_json::Value::Null => String::new(),
                other => other.to_string(),
            })
            .collect();
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    Ok(out)
}

/// Cost ratio full/reduced and the accuracy of each, per precision, from the cross rows at
/// the baseline.
pub fn full_reduced(rows: &[Row]) -> Vec<(String, f64, f64, f64)> {
    let base = rows.iter().find(|r| r.varied == "baseline");
    let mut v = Vec::new();
    for p in ["f64", "f32"] {
        let find = |i: &str| {
            rows.iter().find(|r| {
                r.precision == p
                    && r.integration == i
                    && base.is_some_and(|b| {
                        r.level == b.level
                            && r.dt_safety == b.dt_safety
                            && r.mass_scaling == b.mass_scaling
                            && (i == "full" || r.hourglass == b.hourglass)
                    })
            })
        };
        if let (Some(f), Some(red)) = (find("full"), find("reduced")) {
            v.push((
                p.to_string(),
                f.host_ns_per_element_step / red.host_ns_per_element_step,
                red.u_err_rms_rel,
                f.u_err_rms_rel,
            ));
        }
    }
    v
}

/// The markdown report: table, full/reduced cost ratio, how errors were measured.
pub fn to_markdown(rows: &[Row], name: &str) -> String {
    let mut s = format!("# Speed/accuracy trade-off: {name}\n\n");
    if let Some(r) = rows.first() {
        let _ = writeln!(
            s,
            "Reference: {} {} integration, level {}, dt safety {}, mass scaling {} ({} elements, {} steps, {:.1} s wall). Errors are at the end of {:.3} s simulated, relative ones over the reference's largest displacement (u) or its value (quantity of interest `{}`, energy = stored + kinetic). Cost: host wall time on one thread of this machine. `board instr/elem-step`: {BOARD_NOTE}. `*` marks the Pareto front of (wall s per simulated s, RMS displacement error).\n",
            r.precision, r.integration, r.level, r.dt_safety, r.mass_scaling, r.elements, r.steps, r.wall_s, r.simulated_s, r.qoi
        );
    }
    s.push_str("| varied | prec. | integr. | hg | safety | level | mass sc. | elements | steps | wall s | ns/elem-step | RTF | board instr/elem-step | u max err | u RMS err | QoI err | energy err | Pareto |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let hg = if r.integration == "full" {
            "–".to_string()
        } else {
            format!("{}", r.hourglass)
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.2} | {:.0} | {:.3} | {} | {:.2e} | {:.2e} | {:.2e} | {:.2e} | {} |",
            r.varied,
            r.precision,
            r.integration,
            hg,
            r.dt_safety,
            r.level,
            r.mass_scaling,
            r.elements,
            r.steps,
            r.wall_s,
            r.host_ns_per_element_step,
            r.real_time_factor,
            r.board_instructions_per_element_step,
            r.u_err_max_rel,
            r.u_err_rms_rel,
            r.qoi_err_rel,
            r.energy_err_rel,
            if r.pareto { "*" } else { "" }
        );
    }
    s.push_str("\n## Full against reduced integration\n\n");
    s.push_str("The seed claims reduced integration is 5 to 7 times cheaper than full.\n\n");
    s.push_str("| precision | measured cost full/reduced (host ns per element-step) | reduced: u RMS err | full: u RMS err |\n|---|---|---|---|\n");
    for (p, ratio, er, ef) in full_reduced(rows) {
        let _ = writeln!(s, "| {p} | {ratio:.2} | {er:.2e} | {ef:.2e} |");
    }
    s.push_str("\n## How the errors are measured\n\n");
    s.push_str("- Nodal displacement: at every node of the configuration's mesh, against the reference's field at the same point: node by node on the reference's own mesh, otherwise interpolated with the trilinear shape functions of the reference cell that holds the point (found by inverting the cell map); nodes more than a quarter cell outside the reference mesh are left out (`compared_nodes` in the CSV).\n");
    s.push_str("- Quantity of interest: the force of the tissue on the first tool (the probe) when the scene has tools, else the force the prescribed nodes exert on the tissue when the scene prescribes motion, otherwise the mean displacement of the tip face (largest x); the norm of the vector difference over the reference's norm.\n");
    s.push_str("- Energy: stored + kinetic energy at the end, relative to the reference's.\n");
    s.push_str("- Wall time is measured on a shared 2-core machine: expect ±20% between runs.\n");
    s
}

/// The PNG: error against cost, log axes, Pareto front drawn as a line, points labelled.
pub fn plot(rows: &[Row], path: &Path, title: &str) -> Result<()> {
    use plotters::prelude::*;
    crate::output::font::register_font();
    let pts: Vec<(f64, f64, &Row)> = rows
        .iter()
        .filter(|r| r.varied != "reference")
        .map(|r| (1.0 / r.real_time_factor, r.u_err_rms_rel.max(1e-16), r))
        .collect();
    if pts.is_empty() {
        bail!("nothing to plot");
    }
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (x, y, _) in &pts {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    let (x0, x1, y0, y1) = (x0 / 2.0, x1 * 3.0, y0 / 3.0, y1 * 3.0);
    let root = BitMapBackend::new(path, (1200, 800)).into_drawing_area();
    let err = |e: &dyn std::fmt::Debug| anyhow::anyhow!("plotting {}: {e:?}", path.display());
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 26))
        .margin(20)
        .x_label_area_size(60)
        .y_label_area_size(90)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("cost: host wall seconds per simulated second (1 / real-time factor)")
        .y_desc("RMS nodal displacement error / max reference displacement")
        .x_label_formatter(&|v| format!("{v:.2e}"))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .label_style(("sans-serif", 16))
        .axis_desc_style(("sans-serif", 18))
        .draw()
        .map_err(|e| err(&e))?;
    let mut front: Vec<(f64, f64)> = pts
        .iter()
        .filter(|p| p.2.pareto)
        .map(|p| (p.0, p.1))
        .collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart
        .draw_series(LineSeries::new(front.clone(), RED.stroke_width(2)))
        .map_err(|e| err(&e))?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
    let colour = |r: &Row| match r.varied.as_str() {
        "baseline" => BLACK,
        "precision×integration" => BLUE,
        "hourglass" => GREEN,
        "dt_safety" => MAGENTA,
        "level" => CYAN,
        _ => RGBColor(230, 140, 0),
    };
    for group in [
        "baseline",
        "precision×integration",
        "hourglass",
        "dt_safety",
        "level",
        "mass_scaling",
    ] {
        let g: Vec<&(f64, f64, &Row)> = pts.iter().filter(|p| p.2.varied == group).collect();
        if g.is_empty() {
            continue;
        }
        let c = colour(g[0].2);
        chart
            .draw_series(g.iter().map(|p| Circle::new((p.0, p.1), 6, c.filled())))
            .map_err(|e| err(&e))?
            .label(format!("varied: {group}"))
            .legend(move |(x, y)| Circle::new((x + 10, y), 6, c.filled()));
    }
    chart
        .draw_series(
            front
                .iter()
                .map(|p| Circle::new(*p, 11, RED.stroke_width(2))),
        )
        .map_err(|e| err(&e))?;
    // Short labels: what differs from the baseline; alternately above and below the
    // point so that neighbours do not overwrite each other.
    for (k, (x, y, r)) in pts.iter().enumerate() {
        let text = match r.varied.as_str() {
            "baseline" => format!("baseline ({} {})", r.precision, r.integration),
            "precision×integration" => format!("{} {}", r.precision, r.integration),
            "hourglass" => format!("hourglass {}", r.hourglass),
            "dt_safety" => format!("safety {}", r.dt_safety),
            "level" => format!("level {}", r.level),
            "mass_scaling" => format!("mass ×{}", r.mass_scaling),
            other => other.to_string(),
        };
        let dy = if k % 2 == 0 { 1.12 } else { 0.86 };
        chart
            .draw_series(std::iter::once(Text::new(
                text,
                (*x * 1.1, *y * dy),
                ("sans-serif", 14).into_font(),
            )))
            .map_err(|e| err(&e))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 16))
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

/// `pe tradeoff`: runs the grid, writes DIR/tradeoff.csv, .md and .png, prints the table.
pub fn run_cli(scene: &Scene, dir: &Path, name: &str, opts: &Options, out: &Path) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let rows = run(scene, dir, name, opts, &mut |s| eprintln!("{s}"))?;
    let csv = out.join("tradeoff.csv");
    std::fs::write(&csv, to_csv(&rows)?).with_context(|| format!("writing {}", csv.display()))?;
    let md = to_markdown(&rows, name);
    let mdp = out.join("tradeoff.md");
    std::fs::write(&mdp, &md).with_context(|| format!("writing {}", mdp.display()))?;
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
