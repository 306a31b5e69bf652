//! board-sim against the serial solver, determinism and fault injection.

use host_tools::compare::nan_max;
use std::time::Duration;

use board_sim::clock::Clocking;
use board_sim::faults::FaultSpec;
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
    let u_max = max_abs(&serial);
    assert!(
        u_max > 1e-4,
        "the probe has moved the tube: max |u| {u_max} m"
    );
    // The board's element batches on the host's lanes (the default) and on the firmware's
    // scalar loop itself.
    for batched in [true, false] {
        let opts = SimOptions {
            batched,
            ..Default::default()
        };
        let out = sim(&dir, &opts);
        assert_eq!(out.steps, 1000);
        let what = format!("1x1x1 against serial, batched {batched}");
        assert_bit_identical(&serial, &out.displacements, &what);
    }
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
/// 2000 steps: the probe first touches the tube at step 876, the tube rebounds off it and
/// is struck again in short touches (1106, 1326, 1511, ...) until the probe presses it for
/// good from step 1950 (`pe solve --builtin --level coarse --steps 2200 --tool-force`).
#[test]
fn machines_equal_serial_on_the_builtin_scene() {
    let p = builtin_problem("coarse", 2000);
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

/// Full integration (eight Gauss points, no hourglass control: the boards' other element
/// kernel) on the built-in scene after 1000 steps (the probe has pressed the tube: fields
/// above 1e-4 m): one board is the serial run bit for bit, on the host's lanes and on the
/// firmware's scalar loop; 2x2x2 equals it to 1e-12 relative (only the order of the force
/// sums differs, as for reduced integration). The firmware itself under QEMU:
/// `scripts/qemu-check.sh`.
#[test]
fn full_integration_on_boards_equals_serial() {
    let mut p = builtin_problem("coarse", 1000);
    p.solver.integration = pe_firmware::image::Integration::Full;
    let serial = solver::run(&p, "serial full", &mut ()).unwrap();
    assert_eq!(serial.report.integration, "full");
    let u_max = max_abs(&serial.displacements);
    assert!(
        u_max > 1e-4,
        "the probe has moved the tube: max |u| {u_max} m"
    );
    let reduced = solver::run(&builtin_problem("coarse", 1000), "serial", &mut ()).unwrap();
    let apart = max_rel_diff(&serial.displacements, &reduced.displacements);
    assert!(
        apart > 1e-3,
        "full and reduced differ ({apart:e}): another kernel ran"
    );
    let dir = compile(&p, "builtin:coarse", "1x1x1", "full-b111");
    for batched in [true, false] {
        let out = sim(
            &dir,
            &SimOptions {
                batched,
                ..Default::default()
            },
        );
        assert_eq!(out.steps, 1000);
        let what = format!("full, 1x1x1 against serial, batched {batched}");
        assert_bit_identical(&serial.displacements, &out.displacements, &what);
    }
    let dir = compile(&p, "builtin:coarse", "2x2x2", "full-b222");
    let out = sim(&dir, &SimOptions::default());
    let d = max_rel_diff(&serial.displacements, &out.displacements);
    println!("full 2x2x2: max relative difference {d:e}");
    assert!(d < 1e-12, "full 2x2x2: {d:e}");
}

/// In f32 the boards send their contact nodes' f32 displacements as they are (16-byte
/// entries, not 28): 2x2x2 on the built-in scene equals the f32 serial run to 5e-5 of the
/// largest displacement. Only the order of the force sums differs, but in f32 (round-off
/// 6e-8 per sum) over 1600 steps of dynamics and contact: measured 8.7e-6, the bound is
/// about six times that. The boards did exchange contact nodes (over a hundred per
/// step), the probe touched the tube, and the fields are far from zero (above 1e-4 m).
#[test]
fn f32_machines_equal_the_f32_serial_run_with_contact() {
    let mut p = builtin_problem("coarse", 1600);
    p.solver.precision = pe_firmware::image::Precision::F32;
    let serial = solver::run(&p, "serial f32", &mut ()).unwrap();
    let u_max = max_abs(&serial.displacements);
    assert!(
        u_max > 1e-4,
        "the probe has moved the tube: max |u| {u_max} m"
    );
    let dir = compile(&p, "builtin:coarse", "2x2x2", "builtin-f32-2x2x2");
    let out = sim(&dir, &SimOptions::default());
    assert_eq!(out.steps, 1600);
    assert_eq!(out.displacements.len(), serial.displacements.len());
    let d = max_rel_diff(&serial.displacements, &out.displacements);
    println!("2x2x2 f32: max relative difference {d:e}");
    assert!(d < 5e-5, "2x2x2 f32: {d:e}");
    let vectors: u64 = out.boards.iter().map(|b| b.global.node_vectors).sum();
    assert!(
        vectors > 100 * out.steps,
        "contact nodes crossed the global network: {vectors} in {} steps",
        out.steps
    );
    let probe = out.tool_force.iter().map(|f| f[2].abs()).fold(0.0, nan_max);
    assert!(probe > 0.0, "the probe touched the tube");
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
    faulty_with(dir, spec, None, Duration::from_millis(5), simulated())
}

/// Simulated time at board-sim's quantum (100 us): time advances only while every board
/// waits, so a link timeout of a few ms names a fault whatever the host's load, and a
/// healthy link never times out (`a_healthy_machine_never_waits_in_simulated_time`).
fn simulated() -> Clocking {
    Clocking::Simulated {
        quantum_ns: Clocking::QUANTUM_NS,
    }
}

fn faulty_with(
    dir: &std::path::Path,
    spec: &str,
    workers: Option<usize>,
    link_timeout: Duration,
    clocking: Clocking,
) -> SimFault {
    // Without link recovery: every fault stops the run, and is named.
    let opts = SimOptions {
        faults: Some(FaultSpec::parse(spec).unwrap()),
        link_timeout,
        workers,
        recovery: None,
        clocking,
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

/// The board across `face` (named as in the reports) of `board` on a 2x2x2 machine: the
/// neighbour on a link face, the named board on the global network ("global to (x,y,z)").
fn across(board: [usize; 3], face: &str) -> Option<[usize; 3]> {
    if let Some(to) = face.strip_prefix("global to (") {
        let mut c = to
            .trim_end_matches(')')
            .split(',')
            .map(|v| v.trim().parse().ok());
        let peer = [c.next()??, c.next()??, c.next()??];
        return (c.next().is_none() && peer != board && peer.iter().all(|&v| v < 2))
            .then_some(peer);
    }
    let f = link_proto::Face::ALL
        .into_iter()
        .find(|f| format!("{f:?}") == face)?;
    let a = f.index() / 2;
    let mut c = board;
    c[a] = if f.sign() > 0 {
        c[a] + 1
    } else {
        c[a].checked_sub(1)?
    };
    (c[a] < 2).then_some(c)
}

/// The named cause is ground truth: an injected fault of the expected kind at the earliest
/// step anything was injected (nothing before it can have caused the stop), on a link of
/// the machine, detected by the board at the other end of that link at that step or later.
fn assert_true_cause(f: &SimFault, kind: &str, workers: usize) {
    let c = &f.cause;
    assert!(c.injected, "workers {workers}: cause not injected:\n{f}");
    assert!(
        c.what.starts_with(&format!("injected {kind}")),
        "workers {workers}: {f}"
    );
    let face = c.face.as_deref().expect("a link fault names its link");
    assert!(
        f.injected
            .iter()
            .any(|i| i.board == c.board && i.face == face && i.step as u64 == c.step),
        "workers {workers}: the cause is one of the injected faults:\n{f}"
    );
    let first = f.injected.iter().map(|i| i.step as u64).min().unwrap();
    assert_eq!(
        c.step, first,
        "workers {workers}: the earliest injected step:\n{f}"
    );
    let d = &f.observed[c.detected];
    assert_eq!(
        Some(d.fault.board.map(|v| v as usize)),
        across(c.board, face),
        "workers {workers}: detected across the link (or by the global network's peer):\n{f}"
    );
    assert!(d.fault.step >= c.step, "workers {workers}: {f}");
    assert!(!f.observed.is_empty());
}

/// Worker counts: one thread for all boards, four, one per board.
const WORKERS: [usize; 3] = [1, 4, 8];

/// A corrupted frame is detected by its CRC at the receiver: the run stops naming the
/// board that sent it, the link and the step, whatever the worker threads.
#[test]
fn corrupted_frames_are_detected_and_named() {
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "corrupt");
    for w in WORKERS {
        let f = faulty_with(
            &dir,
            "seed=7,corrupt=0.01,on=links",
            Some(w),
            Duration::from_millis(500),
            // A CRC failure is seen on arrival, not by a timeout: the default clock.
            Clocking::Wall,
        );
        println!("{f}");
        assert_true_cause(&f, "corrupt", w);
        // A CRC failure is the receiver's own observation, not a wait.
        let d = &f.observed[f.cause.detected];
        assert!(
            matches!(
                d.fault.kind,
                pe_firmware::runtime::FaultKind::BadFrame { .. }
            ),
            "{d}"
        );
    }
}

/// A lost frame is detected at the step it was lost (the next frame's step number gives it
/// away, or the link waits), naming the sender, the link and the step.
#[test]
fn dropped_frames_are_detected_and_named() {
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "drop");
    for w in WORKERS {
        let f = faulty_with(
            &dir,
            "seed=3,drop=0.01,on=links",
            Some(w),
            Duration::from_millis(5),
            simulated(),
        );
        println!("{f}");
        assert_true_cause(&f, "drop", w);
    }
}

/// A board that stalls at step 50 is named (not the neighbours that wait for it), by a
/// 2 ms link timeout in simulated time: its neighbours wait from the moment the machine is
/// stuck, whatever the host's load (on the wall clock, a 2 ms timeout with eight workers on
/// two cores names whichever board's thread the host left waiting).
#[test]
fn a_stalled_board_is_named() {
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "stall");
    for w in WORKERS {
        for board in [[1, 0, 0], [1, 1, 1], [0, 0, 0]] {
            let spec = format!("seed=1,stall={}.{}.{}@50", board[0], board[1], board[2]);
            let f = faulty_with(&dir, &spec, Some(w), Duration::from_millis(2), simulated());
            println!("{f}");
            assert_true_cause(&f, "stall", w);
            assert_eq!(f.cause.board, board, "workers {w}: {f}");
            assert_eq!(f.cause.step, 50, "workers {w}: {f}");
        }
    }
}

