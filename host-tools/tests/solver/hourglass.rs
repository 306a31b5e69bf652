//! Hourglass calibration (issue 17): reduced-integration tips at the default coefficient
//! against closed forms that do not depend on it. The static solutions are the solver's
//! own discrete equilibrium (`analysis::hourglass::Statics`: tangent from the elements'
//! internal forces, banded Cholesky). Tables and reasons: docs/measurements/hourglass-calibration.md.

use host_tools::analysis::hourglass::*;
use host_tools::scene::SolverSpec;
use pe_firmware::image::Integration;

fn default_hourglass() -> f64 {
    SolverSpec::default().hourglass
}

/// Tip of `c` at the default coefficient, checked non-trivial (at least half of beam
/// theory, so a locked or unloaded beam fails first), and its relative error.
fn tip_error(c: &Cantilever) -> f64 {
    let r = c.reference();
    let tip = c
        .tip(Integration::Reduced, default_hourglass())
        .expect("static solve");
    println!(
        "{:?} {:?} {}: tip {tip:e}, beam theory {r:e}",
        c.cells, c.load, c.n[0]
    );
    assert!(tip > 0.5 * r, "tip {tip:e} is far from beam theory {r:e}");
    tip / r - 1.0
}

/// The issue's goal: slender-beam bending within 2% of beam theory at the default
/// coefficient with 4 cells through the thickness. MacNeal-Harder's cantilever (L/h = 30,
/// E = 1e7, ν = 0.3) in cubic cells (120x4x2), tip shear (Timoshenko) and end moment
/// (ML²/2EI, exact in beam theory). Measured at 0.1: +1.40% and +1.47%.
#[test]
fn macneal_harder_cubic_cells_within_2_percent_at_default() {
    for load in [TipLoad::Shear, TipLoad::Moment] {
        let mut c = Cantilever::macneal_harder(4, Cells::Regular, load);
        c.n = [120, 4, 2];
        let e = tip_error(&c);
        assert!(
            e.abs() < 0.02,
            "{load:?}: off beam theory by {:.2}%",
            100.0 * e
        );
    }
}

/// Distorted cubic cells, interfaces slanted at 11° (parallelograms, and alternating
/// trapezoids as in MacNeal-Harder): one-point elements with the mean gradient are not
/// exact on distorted cells, so they get 2.5% (measured at 0.1: +1.15% and -0.40%).
/// At MacNeal-Harder's 45° with cells 5 times longer than thick the tip is 60-80% short
/// at any coefficient (the study's table): aspect ratio, not distortion alone, locks.
#[test]
fn macneal_harder_distorted_cells_within_2_5_percent_at_default() {
    for cells in [Cells::Parallelogram, Cells::Trapezoidal] {
        let mut c = Cantilever::macneal_harder(4, cells, TipLoad::Shear);
        c.n = [120, 4, 2];
        c.slant = 0.2;
        let e = tip_error(&c);
        assert!(
            e.abs() < 0.025,
            "{cells:?}: off beam theory by {:.2}%",
            100.0 * e
        );
    }
}

/// A soft (E = 5 kPa) nearly incompressible (ν = 0.49) square cantilever, L/h = 10,
/// 40x4x4 cubic cells, tip shear: within 2% of Timoshenko (Cowper's κ). The hourglass
/// modulus is 2μ, so ν changes its ratio to the bending stiffness; measured -0.84%.
#[test]
fn soft_nearly_incompressible_cantilever_within_2_percent_at_default() {
    let c = Cantilever {
        l: 0.1,
        h: 0.01,
        b: 0.01,
        e: 5e3,
        nu: 0.49,
        n: [40, 4, 4],
        cells: Cells::Regular,
        slant: 0.0,
        load: TipLoad::Shear,
    };
    let e = tip_error(&c);
    assert!(e.abs() < 0.02, "off Timoshenko by {:.2}%", 100.0 * e);
}

