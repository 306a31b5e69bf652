//! An open-ended run for a live session (`crate::live`): the boards start as [`super::run`]
//! starts them, but with no step count (they run until stopped) and with the pose gate
//! ([`PoseFeed::gate`]) in the host's hand: [`OpenArray::run_to`] opens it one step at a
//! time and waits until every board has finished that step. Poses go to the boards as
//! `board-sim run --replay` sends them ([`PoseSender::send_to_holders`]); the host and
//! graphics sinks' packets are taken as they come, so a long session holds none of them.

use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Result};
use link_proto::Machine;
use pe_firmware::image::ImageHeader;
use pe_firmware::physics::pose::Pose;

use super::collect::Report;
use super::poses::{PoseFeed, PoseSender};
use super::worker::spawn_workers;
use super::{prepare, Prepared, Shared, SimOptions};
use crate::check::{attribute, sink_observations, Observed};
use crate::clock::Clocking;
use crate::fabric::GlobalNet;

/// A compiled machine's boards running open-ended, stepped by the host.
pub struct OpenArray {
    machine: Machine,
    header: ImageHeader,
    tools: usize,
    sender: PoseSender,
    shared: Shared,
    /// The host's flow numbers per board address, and a packet's scratch.
    seq: Vec<u16>,
    buf: Vec<u8>,
    rx: mpsc::Receiver<Report>,
    handles: Vec<JoinHandle<()>>,
    /// No board moving for this long is a fault of the array (the boards' own link
    /// timeout names the link first).
    stall: Duration,
}

/// Starts the boards of the compiled machine in `dir` (`opts.steps`, `opts.poses` and
/// `opts.frame_every` are not used: the host steps the array and sends poses itself); they
/// wait at step 0 until [`OpenArray::run_to`].
pub fn start_open(dir: &Path, opts: &SimOptions) -> Result<OpenArray> {
    if opts.faults.is_some() {
        bail!("a live array runs without injected faults");
    }
    if opts.clocking != Clocking::Wall {
        // The host steps a live array as the trainer's clock goes.
        bail!("a live array runs on the wall clock, not simulated time");
    }
    let Prepared {
        machine,
        images,
        header,
        tools,
        holders,
        workers,
        links,
        net,
        tx,
        rx,
        ..
    } = prepare(dir, opts)?;
    let shared = Shared {
        poses: PoseFeed::new(machine.count(), true),
        ..Default::default()
    };
    let sender = PoseSender {
        poses: Vec::new(),
        holders,
        net,
        envelopes: opts.global_recovery.is_some(),
        feed: shared.poses.clone(),
        bells: workers.bells.clone(),
        stop: shared.stop.clone(),
        steps: u64::MAX,
        clock: workers.sender_clock.clone(),
    };
    let opts = SimOptions {
        frame_every: 0,
        ..opts.clone()
    };
    let per_worker = workers.place(machine, images, links, u64::MAX, &opts, &shared)?;
    let handles = spawn_workers(
        per_worker,
        &workers.bells,
        &workers.clocks,
        &tx,
        &shared.stop,
        opts.storage,
        &header,
    )?;
    Ok(OpenArray {
        machine,
        header,
        tools,
        sender,
        shared,
        seq: vec![0; link_proto::BOARD_COUNT],
        buf: vec![0; link_proto::PACKET_LEN_MAX + 16],
        rx,
        handles,
        stall: opts.link_timeout + Duration::from_secs(1),
    })
}

impl OpenArray {
    pub fn machine(&self) -> Machine {
        self.machine
    }

    /// The first board's image header (the scene's parameters, the same on every board).
    pub fn header(&self) -> &ImageHeader {
        &self.header
    }

    /// The scene's tools (the most any image holds).
    pub fn tools(&self) -> usize {
        self.tools
    }

    /// The steps every board has finished.
    pub fn steps_done(&self) -> u64 {
        let steps = &self.shared.poses.board_steps;
        steps
            .iter()
            .map(|s| s.load(Ordering::Acquire))
            .min()
            .unwrap_or(0)
    }

