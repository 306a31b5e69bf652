//! Faults on the global network (contact exchange, graphics, tool forces): injected on the
//! packets the boards send, recovered by global recovery (`link_proto::recovery::global`)
//! with the clean run's bits and outputs, and without recovery detected and attributed.

use std::time::Duration;

use board_sim::clock::Clocking;
use board_sim::faults::FaultSpec;
use board_sim::{run, SimFault, SimOptions, SimOutput};
use system_tests::*;

/// A run's options. Without recovery, a fault is found by a 5 ms link timeout in
/// simulated time (time that advances only while every board waits, `board_sim::clock`):
/// the blame does not depend on how busy the host is.
fn opts(faults: Option<&str>, workers: usize, recovery: bool) -> SimOptions {
    let d = SimOptions::default();
    SimOptions {
        faults: faults.map(|f| FaultSpec::parse(f).unwrap()),
        workers: Some(workers),
        recovery: if recovery { d.recovery } else { None },
        global_recovery: if recovery { d.global_recovery } else { None },
        link_timeout: if recovery {
            d.link_timeout
        } else {
            Duration::from_millis(5)
        },
        clocking: if recovery {
            d.clocking
        } else {
            Clocking::Simulated {
                quantum_ns: Clocking::QUANTUM_NS,
            }
        },
        ..d
    }
}

fn sim(dir: &std::path::Path, o: &SimOptions) -> SimOutput {
    run(dir, o, &mut |_, _| {}).expect("board-sim run")
}

fn stopped(dir: &std::path::Path, o: &SimOptions) -> SimFault {
    match run(dir, o, &mut |_, _| {}) {
        Ok(_) => panic!("{:?}: the run must not finish", o.faults),
        Err(e) => match e.downcast::<SimFault>() {
            Ok(f) => f,
            Err(e) => panic!("not a fault report: {e}"),
        },
    }
}

fn global_injected(o: &[board_sim::faults::Injected]) -> usize {
    o.iter()
        .filter(|i| i.face.starts_with("global to "))
        .count()
}

/// Global recovery's retransmissions over the boards.
fn global_retransmitted(o: &SimOutput) -> u64 {
    o.boards
        .iter()
        .filter_map(|b| b.recovery.as_ref()?.global.as_ref())
        .map(|g| g.retransmitted_packets)
        .sum()
}

/// The outputs of a run that must not depend on faults recovered: every displacement's
/// bits, the kinetic energy, the host's tool force per step, and every graphics frame the
/// graphics engine assembled (nodes and their f32 bits, chunks).
fn assert_same_outputs(clean: &SimOutput, out: &SimOutput, what: &str) {
    assert_eq!(out.steps, clean.steps, "{what}");
    assert_bit_identical(&clean.displacements, &out.displacements, what);
    assert_eq!(
        out.kinetic_energy.to_bits(),
        clean.kinetic_energy.to_bits(),
        "{what}"
    );
    assert_eq!(out.tool_force.len(), clean.tool_force.len(), "{what}");
    assert!(
        out.tool_force
            .iter()
            .zip(&clean.tool_force)
            .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits)),
        "{what}: tool force"
    );
    assert_eq!(out.graphics.len(), clean.graphics.len(), "{what}");
    for (a, b) in out.graphics.iter().zip(&clean.graphics) {
        assert_eq!(
            (a.frame, a.steps, a.packets),
            (b.frame, b.steps, b.packets),
            "{what}"
        );
        assert_eq!(a.nodes.len(), b.nodes.len(), "{what}: frame {}", a.frame);
        assert!(
            a.nodes
                .iter()
                .zip(&b.nodes)
                .all(|(x, y)| x.0 == y.0 && x.1.map(f32::to_bits) == y.1.map(f32::to_bits)),
            "{what}: graphics frame {}",
            a.frame
        );
    }
}

/// The clean run on 2x2x2, 1000 steps: the probe has pressed the tube (max |u| > 1e-4 m),
/// the host received a non-zero tool force and the graphics engine whole frames, over
/// thousands of global packets.
fn clean_run(dir: &std::path::Path) -> SimOutput {
    let clean = sim(dir, &opts(None, 2, true));
    let u_max = max_abs(&clean.displacements);
    assert!(
        u_max > 1e-4,
        "the probe has moved the tube: max |u| {u_max} m"
    );
    let packets: u64 = clean.boards.iter().map(|b| b.global.packets_sent).sum();
    let graphics: u64 = clean.boards.iter().map(|b| b.global.graphics_packets).sum();
    let tool: u64 = clean.boards.iter().map(|b| b.global.tool_packets).sum();
    assert!(
        packets > 1000 && graphics > 10 && tool > 10,
        "{packets} {graphics} {tool}"
    );
    assert!(clean.graphics.len() >= 4 && clean.graphics[0].nodes.len() > 10);
    assert!(clean
        .tool_force
        .iter()
        .any(|f| f.iter().any(|v| v.abs() > 1e-5)));
    clean
}

