//! Tetrahedral meshes as Gmsh writes them (`tests/fixtures/meshes/beam_tet*.msh`, 3480
//! tetrahedra, about five through the depth), run by the host solver: the nearly
//! incompressible cantilever against a converged hexahedral solution (plain T4 locks,
//! T4ANP does not), energy conservation of an undamped run at the default step, and the
//! compiler's refusal.
//!
//! The cantilever: 0.10 x 0.02 x 0.02 m, the face x = 0 clamped (the physical surface
//! "clamped"), neo-Hookean E = 3 MPa, ν = 0.49 (and 0.3), under its own weight (lumped `m g` per
//! node): a small load (the tip sags about 1.3% of the length), solved as the linearised
//! static problem about rest (`Statics::linear`, the tangent by central differences of the
//! internal forces). The reference is the hexahedral solution on 20x4x4 and 40x8x8 cells
//! (reduced integration with the physical hourglass form, an independent element)
//! extrapolated to zero cell size; Timoshenko's beam theory is printed beside it (it
//! ignores the clamp's restraint of the section).

use std::path::PathBuf;

use crate::common::*;
use host_tools::analysis::hourglass::Statics;
use host_tools::problem::{NodeKind, Problem};
use host_tools::scene::Scene;
use host_tools::solver::Model;

const L: f64 = 0.10;
const H: f64 = 0.02;
const E_PA: f64 = 3.0e6;
const RHO: f64 = 1000.0;
const G: f64 = 9.81;

pub(crate) fn fixture(name: &str) -> String {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/meshes"
    ))
    .join(name);
    assert!(p.is_file(), "fixture {} is missing", p.display());
    p.display().to_string()
}

/// The tetrahedral beam (`form`: the `[solver] tetrahedron` value) of Poisson ratio `nu`
/// with `solver` settings.
fn tet_beam(form: &str, nu: f64, solver: &str) -> Problem {
    beam("beam_tet.msh", form, nu, solver)
}

/// The beam of fixture `mesh`.
pub(crate) fn beam(mesh: &str, form: &str, nu: f64, solver: &str) -> Problem {
    let text = format!(
        r#"
[mesh]
file = "{}"
[material]
law = "neo-hookean"
youngs_modulus = {E_PA}
poisson_ratio = {nu}
density = {RHO}
[[fixed]]
set = "clamped"
[gravity]
acceleration = [0.0, 0.0, -{G}]
[solver]
tetrahedron = "{form}"
{solver}
"#,
        fixture(mesh)
    );
    problem(&Scene::from_toml(&text).expect("the tetrahedral scene parses"))
}

/// The mean z displacement of the nodes at x = L under the linearised static solution.
fn static_tip(p: &Problem) -> f64 {
    let fixed: Vec<[bool; 3]> = p
        .node_kind
        .iter()
        .map(|k| [*k == NodeKind::Fixed; 3])
        .collect();
    assert!(fixed.iter().filter(|f| f[0]).count() >= 9, "a clamped face");
    let f: Vec<[f64; 3]> = p.mass.iter().map(|m| [0.0, 0.0, -m * G]).collect();
    let u = Statics::new(p)
        .linear(&fixed, &f)
        .expect("the static solve");
    let tip: Vec<usize> = (0..p.mesh.nodes.len())
        .filter(|&n| (p.mesh.nodes[n][0] - L).abs() < 1e-9)
        .collect();
    assert!(tip.len() >= 9, "the free end's nodes: {}", tip.len());
    tip.iter().map(|&n| u[n][2]).sum::<f64>() / tip.len() as f64
}

/// Timoshenko's cantilever under a uniform load `q = ρ g A`: `q L⁴/(8EI) + q L²/(2 κ G A)`
/// (κ = 10(1+ν)/(12+11ν), a square section), downwards.
fn timoshenko_tip(nu: f64) -> f64 {
    let (a, i) = (H * H, H.powi(4) / 12.0);
    let q = RHO * G * a;
    let shear = E_PA / (2.0 * (1.0 + nu));
    let kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);
    -(q * L.powi(4) / (8.0 * E_PA * i) + q * L * L / (2.0 * kappa * shear * a))
}

/// The tetrahedral beam (plain or nodal) and the hexahedral reference at Poisson ratio
/// `nu`: (hexahedra 20x4x4, 40x8x8, T4ANP, T4) tips (m).
fn tips(nu: f64) -> [f64; 4] {
    let hex = |cells: [usize; 3]| {
        let s = box_scene(
            [L, H, H],
            cells,
            E_PA,
            nu,
            "",
            &format!("[gravity]\nacceleration = [0.0, 0.0, -{G}]"),
        );
        static_tip(&problem(&s))
    };
    let anp_problem = tet_beam("nodal-pressure", nu, "");
    assert_eq!(anp_problem.mesh.cells.len(), 3480);
    [
        hex([20, 4, 4]),
        hex([40, 8, 8]),
        static_tip(&anp_problem),
        static_tip(&tet_beam("plain", nu, "")),
    ]
}

