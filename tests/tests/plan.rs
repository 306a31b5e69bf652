//! `pe plan`: the planned model's error, measured here independently of the planner, stays
//! within the budget on the built-in scene (tool and contact) and on a shared mesh with a
//! load; a budget of 0 gives back the full model; pruning never removes what a tool, a
//! contact surface, a load or a prescribed motion touches; the written scene runs unchanged
//! through the solver, the compiler and board-sim.

use host_tools::compare::nan_max;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use host_tools::analysis::plan::{self, prune, CellKind, Options, PlanReport, Target};
use host_tools::problem::{NodeKind, Problem};
use host_tools::scene::builtin::builtin_scene;
use host_tools::scene::Scene;
use host_tools::solver;
use system_tests::*;

fn options(budget_rel: f64) -> Options {
    Options {
        budget_rel,
        target: Target::Cheapest,
        watch: vec![],
        profile: "pe-board".into(),
    }
}

/// The scene on the shared parametric uterus (320 cells): held at its lower end, a 5 mN
/// downward load on the tip of the left tube (the nodes within 4 mm of the tube's node
/// farthest from the mesh's centre), ramped in over 50 ms; 0.1 s.
fn loaded_uterus(dir: &Path, prescribed: bool) -> PathBuf {
    let mesh_path = shared_meshes_dir().join("uterus_scaffold_hex320.msh");
    let mesh = host_tools::mesh::io::load_mesh(&mesh_path).expect("shared mesh");
    let tube = *mesh
        .region_names
        .iter()
        .find(|(_, n)| *n == "left_oviduct")
        .expect("left_oviduct region")
        .0;
    let tip = |region: i32| {
        let c: [f64; 3] = core::array::from_fn(|i| {
            mesh.nodes.iter().map(|p| p[i]).sum::<f64>() / mesh.nodes.len() as f64
        });
        let d = |p: &[f64; 3]| (0..3).map(|i| (p[i] - c[i]).powi(2)).sum::<f64>();
        mesh.cells
            .iter()
            .zip(&mesh.cell_regions)
            .filter(|(_, r)| **r == region)
            .flat_map(|(cell, _)| cell.iter().map(|&n| mesh.nodes[n as usize]))
            .fold([0.0; 3], |best, p| if d(&p) > d(&best) { p } else { best })
    };
    let t = tip(tube);
    let mut text = format!(
        r#"[mesh]
file = "{}"

[material]
law = "neo-hookean"
youngs_modulus = 10.0e3
poisson_ratio = 0.45
density = 1000.0

[[fixed]]
box = [[-1.0, -1.0, -1.0], [1.0, 1.0, -0.07]]

[[load]]
sphere = {{ center = [{}, {}, {}], radius = 0.004 }}
force = [0.0, 0.0, -0.005]
ramp = [[0.0, 0.0], [0.05, 1.0]]

[solver]
damping = 20.0
duration = 0.1
"#,
        mesh_path.display(),
        t[0],
        t[1],
        t[2]
    );
    if prescribed {
        let right = *mesh
            .region_names
            .iter()
            .find(|(_, n)| *n == "right_oviduct")
            .expect("right_oviduct region")
            .0;
        let r = tip(right);
        text += &format!(
            "\n[[prescribed]]\nsphere = {{ center = [{}, {}, {}], radius = 0.004 }}\npath = [[0.0, 0.0, 0.0, 0.0], [0.05, 0.0, 0.002, 0.0]]\n",
            r[0], r[1], r[2]
        );
    }
    let p = dir.join("scene.toml");
    std::fs::write(&p, text).expect("scene written");
    p
}

/// Node of the full mesh at each node of the planned mesh, by exact coordinates (the plan
/// writes coordinates in their shortest round-trip form).
fn node_match(full: &Problem, planned: &Problem) -> Vec<usize> {
    let key = |p: &[f64; 3]| p.map(f64::to_bits);
    let at: HashMap<[u64; 3], usize> = full
        .mesh
        .nodes
        .iter()
        .enumerate()
        .map(|(n, p)| (key(p), n))
        .collect();
    planned
        .mesh
        .nodes
        .iter()
        .map(|p| {
            *at.get(&key(p))
                .expect("a planned node is a node of the full mesh")
        })
        .collect()
}