    /// Sends `tool`'s pose for `step` to the boards holding the tool. The caller keeps it
    /// within the boards' queue: `step < steps_done() + POSE_DELAY_STEPS`, and no board
    /// may have started `step` (the gate is at most `step`).
    pub fn send_pose(&mut self, step: u64, tool: usize, pose: &Pose) -> Result<()> {
        if self.sender.holders.get(tool).is_none_or(|h| h.is_empty()) {
            bail!("tool {tool}: no board's contact tables hold that tool");
        }
        let gate = self.shared.poses.gate.load(Ordering::Acquire);
        if step < gate {
            bail!("a pose for step {step}: the boards may have started it (gate at {gate})");
        }
        self.sender
            .send_to_holders(step, tool, pose, &mut self.seq, &mut self.buf)?;
        Ok(())
    }

    /// Lets the boards run to `steps` steps and waits until every one has: Err on a board's
    /// fault (attributed as `board-sim run` attributes it) or an array that stops moving.
    pub fn run_to(&mut self, steps: u64) -> Result<()> {
        let feed = &self.shared.poses;
        if steps > feed.gate.load(Ordering::Acquire) {
            feed.gate.store(steps, Ordering::Release);
            self.sender.bells.iter().for_each(|b| b.ring());
        }
        let (mut last, mut moved, mut spins) = (self.steps_done(), Instant::now(), 0u32);
        loop {
            let done = self.steps_done();
            if done >= steps {
                return Ok(());
            }
            self.check_faults()?;
            if done != last {
                (last, moved) = (done, Instant::now());
            } else if moved.elapsed() > self.stall {
                bail!(
                    "the boards stopped moving at step {done} for {:.1} s",
                    self.stall.as_secs_f64()
                );
            }
            spins += 1;
            if spins < 32 {
                std::thread::yield_now();
            } else {
                std::thread::sleep(Duration::from_micros(20));
            }
        }
    }

    /// A board's fault (or a damaged packet at a sink) stops the array: every board's
    /// report, attributed.
    fn check_faults(&mut self) -> Result<()> {
        let mut faults: Vec<Observed> = sink_observations(&self.sender.net);
        while let Ok(r) = self.rx.try_recv() {
            if let Report::Failed(o) = r {
                faults.push(o);
            }
        }
        if faults.is_empty() {
            return Ok(());
        }
        // The other boards run on a moment, so that each reports where it stands.
        std::thread::sleep(super::FAULT_GRACE);
        self.stop();
        while let Ok(r) = self.rx.recv_timeout(Duration::from_millis(100)) {
            if let Report::Failed(o) = r {
                faults.push(o);
            }
        }
        let injected = self
            .shared
            .injected
            .lock()
            .map(|v| v.clone())
            .unwrap_or_default();
        Err(anyhow!(attribute(self.machine, faults, injected)))
    }

    /// The packets the host sink took since the last call (tool forces and hellos).
    pub fn take_host_packets(&self) -> Vec<Vec<u8>> {
        take(&self.sender.net, |n| &n.host)
    }

    /// The packets the graphics sink took since the last call (surface chunks).
    pub fn take_graphics_packets(&self) -> Vec<Vec<u8>> {
        take(&self.sender.net, |n| &n.graphics)
    }

    /// Stops every worker and waits for them.
    fn stop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.sender.bells.iter().for_each(|b| b.ring());
        for h in self.handles.drain(..) {
            let _ = h.join();
        }
    }
}

impl Drop for OpenArray {
    fn drop(&mut self) {
        self.stop();
    }
}

fn take(
    net: &GlobalNet,
    sink: impl Fn(&GlobalNet) -> &std::sync::Mutex<Vec<Vec<u8>>>,
) -> Vec<Vec<u8>> {
    sink(net)
        .lock()
        .map(|mut v| std::mem::take(&mut *v))
        .unwrap_or_default()
}