/// At ν = 0.49 plain T4 locks: its tip is less than 75% of the converged hexahedral
/// solution's (Richardson's extrapolation of 20x4x4 and 40x8x8, which agree within 2%).
/// T4ANP does not: its error there is within 1.5 points of plain T4's at ν = 0.3, where
/// nothing locks, on the same mesh. What remains is the linear tetrahedron's constant
/// strain in bending at five cells through the depth (measured: T4ANP 10% stiff at ν =
/// 0.49, plain T4 9% at ν = 0.3; on Gmsh's H/8 mesh T4ANP 4.4% at ν = 0.49, T4 15%, see
/// docs/measurements/tetrahedra.md): the issue's 3% needs a finer mesh than five cells.
#[test]
fn nearly_incompressible_cantilever_t4anp_does_not_lock_where_t4_does() {
    let error = |nu: f64| {
        let [coarse, fine, anp, plain] = tips(nu);
        let converged = fine + (fine - coarse) / 3.0;
        println!(
            "nu {nu}: tip (m): hexahedra 20x4x4 {coarse:.5e}, 40x8x8 {fine:.5e}, extrapolated {converged:.5e}; T4ANP {anp:.5e} ({:+.2}%), T4 {plain:.5e} ({:+.2}%); Timoshenko {:.5e}",
            100.0 * (anp / converged - 1.0),
            100.0 * (plain / converged - 1.0),
            timoshenko_tip(nu),
        );
        assert!(
            converged < -0.005 * L && converged > -0.05 * L,
            "a small, real sag: {converged}"
        );
        assert!(
            (coarse / fine - 1.0).abs() < 0.02,
            "the reference is not converged: {coarse} against {fine}"
        );
        (anp / converged - 1.0, plain / converged - 1.0)
    };
    let (anp_49, plain_49) = error(0.49);
    let (_, plain_30) = error(0.3);
    assert!(plain_49 < -0.25, "plain T4 locks at nu = 0.49: {plain_49}");
    assert!(
        (anp_49 - plain_30).abs() < 0.015,
        "T4ANP at nu = 0.49 ({anp_49}) is as accurate as the unlocked T4 at nu = 0.3 ({plain_30})"
    );
    assert!(anp_49.abs() < 0.12, "T4ANP's bending error {anp_49}");
}

/// The area of the problem's boundary faces (m²): a quadrilateral's from its diagonals, a
/// triangle stored with a repeated node the same way.
fn surface_area(p: &Problem) -> f64 {
    let x = |n: u32| p.mesh.nodes[n as usize];
    p.surface_faces
        .iter()
        .map(|f| {
            let d1: [f64; 3] = core::array::from_fn(|i| x(f[2])[i] - x(f[0])[i]);
            let d2: [f64; 3] = core::array::from_fn(|i| x(f[3])[i] - x(f[1])[i]);
            let c = [
                d1[1] * d2[2] - d1[2] * d2[1],
                d1[2] * d2[0] - d1[0] * d2[2],
                d1[0] * d2[1] - d1[1] * d2[0],
            ];
            0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
        })
        .sum()
}

/// A mesh of prisms and tetrahedra (Gmsh: 420 prisms over the first half, 886 tetrahedra
/// conforming to their triangles over the second) runs: its cells fill the beam's volume
/// and its surface is exactly the beam's (to 1e-12: no face between a prism and a
/// tetrahedron is left as surface), as for the all-tetrahedral mesh; its static tip at
/// ν = 0.3 is within 10% of the extrapolated hexahedral reference (both of its elements
/// are a few % stiff in bending; measured 2.9% stiff).
#[test]
fn a_mesh_of_prisms_and_tetrahedra_runs_with_the_beams_surface() {
    let box_area = 4.0 * L * H + 2.0 * H * H;
    for p in [
        beam("beam_prism_tet.msh", "nodal-pressure", 0.3, ""),
        tet_beam("nodal-pressure", 0.3, ""),
    ] {
        let volume: f64 = p.reference.iter().map(|r| r.volume()).sum();
        assert!(
            (volume / (L * H * H) - 1.0).abs() < 1e-12,
            "{}: {volume}",
            p.mesh.source
        );
        let area = surface_area(&p);
        assert!(
            (area / box_area - 1.0).abs() < 1e-12,
            "{}: surface {area} against {box_area}",
            p.mesh.source
        );
    }
    let mixed = beam("beam_prism_tet.msh", "nodal-pressure", 0.3, "");
    let tets = mixed
        .mesh
        .cells
        .iter()
        .filter(|c| host_tools::mesh::is_tetrahedron(c))
        .count();
    let prisms = mixed
        .mesh
        .cells
        .iter()
        .filter(|c| host_tools::mesh::is_prism(c))
        .count();
    assert_eq!((prisms, tets), (420, 886));
    let [coarse, fine, ..] = tips(0.3);
    let converged = fine + (fine - coarse) / 3.0;
    let tip = static_tip(&mixed);
    println!(
        "prisms and tetrahedra: tip {tip:.5e} m ({:+.2}% of {converged:.5e})",
        100.0 * (tip / converged - 1.0)
    );
    assert!(
        (tip / converged - 1.0).abs() < 0.10,
        "{tip} against {converged}"
    );
}

