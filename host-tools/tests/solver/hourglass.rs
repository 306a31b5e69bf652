//! Hourglass control (issues 17 and 64): reduced-integration tips at the default (the
//! physical form) and the scalar form against closed forms that do not depend on them. The static solutions are the solver's
//! own discrete equilibrium (`analysis::hourglass::Statics`: tangent from the elements'
//! internal forces, banded Cholesky). Tables and reasons: docs/measurements/hourglass-calibration.md.

use host_tools::analysis::hourglass::*;
use host_tools::scene::SolverSpec;
use pe_firmware::image::Integration;
use pe_firmware::physics::HourglassControl;

fn default_hourglass() -> HourglassControl {
    SolverSpec::default().hourglass
}

/// Tip of `c` at the default hourglass control, checked non-trivial (at least half of
/// beam theory, so a locked or unloaded beam fails first), and its relative error.
fn tip_error(c: &Cantilever) -> f64 {
    let hourglass = default_hourglass();
    let r = c.reference();
    let tip = c
        .tip(Integration::Reduced, hourglass)
        .expect("static solve");
    println!(
        "{:?} {:?} {:?} {hourglass}: tip {tip:e}, beam theory {r:e}",
        c.cells, c.load, c.n
    );
    assert!(tip > 0.5 * r, "tip {tip:e} is far from beam theory {r:e}");
    tip / r - 1.0
}

/// The default is the physical form (issue 64).
#[test]
fn the_default_is_the_physical_form() {
    assert_eq!(default_hourglass(), HourglassControl::Physical);
}

/// Issue 64's goal: MacNeal-Harder's straight cantilever with its own cells (5 times
/// longer than deep), one and four cells through the depth, within 5% of beam theory
/// under tip shear (Timoshenko) and end moment (ML²/2EI). The scalar form at 0.1 is
/// 96% and 40% stiff here (the hourglass stiffness set by the cells' short sides).
/// Measured with the physical form: -2.00% and -0.94% (shear), -0.86% and -0.59% (moment).
#[test]
fn macneal_harder_elongated_cells_within_5_percent_at_default() {
    for load in [TipLoad::Shear, TipLoad::Moment] {
        for depth in [1, 4] {
            let c = Cantilever::macneal_harder(depth, Cells::Regular, load);
            assert_eq!(c.n[0], 6 * c.n[1], "cells 5 times longer than deep");
            let e = tip_error(&c);
            assert!(
                e.abs() < 0.05,
                "{load:?}, {depth} through the depth: off beam theory by {:.2}%",
                100.0 * e
            );
        }
    }
}

/// A constant moment on one cell through the depth: the physical form carries pure
/// bending exactly on a free box (`pe-firmware/tests/hourglass.rs`), so the tip is beam
/// theory's `ML²/2EI` but for the clamp: the clamped face holds the first cell's
/// anticlastic contraction, which stiffens it as a clamp stiffens a 3D beam near its
/// root (a cell long here). Within 1.5% (measured −0.86%; the scalar form at 0.1 −96.6%).
#[test]
fn one_cell_deep_pure_bending_is_beam_theory() {
    let c = Cantilever::macneal_harder(1, Cells::Regular, TipLoad::Moment);
    let e = tip_error(&c);
    assert!(e.abs() < 0.015, "off ML²/2EI by {:.3}%", 100.0 * e);
}

/// Parallelogram cells slanted 45° (MacNeal-Harder's), four through the depth: the
/// physical form works on the cells' edges, along which a bending field's slanted
/// components cancel, so it is within 6% (measured -4.59% shear, -3.12% moment); the
/// scalar form at 0.1 is 59% stiff.
#[test]
fn macneal_harder_parallelograms_within_6_percent_at_default() {
    for load in [TipLoad::Shear, TipLoad::Moment] {
        let c = Cantilever::macneal_harder(4, Cells::Parallelogram, load);
        let e = tip_error(&c);
        assert!(
            e.abs() < 0.06,
            "{load:?}: off beam theory by {:.2}%",
            100.0 * e
        );
        // The scalar form on the same mesh: locked (a tip under 70% of beam theory).
        let scalar = c
            .tip(Integration::Reduced, HourglassControl::Scalar(0.1))
            .expect("static solve");
        let r = c.reference();
        assert!(
            scalar > 0.0 && scalar < 0.7 * r,
            "{load:?}: the scalar form's tip {scalar:e} against {r:e}"
        );
    }
}

/// The issue's goal: slender-beam bending within 2% of beam theory at the default
/// coefficient with 4 cells through the thickness. MacNeal-Harder's cantilever (L/h = 30,
/// E = 1e7, ν = 0.3) in cubic cells (120x4x2), tip shear (Timoshenko) and end moment
/// (ML²/2EI, exact in beam theory). Measured with the physical form: -0.23% and -0.15%
/// (the scalar form at 0.1: +1.40% and +1.47%).
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
/// exact on distorted cells, so they get 2.5% (measured with the physical form: -0.22%
/// and -0.62%; the scalar form at 0.1: +1.15% and -0.40%). MacNeal-Harder's 45°
/// trapezoids with cells 5 times longer than thick stay 77-95% stiff in either form (the
/// study's table): the nodal values of a bending field on a trapezoid have a linear part,
/// a mean axial strain the one-point element cannot leave out (MacNeal's theorem).
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
/// 40x4x4 cubic cells, tip shear, against Timoshenko (Cowper's κ): within 4.5%. Beam
/// theory is not the 3D solution here: the clamped face (all components held) stops
/// the root's lateral contraction, which at ν = 0.49 stiffens the beam. Both forms
/// converge to about 2.1% below Timoshenko (the scalar form at 0.1: -0.84, -1.54, -1.75%
/// on 4, 6 and 8 cells through the depth), so the physical form (-2.97% at 4 cells) is
/// within 1% of the 3D limit; 6 cells must come no further from it.
#[test]
fn soft_nearly_incompressible_cantilever_near_the_3d_limit_at_default() {
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
    assert!(e.abs() < 0.045, "off Timoshenko by {:.2}%", 100.0 * e);
    let finer = Cantilever { n: [60, 6, 6], ..c };
    let e6 = tip_error(&finer);
    assert!(
        e6.abs() < e.abs() + 0.002 && e6.abs() < 0.035,
        "6 cells: {:.2}%, 4 cells: {:.2}%",
        100.0 * e6,
        100.0 * e
    );
}

/// A distorted 4x4x4 block compressed 20% between frictionless faces is homogeneous: the
/// lateral stretch and the nominal stress match the neo-Hookean closed form to 1e-8
/// (Newton's tolerance), with the physical form and the scalar one at 0.01, 0.1 and 0.5
/// (hourglass forces vanish on linear fields whatever their stiffness).
#[test]
fn block_compression_matches_closed_form_at_any_coefficient() {
    let (e, nu, l) = (3000.0, 0.45, 0.8);
    let (t_ref, p_ref) = neo_hookean_uniaxial(e, nu, l);
    assert!(
        t_ref > 1.05 && p_ref < -500.0,
        "closed form {t_ref} {p_ref}"
    );
    for h in [
        HourglassControl::Physical,
        HourglassControl::Scalar(0.01),
        HourglassControl::Scalar(0.1),
        HourglassControl::Scalar(0.5),
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