/// Frames held longer than the link timeout (10 ms against 5 ms of simulated time): the
/// wait names a delayed link, from its first frame.
#[test]
fn a_delay_beyond_the_timeout_is_named() {
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "delay");
    for w in WORKERS {
        let f = faulty_with(
            &dir,
            "seed=1,delay=10",
            Some(w),
            Duration::from_millis(5),
            simulated(),
        );
        println!("{f}");
        assert_true_cause(&f, "delay", w);
        assert_eq!(f.cause.step, 0);
    }
}

/// The built-in coarse scene on 2x2x2, 1000 steps, compiled into a directory named
/// `name`, and its clean run on the wall clock, whose fields move (the probe has pressed
/// the tube; at 300 steps nothing has moved yet): asserted above 1e-4 m.
fn moving_clean_run(name: &str) -> (TempDir, board_sim::SimOutput) {
    let p = builtin_problem("coarse", 1000);
    let dir = compile(&p, "builtin:coarse", "2x2x2", name);
    let clean = sim(&dir, &SimOptions::default());
    let u_max = max_abs(&clean.displacements);
    assert!(u_max > 1e-4, "the fields compared move: max |u| {u_max} m");
    (dir, clean)
}

/// The other side of the line: every frame held 1 ms, within a 5 ms link timeout of
/// simulated time, and no recovery: the run finishes, with the clean run's bits (the
/// frames were late, not lost). A board waits for a delayed frame about the delay (its
/// neighbours send in the same quantum it starts waiting); a wait on the wall clock would
/// add whatever the host's scheduler costs, and with eight workers on two cores a 5 ms
/// timeout is not safe.
#[test]
fn a_delay_within_the_timeout_is_no_fault() {
    let (dir, clean) = moving_clean_run("late");
    for w in WORKERS {
        let late = run(
            &dir,
            &SimOptions {
                faults: Some(FaultSpec::parse("seed=1,delay=1").unwrap()),
                link_timeout: Duration::from_millis(5),
                workers: Some(w),
                recovery: None,
                global_recovery: None,
                clocking: simulated(),
                ..Default::default()
            },
            &mut |_, _| {},
        )
        .unwrap_or_else(|e| panic!("workers {w}: frames 1 ms late are no fault: {e:#}"));
        assert_eq!(late.steps, clean.steps, "workers {w}");
        assert_eq!(late.displacements.len(), clean.displacements.len());
        assert!(
            late.displacements == clean.displacements,
            "workers {w}: the late run's bits are the clean run's"
        );
        assert!(
            late.injected.iter().any(|i| i.what.starts_with("delay")),
            "workers {w}: the delay was injected: {:?}",
            late.injected
        );
    }
}