/// An undamped run of the tetrahedral beam at the default step (0.9 of the critical step,
/// set by the tetrahedra's `L_e`) under sudden gravity conserves energy: kinetic plus
/// stored minus the work of gravity (`Σ m g · u`) stays within 1% of the largest kinetic
/// energy over 2000 steps, for both forms. An unstable step grows it by orders of
/// magnitude; a nodal pressure that were not the energy's derivative would drift.
#[test]
fn undamped_tetrahedra_conserve_energy_at_the_default_step() {
    for form in ["nodal-pressure", "plain"] {
        let p = tet_beam(form, 0.49, "steps = 2000");
        let dt = p.time_step.dt_s;
        let mut m = Model::<f64>::new(&p, dt);
        let mut ke_max: f64 = 0.0;
        let mut balance = Vec::new();
        for _ in 0..2000 {
            m.advance().expect("the step is stable");
            let u = m.displacements();
            let v = m.velocities();
            let ke: f64 = v
                .iter()
                .zip(&p.mass)
                .map(|(v, m)| 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]))
                .sum();
            let work: f64 = u.iter().zip(&p.mass).map(|(u, m)| -m * G * u[2]).sum();
            let stored = m.stored_energy().expect("energy");
            ke_max = ke_max.max(ke);
            balance.push(ke + stored - work);
        }
        let drift = balance.iter().map(|b| b.abs()).fold(0.0, f64::max);
        println!(
            "{form}: largest kinetic energy {ke_max:.4e} J, largest |KE + W - work| {drift:.3e} J"
        );
        assert!(ke_max > 1e-6, "{form}: the beam moves: {ke_max}");
        assert!(
            drift < 0.01 * ke_max,
            "{form}: energy drifts: {drift} against {ke_max}"
        );
    }
}

/// The boards have no tetrahedron kernel: compiling the beam is refused before any work,
/// naming the count and the first cell.
#[test]
fn compiling_tetrahedra_is_refused_naming_them() {
    let p = tet_beam("nodal-pressure", 0.49, "");
    let e = host_tools::compile::refuse_tetrahedra(&p)
        .expect_err("tetrahedra are refused")
        .to_string();
    assert!(e.contains("3480 tetrahedra") && e.contains("cell 0"), "{e}");
    let hexes = problem(&box_scene([L, H, H], [4, 2, 2], E_PA, 0.49, "", ""));
    assert!(host_tools::compile::refuse_tetrahedra(&hexes).is_ok());
}

/// The Kuhn split of a generated box (what `pe bench` times) is conforming: six positive
/// tetrahedra per cell filling the box's volume, whose surface is the box's (to 1e-12).
#[test]
fn the_kuhn_split_of_a_box_is_conforming() {
    let s = box_scene([L, H, H], [5, 2, 3], E_PA, 0.3, "", "");
    let hexes = host_tools::mesh::grid::generate_box([L, H, H], [5, 2, 3]);
    let tets = host_tools::mesh::grid::split_into_tetrahedra(&hexes);
    assert_eq!(tets.cells.len(), 6 * 30);
    let p = Problem::new(&s, tets, Default::default()).expect("the split box resolves");
    let volume: f64 = p.reference.iter().map(|r| r.volume()).sum();
    assert!((volume / (L * H * H) - 1.0).abs() < 1e-12, "{volume}");
    let area = surface_area(&p);
    let box_area = 2.0 * (L * H + L * H + H * H);
    assert!(
        (area / box_area - 1.0).abs() < 1e-12,
        "{area} against {box_area}"
    );
}
