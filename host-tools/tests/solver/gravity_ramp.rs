//! Gravity brought in along a ramp (`[gravity] ramp`, `shape = "poly345"`) against the closed
//! form of a bar hanging under its own weight, and against the same bar under sudden gravity.
//!
//! The bar: 0.1 m along x, clamped at x = 0 (every component of the face held), gravity
//! along +x, neo-Hookean with ν = 0 (no lateral contraction, so the clamp is consistent with
//! the 1D solution), E = 300 kPa, ρ = 1000 kg/m³: the static tip `u(L) = ρ g L² / (2E)` =
//! 1.635e-4 m at a largest strain `ρ g L / E` = 3.3e-3 (the nonlinear correction is of that
//! order). Linear elements with lumped body force give the 1D bar's exact nodal values, so
//! the closed form is the discrete answer up to that correction. Undamped, its slowest axial
//! mode has the period `4L/c` = 23.1 ms (`c = √(E/ρ)`).

use crate::common::*;
use host_tools::compare::nan_max;
use host_tools::problem::Problem;
use host_tools::solver::{self, Observer, StepState};

const E_PA: f64 = 3e5;
const RHO: f64 = 1000.0;
const G: f64 = 9.81;
const L_M: f64 = 0.1;

/// `ρ g L² / (2E)`.
fn static_tip_m() -> f64 {
    RHO * G * L_M * L_M / (2.0 * E_PA)
}

/// The bar under gravity (`gravity` is the `[gravity]` table's extra keys), undamped, for
/// 0.15 s.
fn bar(gravity: &str) -> Problem {
    let extra = format!("[gravity]\nacceleration = [{G}, 0.0, 0.0]\n{gravity}");
    problem(&box_scene(
        [L_M, 0.01, 0.01],
        [20, 2, 2],
        E_PA,
        0.0,
        "duration = 0.15",
        &extra,
    ))
}

/// The mean axial displacement of the free end's nodes, after every step.
struct Tip {
    nodes: Vec<usize>,
    history: Vec<(f64, f64)>,
}

impl Observer for Tip {
    fn after_step(&mut self, _: u64, t: f64, _: u64, state: &dyn StepState) {
        let u = state.displacements();
        let sum: f64 = self.nodes.iter().map(|&n| u[n][0]).sum();
        self.history.push((t, sum / self.nodes.len() as f64));
    }
}

/// Runs `p`; returns (largest tip displacement over the run, tip at the end, steps).
fn run(p: &Problem) -> (f64, f64, usize) {
    let nodes: Vec<usize> = (0..p.mesh.nodes.len())
        .filter(|&n| (p.mesh.nodes[n][0] - L_M).abs() < 1e-9)
        .collect();
    assert_eq!(nodes.len(), 9, "the free end's 3x3 nodes");
    let mut tip = Tip {
        nodes,
        history: Vec::new(),
    };
    solver::run(p, "hanging bar", &mut tip).expect("the bar runs");
    let max = tip
        .history
        .iter()
        .map(|h| h.1)
        .fold(f64::NEG_INFINITY, nan_max);
    let end = tip.history.last().map_or(f64::NAN, |h| h.1);
    (max, end, tip.history.len())
}

/// Sudden gravity overshoots to about twice the static tip (each mode of an undamped bar
/// loaded at once swings to twice its static part: at least 1.6 asserted, the modes do not
/// all peak together); ramped in over 0.1 s (4.3 periods of the slowest mode) along
/// POLY345, the tip never passes the static value by more than 2% (a smooth step of `k`
/// periods leaves a quasi-static lag of about `5.8 / (2π k)²` = 0.8% and a residual swing
/// below it) and ends within 2% of `ρ g L²/(2E)` (the residual swing plus the strain's
/// order, 0.3%). A ramp the solver ignored would overshoot like sudden gravity; one it
/// applied twice or not at all would end 100% off.
#[test]
fn ramped_gravity_brings_a_hanging_bar_to_its_static_sag_without_overshoot() {
    let closed = static_tip_m();
    let (sudden_max, _, n_sudden) = run(&bar(""));
    let ramped = bar("ramp = [[0.0, 0.0], [0.1, 1.0]]\nshape = \"poly345\"");
    assert!(ramped.gravity_ramp.is_some(), "the scene's ramp is read");
    let (ramped_max, ramped_end, n_ramped) = run(&ramped);
    println!(
        "static tip {closed:e} m; sudden: max {:.4} of it ({n_sudden} steps); ramped: max {:.4}, end {:.4} ({n_ramped} steps)",
        sudden_max / closed,
        ramped_max / closed,
        ramped_end / closed
    );
    assert!(
        n_sudden > 300 && n_ramped > 300,
        "runs of 0.15 s: several periods"
    );
    assert!(
        sudden_max > 1.6 * closed,
        "sudden gravity overshoots: {sudden_max:e} m"
    );
    assert!(
        ramped_max < 1.02 * closed,
        "ramped gravity overshoots: {ramped_max:e} m against {closed:e} m"
    );
    assert!(
        (ramped_end / closed - 1.0).abs() < 0.02,
        "ramped end {ramped_end:e} m against {closed:e} m"
    );
}

/// A `shape` with no `ramp`, and a ramp whose times do not increase, are refused naming
/// `[gravity]`.
#[test]
fn a_malformed_gravity_ramp_is_refused_naming_the_table() {
    let scene = |keys: &str| {
        let gravity = format!("[gravity]\nacceleration = [0.0, 0.0, -9.81]\n{keys}");
        let sc = box_scene([0.1, 0.01, 0.01], [2, 1, 1], 3e3, 0.3, "", &gravity);
        Problem::from_scene(&sc, std::path::Path::new("."))
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    };
    for (keys, want) in [
        ("shape = \"poly345\"", "[gravity]: `shape` without a `ramp`"),
        (
            "ramp = [[0.1, 0.0], [0.1, 1.0]]",
            "[gravity]: `ramp` needs points [t, factor] with increasing t",
        ),
        ("ramp = []", "[gravity]: `ramp` needs points"),
    ] {
        let e = scene(keys);
        assert!(e.contains(want), "{keys}: got {e:?}");
    }
}
