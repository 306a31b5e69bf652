//! board-sim against the serial solver, determinism and fault injection.

use std::time::Duration;

use board_sim::links::FaultSpec;
use board_sim::{run, SimFault, SimOptions};
use host_tools::solver;
use system_tests::*;

fn sim(dir: &std::path::Path, opts: &SimOptions) -> board_sim::SimOutput {
    run(dir, opts, &mut |_, _| {}).expect("board-sim run")
}

/// One board runs the same additions in the same order as the serial solver: bit for bit.
/// 1000 steps: the probe has pressed the tube by 0.19 mm (the fields compared are far from
/// zero: asserted above 1e-4 m, half of that, before the comparison).
#[test]
fn one_board_equals_serial_bit_for_bit() {
    let p = builtin_problem("coarse", 1000);
    let serial = solver::run(&p, "serial", &mut ()).unwrap().displacements;
    let dir = compile(&p, "builtin:coarse", "1x1x1", "b111");
    let out = sim(&dir, &SimOptions::default());
    assert_eq!(out.steps, 1000);
    let u_max = max_abs(&serial);
    assert!(
        u_max > 1e-4,
        "the probe has moved the tube: max |u| {u_max} m"
    );
    assert_bit_identical(&serial, &out.displacements, "1x1x1 against serial");
}

/// The parallel solver (`pe solve --threads N`) computes the bits of one thread and of one
/// board, whatever N, in both precisions: on the built-in (general kernel, contact) and on
/// the seed's box (parallelepiped kernel), each far from rest after its steps.
#[test]
fn threads_give_the_bits_of_one_thread_and_of_one_board() {
    let mut cases = vec![(builtin_problem("coarse", 1000), "builtin")];
    let mut seed_box = repo_scene("seed-box.toml");
    seed_box.solver.steps = Some(400);
    cases.push((seed_box, "seed box"));
    for (mut p, name) in cases {
        for precision in [
            pe_firmware::image::Precision::F64,
            pe_firmware::image::Precision::F32,
        ] {
            p.solver.precision = precision;
            let one = solver::run(&p, name, &mut ()).unwrap().displacements;
            let u_max = max_abs(&one);
            assert!(u_max > 1e-4, "{name} {precision}: moved, max |u| {u_max} m");
            for threads in [2, 3] {
                let many = solver::run_threads(&p, name, &mut (), threads)
                    .unwrap()
                    .displacements;
                assert_bit_identical(
                    &one,
                    &many,
                    &format!("{name} {precision}: {threads} threads against one"),
                );
            }
            if name == "builtin" && precision == pe_firmware::image::Precision::F64 {
                let dir = compile(&p, "builtin:coarse", "1x1x1", "threads-b111");
                let board = sim(&dir, &SimOptions::default()).displacements;
                assert_bit_identical(&one, &board, "one board against one thread");
            }
        }
    }
}

