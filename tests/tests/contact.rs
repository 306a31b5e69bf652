//! Contact: a probe pressing a block against the static closed form, the penalty's
//! penetration, the same contact on one board and across board boundaries, and the speed
//! bound behind the bounding-box interval.

use board_sim::{run, SimFault, SimOptions};
use host_tools::compare::nan_max;
use host_tools::solver;
use pe_firmware::physics::PhysicsError;
use pe_firmware::runtime::FaultKind;
use system_tests::*;

/// `probe_block.toml`: a flat probe (capsule of 5 m radius) pressed 1 mm into a 10 mm
/// cube of neo-Hookean tissue with ν = 0 (lateral stretch stays 1), held at its base. At
/// rest the probe's force equals the uniaxial closed form `F = A μ (λ − 1/λ)` at the
/// compression the top actually reached (within 1%: the probe sags 2.5 µm over the block
/// and the mesh is 8 cells high), the base carries the same force (equilibrium, 1e-6),
/// and the probe's penetration is what the penalty law says: the probe's force is
/// `Σ k_i p_i` over the top nodes, with `p_i` each node's depth in the capsule computed here
/// from the final positions and `k_i = β m_i / Δt²` from the scene's `penalty` β, the step
/// and the lumped mass `m_i = Σ ρ V_cell / 8` computed here from the cells (within 1e-4, measured 3e-7: the
/// force is evaluated at a step's start, the positions are its end). A penalty stiffness off
/// by any factor moves the force off this sum by that factor.
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
    // f = Σ k_i p_i, every factor computed here: the capsule (radius 5 m, axis along x at
    // y = 5 mm, z = 5.0102 m lowered 1.2 mm by the path's end), the lumped masses.
    let (rho, beta, dt) = (1000.0, 0.5, out.report.dt_final_s);
    let mut mass = vec![0.0; p.mesh.nodes.len()];
    for cell in &p.mesh.cells {
        let x = |i: usize| p.mesh.nodes[cell[i] as usize];
        let span = |k: usize| {
            let v: Vec<f64> = (0..8).map(|i| x(i)[k]).collect();
            v.iter().copied().fold(f64::NEG_INFINITY, nan_max)
                - v.iter().copied().fold(f64::INFINITY, f64::min)
        };
        let volume = span(0) * span(1) * span(2);
        for &n in cell {
            mass[n as usize] += rho * volume / 8.0;
        }
    }
    let total: f64 = mass.iter().sum();
    assert!(
        (total - rho * h * h * h).abs() < 1e-12,
        "block mass {total} kg"
    );
    let (mut spring, mut touching) = (0.0, 0);
    for &n in &top {
        let x: Vec<f64> = (0..3)
            .map(|k| p.mesh.nodes[n][k] + out.displacements[n][k])
            .collect();
        let depth = 5.0 - ((x[1] - 0.005).powi(2) + (x[2] - (5.0102 - 0.0012)).powi(2)).sqrt();
        if depth > 0.0 {
            spring += beta * mass[n] / (dt * dt) * depth;
            touching += 1;
        }
    }
    println!(
        "Σ k p = {spring:.6e} N over {touching} of {} top nodes",
        top.len()
    );
    assert_eq!(
        (top.len(), touching),
        (25, 25),
        "every top node under the probe"
    );
    assert!((spring - f).abs() < 1e-4 * f, "Σ k p = {spring} vs {f}");
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
    p.update_time_step().expect("stable step");
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
        f.observed[0].fault.kind,
        FaultKind::Physics(PhysicsError::ContactSpeedBound { .. })
    ));
}

