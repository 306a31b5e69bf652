//! `pe tradeoff`: the grid, the error measures, the Pareto front and the files it writes.

use std::path::PathBuf;

use host_tools::analysis::tradeoff::{self, Interpolator, Options};
use host_tools::scene::Scene;

/// A damped cantilever under gravity, settled by the end (damping 30/s ≈ critical for its
/// first bending mode, ω₁ ≈ 14 rad/s, over 1 s): the errors are then mostly spatial.
fn beam() -> Scene {
    Scene::from_toml(
        r#"
[mesh]
generate = { kind = "box", size = [0.1, 0.02, 0.02], cells = [6, 2, 2] }
[material]
law = "neo-hookean"
youngs_modulus = 5e4
poisson_ratio = 0.45
density = 1000.0
[[fixed]]
box = [[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]
[gravity]
acceleration = [0.0, 0.0, -9.81]
[solver]
damping = 30.0
duration = 1.0
"#,
    )
    .expect("scene parses")
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pe-tradeoff-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Trilinear shape functions reproduce linear fields, so the interpolated reference field of
/// a linear displacement is exact at any point inside a distorted mesh (round-off: 1e-12);
/// a point far outside is refused rather than extrapolated.
#[test]
fn interpolation_is_exact_for_linear_fields_on_a_distorted_mesh() {
    let mesh = host_tools::analysis::stability::skewed_mesh();
    let lin = |x: [f64; 3]| {
        [
            0.3 * x[0] - 0.1 * x[2],
            0.2 * x[1] + 0.05,
            -0.4 * x[0] + x[2],
        ]
    };
    let u: Vec<[f64; 3]> = mesh.nodes.iter().map(|x| lin(*x)).collect();
    let it = Interpolator::new(&mesh);
    let mut worst = 0.0f64;
    let mut found = 0;
    // Points at cell centroids and between nodes of each cell (all inside the mesh).
    for c in 0..mesh.cells.len() {
        let x = mesh.cell_coords(c);
        for w in [[0.125; 8], [0.5, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05, 0.05]] {
            let p: [f64; 3] = core::array::from_fn(|i| (0..8).map(|a| w[a] * x[a][i]).sum());
            let got = it.at(&u, p).expect("inside the mesh");
            let want = lin(p);
            found += 1;
            for i in 0..3 {
                worst = worst.max((got[i] - want[i]).abs());
            }
        }
    }
    println!("{found} points, worst error {worst:e}");
    assert!(worst < 1e-12, "interpolation error {worst:e}");
    assert!(
        it.at(&u, [1.0, 1.0, 1.0]).is_none(),
        "far outside must be refused"
    );
}

/// The whole command on a small box scene: the grid holds every factor, the reference has
/// zero error, refinement and the hourglass coefficient move the error the way the theory
/// says, the step counts follow the closed forms (dt ∝ safety, dt ∝ √mass_scaling), the
/// Pareto front is exactly the non-dominated set, and the three files are written.
#[test]
fn tradeoff_grid_on_a_box_scene() {
    let dir = temp_dir("box");
    let opts = Options {
        fine: false,
        level: None,
        profile: &pe_firmware::profile::PE_BOARD,
    };
    tradeoff::run_cli(&beam(), std::path::Path::new("."), "beam", &opts, &dir).unwrap();
    let csv = std::fs::read_to_string(dir.join("tradeoff.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    for col in [
        "precision",
        "integration",
        "hourglass",
        "dt_safety",
        "level",
        "mass_scaling",
        "host_ns_per_element_step",
        "steps",
        "wall_s",
        "real_time_factor",
        "board_instructions_per_element_step",
        "u_err_max_m",
        "u_err_rms_m",
        "qoi_err_rel",
        "energy_err_rel",
        "pareto",
    ] {
        assert!(header.contains(&col), "column {col} missing: {header:?}");
    }
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let get = |r: &Vec<String>, name: &str| -> f64 { r[col(name)].parse().unwrap() };
    let find = |pred: &dyn Fn(&Vec<String>) -> bool| -> &Vec<String> {
        rows.iter().find(|r| pred(r)).expect("row in the grid")
    };
    let is = |r: &Vec<String>, name: &str, v: &str| r[col(name)] == v;
    let base = |r: &Vec<String>| is(r, "varied", "baseline");
    // Reference first, f64 full at the finest level (x2), zero error against itself.
    let reference = &rows[0];
    assert!(is(reference, "varied", "reference") && is(reference, "integration", "full"));
    assert!(is(reference, "level", "x2") && is(reference, "precision", "f64"));
    for e in [
        "u_err_max_m",
        "u_err_rms_m",
        "qoi_err_rel",
        "energy_err_rel",
    ] {
        assert_eq!(get(reference, e), 0.0, "{e} of the reference");
    }
    // The precision × integration cross at the baseline's level.
    for p in ["f32", "f64"] {
        for i in ["reduced", "full"] {
            find(&|r| is(r, "precision", p) && is(r, "integration", i) && is(r, "level", "x1"));
        }
    }
    for (factor, values) in [
        ("hourglass", vec!["physical", "0.05", "0.1", "0.2"]),
        ("dt_safety", vec!["0.5", "0.9"]),
        ("level", vec!["x0.5", "x1", "x2"]),
        ("mass_scaling", vec!["1.0", "4.0", "16.0"]),
    ] {
        for v in values {
            find(&|r| is(r, factor, v) && is(r, "integration", "reduced"));
        }
    }
    // Board column: the measured firmware cost of the row's precision and integration.
    for r in &rows {
        use pe_firmware::image::{Integration, Precision};
        let p = if r[col("precision")] == "f32" {
            Precision::F32
        } else {
            Precision::F64
        };
        let i = if r[col("integration")] == "full" {
            Integration::Full
        } else {
            Integration::Reduced
        };
        let expected = pe_firmware::profile::measured_cost(p, i)
            .step_per_element
            .to_string();
        let cell = &r[col("board_instructions_per_element_step")];
        assert!(
            cell.starts_with(&format!("{expected} ")),
            "{cell} vs {expected}"
        );
    }
    // Refinement: the coarser mesh is farther from the reference (spatial convergence).
    let lv = |l: &str| {
        find(&|r| {
            is(r, "level", l)
                && is(r, "precision", "f64")
                && is(r, "integration", "reduced")
                && is(r, "mass_scaling", "1.0")
                && is(r, "hourglass", "physical")
                && is(r, "dt_safety", "0.9")
        })
    };
    let (e_half, e_one) = (
        get(lv("x0.5"), "u_err_rms_rel"),
        get(lv("x1"), "u_err_rms_rel"),
    );
    println!("rms error x0.5 {e_half:e}, x1 {e_one:e}");
    assert!(
        e_half > e_one,
        "refining did not reduce the error: {e_half} vs {e_one}"
    );
    // Step counts: dt = safety × critical, critical ∝ √mass_scaling; steps = ⌈T/dt⌉, so
    // the ratios hold within one step (1%).
    let steps = |pred: &dyn Fn(&Vec<String>) -> bool| get(find(pred), "steps");
    let s_base = get(find(&base), "steps");
    let s_half = steps(&|r| is(r, "varied", "dt_safety") && is(r, "dt_safety", "0.5"));
    let s4 = steps(&|r| is(r, "mass_scaling", "4.0"));
    let s16 = steps(&|r| is(r, "mass_scaling", "16.0"));
    assert!(
        (s_half / s_base - 0.9 / 0.5).abs() < 0.01 * 1.8,
        "{s_half} vs {s_base}"
    );
    assert!((s4 / s_base - 0.5).abs() < 0.01, "{s4} vs {s_base}");
    assert!((s16 / s_base - 0.25).abs() < 0.01, "{s16} vs {s_base}");
    // Time step: the stable step is set by the highest mode, so for the bending modes that
    // carry the answer the temporal error (ω₁dt)² ~ 1e-5 is far below the spatial one:
    // halving dt changes the error by < 1% of itself.
    let e_safe = get(
        find(&|r| is(r, "varied", "dt_safety") && is(r, "dt_safety", "0.5")),
        "u_err_rms_rel",
    );
    let e_base = get(find(&base), "u_err_rms_rel");
    assert!(
        (e_safe - e_base).abs() < 0.01 * e_base,
        "{e_safe} vs {e_base}"
    );
    // Pareto front: exactly the rows no other (non-reference) row dominates in
    // (1/RTF, u_err_rms_rel).
    let pts: Vec<(f64, f64, bool)> = rows[1..]
        .iter()
        .map(|r| {
            (
                1.0 / get(r, "real_time_factor"),
                get(r, "u_err_rms_rel"),
                r[col("pareto")] == "true",
            )
        })
        .collect();
    for (k, &(c, e, on)) in pts.iter().enumerate() {
        let dominated = pts
            .iter()
            .enumerate()
            .any(|(j, &(cj, ej, _))| j != k && cj <= c && ej <= e && (cj < c || ej < e));
        assert_eq!(on, !dominated, "row {} pareto flag", k + 1);
    }
    assert!(pts.iter().any(|p| p.2), "an empty Pareto front");
    // The PNG: signature and the 1200×800 IHDR.
    let png = std::fs::read(dir.join("tradeoff.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let w = u32::from_be_bytes(png[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(png[20..24].try_into().unwrap());
    assert_eq!((w, h), (1200, 800));
    // The markdown table: one row per configuration, and the full/reduced section.
    let md = std::fs::read_to_string(dir.join("tradeoff.md")).unwrap();
    let table_rows = md
        .lines()
        .filter(|l| {
            l.starts_with("| ")
                && !l.starts_with("| varied")
                && !l.starts_with("| precision | measured")
        })
        .count();
    assert!(
        table_rows >= rows.len(),
        "{table_rows} table rows for {} configs",
        rows.len()
    );
    assert!(md.contains("5 to 7 times cheaper"));
    let _ = std::fs::remove_dir_all(&dir);
}
