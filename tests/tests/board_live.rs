//! `board-sim live` (issue 60): the live session over the emulated array (board-sim's
//! `BoardSimEngine`), driven by an in-process client through the session's hub exactly as
//! a WebSocket client's reader thread drives it; and the session's record replayed by
//! `board-sim run --replay` (the poses sent to the boards as ToolPose packets) gives the
//! same tool forces bit for bit.

use host_tools::compare::nan_max;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use board_sim::live::BoardSimEngine;
use board_sim::{run, SimOptions};
use host_tools::live::engine::{Engine, EngineInfo, Pose};
use host_tools::live::hub::{Inbound, Outbound, Outbox, Transport};
use host_tools::live::session::record::replay_schedule_for;
use host_tools::live::session::{self, Config};
use system_tests::*;

/// Steps of the session: 0.28 s at the coarse level's 1.398e-4 s, six surface frames of
/// the images' graphics stream (every 40 ms of simulated time).
const STEPS: u64 = 2000;
/// How far the client's one pose moves the probe along the scene's push (m): the scene's
/// own push (1 mm gap + 3.5 mm), which the session reaches at the contact search's bound
/// (10 cm/s, 14 µm a step) in ~330 steps.
const PRESS_M: f64 = 0.0045;
/// The probe's force rises past this (N): the live replay test's bound for its press
/// (measured here: 8.3e-3 N at most over 1 ms means, 1e-3 to 3.7e-3 N a step from step
/// 800 on, as the soft coarse tube rings under the held probe).
const FORCE_MIN_N: f64 = 1e-3;
/// The surface moves at least this much (m) by the last frame.
const MOVE_MIN_M: f64 = 2e-4;

/// The engine, each step's tool forces kept (what the replay must reproduce).
struct Kept {
    engine: BoardSimEngine,
    forces: Vec<[f64; 3]>,
}