/// With recovery (the default), global packets (and frames) lost or corrupted at 1e-3, and
/// global packets alone at 1e-2 (about 50 faults a run, so that global faults certainly
/// hit), over one and two worker threads: the clean run's displacement bits, tool forces
/// and graphics frames, and global recovery retransmitted.
#[test]
fn global_loss_and_corruption_are_recovered_with_the_clean_outputs() {
    let p = builtin_problem("coarse", 1000);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "global-recover");
    let clean = clean_run(&dir);
    assert_eq!(clean.displacements.len(), p.mesh.nodes.len());
    for w in [1, 2] {
        for (spec, must_hit) in [
            ("seed=5,drop=1e-3,corrupt=1e-3", false),
            ("seed=8,drop=1e-2,corrupt=1e-2,on=global", true),
            ("seed=9,drop=1e-2,on=global", true),
        ] {
            let out = sim(&dir, &opts(Some(spec), w, true));
            let g = global_injected(&out.injected);
            println!("workers {w} {spec}: {g} global faults of {} injected, {} global packets retransmitted", out.injected.len(), global_retransmitted(&out));
            assert!(!out.injected.is_empty(), "{spec}: faults were injected");
            if must_hit {
                assert!(g >= 10, "{spec}: global packets were faulted: {g}");
                assert!(global_retransmitted(&out) > 0, "{spec}: and recovered");
            }
            assert_same_outputs(&clean, &out, &format!("workers {w} {spec}"));
        }
    }
}

/// The cause named is a global fault: an injected fault on a global packet ("global to
/// ..."), of the expected kind, and one of those recorded.
fn assert_global_cause(f: &SimFault, kind: &str) {
    let c = &f.cause;
    assert!(c.injected, "cause not injected:\n{f}");
    assert!(c.what.starts_with(&format!("injected {kind}")), "{f}");
    let face = c.face.as_deref().expect("names where");
    assert!(face.starts_with("global to "), "{f}");
    assert!(
        f.injected
            .iter()
            .any(|i| i.board == c.board && i.face == face && i.step as u64 == c.step),
        "the cause is one of the injected faults:\n{f}"
    );
}

/// Without recovery, a dropped global packet stops the run: a board waiting for a partner's
/// packet times out, or the sinks find a board's graphics or tool-force packets missing at
/// the end (a silent wrong output otherwise); the cause named is the injected drop on that
/// board's packets to that destination, and the observation matches it.
#[test]
fn a_dropped_global_packet_stops_the_run_naming_it() {
    use pe_firmware::runtime::FaultKind as K;
    let p = builtin_problem("coarse", 1000);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "global-drop");
    let mut causes = std::collections::HashMap::new();
    for w in [1, 2] {
        for seed in [8, 21] {
            let spec = format!("seed={seed},drop=5e-3,on=global");
            let f = stopped(&dir, &opts(Some(&spec), w, false));
            println!("{f}");
            assert_global_cause(&f, "drop");
            let d = &f.observed[f.cause.detected];
            let face = f.cause.face.as_deref().unwrap();
            let src = link_proto::Machine::address(f.cause.board).unwrap();
            match (d.sink, d.fault.kind) {
                (Some(sink), _) => {
                    assert_eq!(
                        face,
                        format!("global to {}", board_sim::fabric::address_name(sink)),
                        "{f}"
                    );
                    assert_eq!(d.fault.board.map(|v| v as usize), f.cause.board, "{f}");
                }
                (None, K::GlobalTimeout { src: s }) => {
                    assert_eq!(s, src, "the board waited for the sender:\n{f}");
                    let [x, y, z] = d.fault.board;
                    assert_eq!(face, format!("global to ({x},{y},{z})"), "{f}");
                    assert!(f.cause.step <= d.fault.step + 1, "{f}");
                }
                _ => panic!("workers {w}: detected by a wait or a sink:\n{f}"),
            }
            // The faults replay from the seed whatever the threads: the same cause.
            let first = causes.entry(seed).or_insert_with(|| f.cause.clone());
            assert_eq!(*first, f.cause, "workers {w}");
        }
    }
}

/// Without recovery, a corrupted global packet stops the run at its CRC: at the receiving
/// board (bad packet) or the sink; the cause named is the injected corruption.
#[test]
fn a_corrupted_global_packet_stops_the_run_naming_it() {
    use pe_firmware::runtime::FaultKind as K;
    let p = builtin_problem("coarse", 1000);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "global-corrupt");
    let mut causes = std::collections::HashMap::new();
    for w in [1, 2] {
        for seed in [9, 22] {
            let spec = format!("seed={seed},corrupt=5e-3,on=global");
            let f = stopped(&dir, &opts(Some(&spec), w, false));
            println!("{f}");
            assert_global_cause(&f, "corrupt");
            let d = &f.observed[f.cause.detected];
            assert!(
                matches!(d.fault.kind, K::BadPacket { .. } | K::GlobalTimeout { .. }),
                "{f}"
            );
            // The first global fault injected stopped it (a corrupted packet is seen at once).
            let first = f
                .injected
                .iter()
                .filter(|i| i.face.starts_with("global"))
                .map(|i| i.step)
                .min()
                .unwrap();
            assert_eq!(f.cause.step, first as u64, "{f}");
            let c = causes.entry(seed).or_insert_with(|| f.cause.clone());
            assert_eq!(*c, f.cause, "workers {w}");
        }
    }
}