/// Simulated time stands still while anything in the machine can move: a clean run with a
/// link timeout of two quanta (200 us), eight workers on however few cores, 1000 steps,
/// finishes with the wall-clock run's bits. Seen failing: with time advancing whenever one worker found
/// nothing to do (not every one), the run stops on a link timeout.
#[test]
fn a_healthy_machine_never_waits_in_simulated_time() {
    let (dir, clean) = moving_clean_run("still");
    for w in WORKERS {
        let still = run(
            &dir,
            &SimOptions {
                link_timeout: Duration::from_micros(200),
                workers: Some(w),
                clocking: simulated(),
                ..Default::default()
            },
            &mut |_, _| {},
        )
        .unwrap_or_else(|e| panic!("workers {w}: a healthy machine timed out: {e:#}"));
        assert_eq!(still.displacements.len(), clean.displacements.len());
        assert!(
            still.displacements == clean.displacements,
            "workers {w}: the bits of the wall-clock run"
        );
    }
}

/// The same seed replays the same faults and the same cause (all randomness comes from the
/// printed seed).
///
/// Each board's faults come from its own stream (the seed mixed with the board; global
/// packets keyed by destination, kind, step and count), so on every board and face both runs
/// inject the same faults in the same order. Which board injects first in wall time, and how
/// far the others get before the run stops, is the threads' timing: the runs are compared
/// stream by stream, up to the shorter one (once, `injected[0]` was compared and a run whose
/// board (0,1,1) corrupted a global packet at step 15 met one where board (0,0,0) had
/// corrupted a frame at step 16 first).
#[test]
fn fault_injection_replays_from_its_seed() {
    use std::collections::BTreeMap;
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "replay");
    let a = faulty(&dir, "seed=11,corrupt=0.005");
    let b = faulty(&dir, "seed=11,corrupt=0.005");
    type Streams = BTreeMap<([usize; 3], String), Vec<(u32, String)>>;
    let streams = |f: &SimFault| -> Streams {
        let mut m = Streams::new();
        for i in &f.injected {
            m.entry((i.board, i.face.clone()))
                .or_default()
                .push((i.step, i.what.clone()));
        }
        m
    };
    let (sa, sb) = (streams(&a), streams(&b));
    assert!(
        !sa.is_empty() && !sb.is_empty(),
        "both runs inject: {a}\n{b}"
    );
    let mut compared = 0;
    for (key, va) in &sa {
        if let Some(vb) = sb.get(key) {
            let n = va.len().min(vb.len());
            assert_eq!(va[..n], vb[..n], "board {:?} {}: {a}\n{b}", key.0, key.1);
            compared += n;
        }
    }
    assert!(compared >= 1, "no stream injected in both runs: {a}\n{b}");
    assert_eq!(a.cause, b.cause);
}

