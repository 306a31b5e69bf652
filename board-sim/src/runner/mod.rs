//! The runner: a compiled machine's boards as firmware runtimes on worker threads, each
//! board's links built from the fabric, the fault injector and recovery ([`stack`]); a
//! collector gathers what the workers report ([`collect`]), runs the host's checks as the
//! boards go, and stops the run a grace period after the first fault.

mod collect;
mod images;
mod open;
mod options;
mod poses;
pub mod stack;
mod worker;

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Result};
use host_tools::compile::read_manifest;
use link_proto::Machine;
use pe_firmware::image::ImageReader;
use pe_firmware::runtime::RuntimeConfig;

pub use images::manifest_machine;
pub(crate) use images::read_images;
pub use open::{start_open, OpenArray};
pub use options::SimOptions;
pub(crate) use poses::{check_schedule, one_per_tool_and_step, pose_repr};

use crate::check::{attribute, collect_sinks, missing_sink_packets, sink_observations, HostCheck};
use crate::clock::{Clocking, Participant, SimulatedTime, SweepClock};
use crate::fabric::{build_links, Doorbell, EmuLinks, GlobalNet};
use crate::faults::{FaultyLinks, Injected};
use crate::results::SimOutput;
use collect::{Collected, Report};
use poses::{PoseFeed, PoseSender};
use stack::{BoardLinks, Lower};
use worker::{spawn_workers, BoardCtx, BoxedLinks};

/// How long the other boards run on after the first fault (at most the link timeout).
pub const FAULT_GRACE: Duration = Duration::from_millis(250);

/// Runs the compiled machine in `dir`. `on_progress(step, total)` is called from the
/// collector thread.
pub fn run(
    dir: &Path,
    opts: &SimOptions,
    on_progress: &mut dyn FnMut(u64, u64),
) -> Result<SimOutput> {
    let Prepared {
        manifest,
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
    } = prepare(dir, opts)?;
    let steps = opts
        .steps
        .unwrap_or(header.params.steps)
        .min(header.params.steps.max(opts.steps.unwrap_or(0)));
    let shared = Shared {
        poses: PoseFeed::new(machine.count(), !opts.poses.poses.is_empty()),
        ..Default::default()
    };
    let sender = PoseSender {
        poses: one_per_tool_and_step(&opts.poses),
        holders,
        net: net.clone(),
        envelopes: opts.global_recovery.is_some(),
        feed: shared.poses.clone(),
        bells: workers.bells.clone(),
        stop: shared.stop.clone(),
        steps,
        clock: workers.sender_clock.clone(),
    };
    sender.check()?;
    let start = Instant::now();
    let per_worker = workers.place(machine, images, links, steps, opts, &shared)?;
    let handles = spawn_workers(
        per_worker,
        &workers.bells,
        &workers.clocks,
        &tx,
        &shared.stop,
        opts.storage,
        &header,
    )?;
    drop(tx);
    let sending = sender.start();
    let mut c = Collected::new(steps, header.scene_nodes as usize, machine.count());
    let mut host_check = opts
        .check_manifest
        .then(|| HostCheck::new(&manifest.compilation, machine));
    let watch = Watch {
        net: &net,
        shared: &shared,
        grace: opts.link_timeout.min(FAULT_GRACE),
        steps,
        workers: &workers,
        start,
    };
    let watched = watch.collect(&rx, &mut c, host_check.as_mut(), on_progress);
    join(handles);
    shared.stop.store(true, Ordering::Relaxed);
    let sent = sending.map(|h| h.join().map_err(|_| anyhow!("the pose sender panicked")));
    watched?;
    if let Some(sent) = sent {
        sent??;
    }
    let wall_s = start.elapsed().as_secs_f64();
    let injected = shared
        .injected
        .lock()
        .map(|v| v.clone())
        .unwrap_or_default();
    c.faults.extend(sink_observations(&net));
    if !c.faults.is_empty() {
        return Err(attribute(machine, c.faults, injected).into());
    }
    let mut boards = std::mem::take(&mut c.results)
        .into_iter()
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| anyhow!("a board ended without a report"))?;
    let missing = missing_sink_packets(&net, &boards, steps);
    if !missing.is_empty() {
        return Err(attribute(machine, missing, injected).into());
    }
    for (b, r) in boards.iter_mut().zip(std::mem::take(&mut c.recovery)) {
        b.recovery = r;
    }
    c.frames.sort_by_key(|f| f.0);
    if let Some(h) = host_check.as_mut() {
        h.finish(&net)?;
    }
    let (graphics, tool_force) = collect_sinks(&net, steps, tools)?;
    let sink_recovery = opts
        .global_recovery
        .and_then(|_| net.sink_stats.lock().ok().map(|g| *g));
    let (reaction_prescribed, reaction_fixed, kinetic_energy) = c.energies();
    Ok(SimOutput {
        sink_recovery,
        graphics,
        tool_force,
        tools,
        manifest,
        steps,
        wall_s,
        displacements: c.displacements,
        frames: c.frames,
        boards,
        reaction_prescribed,
        reaction_fixed,
        kinetic_energy,
        injected,
    })
}