/// The manifest repeats the images' step; an image set whose step differs from it (an
/// image from another compilation) is refused before the run, naming the image.
#[test]
fn a_manifest_that_disagrees_with_its_images_is_refused() {
    let p = builtin_problem("coarse", 10);
    let dir = compile(&p, "builtin:coarse", "1x1x1", "manifest-dt");
    let path = dir.join("manifest.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let mut m: serde_json::Value = serde_json::from_str(&text).unwrap();
    let dt = m["dt_s"].as_f64().unwrap();
    assert!(dt > 0.0);
    m["dt_s"] = serde_json::json!(dt * 1.5);
    std::fs::write(&path, m.to_string()).unwrap();
    let e = run(&dir, &SimOptions::default(), &mut |_, _| {})
        .err()
        .expect("refused")
        .to_string();
    assert!(
        e.contains("board-0-0-0.bin") && e.contains("another compilation"),
        "{e}"
    );
}

/// 2x2x2 and 4x4x4 (and a non-cubic 4x2x1) on the built-in scene equal the serial run to
/// 1e-12 relative: only the order of the force sums differs (round-off ~1e-16 per step).
/// 1600 steps: the probe first touches the tube after about 800, the tube rebounds off it
/// and is pressed again from about 1450.
#[test]
fn machines_equal_serial_on_the_builtin_scene() {
    let p = builtin_problem("coarse", 1600);
    let serial = solver::run(&p, "serial", &mut ()).unwrap();
    for m in ["2x2x2", "4x4x4", "4x2x1"] {
        let dir = compile(&p, "builtin:coarse", m, &format!("builtin-{m}"));
        let out = sim(&dir, &SimOptions::default());
        let d = max_rel_diff(&serial.displacements, &out.displacements);
        println!("{m}: max relative difference {d:e}");
        assert!(d < 1e-12, "{m}: {d:e}");
        // The probe's force, summed by the host from the boards' packets, matches too
        // (summed in another order: round-off).
        let a = serial.report.contact.as_ref().unwrap().tool_force_final_n[0][2];
        let b = out.tool_force[out.tool_force.len() - 1][2];
        assert!(a.abs() > 0.0, "{m}: the probe touches the tube");
        assert!(
            (a - b).abs() < 1e-9 * a.abs(),
            "{m}: probe force {a} vs {b}"
        );
    }
}

/// The same on a real mesh (the uterus reference mesh, two materials incl. Mooney-Rivlin,
/// gravity): 1x1x1 bit-identical, 2x2x2 and 4x4x4 within 1e-12.
#[test]
fn machines_equal_serial_on_a_real_mesh() {
    shared_meshes_dir();
    let (p, src) = file_problem("uterus320.toml");
    let serial = solver::run(&p, "serial", &mut ()).unwrap().displacements;
    for m in ["1x1x1", "2x2x2", "4x4x4"] {
        let dir = compile(&p, &src, m, &format!("uterus-{m}"));
        let out = sim(&dir, &SimOptions::default());
        let d = max_rel_diff(&serial, &out.displacements);
        println!("{m}: max relative difference {d:e}");
        if m == "1x1x1" {
            assert_eq!(d, 0.0);
        }
        assert!(d < 1e-12, "{m}: {d:e}");
    }
}

/// Prisms on the boards: Gmsh's hex-and-prism beam (prisms as degenerate hexahedra, a
/// node repeated in every prism) sagging from its physical surface "clamped": one board
/// bit-identical to the serial run, two boards within 1e-12 (their partial sums meet in
/// another order), with a tip motion far from zero.
#[test]
fn machines_equal_serial_on_a_hex_and_prism_mesh() {
    let (p, src) = file_problem("beam_mixed.toml");
    let prisms = p
        .mesh
        .cells
        .iter()
        .filter(|c| host_tools::mesh::is_prism(c))
        .count();
    assert!(prisms >= 20, "{prisms} prisms");
    let serial = solver::run(&p, "serial", &mut ()).unwrap().displacements;
    let u_max = max_abs(&serial);
    assert!(u_max > 1e-3, "the beam sags: max |u| {u_max} m");
    for m in ["1x1x1", "2x1x1"] {
        let dir = compile(&p, &src, m, &format!("beam-mixed-{m}"));
        let out = sim(&dir, &SimOptions::default());
        assert_eq!(serial.len(), out.displacements.len());
        let d = max_rel_diff(&serial, &out.displacements);
        println!("{m}: max relative difference {d:e}");
        if m == "1x1x1" {
            assert_eq!(d, 0.0);
        }
        assert!(d < 1e-12, "{m}: {d:e}");
    }
}

/// Two runs give identical bytes whatever the threads' timing: every sum's order is fixed
/// by the schedule, not by arrival.
#[test]
fn two_runs_are_bit_identical() {
    // 1000 steps: the probe has pressed the tube, so the fields and sums are far from zero.
    let p = builtin_problem("coarse", 1000);
    let dir = compile(&p, "builtin:coarse", "4x4x4", "repeat");
    // Two worker threads, so boards finish in an order the threads decide.
    let opts = SimOptions {
        workers: Some(2),
        ..Default::default()
    };
    let (a, b) = (sim(&dir, &opts), sim(&dir, &opts));
    // 1e-4 m: half the 0.19 mm the probe has pressed the tube by at 1000 steps.
    let u_max = max_abs(&a.displacements);
    assert!(u_max > 1e-4, "max |u| {u_max} m");
    assert!(a.kinetic_energy > 0.0 && a.reaction_fixed.iter().any(|v| v.abs() > 1e-9));
    assert_bit_identical(&a.displacements, &b.displacements, "two runs");
    // The host's sums over the boards are taken in board order, not arrival order.
    assert_eq!(a.kinetic_energy.to_bits(), b.kinetic_energy.to_bits());
    assert_eq!(
        a.reaction_fixed.map(f64::to_bits),
        b.reaction_fixed.map(f64::to_bits)
    );
    assert_eq!(
        a.reaction_prescribed.map(f64::to_bits),
        b.reaction_prescribed.map(f64::to_bits)
    );
}

/// A stall on a board the machine does not have is refused, not silently ignored.
#[test]
fn a_stall_outside_the_machine_is_refused() {
    let p = builtin_problem("coarse", 20);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "stall-outside");
    let opts = SimOptions {
        faults: Some(FaultSpec::parse("seed=1,stall=5.5.5@10").unwrap()),
        ..Default::default()
    };
    let e = run(&dir, &opts, &mut |_, _| {})
        .err()
        .expect("refused")
        .to_string();
    assert!(e.contains("no board (5,5,5)") && e.contains("2x2x2"), "{e}");
    // Inside the machine the same spec runs (and stalls).
    let opts = SimOptions {
        faults: Some(FaultSpec::parse("seed=1,stall=1.1.1@10").unwrap()),
        link_timeout: Duration::from_millis(500),
        ..Default::default()
    };
    assert!(run(&dir, &opts, &mut |_, _| {})
        .err()
        .expect("a stall is a fault")
        .downcast::<SimFault>()
        .is_ok());
}