/// `two_blocks.toml`: two equal 10 x 10 x 5 mm blocks (ν = 0) 0.3 mm apart, the lower held
/// at its base, the upper pushed down 0.4 mm at its top, touching only through the
/// node-to-surface pair (each surface slave against the other's faces, averaged). At rest:
/// - the contact forces of the pair sum to zero to round-off (1e-12 of their magnitudes);
/// - the force the base carries is equal and opposite to the push (1e-6: equilibrium);
/// - each block carries the uniaxial closed form `A μ (1/λ − λ)` at the stretch its own
///   nodes reached (1e-4: the compression is homogeneous, which the hexahedra represent
///   exactly; what is left is the interface's slightly uneven penetration, measured
///   1e-6), so the forces across the interface are equal and opposite and of the right
///   size;
/// - the interface penetrates less than the tolerance and less than 5% of the gap closure.
#[test]
fn two_blocks_pressed_together_push_equal_and_opposite() {
    let (p, _) = file_problem("two_blocks.toml");
    let out = solver::run(&p, "two_blocks", &mut ()).unwrap();
    let c = out.report.contact.as_ref().unwrap();
    let push = out.report.prescribed_reaction_n[2];
    let base = out.report.fixed_reaction_n[2];
    println!(
        "push {push:.6e} N, base {base:.6e} N, pair sum {:.1e}, KE {:.1e} J",
        c.pair_force_sum_rel_max, out.report.kinetic_energy_final
    );
    assert!(c.pair_force_sum_rel_max < 1e-12);
    assert!(base > 0.0 && (base + push).abs() < 1e-6 * base);
    let (h, a, mu) = (0.005, 1e-4, 10e3 / 2.0);
    let mean_uz = |z: f64| {
        let nodes: Vec<usize> = (0..p.mesh.nodes.len())
            .filter(|&n| (p.mesh.nodes[n][2] - z).abs() < 1e-9)
            .collect();
        nodes.iter().map(|&n| out.displacements[n][2]).sum::<f64>() / nodes.len() as f64
    };
    let (lower_top, upper_bottom, upper_top) = (mean_uz(0.005), mean_uz(0.0053), mean_uz(0.0103));
    for (name, l) in [
        ("lower", 1.0 + lower_top / h),
        ("upper", 1.0 + (upper_top - upper_bottom) / h),
    ] {
        let closed = a * mu * (1.0 / l - l);
        println!("{name}: stretch {l:.5}, closed form {closed:.6e} N");
        assert!(
            (base - closed).abs() < 1e-4 * closed,
            "{name}: {base} vs {closed}"
        );
    }
    let pen = lower_top - (0.0003 + upper_bottom);
    println!(
        "mean interface penetration {pen:.3e} m, max {:.3e} m",
        c.max_penetration_m
    );
    assert!(c.max_penetration_m <= c.tolerance_m);
    assert!(c.max_penetration_m < 0.05 * (0.0004 - 0.0003 + pen));
}

/// The pair of `two_blocks.toml` on one board is bit for bit the serial run; split so the
/// interface runs across board boundaries (1x1x2: between the blocks; 2x2x2 and the full
/// 4x4x4 array) it agrees to 1e-10 relative, the tolerance of the probe across boards.
#[test]
fn pair_contact_across_boards_equals_one_board() {
    let (p, src) = file_problem("two_blocks.toml");
    let serial = solver::run(&p, "serial", &mut ()).unwrap();
    for m in ["1x1x1", "1x1x2", "2x2x2", "4x4x4"] {
        let dir = compile(&p, &src, m, &format!("pair-{m}"));
        let out = run(&dir, &SimOptions::default(), &mut |_, _| {}).unwrap();
        let d = max_rel_diff(&serial.displacements, &out.displacements);
        println!("{m}: max relative difference {d:e}");
        if m == "1x1x1" {
            assert_eq!(d, 0.0);
        }
        assert!(d < 1e-10, "{m}: {d:e}");
    }
}

