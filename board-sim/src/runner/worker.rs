//! A worker thread and the boards it runs: each board's firmware runtime is loaded into
//! host storage, then polled in turn as far as its links allow; when no board can move,
//! the worker waits on its doorbell.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{mpsc, Arc};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{Context, Result};
use host_tools::solver::batched::board::{BoardBatches, BoardElements};
use host_tools::solver::batched::Isa;
use host_tools::subnormals::{FlushGuard, Subnormals};
use link_proto::Links;
use pe_firmware::image::{ElementRecord, ImageError, ImageHeader, Integration, Precision};
use pe_firmware::runtime::{Fault, FaultKind, LinkStats, Runtime, RuntimeConfig, WireReal};

use super::collect::Report;
use super::stack::BoardLinks;
use crate::check::{phase, Observed};
use crate::clock::{Retire, SweepClock, ThreadEnv};
use crate::fabric::Doorbell;
use crate::results::BoardResult;
use crate::storage::{HostStorage, StorageSizing};

/// A board's links as the worker threads hold them.
pub(crate) type BoxedLinks = Box<BoardLinks>;

/// What a worker needs to run one board.
pub(crate) struct BoardCtx {
    pub index: usize,
    pub coords: [usize; 3],
    pub image: Vec<u8>,
    pub steps: u64,
    pub frame_every: u64,
    pub config: RuntimeConfig,
    pub progress: Arc<AtomicU64>,
    pub stop: Arc<AtomicBool>,
    /// Boards that finished or stopped on a fault, of `total`.
    pub finished: Arc<AtomicUsize>,
    pub total: usize,
    /// Element batches on the host's lanes ([`super::SimOptions::batched`]).
    pub batched: bool,
    /// The host's tool poses: the gate a board waits at, its steps reported.
    pub poses: super::poses::PoseFeed,
}

/// One thread per worker, each running its boards; a fault stops its board, and the run
/// stops (see [`super::run`]) a grace period after the first.
pub(crate) fn spawn_workers(
    per_worker: Vec<(Vec<BoardCtx>, Vec<BoxedLinks>)>,
    bells: &[Arc<Doorbell>],
    clocks: &[Arc<SweepClock>],
    tx: &mpsc::Sender<Report>,
    stop: &Arc<AtomicBool>,
    sizing: StorageSizing,
    header: &ImageHeader,
) -> Result<Vec<JoinHandle<()>>> {
    let (p, i) = (header.precision, header.integration);
    let mut handles = Vec::new();
    for (w, (ctxs, mut ls)) in per_worker.into_iter().enumerate() {
        let out = tx.clone();
        let bell = bells[w].clone();
        let clock = clocks[w].clone();
        let stop = stop.clone();
        let h = std::thread::Builder::new()
            .name(format!("board-worker-{w}"))
            .stack_size(16 << 20)
            .spawn(move || {
                // The firmware runs with subnormals flushed (FPSCR.FZ), so do its boards here.
                let _mode = FlushGuard::enter(Subnormals::Flush);
                // However the worker ends, it holds no simulated time back.
                let retiring = clock.clone();
                let _retire = Retire(&retiring);
                let mut env = ThreadEnv::new(bell, clock);
                if let Err(f) = dispatch(ctxs, sizing, &mut ls, &mut env, &out, p, i) {
                    // A board's image was refused: nothing of this worker runs.
                    stop.store(true, Ordering::Relaxed);
                    let _ = out.send(Report::Failed(Observed {
                        fault: f,
                        phase: 0,
                        waiting: false,
                        sink: None,
                    }));
                }
            })
            .context("spawning a worker thread")?;
        handles.push(h);
    }
    Ok(handles)
}