/// With link recovery (the default), frames lost or corrupted at 1e-3 per frame (each alone
/// and both) are sent again: the run finishes with the clean run's bits, and the report
/// shows the retransmissions.
#[test]
fn recovery_gives_the_clean_bits_under_loss_and_corruption() {
    // 1000 steps: the probe has pressed the tube, the fields compared are far from zero.
    let p = builtin_problem("coarse", 1000);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "recover");
    let opts = |faults: Option<&str>| SimOptions {
        faults: faults.map(|f| FaultSpec::parse(f).unwrap()),
        workers: Some(2),
        ..Default::default()
    };
    let clean = sim(&dir, &opts(None));
    let u_max = host_tools::compare::max_abs(&clean.displacements);
    assert!(
        u_max > 1e-4,
        "the probe has moved the tube: max |u| {u_max} m"
    );
    assert_eq!(clean.displacements.len(), p.mesh.nodes.len());
    let retransmitted = |o: &board_sim::SimOutput| -> u64 {
        o.boards
            .iter()
            .filter_map(|b| b.recovery.as_ref())
            .map(|r| r.faces_sum(|f| f.retransmitted_frames))
            .sum()
    };
    // (The clean run may send a frame again too: a request for a frame that crossed it on
    // the way, on a loaded machine. The receiver drops the copy.)
    for spec in [
        "seed=5,drop=1e-3",
        "seed=6,corrupt=1e-3",
        "seed=7,drop=1e-3,corrupt=1e-3",
    ] {
        let out = sim(&dir, &opts(Some(spec)));
        assert!(!out.injected.is_empty(), "{spec}: faults were injected");
        assert!(
            retransmitted(&out) > 0,
            "{spec}: and recovered by retransmission"
        );
        assert_eq!(out.steps, clean.steps, "{spec}");
        assert_eq!(out.displacements.len(), clean.displacements.len(), "{spec}");
        assert!(
            out.displacements
                .iter()
                .zip(&clean.displacements)
                .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits)),
            "{spec}: the clean run's bits"
        );
        assert_eq!(out.kinetic_energy.to_bits(), clean.kinetic_energy.to_bits());
        assert_eq!(out.tool_force.len(), clean.tool_force.len());
        assert!(out
            .tool_force
            .iter()
            .zip(&clean.tool_force)
            .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits)));
    }
}