/// `approach.toml`: a rigid block approaches a soft one at exactly the speed bound from
/// farther than the bounding boxes reach, and presses into it. With the interval `K` the
/// bound gives (168 steps here) the run is the same as with a search every step (gap so
/// small that K = 1): bit for bit serially, and to 1e-10 on boards where the blocks meet
/// across a board boundary. A missed contact would leave the soft block untouched (or
/// trip the tolerance), so the final state would differ by the whole indentation.
#[test]
fn the_bounding_box_interval_never_misses_a_surface_at_the_speed_bound() {
    let (p, src) = file_problem("approach.toml");
    let mut every_step = p.clone();
    if let Some(c) = every_step.contact.as_mut() {
        c.settings.gap = 1e-6;
    }
    let reference = solver::run(&every_step, "every step", &mut ()).unwrap();
    let rc = reference.report.contact.as_ref().unwrap();
    assert_eq!(rc.check_interval_steps, 1);
    let out = solver::run(&p, "interval", &mut ()).unwrap();
    let c = out.report.contact.as_ref().unwrap();
    let soft_top = (0..p.mesh.nodes.len())
        .filter(|&n| (p.mesh.nodes[n][2] - 0.005).abs() < 1e-9)
        .map(|n| out.displacements[n][2])
        .fold(0.0, f64::min);
    println!(
        "K = {} ({} checks) vs 1; soft top pressed {soft_top:.3e} m; max penetration {:.3e} m",
        c.check_interval_steps, c.checks, c.max_penetration_m
    );
    assert!(c.check_interval_steps > 100);
    assert!(soft_top < -5e-4, "the rigid block pressed the soft one");
    assert_eq!(
        max_rel_diff(&reference.displacements, &out.displacements),
        0.0
    );
    for m in ["1x1x2", "2x2x2"] {
        let dir = compile(&p, &src, m, &format!("approach-{m}"));
        let b = run(&dir, &SimOptions::default(), &mut |_, _| {}).unwrap();
        let d = max_rel_diff(&reference.displacements, &b.displacements);
        println!("{m}: max relative difference to a search every step {d:e}");
        assert!(d < 1e-10, "{m}: {d:e}");
    }
}