/// The worker's precision x integration dispatch: the concrete types its boards run.
fn dispatch(
    ctx: Vec<BoardCtx>,
    sizing: StorageSizing,
    links: &mut [BoxedLinks],
    env: &mut ThreadEnv,
    out: &mpsc::Sender<Report>,
    precision: Precision,
    integration: Integration,
) -> Result<(), Fault> {
    pe_firmware::with_element_types!(precision, integration, |T, E| {
        run_worker::<T, E>(ctx, sizing, links, env, out)
    })
}

/// Runs a worker's boards: each is polled in turn as far as its links allow; when no board
/// can move, the worker waits on its doorbell.
fn run_worker<T: WireReal + 'static, E: ElementRecord<T> + 'static>(
    boards: Vec<BoardCtx>,
    sizing: StorageSizing,
    links: &mut [BoxedLinks],
    env: &mut ThreadEnv,
    out: &mpsc::Sender<Report>,
) -> Result<(), Fault> {
    let mut storages: Vec<HostStorage<T, E>> = Vec::with_capacity(boards.len());
    storages.resize_with(boards.len(), HostStorage::empty);
    let rts = load_runtimes(&mut storages, &boards, sizing)?;
    let kernels = element_kernels(&rts, &boards)?;
    let Some(first) = boards.first() else {
        return Ok(());
    };
    let (stop, total) = (first.stop.clone(), first.total);
    let mut w = Worker {
        state: vec![State::Running; boards.len()],
        finished: first.finished.clone(),
        boards: &boards,
        rts,
        kernels,
        links,
        out,
        discard: vec![0u8; link_proto::PACKET_LEN_MAX],
    };
    let mut idle_sweeps = 0u32;
    loop {
        let sweep = env.clock.tick();
        let progressed = w.sweep(env);
        let exiting = stop.load(Ordering::Relaxed) || w.finished.load(Ordering::Relaxed) >= total;
        if exiting {
            w.report_recovery();
        }
        if stop.load(Ordering::Relaxed) {
            // Where every board still running stood: the consequences of the fault, and
            // evidence of where it came from.
            w.report_waits(link_proto::Clock::now_ns(env));
            return Ok(());
        }
        if w.finished.load(Ordering::Relaxed) >= total {
            return Ok(());
        }
        // Time advanced (simulated, every board waiting): sweep again at once.
        if env.clock.swept(sweep, progressed) || progressed {
            idle_sweeps = 0;
        } else {
            idle_sweeps += 1;
            if idle_sweeps < 64 {
                std::hint::spin_loop();
            } else {
                env.bell.wait(Duration::from_millis(1));
            }
        }
    }
}

/// A fault of board `c` before its step 0: its image refused.
fn load_fault(c: [usize; 3]) -> impl Fn(ImageError) -> Fault {
    move |e| Fault {
        board: c.map(|v| v as u8),
        step: 0,
        kind: FaultKind::Image(e),
    }
}

/// Each board's runtime, its image loaded into its storage (sized by `sizing`).
fn load_runtimes<'s, T: WireReal, E: ElementRecord<T>>(
    storages: &'s mut [HostStorage<T, E>],
    boards: &[BoardCtx],
    sizing: StorageSizing,
) -> Result<Vec<Runtime<'s, T, E>>, Fault> {
    let mut rts = Vec::with_capacity(boards.len());
    for (buf, ctx) in storages.iter_mut().zip(boards) {
        let caps = sizing
            .capacities::<T, E>(&ctx.image)
            .map_err(load_fault(ctx.coords))?;
        let st = buf.fill(&caps).ok_or_else(|| {
            load_fault(ctx.coords)(ImageError::Malformed {
                record: "zero record (storage)",
            })
        })?;
        rts.push(
            Runtime::load(&ctx.image, ctx.coords.map(|c| c as u8), st, ctx.config)
                .map_err(load_fault(ctx.coords))?,
        );
    }
    Ok(rts)
}

