//! The session: an [`Engine`] stepped on its own thread, paced to the wall clock, driven by
//! its clients' poses and telling them the forces, the surface and its status. It knows
//! clients only through the hub ([`Inbound`] in, [`Outbound`] out), never a transport.
//!
//! Each step: wait until wall time reaches the step's end (never ahead of real time), take
//! the events that came in, give the engine the poses due (each tool's end moving at most
//! the contact search's bound per step), step, and send what is due: the mean tool forces
//! of each completed millisecond of simulated time, a surface frame every `1/graphics_hz`
//! of wall time, a status every 250 ms. Behind, it steps as fast as it can and past
//! `max_lag_s` lets its clock slip ([`pacing`]).

pub mod clients;
pub mod forces;
pub mod latency;
pub mod pacing;
pub mod record;
pub mod summary;
pub mod tools;

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Receiver;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Result;

use super::engine::{Engine, Pose};
use super::hub::{ClientId, Inbound, Outbound};
use super::protocol::{self, Hello, HelloSurface, HelloTool, ServerMessage, Status};
use clients::Clients;
use forces::ForceMeans;
use latency::Latency;
use pacing::Pacer;
use record::{RecordHeader, Recorder};
pub use summary::Summary;
use tools::Tools;

/// The least graphics rate a session takes (Hz).
pub const GRAPHICS_HZ_MIN: f64 = 25.0;

/// How a session runs.
#[derive(Clone, Debug)]
pub struct Config {
    /// Surface frames per second of wall time (≥ [`GRAPHICS_HZ_MIN`]).
    pub graphics_hz: f64,
    pub status_every: Duration,
    /// Lag past which the clock slips (s).
    pub max_lag_s: f64,
    /// false: run as fast as possible (tests and benchmarks that do not test pacing).
    pub pace: bool,
    /// End after this much wall time (s).
    pub duration_s: Option<f64>,
    /// End after this many steps (tests).
    pub max_steps: Option<u64>,
    pub record: Option<PathBuf>,
    /// No log lines on standard error.
    pub quiet: bool,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            graphics_hz: 30.0,
            status_every: Duration::from_millis(250),
            max_lag_s: 0.1,
            pace: true,
            duration_s: None,
            max_steps: None,
            record: None,
            quiet: false,
        }
    }
}

/// The pacing policy, as `hello` tells it.
fn policy(cfg: &Config) -> String {
    format!(
        "simulated time never runs ahead of wall time; behind, every step is still taken (as fast as the engine goes) and the lag reported; past {} s of lag the session's clock slips forward by the lag (time slows, counted in slips and slipped_s)",
        cfg.max_lag_s
    )
}

/// Runs `engine` as a live session until `stop` is set, the duration or step count is
/// reached, or a step fails (the summary's `error`). Events come from `inbound`.
pub fn run(
    engine: &mut dyn Engine,
    inbound: &Receiver<Inbound>,
    cfg: &Config,
    stop: &AtomicBool,
) -> Result<Summary> {
    let mut s = Session::new(engine, cfg)?;
    let error = s.run_loop(inbound, stop).err().map(|e| format!("{e:#}"));
    if let Some(e) = &error {
        s.log(&format!("the session stopped: {e}"));
        s.clients
            .broadcast(&Outbound::Error(format!("the simulation stopped: {e}")));
    }
    Ok(s.finish(error))
}

struct Session<'e> {
    engine: &'e mut dyn Engine,
    cfg: &'e Config,
    clients: Clients,
    tools: Tools,
    tool_names: Vec<Arc<str>>,
    forces: ForceMeans,
    latency: Latency,
    pacer: Pacer,
    recorder: Option<Recorder>,
    topology: Arc<Vec<u8>>,
    /// The tools' speed bound (m/s): each step's travel bound is this times `dt`.
    speed_m_s: f64,
    dt0_s: f64,
    positions: Vec<f32>,
    frame_seq: u32,
    next_frame: Instant,
    next_status: Instant,
    next_log: Instant,
    next_slip_notice: Instant,
    force_ms: u64,
    surface_frames: u64,
    bad_messages: u64,
    poses_given: u64,
}