/// Half the frames lost: recovery gives up on a frame after its bounded requests, and the
/// run stops naming the receiving board, the link and the step, and the injected loss on
/// that link as the cause.
#[test]
fn losses_beyond_the_retry_bound_stop_the_run_naming_the_link() {
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "retries");
    for w in [1, 8] {
        let opts = SimOptions {
            faults: Some(FaultSpec::parse("seed=3,drop=0.5,on=links").unwrap()),
            // Longer than recovery's requests take, so that they are what gives up.
            link_timeout: Duration::from_secs(5),
            workers: Some(w),
            ..Default::default()
        };
        let f = match run(&dir, &opts, &mut |_, _| {}) {
            Ok(_) => panic!("half the frames lost: the run cannot finish"),
            Err(e) => e.downcast::<SimFault>().expect("a fault report"),
        };
        println!("{f}");
        let d = &f.observed[f.cause.detected];
        let pe_firmware::runtime::FaultKind::LinkError { face, error } = d.fault.kind else {
            panic!("workers {w}: detected by recovery giving up: {f}");
        };
        assert!(
            matches!(error, link_proto::RecvError::RetriesExhausted { .. }),
            "{f}"
        );
        assert!(f.cause.injected && f.cause.what == "injected drop", "{f}");
        assert_eq!(
            f.cause.face.as_deref(),
            Some(format!("{:?}", face.opposite()).as_str())
        );
        assert_eq!(
            Some(d.fault.board.map(|v| v as usize)),
            across(f.cause.board, f.cause.face.as_deref().unwrap()),
            "{f}"
        );
        assert!(
            f.cause.step <= d.fault.step && d.fault.step <= f.cause.step + 1,
            "{f}"
        );
    }
}