/// Each board's element batches, packed for the host's lanes (or the scalar loop).
fn element_kernels<T: WireReal + 'static, E: ElementRecord<T> + 'static>(
    rts: &[Runtime<'_, T, E>],
    boards: &[BoardCtx],
) -> Result<Vec<BoardBatches<T, E>>, Fault> {
    let mut kernels = Vec::with_capacity(rts.len());
    for (rt, ctx) in rts.iter().zip(boards) {
        let (general, laws) = rt.elements();
        let counts = rt.header.counts;
        let board = BoardElements {
            general,
            boxes: rt.boxes(),
            cuboids: rt.cuboids(),
            laws,
            general_ends: counts.batch_ends,
            box_ends: counts.box_batch_ends,
            cuboid_ends: counts.cuboid_batch_ends,
        };
        let k = if ctx.batched {
            BoardBatches::build(&board, Isa::detect_narrow())
        } else {
            Ok(BoardBatches::scalar())
        };
        kernels.push(k.map_err(|e| Fault {
            board: ctx.coords.map(|v| v as u8),
            step: 0,
            kind: FaultKind::Physics(e),
        })?);
    }
    Ok(kernels)
}

/// Per board: running, finished its steps (draining: until every global packet it sent
/// is acknowledged; done), or stopped on a fault. A board that finished keeps its links
/// polled (a neighbour may still need a frame again) until every board has finished or
/// the run is stopped.
#[derive(Clone, Copy, PartialEq)]
enum State {
    Running,
    Draining,
    Done,
    Failed,
}

/// A worker's boards as it polls them.
struct Worker<'w, 's, T, E> {
    boards: &'w [BoardCtx],
    rts: Vec<Runtime<'s, T, E>>,
    kernels: Vec<BoardBatches<T, E>>,
    state: Vec<State>,
    links: &'w mut [BoxedLinks],
    out: &'w mpsc::Sender<Report>,
    finished: Arc<AtomicUsize>,
    /// Where a finished board's global packets are taken to.
    discard: Vec<u8>,
}

impl<T: WireReal + 'static, E: ElementRecord<T> + 'static> Worker<'_, '_, T, E> {
    /// One pass over the boards; whether any moved.
    fn sweep(&mut self, env: &mut ThreadEnv) -> bool {
        let mut progressed = false;
        for i in 0..self.boards.len() {
            match self.service(i) {
                Some(p) => progressed |= p,
                None => {
                    progressed = true;
                    continue;
                }
            }
            if self.state[i] == State::Running {
                progressed |= self.advance(i, env);
            }
        }
        progressed
    }

    /// The links of board `i` beside its runtime: a finished board's drained, a global
    /// flow recovery gave up on (the board stops: None), a drained board done; whether it
    /// moved on.
    fn service(&mut self, i: usize) -> Option<bool> {
        let mut progressed = false;
        if matches!(self.state[i], State::Done | State::Draining) {
            self.links[i].poll();
            // A finished firmware reads no more packets: taken (and acknowledged) here.
            while let Ok(Some(_)) = self.links[i].try_recv_global(&mut self.discard) {}
        }
        if matches!(self.state[i], State::Running | State::Draining) {
            if let Some((peer, seq, requests)) = self.links[i].global_failure() {
                let error = link_proto::RecvError::GlobalRetriesExhausted {
                    peer,
                    seq,
                    requests,
                };
                let f = Fault {
                    board: self.boards[i].coords.map(|c| c as u8),
                    step: self.rts[i].step_index(),
                    kind: FaultKind::GlobalError { error },
                };
                self.failed(i, f);
                return None;
            }
        }
        if self.state[i] == State::Draining && self.links[i].global_unacknowledged() == 0 {
            self.state[i] = State::Done;
            self.finished.fetch_add(1, Ordering::Relaxed);
            progressed = true;
        }
        Some(progressed)
    }

    /// Runs board `i` as far as its links allow; whether it moved on.
    fn advance(&mut self, i: usize, env: &mut ThreadEnv) -> bool {
        let boards = self.boards;
        let ctx = &boards[i];
        let mut progressed = false;
        loop {
            let rt = &mut self.rts[i];
            if rt.step_index() >= ctx.steps {
                self.done(i);
                return true;
            }
            let before = rt.progress();
            if before.1 == 0 && !ctx.poses.open(before.0) {
                // The host has not sent this step's poses yet (`super::poses`).
                self.links[i].poll();
                return progressed;
            }
            let mut link: &mut (dyn Links + Send) = &mut *self.links[i];
            let complete = match rt.poll_step_with(&mut link, env, &self.kernels[i]) {
                Ok(c) => c,
                Err(f) => {
                    self.failed(i, f);
                    return true;
                }
            };
            if rt.progress() != before {
                progressed = true;
            }
            if !complete {
                // Waiting (perhaps on the global network): the links still answer
                // (link recovery's acks and retransmissions), as `Runtime::step` does.
                self.links[i].poll();
                return progressed;
            }
            let s = rt.step_index();
            ctx.poses.done(ctx.index, s);
            if ctx.index == 0 {
                ctx.progress.store(s, Ordering::Relaxed);
            }
            if ctx.frame_every > 0 && s.is_multiple_of(ctx.frame_every) && s < ctx.steps {
                self.send_frame(i, s);
            }
        }
    }

    /// Board `i`'s owned nodes' displacements at `step`, to the collector.
    fn send_frame(&self, i: usize, step: u64) {
        let rt = &self.rts[i];
        let nodes = rt
            .nodes()
            .iter()
            .zip(rt.displacements())
            .filter(|(n, _)| n.owner)
            .map(|(n, u)| (n.global, u.map(|v| v.to_f64())))
            .collect();
        let _ = self.out.send(Report::Frame { step, nodes });
    }

    /// Board `i` finished its steps: its last frame and results; it drains.
    fn done(&mut self, i: usize) {
        let (ctx, rt) = (&self.boards[i], &self.rts[i]);
        self.send_frame(i, rt.step_index());
        let st: LinkStats = rt.stats;
        let _ = self.out.send(Report::Done {
            board: ctx.index,
            result: BoardResult {
                board: ctx.coords,
                steps: rt.step_index(),
                frames_sent: st.frames_sent,
                bytes_sent: st.bytes_sent,
                wait_s: st.wait_ns as f64 * 1e-9,
                global: rt.global_stats(),
                recovery: None,
            },
            reaction_prescribed: rt.reaction_prescribed,
            reaction_fixed: rt.reaction_fixed,
            kinetic_energy: rt.kinetic_energy,
        });
        self.state[i] = State::Draining;
    }

    /// Board `i` stopped on fault `f`.
    fn failed(&mut self, i: usize, f: Fault) {
        let _ = self.out.send(Report::Failed(Observed {
            fault: f,
            phase: phase(self.rts[i].current_op()),
            waiting: false,
            sink: None,
        }));
        self.finished.fetch_add(1, Ordering::Relaxed);
        self.state[i] = State::Failed;
    }

    /// What link recovery cost on each board, as the run ends.
    fn report_recovery(&self) {
        for (ctx, l) in self.boards.iter().zip(self.links.iter()) {
            let (faces, global) = (l.recovery(), l.global_recovery());
            if faces.is_some() || global.is_some() {
                let _ = self.out.send(Report::Recovery {
                    board: ctx.index,
                    faces: faces.unwrap_or_default(),
                    global,
                });
            }
        }
    }

    /// Where every board still running waits, at `now_ns`, as the run is stopped.
    fn report_waits(&self, now_ns: u64) {
        for (i, rt) in self.rts.iter().enumerate() {
            if self.state[i] != State::Running {
                continue;
            }
            if let Some((fault, _)) = rt.waiting(now_ns) {
                let _ = self.out.send(Report::Failed(Observed {
                    fault,
                    phase: phase(rt.current_op()),
                    waiting: true,
                    sink: None,
                }));
            }
        }
    }
}