/// A distorted 4x4x4 block compressed 20% between frictionless faces is homogeneous: the
/// lateral stretch and the nominal stress match the neo-Hookean closed form to 1e-8
/// (Newton's tolerance), at the default and at a 10x smaller and 5x larger coefficient
/// (hourglass forces vanish on linear fields whatever the coefficient).
#[test]
fn block_compression_matches_closed_form_at_any_coefficient() {
    let (e, nu, l) = (3000.0, 0.45, 0.8);
    let (t_ref, p_ref) = neo_hookean_uniaxial(e, nu, l);
    assert!(
        t_ref > 1.05 && p_ref < -500.0,
        "closed form {t_ref} {p_ref}"
    );
    for h in [
        0.1 * default_hourglass(),
        default_hourglass(),
        5.0 * default_hourglass(),
    ] {
        let (t, p) = block_compression(4, e, nu, l, h).expect("Newton converges");
        println!("hourglass {h}: stretch {t} ({t_ref}), nominal stress {p} ({p_ref}) Pa");
        assert!((t / t_ref - 1.0).abs() < 1e-8, "stretch {t} vs {t_ref}");
        assert!((p / p_ref - 1.0).abs() < 1e-8, "stress {p} vs {p_ref}");
    }
}

/// The study's static solver against the explicit solver: a damped explicit run of a
/// short cantilever (0.1 x 0.02 x 0.02 m, 10x2x2 cells, E = 1 MPa, ν = 0.3, 0.01 N tip
/// load: deflection/L ~ 1e-3, the linear range) settles, with its kinetic energy below
/// 1e-8 of the stored energy, to the direct solve's tip within 0.1% (the explicit run
/// stops at a relative change below 1e-7 per 500 steps; geometric nonlinearity at this
/// load is ~1e-4). Measured: 7e-6 apart, kinetic/stored 1e-17. Checks the solver of the
/// study, not the physics.
#[test]
fn static_solver_agrees_with_damped_explicit_run() {
    use host_tools::analysis::hourglass::Statics;
    use host_tools::problem::{NodeKind, Problem};
    use host_tools::scene::Scene;
    use host_tools::solver::Model;
    let text = r#"
[mesh]
generate = { kind = "box", size = [0.1, 0.02, 0.02], cells = [10, 2, 2] }
[material]
law = "neo-hookean"
youngs_modulus = 1e6
poisson_ratio = 0.3
density = 1000.0
[[fixed]]
box = [[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]
[[load]]
box = [[0.0999, -1.0, -1.0], [1.0, 1.0, 1.0]]
force = [0.0, 0.0, -0.01]
[solver]
damping = 300.0
"#;
    let scene = Scene::from_toml(text).expect("scene parses");
    let p = Problem::from_scene(&scene, std::path::Path::new(".")).expect("scene resolves");
    let fixed: Vec<[bool; 3]> = p
        .node_kind
        .iter()
        .map(|k| [*k != NodeKind::Free; 3])
        .collect();
    let mut f = vec![[0.0; 3]; p.mesh.nodes.len()];
    for l in &p.loads {
        for (fi, li) in f[l.node as usize].iter_mut().zip(l.force) {
            *fi += li;
        }
    }
    let tip_nodes: Vec<usize> = (0..p.mesh.nodes.len())
        .filter(|&a| p.mesh.nodes[a][0] > 0.0999)
        .collect();
    let u = Statics::new(&p).linear(&fixed, &f).expect("static solve");
    let w_static = mean(&u, &tip_nodes, 2);
    assert!(w_static < -1e-5, "tip {w_static:e} m: load not applied");
    let mut m = Model::<f64>::new(&p, p.time_step.dt_s);
    let mut last = f64::NAN;
    let mut w = f64::NAN;
    for k in 0..400_000u64 {
        m.advance().expect("stable run");
        if k % 500 == 499 {
            w = mean(&m.displacements(), &tip_nodes, 2);
            if (w - last).abs() < 1e-7 * w.abs() {
                break;
            }
            last = w;
        }
    }
    let e = m.energies().expect("energies");
    println!(
        "static {w_static:e} m, explicit {w:e} m, kinetic {:e} J, stored {:e} J",
        e.kinetic, e.stored
    );
    assert!(e.kinetic < 1e-8 * e.stored, "not settled: {e:?}");
    assert!(
        (w / w_static - 1.0).abs() < 1e-3,
        "explicit {w:e} vs static {w_static:e}"
    );
}
