//! Contact: a probe pressing a block against the static closed form, the penalty's
//! penetration, the same contact on one board and across board boundaries, and the speed
//! bound behind the bounding-box interval.

use board_sim::{run, SimFault, SimOptions};
use host_tools::solver;
use pe_firmware::physics::PhysicsError;
use pe_firmware::runtime::FaultKind;
use system_tests::*;

/// `probe_block.toml`: a flat probe (capsule of 5 m radius) pressed 1 mm into a 10 mm
/// cube of neo-Hookean tissue with ν = 0 (lateral stretch stays 1), held at its base. At
/// rest the probe's force equals the uniaxial closed form `F = A μ (λ − 1/λ)` at the
/// compression the top actually reached (within 1%: the probe sags 2.5 µm over the block
/// and the mesh is 8 cells high), the base carries the same force (equilibrium, 1e-6),
/// and the probe's penetration is what the penalty law says, `f / k` per node (within 2%),
/// and below the scene's tolerance.
#[test]
fn probe_pressing_a_block_matches_the_static_solution() {
    let (p, _) = file_problem("probe_block.toml");
    let out = solver::run(&p, "probe_block", &mut ()).unwrap();
    let c = out.report.contact.as_ref().unwrap();
    let f = c.tool_force_final_n[0][2];
    let (h, a, mu) = (0.01, 1e-4, 10e3 / 2.0);
    let top: Vec<usize> = (0..p.mesh.nodes.len())
        .filter(|&n| p.mesh.nodes[n][2] > h - 1e-9)
        .collect();
    let uz = top.iter().map(|&n| out.displacements[n][2]).sum::<f64>() / top.len() as f64;
    let l = 1.0 + uz / h;
    let closed = -a * mu * (l - 1.0 / l);
    println!("probe force {f:.6e} N, closed form {closed:.6e} N at stretch {l:.5}");
    assert!(
        f > 0.0 && (f - closed).abs() < 0.01 * closed,
        "{f} vs {closed}"
    );
    let base = out.report.fixed_reaction_n[2];
    assert!((base - f).abs() < 1e-6 * f, "base {base} vs probe {f}");
    // Penetration: the probe's surface is 1 mm below the block's top; the top sits at uz.
    let pen = 1e-3 + uz;
    println!("penetration {pen:.4e} m, max {:.4e} m", c.max_penetration_m);
    assert!(c.max_penetration_m <= c.tolerance_m);
    assert!((c.max_penetration_m - pen).abs() < 0.02 * pen);
}

/// The same scene on one board is bit for bit the serial run; split across boards (the
/// contact nodes on several boards, the probe force summed by the host from the boards'
/// packets) it agrees to 1e-10 relative. Measured 2e-12: the quasi-static run amplifies the
/// round-off of the force sums more than a dynamic one.
#[test]
fn contact_across_boards_equals_one_board() {
    let (p, src) = file_problem("probe_block.toml");
    let serial = solver::run(&p, "serial", &mut ()).unwrap();
    let fs = serial.report.contact.as_ref().unwrap().tool_force_final_n[0][2];
    for m in ["1x1x1", "1x1x2", "2x2x2"] {
        let dir = compile(&p, &src, m, &format!("probe-{m}"));
        let out = run(&dir, &SimOptions::default(), &mut |_, _| {}).unwrap();
        let d = max_rel_diff(&serial.displacements, &out.displacements);
        let fb = out.tool_force[out.tool_force.len() - 1][2];
        println!("{m}: max relative difference {d:e}, probe force {fb:e} vs {fs:e}");
        if m == "1x1x1" {
            assert_eq!(d, 0.0);
        }
        assert!(d < 1e-10, "{m}: {d:e}");
        assert!((fb - fs).abs() < 1e-9 * fs, "{m}: {fb} vs {fs}");
    }
}

/// A contact surface faster than the scene's speed bound could reach a face the bounding
/// boxes did not cover: the serial solver and every board stop with an error naming the
/// node, not a silently missed contact.
#[test]
fn a_surface_faster_than_the_speed_bound_is_reported() {
    let (mut p, src) = file_problem("two_blocks.toml");
    // The whole upper block slides sideways 5 mm in 5 ms: 1 m/s against the bound of
    // 0.1 m/s (it travels the 2 mm the interval allows in about 17 steps).
    for n in 0..p.mesh.nodes.len() {
        if p.mesh.nodes[n][2] > 0.0052 {
            p.node_kind[n] = host_tools::problem::NodeKind::Prescribed(0);
        }
    }
    p.paths[0].points = vec![(0.0, [0.0; 3]), (0.005, [0.005, 0.0, 0.0])];
    p.solver.steps = Some(100);
    let e = solver::run(&p, "fast", &mut ()).err().expect("refused");
    let msg = format!("{e}");
    println!("{msg}");
    assert!(msg.contains("speed bound"), "{msg}");
    let dir = compile(&p, &src, "1x1x2", "fast-1x1x2");
    let err = run(&dir, &SimOptions::default(), &mut |_, _| {})
        .err()
        .expect("the boards refuse it too");
    let f = err.downcast_ref::<SimFault>().expect("a fault report");
    println!("{f}");
    assert!(matches!(
        f.faults[0].kind,
        FaultKind::Physics(PhysicsError::ContactSpeedBound { .. })
    ));
}