fn faulty(dir: &std::path::Path, spec: &str) -> SimFault {
    let opts = SimOptions {
        faults: Some(FaultSpec::parse(spec).unwrap()),
        link_timeout: Duration::from_millis(500),
        ..Default::default()
    };
    match run(dir, &opts, &mut |_, _| {}) {
        Ok(_) => panic!("faults {spec}: the run must not finish silently"),
        Err(e) => match e.downcast::<SimFault>() {
            Ok(f) => f,
            Err(e) => panic!("faults {spec}: not a fault report: {e}"),
        },
    }
}

/// A corrupted frame is detected by its CRC at the receiver: the run stops with a report
/// naming the board, the link and the step of the injected corruption.
#[test]
fn corrupted_frames_are_detected_and_named() {
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "corrupt");
    let f = faulty(&dir, "seed=7,corrupt=0.01");
    let first = &f.injected[0];
    let root = &f.faults[0];
    println!("{f}");
    assert!(
        matches!(root.kind, pe_firmware::runtime::FaultKind::BadFrame { .. }),
        "{root}"
    );
    assert_eq!(
        root.step, first.step as u64,
        "detected at the step it was injected"
    );
    assert!(root.to_string().contains("link"), "{root}");
}

/// A lost frame is detected at the step it was lost, naming board, link and step: either
/// the next step's frame arrives in its place (its step number gives it away) or, at the
/// last exchange, the link times out.
#[test]
fn dropped_frames_are_detected_and_named() {
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "drop");
    let f = faulty(&dir, "seed=3,drop=0.01");
    let first = &f.injected[0];
    let root = &f.faults[0];
    assert!(
        matches!(
            root.kind,
            pe_firmware::runtime::FaultKind::LinkTimeout { .. }
                | pe_firmware::runtime::FaultKind::UnexpectedFrame { .. }
        ),
        "{root}"
    );
    assert_eq!(root.step, first.step as u64);
}

/// A board that stalls is detected by its neighbours at that step.
#[test]
fn a_stalled_board_is_detected() {
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "stall");
    let f = faulty(&dir, "seed=1,stall=1.0.0@50");
    assert_eq!(f.faults[0].step, 50, "{f}");
    assert!(f
        .injected
        .iter()
        .any(|i| i.board == [1, 0, 0] && i.what == "stall"));
}

/// The same seed replays the same faults (all randomness comes from the printed seed).
#[test]
fn fault_injection_replays_from_its_seed() {
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "replay");
    let a = faulty(&dir, "seed=11,corrupt=0.005");
    let b = faulty(&dir, "seed=11,corrupt=0.005");
    assert_eq!(a.injected[0], b.injected[0]);
    assert_eq!(a.faults[0], b.faults[0]);
}