/// Every global packet lost, with recovery: the flows are given up after the bounded
/// retransmissions and the run stops (no hang) naming an injected global drop; a stalled
/// board (frames and packets) is named too.
#[test]
fn global_retries_exhausted_stop_the_run() {
    use pe_firmware::runtime::FaultKind as K;
    let p = builtin_problem("coarse", 200);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "global-retries");
    for w in [1, 2] {
        let f = stopped(&dir, &opts(Some("seed=1,drop=1.0,on=global"), w, true));
        println!("{f}");
        // Recovery gives up (after about 1.5 s of retransmissions: 10 + 20 + 40 + 80 +
        // 160 ms x 5, then the next timer) before the 10 s link timeout: shown by what
        // detected it, recovery's exhausted retries with the configured count, not by the
        // wall clock (no timing assert on a shared machine).
        assert_global_cause(&f, "drop");
        let d = &f.observed[f.cause.detected];
        let K::GlobalError {
            error: link_proto::RecvError::GlobalRetriesExhausted { peer, requests, .. },
        } = d.fault.kind
        else {
            panic!("detected by global recovery giving up:\n{f}");
        };
        assert_eq!(
            requests,
            link_proto::recovery::global::GlobalConfig::default().retries
        );
        assert_eq!(
            d.fault.board.map(|v| v as usize),
            f.cause.board,
            "the sender gave up:\n{f}"
        );
        assert_eq!(
            f.cause.face.as_deref(),
            Some(format!("global to {}", board_sim::fabric::address_name(peer)).as_str()),
            "{f}"
        );
    }
}

/// One board (no contact partners: its global packets go to the graphics engine and the
/// host only): without recovery a lost graphics or tool-force packet would only leave the
/// outputs one packet short, a silent wrong answer. The sinks compare what arrived from
/// each board with what the board counted sent, and the run stops naming the injected drop
/// on that board's packets to that sink. (131 packets in 1000 steps, 5% lost: a run without
/// a loss has probability 0.95^131 ≈ 1e-3, and the seeds are fixed.)
#[test]
fn a_lost_graphics_or_tool_force_packet_is_not_a_silent_wrong_answer() {
    let p = builtin_problem("coarse", 1000);
    let dir = compile(&p, "builtin:coarse", "1x1x1", "global-sink");
    let clean = sim(&dir, &opts(None, 1, false));
    assert!(clean.boards[0].global.graphics_packets > 50);
    assert!(clean.boards[0].global.tool_packets > 10);
    for seed in [3, 4] {
        let spec = format!("seed={seed},drop=5e-2,on=global");
        let f = stopped(&dir, &opts(Some(&spec), 1, false));
        println!("{f}");
        assert!(global_injected(&f.injected) > 0);
        assert_global_cause(&f, "drop");
        let d = &f.observed[f.cause.detected];
        let sink = d.sink.expect("detected by a sink");
        assert_eq!(
            f.cause.face.as_deref(),
            Some(format!("global to {}", board_sim::fabric::address_name(sink)).as_str()),
            "{f}"
        );
        assert_eq!(f.cause.board, [0, 0, 0]);
    }
}

/// A board that stalls sends no more global packets either: on one board (whose packets go
/// to the sinks only), with recovery, its unacknowledged packets fill its window and its
/// wait times out; the cause named is the injected stall on its global packets, at the
/// stall's step.
#[test]
fn a_stalled_board_stops_its_global_packets_and_is_named() {
    let p = builtin_problem("coarse", 1000);
    let dir = compile(&p, "builtin:coarse", "1x1x1", "global-stall");
    // Simulated time: the stalled board's wait times out after 20 ms of it, whatever the
    // host's load.
    let o = SimOptions {
        link_timeout: Duration::from_millis(20),
        clocking: Clocking::Simulated {
            quantum_ns: Clocking::QUANTUM_NS,
        },
        ..opts(Some("seed=1,stall=0.0.0@900"), 1, true)
    };
    let f = stopped(&dir, &o);
    println!("{f}");
    assert_global_cause(&f, "stall");
    assert_eq!(f.cause.board, [0, 0, 0]);
    assert_eq!(f.cause.step, 900);
    let d = &f.observed[f.cause.detected];
    assert!(d.fault.step >= 900, "{f}");
}