/// What the collector and the workers share.
#[derive(Default)]
struct Shared {
    /// The steps board 0 finished.
    progress: Arc<AtomicU64>,
    /// Set to stop every worker.
    stop: Arc<AtomicBool>,
    /// Boards that finished or stopped on a fault.
    finished: Arc<AtomicUsize>,
    /// What the fault injectors injected.
    injected: Arc<Mutex<Vec<Injected>>>,
    /// The host's tool poses: the gate and each board's steps ([`poses`]).
    poses: PoseFeed,
}

impl Default for PoseFeed {
    fn default() -> Self {
        PoseFeed::new(0, false)
    }
}

/// The global addresses of the boards whose contact tables hold each of the scene's
/// `tools` tools (an image that does not read holds none: `read_images` checked them).
/// What a run to its end ([`run`]) and an open-ended one ([`start_open`]) set up alike
/// before their boards start: the compiled machine and its images, which boards hold each
/// tool, the workers and their doorbells, each board's links and the global network, and
/// the channel the workers report on.
struct Prepared {
    manifest: host_tools::compile::Manifest,
    machine: Machine,
    images: Vec<Vec<u8>>,
    header: pe_firmware::image::ImageHeader,
    tools: usize,
    holders: Vec<Vec<u8>>,
    workers: Workers,
    links: Vec<EmuLinks>,
    net: Arc<GlobalNet>,
    tx: mpsc::Sender<Report>,
    rx: mpsc::Receiver<Report>,
}

/// Reads the compiled machine in `dir`, checks the fault spec against it, and builds what
/// its boards run on ([`Prepared`]).
fn prepare(dir: &Path, opts: &SimOptions) -> Result<Prepared> {
    let manifest = read_manifest(dir)?;
    let machine = manifest_machine(dir, &manifest)?;
    let (images, header, tools) =
        images::read_images(dir, &manifest, machine, opts.check_manifest)?;
    if let Some(spec) = &opts.faults {
        spec.check(machine)?;
    }
    let holders = tool_holders(machine, &images, tools);
    let workers = Workers::new(opts.workers, machine.count(), opts.clocking);
    let board_bells: Vec<Arc<Doorbell>> = (0..machine.count())
        .map(|b| workers.bells[workers.of(b)].clone())
        .collect();
    let (links, net) = build_links(machine, &board_bells, opts.global_recovery.is_some());
    let (tx, rx) = mpsc::channel::<Report>();
    Ok(Prepared {
        manifest,
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
    })
}

pub(crate) fn tool_holders(machine: Machine, images: &[Vec<u8>], tools: usize) -> Vec<Vec<u8>> {
    let mut holders = vec![Vec::new(); tools];
    for (c, image) in machine.boards().zip(images) {
        let (Ok(r), Some(a)) = (ImageReader::new(image, None), Machine::address(c)) else {
            continue;
        };
        for h in holders.iter_mut().take(r.header.counts.tools as usize) {
            h.push(a);
        }
    }
    holders
}

/// The worker threads the boards are multiplexed over: contiguous blocks of boards (by
/// index, x fastest) per worker, so that most links join boards of one worker, whose frames
/// need no other core; a doorbell and a clock per worker, and the host's pose sender's
/// clock (with simulated time, the sender is a participant: the boards it holds at the
/// gate wait for it).
struct Workers {
    count: usize,
    boards: usize,
    bells: Vec<Arc<Doorbell>>,
    clocks: Vec<Arc<SweepClock>>,
    sender_clock: Arc<SweepClock>,
    /// The run's simulated time, if [`Clocking::Simulated`].
    time: Option<Arc<SimulatedTime>>,
}

impl Workers {
    /// `asked` workers (default: the machine's cores), 1 to one per board, on `clocking`.
    fn new(asked: Option<usize>, boards: usize, clocking: Clocking) -> Workers {
        let count = asked
            .unwrap_or_else(|| {
                std::thread::available_parallelism()
                    .map(|n| n.get())
                    .unwrap_or(2)
            })
            .clamp(1, boards);
        let Clocking::Simulated { quantum_ns } = clocking else {
            return Workers {
                count,
                boards,
                bells: (0..count).map(|_| Arc::new(Doorbell::default())).collect(),
                clocks: (0..count).map(|_| SweepClock::new()).collect(),
                sender_clock: SweepClock::new(),
                time: None,
            };
        };
        // Participants: the workers, then the pose sender.
        let time = SimulatedTime::new(count + 1, quantum_ns);
        let bells: Vec<Arc<Doorbell>> = (0..count)
            .map(|_| Arc::new(Doorbell::counting(time.clone())))
            .collect();
        let clock = |index| {
            SweepClock::simulated(Participant {
                time: time.clone(),
                index,
                bells: bells.clone(),
            })
        };
        Workers {
            count,
            boards,
            clocks: (0..count).map(clock).collect(),
            sender_clock: clock(count),
            bells,
            time: Some(time),
        }
    }