impl Engine for Kept {
    fn info(&self) -> &EngineInfo {
        self.engine.info()
    }
    fn set_pose(&mut self, tool: usize, pose: Pose, step: u64) -> anyhow::Result<()> {
        self.engine.set_pose(tool, pose, step)
    }
    fn step(&mut self) -> anyhow::Result<()> {
        self.engine.step()?;
        self.forces.extend_from_slice(self.engine.tool_forces());
        Ok(())
    }
    fn step_index(&self) -> u64 {
        self.engine.step_index()
    }
    fn time_s(&self) -> f64 {
        self.engine.time_s()
    }
    fn dt_s(&self) -> f64 {
        self.engine.dt_s()
    }
    fn tool_forces(&self) -> &[[f64; 3]] {
        self.engine.tool_forces()
    }
    fn surface_positions(&mut self, out: &mut Vec<f32>) {
        self.engine.surface_positions(out)
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The scene's push direction (unit): where its scripted path moves the probe.
fn push_direction() -> [f64; 3] {
    let sc = host_tools::scene::builtin::builtin_scene("coarse").expect("builtin scene");
    let end = sc.tool[0].path[1];
    let len = norm([end[1], end[2], end[3]]);
    [end[1] / len, end[2] / len, end[3] / len]
}

/// The coarse built-in scene on 2x2x2 emulated boards, live (not paced), one client that
/// presses the probe onto the right tube with one pose: the client sees the force rise and
/// the surface move; the session's record replayed by board-sim gives its tool forces.
#[test]
fn board_sim_live_presses_the_tube_and_its_record_replays_bit_for_bit() {
    let p = builtin_problem("coarse", STEPS);
    let dir = compile(&p, "builtin:coarse", "2x2x2", "board-live-2x2x2");
    let record = dir.join("session.jsonl");
    let engine = BoardSimEngine::start(&dir, &SimOptions::default()).expect("boards start");
    assert_eq!(engine.info().tools.len(), 1);
    assert_eq!(
        engine.info().pose_delay_steps,
        link_proto::tool_pose::POSE_DELAY_STEPS
    );
    let reference: Vec<f32> = engine
        .info()
        .surface
        .reference_m
        .iter()
        .flatten()
        .copied()
        .collect();
    assert!(reference.len() > 300, "{} surface values", reference.len());
    let scene = engine.info().scene.clone();
    let mut kept = Kept {
        engine,
        forces: Vec::new(),
    };

    // The client: connects, sends one pose.
    let (tx, rx) = mpsc::channel();
    let outbox = Outbox::new(1 << 20);
    let send = |m| tx.send(m).expect("session's inbound");
    send(Inbound::Connected {
        client: 1,
        transport: Transport::WebSocket,
        peer: "in-process test client".into(),
        outbox: outbox.clone(),
    });
    let d = push_direction();
    send(Inbound::Pose {
        client: 1,
        tool: "probe".into(),
        pose: Pose {
            q: [1.0, 0.0, 0.0, 0.0],
            p_m: d.map(|v| v * PRESS_M),
        },
        received: Instant::now(),
    });
    let reader = {
        let reference = reference.clone();
        std::thread::spawn(move || {
            let (mut f_max, mut u_max, mut frames) = (0.0f64, 0.0f64, 0);
            loop {
                let Some(m) = outbox.pop(Duration::from_millis(50)) else {
                    if outbox.is_closed() {
                        return (f_max, u_max, frames);
                    }
                    continue;
                };
                match m {
                    Outbound::Force { force_n, .. } => f_max = f_max.max(norm(force_n)),
                    Outbound::Surface { positions_m, .. } => {
                        assert_eq!(positions_m.len(), reference.len(), "surface frame length");
                        frames += 1;
                        for (x, x0) in positions_m.iter().zip(&reference) {
                            u_max = u_max.max(f64::from((x - x0).abs()));
                        }
                    }
                    _ => {}
                }
            }
        })
    };
    let cfg = Config {
        pace: false,
        max_steps: Some(STEPS),
        record: Some(record.clone()),
        quiet: true,
        ..Config::default()
    };
    let summary = session::run(&mut kept, &rx, &cfg, &AtomicBool::new(false)).expect("session");
    assert_eq!(summary.error, None);
    assert_eq!(summary.steps, STEPS);
    drop(tx);

    // What the client received (read as it came: the session closes a client's outbox as
    // it ends): the force rises, the surface moves.
    let (f_max, u_max, frames) = reader.join().expect("client reader");
    println!("client: force max {f_max:.4e} N (1 ms means), surface moved {u_max:.3e} m over {frames} frames");
    assert!(f_max > FORCE_MIN_N, "the probe presses: {f_max} N");
    assert!(u_max > MOVE_MIN_M, "the tube moves: {u_max} m");

    // The record replayed by `board-sim run --replay` (its reader and sender).
    let forces = std::mem::take(&mut kept.forces);
    drop(kept);
    let schedule =
        replay_schedule_for(&record, &scene, p.time_step.dt_s, &["probe"]).expect("record");
    assert!(
        schedule.poses.len() > 100,
        "{} poses recorded",
        schedule.poses.len()
    );
    let opts = SimOptions {
        poses: schedule,
        ..SimOptions::default()
    };
    let replay = run(&dir, &opts, &mut |_, _| {}).expect("board-sim replay");
    let f_max_step = forces.iter().map(|f| norm(*f)).fold(0.0, nan_max);
    let touched = forces.iter().filter(|f| norm(**f) > 0.0).count();
    println!("live: probe force at most {f_max_step:.4e} N a step, {touched} of {STEPS} steps in contact");
    assert_eq!(forces.len(), STEPS as usize);
    assert_eq!(replay.tool_force.len(), forces.len());
    assert!(f_max_step > FORCE_MIN_N, "pressed: {f_max_step} N");
    assert!(
        touched > STEPS as usize / 4,
        "in contact for {touched} steps"
    );
    let bits =
        |v: &[[f64; 3]]| -> Vec<[u64; 3]> { v.iter().map(|x| x.map(f64::to_bits)).collect() };
    assert_eq!(
        bits(&replay.tool_force),
        bits(&forces),
        "tool force, step by step"
    );
}