/// The built-in scene at the coarse level, run to its end (0.6 s): the probe pushes the
/// right tube down onto the ovary, which moves only through the tube-ovary contact pair.
/// On the full 4x4x4 array the result equals the serial run to 1e-10 relative (board-sim's
/// tolerance), the probe force the host sums from the boards' packets to 1e-9, and the
/// pair's forces sum to zero to round-off (1e-12 of their magnitudes).
#[test]
fn builtin_scene_probe_tube_and_ovary_on_64_boards_equal_serial() {
    let mut sc = host_tools::scene::builtin::builtin_scene("coarse").unwrap();
    sc.solver.steps = None;
    let p = host_tools::problem::Problem::from_scene(&sc, std::path::Path::new(".")).unwrap();
    let serial = solver::run(&p, "serial", &mut ()).unwrap();
    let c = serial.report.contact.as_ref().unwrap();
    let ovary = p
        .mesh
        .region_names
        .iter()
        .find(|(_, n)| n.as_str() == "right_ovary")
        .map(|(t, _)| *t)
        .expect("the ovary region");
    let moved = p
        .mesh
        .cells
        .iter()
        .zip(&p.mesh.cell_regions)
        .filter(|(_, r)| **r == ovary)
        .flat_map(|(cell, _)| cell.iter())
        .map(|&n| {
            let u = serial.displacements[n as usize];
            (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt()
        })
        .fold(0.0, nan_max);
    let fs = c.tool_force_final_n[0];
    println!(
        "ovary pressed {moved:.3e} m; probe force {fs:?} N; pair sum {:.1e}",
        c.pair_force_sum_rel_max
    );
    // Without the pair the ovary would not move at all (measured 0.12 mm).
    assert!(moved > 1e-5, "the tube pressed the ovary");
    assert!(c.pair_force_sum_rel_max < 1e-12);
    let dir = compile(&p, "builtin:coarse", "4x4x4", "builtin-ovary-4x4x4");
    let out = run(&dir, &SimOptions::default(), &mut |_, _| {}).unwrap();
    let d = max_rel_diff(&serial.displacements, &out.displacements);
    let fb = out.tool_force[out.tool_force.len() - 1];
    println!("4x4x4: max relative difference {d:e}, probe force {fb:?} N");
    assert!(d < 1e-10, "{d:e}");
    let scale = (fs[0] * fs[0] + fs[1] * fs[1] + fs[2] * fs[2]).sqrt();
    assert!((0..3).all(|i| (fb[i] - fs[i]).abs() < 1e-9 * scale));
}

/// Contact tables larger than the firmware holds are refused when the schedule is
/// compiled, naming the table and both counts (not only at load time on the board).
#[test]
fn contact_tables_too_large_for_the_firmware_are_refused_at_compile_time() {
    use host_tools::compile::partition::Machine;
    use host_tools::compile::{check_fit, compile_images, plan};
    use pe_firmware::profile::{BoardProfile, PE_BOARD};
    let (p, _) = file_problem("two_blocks.toml");
    let images = compile_images(&p, &plan(&p, Machine::parse("1x1x2").unwrap()).unwrap()).unwrap();
    assert!(check_fit(&images, &PE_BOARD).is_ok());
    let small = BoardProfile {
        name: "small",
        contact_nodes_max: 40,
        ..PE_BOARD
    };
    let e = check_fit(&images, &small).unwrap_err().to_string();
    println!("{e}");
    // Two 5 x 5 node grids: 50 contact nodes in the table every board that owns one holds.
    assert!(
        e.contains("every board that owns a contact node: 50 contact-surface nodes exceed the 40 the small firmware holds"),
        "{e}"
    );
}

/// Only a board that owns a contact node carries the contact tables (the whole table): the
/// others' images have none (no tools, pairs, nodes or faces), so their step has no contact
/// operation and a firmware built without `contact` would run them. On the built-in coarse
/// scene on 4x4x4 both kinds of board exist; the firmware parts the set needs are contact
/// and graphics (no loads), and the seed box's only graphics; the compile summary counts
/// the boards that need each part. (That the trimmed set computes the serial run's
/// displacements and probe force: `builtin_scene_probe_tube_and_ovary_on_64_boards_equal_serial`.)
#[test]
fn only_the_boards_that_own_contact_nodes_carry_the_contact_tables() {
    use host_tools::compile::partition::Machine;
    use host_tools::compile::{compile_images, decode_image, plan, report, summary};
    use host_tools::firmware::parts_needed;
    use pe_firmware::image::Feature;
    let p = builtin_problem("coarse", 10);
    let table = p.contact.as_ref().expect("contact").node_globals.len();
    assert!(table > 50, "{table} contact nodes");
    let pl = plan(&p, Machine::parse("4x4x4").expect("machine")).expect("plans");
    let images = compile_images(&p, &pl).expect("images");
    assert_eq!(images.len(), 64);
    assert_eq!(pl.boards.len(), images.len());
    let on_contact = &p.contact.as_ref().expect("contact").node_globals;
    let (mut with, mut without) = (0, 0);
    for (im, b) in images.iter().zip(&pl.boards) {
        assert_eq!(im.coords, b.coords);
        let d = decode_image(&im.bytes, Some(im.header.board)).expect("decodes");
        let owns = (b.nodes.iter().zip(&b.owner)).any(|(n, &o)| o && on_contact.contains(n));
        if owns {
            with += 1;
            assert_eq!(d.contact_nodes.len(), table, "board {:?}", im.coords);
            assert!(d.contact_nodes.iter().any(|(_, place)| place.owned));
            assert!(im.header.uses(Feature::Contact).is_some());
        } else {
            without += 1;
            let c = im.header.counts;
            assert_eq!(
                (
                    c.contact_nodes,
                    c.contact_faces,
                    c.tools,
                    c.pairs,
                    c.contact_boards
                ),
                (0, 0, 0, 0, 0),
                "board {:?}",
                im.coords
            );
            assert!(im.header.uses(Feature::Contact).is_none());
        }
    }
    println!("{with} boards with the contact tables, {without} without");
    assert!(with > 0 && without > 0);
    assert_eq!(
        parts_needed(images.iter().map(|im| &im.header)),
        vec!["contact", "graphics"]
    );
    let r = report(
        "builtin coarse",
        &p,
        &pl,
        &images,
        &pe_firmware::profile::PE_BOARD,
    )
    .expect("report");
    let text = summary(&r);
    let said = format!("contact on {with} of 64 boards");
    assert!(text.contains(&said), "{said} missing in:\n{text}");

    let seed = repo_scene("seed-box.toml");
    let pl = plan(&seed, Machine::parse("2x2x2").expect("machine")).expect("plans");
    let images = compile_images(&seed, &pl).expect("images");
    assert_eq!(
        parts_needed(images.iter().map(|im| &im.header)),
        vec!["graphics"]
    );
}