    /// The run's time now (ns): simulated, or `start`'s wall clock.
    fn now_ns(&self, start: Instant) -> u64 {
        match &self.time {
            Some(t) => t.now_ns(),
            None => start.elapsed().as_nanos() as u64,
        }
    }

    /// The worker of board `b`.
    fn of(&self, b: usize) -> usize {
        b * self.count / self.boards
    }

    /// Each worker's boards, in board order: what a worker needs to run each, and its
    /// links as its runtime sees them.
    fn place(
        &self,
        machine: Machine,
        images: Vec<Vec<u8>>,
        links: Vec<EmuLinks>,
        steps: u64,
        opts: &SimOptions,
        shared: &Shared,
    ) -> Result<Vec<(Vec<BoardCtx>, Vec<BoxedLinks>)>> {
        let mut per_worker: Vec<(Vec<BoardCtx>, Vec<BoxedLinks>)> =
            (0..self.count).map(|_| (Vec::new(), Vec::new())).collect();
        for (b, (image, link)) in images.into_iter().zip(links).enumerate() {
            let coords = machine.coords(b);
            let ctx = BoardCtx {
                index: b,
                coords,
                image,
                steps,
                frame_every: opts.frame_every,
                config: RuntimeConfig {
                    link_timeout_ns: opts.link_timeout.as_nanos() as u64,
                    // board-sim's host gates its workers itself (`runner::poses`).
                    host_gate: false,
                },
                progress: shared.progress.clone(),
                stop: shared.stop.clone(),
                finished: shared.finished.clone(),
                total: machine.count(),
                batched: opts.batched,
                poses: shared.poses.clone(),
            };
            let l = board_links(link, coords, b, opts, &self.clocks[self.of(b)], shared)?;
            per_worker[self.of(b)].0.push(ctx);
            per_worker[self.of(b)].1.push(l);
        }
        Ok(per_worker)
    }
}

/// Board `b`'s links as its runtime sees them: its emulated links, with the fault
/// injector when faults are asked for, and recovery as `opts` says.
fn board_links(
    link: EmuLinks,
    coords: [usize; 3],
    b: usize,
    opts: &SimOptions,
    clock: &Arc<SweepClock>,
    shared: &Shared,
) -> Result<BoxedLinks> {
    let lower = match &opts.faults {
        Some(spec) => {
            let mut f = FaultyLinks::new(
                link,
                coords,
                b,
                spec.clone(),
                shared.injected.clone(),
                clock.clone(),
            );
            f.global_envelopes = opts.global_recovery.is_some();
            Lower::Faulty(Box::new(f))
        }
        None => Lower::Clean(link),
    };
    let l = BoardLinks::new(lower, clock.clone(), opts.recovery, opts.global_recovery).map_err(
        |e| {
            anyhow!(
                "link recovery {:?} / global recovery {:?}: {e}",
                opts.recovery,
                opts.global_recovery
            )
        },
    )?;
    Ok(Box::new(l))
}

fn join(handles: Vec<JoinHandle<()>>) {
    for h in handles {
        let _ = h.join();
    }
}

/// The collector's watch over a running machine.
struct Watch<'a> {
    net: &'a GlobalNet,
    shared: &'a Shared,
    /// After the first fault the other boards run on this long (on the run's clock), so
    /// that every board reports its own fault or where it waits: the evidence the cause is
    /// found from.
    grace: Duration,
    steps: u64,
    /// The run's time (the grace is counted in it).
    workers: &'a Workers,
    start: Instant,
}

impl Watch<'_> {
    /// Files the workers' reports into `c` until every worker has ended, checking the
    /// boards' hellos and the sinks' packets as they come; stops the run a grace period
    /// after the first fault, or at once when the host's check fails (its error).
    fn collect(
        &self,
        rx: &mpsc::Receiver<Report>,
        c: &mut Collected,
        mut host_check: Option<&mut HostCheck>,
        on_progress: &mut dyn FnMut(u64, u64),
    ) -> Result<()> {
        let mut first_fault_ns: Option<u64> = None;
        loop {
            match rx.recv_timeout(Duration::from_millis(20)) {
                Ok(report) => c.file(report),
                Err(mpsc::RecvTimeoutError::Timeout) => {}
                Err(mpsc::RecvTimeoutError::Disconnected) => return Ok(()),
            }
            if let Some(Err(e)) = host_check.as_mut().map(|h| h.poll(self.net)) {
                self.shared.stop.store(true, Ordering::Relaxed);
                return Err(e);
            }
            c.faults.extend(sink_observations(self.net));
            if !c.faults.is_empty() {
                let now = self.workers.now_ns(self.start);
                let t = *first_fault_ns.get_or_insert(now);
                if now.saturating_sub(t) >= self.grace.as_nanos() as u64 {
                    self.shared.stop.store(true, Ordering::Relaxed);
                }
            }
            on_progress(self.shared.progress.load(Ordering::Relaxed), self.steps);
        }
    }
}