/// Tool force averaged over each of `windows` equal windows of `duration_s` (a run with a
/// constant step `dt_s`; `series[step * tools + tool]`).
fn window_means(
    series: &[[f64; 3]],
    tools: usize,
    dt_s: f64,
    duration_s: f64,
    windows: usize,
) -> Vec<Vec<f64>> {
    (0..tools)
        .map(|t| {
            let per: Vec<[f64; 3]> = series.iter().skip(t).step_by(tools).copied().collect();
            (1..=windows)
                .map(|k| {
                    let (lo, hi) = (
                        duration_s * (k - 1) as f64 / windows as f64,
                        duration_s * k as f64 / windows as f64,
                    );
                    let inside: Vec<[f64; 3]> = per
                        .iter()
                        .enumerate()
                        .filter(|(s, _)| {
                            let time = (*s as f64 + 1.0) * dt_s;
                            time > lo && time <= hi
                        })
                        .map(|(_, f)| *f)
                        .collect();
                    assert!(!inside.is_empty(), "window {k} holds a step");
                    let m: [f64; 3] = core::array::from_fn(|i| {
                        inside.iter().map(|f| f[i]).sum::<f64>() / inside.len() as f64
                    });
                    (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt()
                })
                .collect()
        })
        .collect()
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Checks a plan independently of the planner: the full scene and the written one run
/// here, the final displacements of the touched nodes (contact surfaces, loads) compared
/// node by node, and, with a tool, the tool force's 1 ms and 40 ms window means (its
/// magnitude: a weaker check than the planner's vector difference, done from the raw
/// per-step series).
/// Returns (planned problem, displacement error, force error).
fn check_plan(
    full_scene: &Scene,
    dir: &Path,
    out: &Path,
    r: &PlanReport,
) -> (Problem, f64, Option<f64>) {
    let full = Problem::from_scene(full_scene, dir).expect("full scene");
    let planned_scene = Scene::from_file(&out.join("scene.toml")).expect("written scene parses");
    let planned = Problem::from_scene(&planned_scene, out).expect("written scene resolves");
    assert_eq!(planned.mesh.cells.len(), r.final_model.elements);
    let a = solver::run(&full, "full", &mut ()).expect("full run");
    let b = solver::run(&planned, "planned", &mut ()).expect("planned run");
    let map = node_match(&full, &planned);
    assert_eq!(map.len(), b.displacements.len());
    let mut touched: Vec<usize> = full.loads.iter().map(|l| l.node as usize).collect();
    if let Some(c) = &full.contact {
        touched.extend(c.node_globals.iter().map(|&n| n as usize));
    }
    touched.sort_unstable();
    touched.dedup();
    assert!(!touched.is_empty());
    let back: HashMap<usize, usize> = map.iter().enumerate().map(|(k, &n)| (n, k)).collect();
    let u_ref = touched
        .iter()
        .map(|&n| norm(a.displacements[n]))
        .fold(0.0, nan_max);
    assert!(u_ref > 1e-4, "the touched nodes moved: {u_ref:e} m");
    let mut e = 0.0f64;
    for &n in &touched {
        let k = back[&n];
        let d: [f64; 3] = core::array::from_fn(|i| a.displacements[n][i] - b.displacements[k][i]);
        e = e.max(norm(d));
    }
    // At the rates the force's consumers sample it: 1 ms means (a haptic loop) and 40 ms
    // means (a graphics frame); the worse of the two.
    let force = full.contact.as_ref().map(|c| {
        let tools = c.tool_names.len();
        assert!(tools > 0);
        let duration = full_scene.solver.duration.expect("duration");
        [1e-3, 0.04]
            .into_iter()
            .map(|window_s| {
                let windows = (duration / window_s).round() as usize;
                assert!(
                    windows > 10 && (windows as f64 * window_s - duration).abs() < 1e-9,
                    "{duration} s is a whole number of {window_s} s windows"
                );
                let fa = window_means(&a.tool_force, tools, full.time_step.dt_s, duration, windows);
                let fb = window_means(
                    &b.tool_force,
                    tools,
                    planned.time_step.dt_s,
                    duration,
                    windows,
                );
                assert_eq!(fa.len(), fb.len());
                fa.iter()
                    .zip(&fb)
                    .map(|(x, y)| {
                        assert_eq!(x.len(), y.len());
                        assert_eq!(x.len(), windows);
                        // (f64::max below would drop a NaN.)
                        assert!(x.iter().chain(y).all(|v| v.is_finite()), "finite means");
                        let peak = x.iter().copied().fold(0.0, nan_max);
                        assert!(
                            peak > 1e-4,
                            "the tool pressed: peak window force {peak:e} N"
                        );
                        x.iter()
                            .zip(y)
                            .map(|(p, q)| (p - q).abs())
                            .fold(0.0, nan_max)
                            / peak
                    })
                    .fold(0.0, nan_max)
            })
            .fold(0.0, nan_max)
    });
    (planned, e / u_ref, force)
}

/// The built-in scene (coarse, its 0.6 s), budget 2%: a model with fewer elements, its
/// error within the budget by the planner's measure and by this test's own, and the
/// written scene runs through the compiler and board-sim: one board bit-identical to the
/// solver, a 2x2x2 machine within round-off of the sums' order.
#[test]
fn the_planned_builtin_scene_stays_within_its_budget_and_runs_everywhere() {
    let out = temp_dir("plan-builtin");
    let scene = builtin_scene("coarse").expect("builtin");
    let r = plan::run(
        &scene,
        Path::new("."),
        "builtin:coarse",
        &options(0.02),
        &out,
    )
    .expect("plan");
    assert!(r.within_budget, "{:?}", r.final_model);
    let full_elements = r.rows[0].elements;
    assert!(
        r.final_model.elements < full_elements,
        "the plan pruned: {} of {full_elements}",
        r.final_model.elements
    );
    let (planned, u_err, f_err) = check_plan(&scene, Path::new("."), &out, &r);
    println!("builtin coarse: {} of {full_elements} elements, displacement error {u_err:e}, tool force error {f_err:?}", planned.mesh.cells.len());
    assert!(u_err <= 0.02, "displacement error {u_err:e}");
    let f_err = f_err.expect("the scene has a tool");
    assert!(f_err <= 0.02, "tool force error {f_err:e}");
    for name in ["plan.md", "plan.json", "plan.png", "mesh.msh"] {
        let len = std::fs::metadata(out.join(name))
            .map(|m| m.len())
            .unwrap_or(0);
        assert!(len > 100, "{name} written ({len} bytes)");
    }
    // Unchanged through the compiler and board-sim.
    let serial = solver::run(&planned, "planned", &mut ())
        .expect("solve")
        .displacements;
    assert!(max_abs(&serial) > 1e-4);
    let src = out.join("scene.toml").display().to_string();
    let one = compile(&planned, &src, "1x1x1", "plan-b111");
    let sim =
        board_sim::run(&one, &board_sim::SimOptions::default(), &mut |_, _| {}).expect("board-sim");
    assert_bit_identical(
        &serial,
        &sim.displacements,
        "planned scene, 1x1x1 against the solver",
    );
    let eight = compile(&planned, &src, "2x2x2", "plan-b222");
    let sim = board_sim::run(&eight, &board_sim::SimOptions::default(), &mut |_, _| {})
        .expect("board-sim");
    let d = max_rel_diff(&serial, &sim.displacements);
    let tol = match planned.solver.precision {
        pe_firmware::image::Precision::F64 => 1e-12,
        pe_firmware::image::Precision::F32 => 1e-4,
    };
    assert!(d < tol, "2x2x2 against the solver: {d:e}");
    live_serves_the_plan(&scene, &out, &planned, full_elements);
}

/// `pe live --plan DIR` (issue 60) on the plan just made: where the full model cannot keep
/// up (a `--min-rtf` no machine reaches) it serves the plan, read back, not planned again,
/// and says so; where it can (`--min-rtf 0`), the full model; a plan for another scene is
/// refused, naming both.
fn live_serves_the_plan(scene: &Scene, out: &Path, planned: &Problem, full_elements: usize) {
    use host_tools::live::model::{choose, read_plan, ModelArgs};
    let plan_json = std::fs::read(out.join("plan.json")).expect("plan.json");
    assert!(plan_json.len() > 100, "plan.json written");
    let args = |min_rtf| ModelArgs {
        plan: Some(out.to_path_buf()),
        plan_budget: "2%".into(),
        min_rtf,
    };
    let here = Path::new(".");
    let (name, arg) = ("builtin:coarse", "--builtin --level coarse");
    let c = choose(scene, here, name, arg, &args(1e9), 1).expect("the plan chosen");
    println!("pe live --min-rtf 1e9: {}", c.note);
    assert!(
        c.planned && c.note.starts_with("planned model"),
        "{}",
        c.note
    );
    assert!(c.note.contains("budget 2.000%"), "{}", c.note);
    assert_eq!(c.problem.mesh.cells.len(), planned.mesh.cells.len());
    assert!(planned.mesh.cells.len() < full_elements);
    assert_eq!(c.scene_arg, out.join("scene.toml").display().to_string());
    let again = std::fs::read(out.join("plan.json")).expect("plan.json");
    assert_eq!(again, plan_json, "the plan was read back, not made again");
    let c = choose(scene, here, name, arg, &args(0.0), 1).expect("the full model chosen");
    assert!(!c.planned && c.note.starts_with("full model"), "{}", c.note);
    assert_eq!(c.problem.mesh.cells.len(), full_elements);
    let e = read_plan(out, "builtin:medium")
        .err()
        .map(|e| e.to_string());
    let e = e.expect("a plan for another scene is refused");
    assert!(
        e.contains("builtin:coarse") && e.contains("builtin:medium"),
        "{e}"
    );
}

/// A shared mesh with a load (no tool): the same, by the displacement of the loaded nodes.
#[test]
fn a_planned_shared_mesh_with_a_load_stays_within_its_budget() {
    let dir = temp_dir("plan-load");
    let path = loaded_uterus(&dir, false);
    let scene = Scene::from_file(&path).expect("scene");
    let out = dir.join("plan");
    let r = plan::run(&scene, &dir, "uterus320 loaded", &options(0.02), &out).expect("plan");
    assert!(r.within_budget, "{:?}", r.final_model);
    assert!(
        r.final_model.elements < r.rows[0].elements,
        "the plan pruned"
    );
    let (planned, u_err, f_err) = check_plan(&scene, &dir, &out, &r);
    println!(
        "uterus320: {} of {} elements, displacement error {u_err:e}",
        planned.mesh.cells.len(),
        r.rows[0].elements
    );
    assert!(f_err.is_none());
    assert!(u_err <= 0.02, "displacement error {u_err:e}");
}

/// A voxel mesh is coarsened when the budget allows it: `scenes/liver.toml` (the shared
/// voxelised liver, 1997 voxels of 8.4 mm, under gravity).
/// - Budget 2%: the coarsening is tried and measured (its row compares at least 90% of
///   the reference's nodes, it doubles the step), and accepted exactly when its errors
///   are within the budget.
/// - Budget 25%: the plan keeps a coarsened model: at most a quarter of the elements on
///   16.8 mm voxels (or coarser), at least 8x fewer element-steps per simulated second, its
///   error within the budget by the planner's measure and by this test's own: both models
///   run here, their final displacements compared at the planned nodes that are nodes of
///   the full mesh (no interpolation), against the largest there.
#[test]
fn a_voxel_mesh_is_coarsened_when_its_budget_allows() {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/liver.toml");
    let dir = path.parent().expect("scenes dir").to_path_buf();
    let scene = Scene::from_file(&path).expect("scene");
    let out = temp_dir("plan-voxels");
    let tight = plan::run(&scene, &dir, "liver", &options(0.02), &out.join("tight")).expect("plan");
    let full = &tight.rows[0];
    let row = tight
        .rows
        .iter()
        .find(|r| r.choice.starts_with("voxels coarsened 2x"))
        .expect("coarsening tried");
    assert!(
        row.elements * 4 <= full.elements,
        "{} of {}",
        row.elements,
        full.elements
    );
    assert!(
        row.compared_nodes * 10 >= 9 * full.nodes,
        "{} of {} nodes compared",
        row.compared_nodes,
        full.nodes
    );
    assert!(
        row.dt_s > 1.9 * full.dt_s,
        "{} s against {} s",
        row.dt_s,
        full.dt_s
    );
    assert!(row.displacement_err_rel.is_finite() && row.displacement_err_rel > 0.0);
    assert_eq!(row.accepted, row.displacement_err_rel <= 0.02);

    let budget = 0.25;
    let wide = out.join("wide");
    let r = plan::run(&scene, &dir, "liver", &options(budget), &wide).expect("plan");
    assert!(r.within_budget, "{:?}", r.final_model);
    assert!(r.final_model.displacement_err_rel <= budget);
    assert!(
        r.final_model.elements * 4 <= full.elements,
        "{} of {}",
        r.final_model.elements,
        full.elements
    );
    assert!(r.saving_factor >= 8.0, "{}x", r.saving_factor);
    let a = Problem::from_scene(&scene, &dir).expect("full");
    let planned_scene = Scene::from_file(&wide.join("scene.toml")).expect("written scene parses");
    let b = Problem::from_scene(&planned_scene, &wide).expect("written scene resolves");
    let lat = host_tools::mesh::coarsen::lattice(&b.mesh).expect("still a voxel mesh");
    assert!(
        lat.h_m
            > 1.9
                * host_tools::mesh::coarsen::lattice(&a.mesh)
                    .expect("voxels")
                    .h_m
    );
    let ua = solver::run(&a, "full", &mut ())
        .expect("full run")
        .displacements;
    let ub = solver::run(&b, "planned", &mut ())
        .expect("planned run")
        .displacements;
    assert_eq!(ua.len(), a.mesh.nodes.len());
    assert_eq!(ub.len(), b.mesh.nodes.len());
    let key = |x: [f64; 3]| -> [i64; 3] { core::array::from_fn(|i| (x[i] * 1e7).round() as i64) };
    let full_at: HashMap<[i64; 3], usize> = a
        .mesh
        .nodes
        .iter()
        .enumerate()
        .map(|(n, &x)| (key(x), n))
        .collect();
    let pairs: Vec<(usize, usize)> = b
        .mesh
        .nodes
        .iter()
        .enumerate()
        .filter_map(|(k, &x)| full_at.get(&key(x)).map(|&n| (n, k)))
        .collect();
    assert!(
        pairs.len() * 2 >= b.mesh.nodes.len(),
        "{} of {} planned nodes are full-mesh nodes",
        pairs.len(),
        b.mesh.nodes.len()
    );
    let u_ref = pairs.iter().map(|&(n, _)| norm(ua[n])).fold(0.0, nan_max);
    assert!(u_ref > 1e-3, "the liver sagged: {u_ref:e} m");
    let e = pairs
        .iter()
        .map(|&(n, k)| norm(core::array::from_fn(|i| ua[n][i] - ub[k][i])))
        .fold(0.0, nan_max)
        / u_ref;
    println!(
        "liver: {} of {} elements, planner's error {:.4}, this test's {e:.4}",
        r.final_model.elements, full.elements, r.final_model.displacement_err_rel
    );
    assert!(e <= budget, "displacement error {e:e}");
}

/// Budget 0: nothing may change, so the written model is the full one, run to the same
/// bits.
#[test]
fn a_budget_of_zero_gives_the_full_model() {
    let out = temp_dir("plan-zero");
    let scene = builtin_scene("coarse").expect("builtin");
    let r = plan::run(
        &scene,
        Path::new("."),
        "builtin:coarse",
        &options(0.0),
        &out,
    )
    .expect("plan");
    let full = Problem::from_scene(&scene, Path::new(".")).expect("full");
    assert_eq!(r.rows.len(), 1, "only the reference ran");
    assert_eq!(r.final_model.elements, full.mesh.cells.len());
    assert_eq!(r.pruned_elements, 0);
    let planned = Problem::from_scene(
        &Scene::from_file(&out.join("scene.toml")).expect("parses"),
        &out,
    )
    .expect("resolves");
    assert_eq!(planned.mesh.cells, full.mesh.cells);
    assert_eq!(planned.mesh.nodes, full.mesh.nodes);
    assert_eq!(planned.solver.precision, full.solver.precision);
    assert_eq!(planned.time_step.dt_s, full.time_step.dt_s);
    assert_eq!(r.final_model.displacement_err_rel, 0.0);
    assert_eq!(r.final_model.tool_force_err_rel, Some(0.0));
    assert!(r.within_budget);
}

/// Pruning as hard as it goes (everything moving less than half the largest motion) still
/// keeps every element around a tool's or a contact pair's surface node, a loaded node and
/// a prescribed node (found here from the resolved problem), holds none of those nodes,
/// and gives the reduced problem the same loads, contact faces and prescribed nodes.
#[test]
fn pruning_never_removes_what_tools_contacts_loads_or_prescribed_motions_touch() {
    let dir = temp_dir("plan-prune");
    let path = loaded_uterus(&dir, true);
    let uterus = Scene::from_file(&path).expect("scene");
    let builtin = builtin_scene("coarse").expect("builtin");
    for (scene, sdir) in [(uterus, dir.to_path_buf()), (builtin, PathBuf::from("."))] {
        let mut scene = scene;
        scene.solver.duration = None;
        scene.solver.steps = Some(1500);
        let p = Problem::from_scene(&scene, &sdir).expect("resolves");
        let pilot = plan::trace::run(&p, "pilot").expect("pilot");
        let mut touched = vec![false; p.mesh.nodes.len()];
        for l in &p.loads {
            touched[l.node as usize] = true;
        }
        for (n, k) in p.node_kind.iter().enumerate() {
            if matches!(k, NodeKind::Prescribed(_)) {
                touched[n] = true;
            }
        }
        if let Some(c) = &p.contact {
            for s in &c.surfaces {
                for (q, _) in &s.faces {
                    for &n in q {
                        touched[n as usize] = true;
                    }
                }
            }
        }
        let driven = prune::driven_nodes(&p, &[]).expect("driven");
        let pilot = prune::Pilot {
            motion_m: &pilot.motion_m,
            energy_j: &pilot.energy_j,
        };
        let r = prune::prune(&p, &scene, pilot, &driven, Some(0.5)).expect("prunes");
        let pruned = r
            .cell_kind
            .iter()
            .filter(|k| **k == CellKind::Pruned)
            .count();
        assert!(pruned > 0, "{}: something was pruned", p.mesh.source);
        assert!(touched.iter().any(|&t| t));
        for (c, cell) in p.mesh.cells.iter().enumerate() {
            if cell.iter().any(|&n| touched[n as usize]) {
                assert_ne!(
                    r.cell_kind[c],
                    CellKind::Pruned,
                    "cell {c} touches a driven node"
                );
            }
        }
        let q = r.problem().expect("the reduced scene resolves");
        let held: Vec<usize> = (0..p.mesh.nodes.len())
            .filter(|&n| touched[n])
            .map(|n| r.node_map[n].expect("a touched node is kept") as usize)
            .filter(|&k| q.node_kind[k] == NodeKind::Fixed)
            .collect();
        let fixed_before: usize = (0..p.mesh.nodes.len())
            .filter(|&n| touched[n] && p.node_kind[n] == NodeKind::Fixed)
            .count();
        assert_eq!(
            held.len(),
            fixed_before,
            "no touched node is held at the cut"
        );
        assert_eq!(q.loads.len(), p.loads.len());
        for (a, b) in p.loads.iter().zip(&q.loads) {
            assert_eq!(r.node_map[a.node as usize], Some(b.node));
            assert_eq!(a.force, b.force);
        }
        let presc = |pp: &Problem| {
            pp.node_kind
                .iter()
                .filter(|k| matches!(k, NodeKind::Prescribed(_)))
                .count()
        };
        assert_eq!(presc(&q), presc(&p));
        match (&p.contact, &q.contact) {
            (Some(a), Some(b)) => {
                assert_eq!(a.surfaces.len(), b.surfaces.len());
                for (sa, sb) in a.surfaces.iter().zip(&b.surfaces) {
                    let mut fa: Vec<[u32; 4]> = sa
                        .faces
                        .iter()
                        .map(|(f, _)| f.map(|n| r.node_map[n as usize].unwrap_or(u32::MAX)))
                        .collect();
                    let mut fb: Vec<[u32; 4]> = sb.faces.iter().map(|(f, _)| *f).collect();
                    fa.sort_unstable();
                    fb.sort_unstable();
                    assert!(!fa.is_empty());
                    assert_eq!(fa, fb, "surface {} keeps exactly its faces", sa.name);
                }
            }
            (None, None) => {}
            _ => panic!("contact kept or lost"),
        }
    }
}

/// A contact pair that never touches costs every step and changes nothing: the built-in
/// scene plus a pair between the left tube and the vagina (tens of millimetres apart, the
/// probe on the other side) runs to the same tool-force bits as without it (checked here,
/// so the pair is truly inert), and `pe plan` drops it with its two surfaces, and the
/// written scene is within the budget of the scene without the pair by this test's own
/// measure.
#[test]
fn a_contact_pair_that_never_touches_is_dropped() {
    use host_tools::scene::{ContactPairSpec, RegionRef, SurfaceSpec};
    let out = temp_dir("plan-pair");
    let base = builtin_scene("coarse").expect("builtin");
    let mut scene = base.clone();
    for (name, region) in [("left_tube", "left_oviduct"), ("vagina", "vagina")] {
        scene.surface.push(SurfaceSpec {
            name: name.into(),
            region: Some(RegionRef::Name(region.into())),
            box_: None,
            sphere: None,
            set: None,
        });
    }
    scene.contact_pair.push(ContactPairSpec {
        surfaces: ["left_tube".into(), "vagina".into()],
        depth: None,
    });
    let with = Problem::from_scene(&scene, Path::new(".")).expect("with the pair");
    let without = Problem::from_scene(&base, Path::new(".")).expect("without");
    let (cw, co) = (
        with.contact.as_ref().expect("contact"),
        without.contact.as_ref().expect("contact"),
    );
    assert_eq!(cw.pairs.len(), co.pairs.len() + 1);
    assert!(
        cw.node_globals.len() > co.node_globals.len() + 50,
        "the pair adds contact nodes"
    );
    let a = solver::run(&with, "with", &mut ()).expect("run");
    let b = solver::run(&without, "without", &mut ()).expect("run");
    assert_eq!(a.tool_force.len(), b.tool_force.len());
    let peak = b.tool_force.iter().map(|f| norm(*f)).fold(0.0, nan_max);
    assert!(peak > 1e-3, "the probe pressed: {peak:e} N");
    assert_eq!(a.tool_force, b.tool_force, "the extra pair never acts");

    let r = plan::run(
        &scene,
        Path::new("."),
        "builtin:coarse+pair",
        &options(0.02),
        &out,
    )
    .expect("plan");
    let dropped = r
        .rows
        .iter()
        .find(|row| row.choice.contains("\"left_tube\"-\"vagina\""))
        .expect("the pair was tried");
    assert!(dropped.accepted, "{dropped:?}");
    assert!(r.within_budget);
    let written = Scene::from_file(&out.join("scene.toml")).expect("parses");
    assert!(written
        .contact_pair
        .iter()
        .all(|p| !p.surfaces.contains(&"vagina".to_string())));
    assert!(written
        .surface
        .iter()
        .all(|s| s.name != "left_tube" && s.name != "vagina"));
    assert_eq!(written.tool.len(), 1, "the probe stays");
    let (_, u_err, f_err) = check_plan(&base, Path::new("."), &out, &r);
    assert!(u_err <= 0.02, "displacement error {u_err:e}");
    let f_err = f_err.expect("the scene has a tool");
    assert!(f_err <= 0.02, "tool force error {f_err:e}");
}