impl<'e> Session<'e> {
    fn new(engine: &'e mut dyn Engine, cfg: &'e Config) -> Result<Session<'e>> {
        let info = engine.info().clone();
        let dt0_s = engine.dt_s();
        let recorder = match &cfg.record {
            Some(p) => Some(Recorder::create(
                p,
                &RecordHeader {
                    record: record::RECORD_KIND.into(),
                    version: record::RECORD_VERSION,
                    scene: info.scene.clone(),
                    dt_s: dt0_s,
                    tools: info.tools.iter().map(|t| t.name.clone()).collect(),
                },
            )?),
            None => None,
        };
        let now = Instant::now();
        Ok(Session {
            tools: Tools::new(&info),
            tool_names: info
                .tools
                .iter()
                .map(|t| Arc::from(t.name.as_str()))
                .collect(),
            forces: ForceMeans::new(info.tools.len()),
            latency: Latency::default(),
            pacer: Pacer::new(now, cfg.pace, cfg.max_lag_s),
            recorder,
            topology: Arc::new(protocol::topology_frame(&info.surface)),
            speed_m_s: if dt0_s > 0.0 {
                info.tool_travel_max_m / dt0_s
            } else {
                0.0
            },
            dt0_s,
            positions: Vec::new(),
            frame_seq: 0,
            next_frame: now,
            next_status: now,
            next_log: now + Duration::from_secs(5),
            next_slip_notice: now,
            force_ms: 0,
            surface_frames: 0,
            bad_messages: 0,
            poses_given: 0,
            clients: Clients::default(),
            engine,
            cfg,
        })
    }

    fn log(&self, msg: &str) {
        if !self.cfg.quiet {
            eprintln!("pe live: {msg}");
        }
    }

    fn run_loop(&mut self, inbound: &Receiver<Inbound>, stop: &AtomicBool) -> Result<()> {
        // Every tool starts where the scene places it: the trainer drives, not the path.
        for tool in 0..self.tool_names.len() {
            self.give(tool, Pose::IDENTITY, None)?;
        }
        loop {
            let now = Instant::now();
            let steps_done = self
                .cfg
                .max_steps
                .is_some_and(|n| self.engine.step_index() >= n);
            let time_up = self
                .cfg
                .duration_s
                .is_some_and(|d| self.pacer.wall_s(now) >= d);
            if stop.load(Ordering::Relaxed) || steps_done || time_up {
                return Ok(());
            }
            self.wait_until_due();
            while let Ok(event) = inbound.try_recv() {
                self.handle(event);
            }
            let now = Instant::now();
            let (moves, notices) = self.tools.advance(self.speed_m_s * self.engine.dt_s(), now);
            for m in moves {
                self.give(m.tool, m.pose, m.received)?;
            }
            for n in notices {
                self.clients.send(n.client, Outbound::Notice(n.message));
            }
            let start_s = self.engine.time_s();
            self.engine.step()?;
            self.after_step(start_s);
        }
    }

    /// Sleeps (or spins, for the last fraction of a millisecond) until wall time reaches
    /// the end of the next step.
    fn wait_until_due(&self) {
        let end_s = self.engine.time_s() + self.engine.dt_s();
        while let Some(left) = self.pacer.wait(end_s, Instant::now()) {
            if left > Duration::from_micros(300) {
                std::thread::sleep(left - Duration::from_micros(200));
            } else {
                std::thread::yield_now();
            }
        }
    }

    /// Gives the engine `pose` for `tool` at the first step it can take it; records it.
    fn give(&mut self, tool: usize, pose: Pose, received: Option<Instant>) -> Result<()> {
        let step = self.engine.step_index() + self.engine.info().pose_delay_steps.max(1) - 1;
        self.engine.set_pose(tool, pose, step)?;
        self.poses_given += 1;
        if let Some(r) = received {
            self.latency.took_effect(step, r);
        }
        if let Some(rec) = &mut self.recorder {
            rec.pose(step, tool, &pose)?;
        }
        Ok(())
    }

    fn handle(&mut self, event: Inbound) {
        match event {
            Inbound::Connected {
                client,
                transport,
                peer,
                outbox,
            } => {
                self.log(&format!(
                    "client {client} ({transport:?}, {peer}) connected"
                ));
                self.clients.connect(client, transport, peer, outbox);
                self.clients.send(client, self.hello(client));
                self.clients
                    .send(client, Outbound::Topology(self.topology.clone()));
                for (k, d) in self.tools.driver.iter().enumerate() {
                    if let Some(d) = d {
                        self.clients.send(
                            client,
                            Outbound::Driver {
                                tool: self.tool_names[k].clone(),
                                client: Some(*d),
                            },
                        );
                    }
                }
            }
            Inbound::Pose {
                client,
                tool,
                pose,
                received,
            } => match self.tools.offer(client, &tool, pose, received) {
                Ok(Some(k)) => self.driver_changed(k, Some(client)),
                Ok(None) => {}
                Err(e) => self.clients.send(client, Outbound::Error(e)),
            },
            Inbound::Release { client, tool } => match self.tools.release(client, &tool) {
                Ok(k) => self.driver_changed(k, None),
                Err(e) => self.clients.send(client, Outbound::Error(e)),
            },
            Inbound::Bad { client, message } => {
                self.bad_messages += 1;
                self.log(&format!("client {client}: {message}"));
                self.clients.send(client, Outbound::Error(message));
            }
            Inbound::Disconnected { client, reason } => {
                if let Some(peer) = self.clients.disconnect(client, &reason) {
                    self.log(&format!("client {client} ({peer}) left: {reason}"));
                }
                for k in self.tools.release_all(client) {
                    self.driver_changed(k, None);
                }
            }
        }
    }

    fn driver_changed(&mut self, tool: usize, client: Option<ClientId>) {
        let who = match client {
            Some(c) => format!("client {c} ({})", self.clients.peer(c)),
            None => "nobody".into(),
        };
        self.log(&format!("tool {:?} driven by {who}", self.tool_names[tool]));
        self.clients.broadcast(&Outbound::Driver {
            tool: self.tool_names[tool].clone(),
            client,
        });
    }

    fn hello(&self, client: ClientId) -> Outbound {
        let info = self.engine.info();
        let hello = ServerMessage::Hello(Hello {
            protocol: protocol::VERSION,
            client,
            scene: info.scene.clone(),
            model: info.model.clone(),
            dt_s: self.dt0_s,
            graphics_hz: self.cfg.graphics_hz,
            force_hz: protocol::FORCE_HZ,
            tools: info.tools.iter().map(HelloTool::from).collect(),
            surface: HelloSurface {
                nodes: info.surface.reference_m.len(),
                triangles: info.surface.triangles.len(),
                bodies: info.surface.body_names.clone(),
            },
            pose_delay_steps: info.pose_delay_steps,
            tool_speed_max_m_s: self.speed_m_s,
            max_lag_s: self.cfg.max_lag_s,
            policy: policy(self.cfg),
        });
        Outbound::Hello(Arc::new(
            serde_json::to_value(&hello).unwrap_or(serde_json::Value::Null),
        ))
    }

    /// The forces of a completed millisecond, the pacing, and whatever is due by wall time.
    fn after_step(&mut self, start_s: f64) {
        let end_s = self.engine.time_s();
        if let Some(mean) = self.forces.add(start_s, end_s, self.engine.tool_forces()) {
            for (name, f) in self.tool_names.iter().zip(&mean.force_n) {
                self.clients.broadcast(&Outbound::Force {
                    time_s: mean.time_s,
                    tool: name.clone(),
                    force_n: *f,
                });
            }
            self.force_ms += 1;
            let last_step = self.engine.step_index().saturating_sub(1);
            self.latency.forces_sent(last_step, Instant::now());
        }
        let now = Instant::now();
        if let Some(slip) = self.pacer.after_step(end_s, now) {
            if now >= self.next_slip_notice {
                self.next_slip_notice = now + Duration::from_secs(5);
                let m = format!(
                    "the simulation fell {:.0} ms behind real time: its clock slipped (time slows; {} slips so far)",
                    1e3 * slip,
                    self.pacer.slips
                );
                self.log(&m);
                self.clients.broadcast(&Outbound::Notice(m));
            }
        }
        if now >= self.next_frame {
            self.next_frame =
                (self.next_frame + Duration::from_secs_f64(1.0 / self.cfg.graphics_hz)).max(now);
            self.surface_frame(end_s);
        }
        if now >= self.next_status {
            self.next_status = (self.next_status + self.cfg.status_every).max(now);
            self.status(now);
        }
    }

    fn surface_frame(&mut self, time_s: f64) {
        if self.clients.count() == 0 {
            return;
        }
        self.engine.surface_positions(&mut self.positions);
        self.frame_seq = self.frame_seq.wrapping_add(1);
        let seq = self.frame_seq;
        self.clients.broadcast(&Outbound::Surface {
            seq,
            time_s,
            frame: Arc::new(protocol::positions_frame(seq, time_s, &self.positions)),
            positions_m: Arc::new(self.positions.clone()),
            tools: Arc::new(protocol::tools_frame(seq, time_s, &self.tools.applied)),
        });
        self.surface_frames += 1;
    }

    fn status(&mut self, now: Instant) {
        let mut st = Status {
            time_s: self.engine.time_s(),
            step: self.engine.step_index(),
            dt_s: self.engine.dt_s(),
            real_time_factor: self.pacer.real_time_factor(),
            lag_s: self.pacer.lag_s(),
            slips: self.pacer.slips,
            slipped_s: self.pacer.slipped_s,
            model: self.engine.info().model.clone(),
            drivers: self
                .tool_names
                .iter()
                .zip(&self.tools.driver)
                .map(|(n, d)| (n.to_string(), *d))
                .collect(),
            clients: self.clients.count(),
            latency_ms: self.latency.stats(),
            surface_frames_dropped: 0,
        };
        for (client, dropped) in self.clients.connected() {
            st.surface_frames_dropped = dropped;
            let v = serde_json::to_value(ServerMessage::Status(st.clone()));
            self.clients.send(
                client,
                Outbound::Status(Arc::new(v.unwrap_or(serde_json::Value::Null))),
            );
        }
        if let Some(rec) = &mut self.recorder {
            if let Err(e) = rec.flush() {
                self.log(&format!("{e:#}"));
            }
        }
        if now >= self.next_log {
            self.next_log = now + Duration::from_secs(5);
            self.log(&format!(
                "t = {:.3} s, real-time factor {:.3}, lag {:.1} ms, {} slips, {} client(s), latency p99 {:.3} ms",
                st.time_s,
                st.real_time_factor,
                1e3 * st.lag_s,
                st.slips,
                st.clients,
                st.latency_ms.p99
            ));
        }
    }

    fn finish(mut self, error: Option<String>) -> Summary {
        let mut error = error;
        if let Some(rec) = &mut self.recorder {
            if let Err(e) = rec.flush() {
                error.get_or_insert(format!("{e:#}"));
            }
        }
        if self.clients.count() > 0 {
            // Let the writers send the last messages (forces, an error) before closing.
            std::thread::sleep(Duration::from_millis(100));
        }
        self.clients.close_all();
        let now = Instant::now();
        let wall_s = self.pacer.wall_s(now);
        let simulated_s = self.engine.time_s();
        let info = self.engine.info();
        Summary {
            scene: info.scene.clone(),
            model: info.model.clone(),
            steps: self.engine.step_index(),
            simulated_s,
            wall_s,
            real_time_factor: simulated_s / wall_s.max(1e-12),
            lag_max_s: self.pacer.lag_max_s,
            slips: self.pacer.slips,
            slipped_s: self.pacer.slipped_s,
            force_ms: self.force_ms,
            surface_frames: self.surface_frames,
            poses_applied: self.tools.poses_applied,
            poses_clamped: self.tools.poses_clamped,
            poses_refused: self.tools.poses_refused,
            bad_messages: self.bad_messages,
            poses_given: self.poses_given,
            latency_ms: self.latency.stats(),
            clients: self.clients.summaries(),
            error,
        }
    }
}
