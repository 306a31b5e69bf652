//! board-sim: one firmware runtime per board image, each on a host thread, connected by
//! emulated point-to-point links. It runs the firmware's own runtime
//! (`pe_firmware::runtime`), not a copy.

pub mod links;
mod storage;
pub mod timing;

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use host_tools::compile::{check_image_set, image_file_name, read_manifest, ImageFile, Manifest};
use link_proto::Links;
use pe_firmware::image::{
    ElementRecord, ImageError, ImageHeader, ImageReader, Integration, Precision,
};
use pe_firmware::physics::{HexFull, HexReduced};
use pe_firmware::runtime::{Fault, GlobalStats, LinkStats, Runtime, RuntimeConfig, WireReal};

use links::{build_links, FaultSpec, FaultyLinks, Injected, ThreadEnv};
use storage::HostStorage;
pub use storage::{load_check, StorageSizing, VecShelf};

/// How to run.
#[derive(Clone, Debug)]
pub struct SimOptions {
    /// Stop after this many steps (default: the images' step count).
    pub steps: Option<u64>,
    pub faults: Option<FaultSpec>,
    pub link_timeout: Duration,
    /// Collect every mesh node's displacement every this many steps (0 = only the end).
    pub frame_every: u64,
    /// Host threads the boards are multiplexed over (default: the machine's cores; as many
    /// as boards gives one thread per board).
    pub workers: Option<usize>,
    /// How each board's storage is sized.
    pub storage: StorageSizing,
    /// Check the image set against `manifest.json` before any board runs: every file's CRC
    /// and every image's compilation id (true by default). False leaves a mixed set to the
    /// boards' own check with their neighbours (the Hello frames), which tests exercise.
    pub check_manifest: bool,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            steps: None,
            faults: None,
            link_timeout: Duration::from_secs(10),
            frame_every: 0,
            workers: None,
            storage: StorageSizing::Exact,
            check_manifest: true,
        }
    }
}

/// Per-board results.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BoardResult {
    pub board: [usize; 3],
    pub steps: u64,
    pub frames_sent: [u64; 6],
    pub bytes_sent: [u64; 6],
    pub wait_s: f64,
    /// Global-network traffic (contact exchange, graphics, tool forces).
    pub global: GlobalStats,
}

/// What a run produced.
pub struct SimOutput {
    pub manifest: Manifest,
    pub steps: u64,
    pub wall_s: f64,
    /// Displacement of every mesh node (global numbering) at the end.
    pub displacements: Vec<[f64; 3]>,
    /// Frames collected during the run: (step, displacements).
    pub frames: Vec<(u64, Vec<[f64; 3]>)>,
    pub boards: Vec<BoardResult>,
    pub reaction_prescribed: [f64; 3],
    pub reaction_fixed: [f64; 3],
    pub kinetic_energy: f64,
    pub injected: Vec<Injected>,
    /// What the graphics engine received: one frame per graphics interval.
    pub graphics: Vec<GraphicsFrame>,
    /// Per step, the force on each tool as the host summed it from the boards' shares (N).
    pub tool_force: Vec<[f64; 3]>,
    pub tools: usize,
    pub dt_s: f64,
}

/// A surface frame as the graphics engine assembled it from the boards' chunks.
#[derive(Clone, Debug)]
pub struct GraphicsFrame {
    pub frame: u32,
    /// First and last step of the chunks.
    pub steps: (u32, u32),
    /// (mesh node, displacement) of every surface node received, ascending node.
    pub nodes: Vec<(u32, [f32; 3])>,
    /// Chunks received.
    pub packets: u32,
}

/// The sinks' packets turned into frames and per-step tool forces (summed in board order).
fn collect_sinks(
    net: &links::GlobalNet,
    steps: u64,
    tools: usize,
) -> Result<(Vec<GraphicsFrame>, Vec<[f64; 3]>)> {
    use link_proto::payload::{surface_entry, SurfaceHeader, ToolForcePayload};
    let mut frames: std::collections::BTreeMap<u32, GraphicsFrame> = Default::default();
    let graphics = net.graphics.lock().map(|v| v.clone()).unwrap_or_default();
    for p in &graphics {
        let r = link_proto::PacketRepr::parse_bytes(p)
            .map_err(|e| anyhow!("graphics engine: bad packet: {e}"))?;
        let h = SurfaceHeader::parse(r.payload)
            .map_err(|e| anyhow!("graphics engine: bad surface payload from {}: {e}", r.src))?;
        let f = frames.entry(h.frame).or_insert_with(|| GraphicsFrame {
            frame: h.frame,
            steps: (h.step, h.step),
            nodes: Vec::new(),
            packets: 0,
        });
        f.steps = (f.steps.0.min(h.step), f.steps.1.max(h.step));
        f.packets += 1;
        for k in 0..h.count as usize {
            f.nodes.push(
                surface_entry(r.payload, k)
                    .map_err(|e| anyhow!("graphics engine: bad surface entry: {e}"))?,
            );
        }
    }
    let mut out: Vec<GraphicsFrame> = frames.into_values().collect();
    for f in &mut out {
        f.nodes.sort_by_key(|e| e.0);
    }
    let mut shares: Vec<(u32, u8, u8, [f64; 3])> = Vec::new();
    let host = net.host.lock().map(|v| v.clone()).unwrap_or_default();
    for p in &host {
        let r =
            link_proto::PacketRepr::parse_bytes(p).map_err(|e| anyhow!("host: bad packet: {e}"))?;
        let t = ToolForcePayload::parse(r.payload)
            .map_err(|e| anyhow!("host: bad tool-force payload from {}: {e}", r.src))?;
        shares.push((t.step, t.tool, r.src, t.force));
    }
    shares.sort_by_key(|a| (a.0, a.1, a.2));
    let mut tool_force = vec![[0.0; 3]; steps as usize * tools];
    for (step, tool, _, f) in shares {
        if let Some(d) = tool_force.get_mut(step as usize * tools + tool as usize) {
            for i in 0..3 {
                d[i] += f[i];
            }
        }
    }
    Ok((out, tool_force))
}

/// A run that stopped on a fault: the faults reported (root cause first) and what was
/// injected.
#[derive(Debug)]
pub struct SimFault {
    pub faults: Vec<Fault>,
    pub injected: Vec<Injected>,
}

impl std::fmt::Display for SimFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "the run stopped on a fault:")?;
        for x in self.faults.iter().take(8) {
            writeln!(f, "  {x}")?;
        }
        if self.faults.len() > 8 {
            writeln!(f, "  ... and {} more", self.faults.len() - 8)?;
        }
        if !self.injected.is_empty() {
            writeln!(f, "injected faults ({}):", self.injected.len())?;
            for i in self.injected.iter().take(8) {
                writeln!(
                    f,
                    "  board ({},{},{}) link {} step {}: {}",
                    i.board[0], i.board[1], i.board[2], i.face, i.step, i.what
                )?;
            }
        }
        Ok(())
    }
}
impl std::error::Error for SimFault {}

/// A board's links as the worker threads hold them.
type BoxedLinks = Box<dyn Links + Send>;

/// Messages from board threads to the collector.
#[allow(clippy::large_enum_variant)]
enum Report {
    /// Owned nodes' displacements at a step: (global, u).
    Frame {
        step: u64,
        nodes: Vec<(u32, [f64; 3])>,
    },
    Done {
        board: usize,
        result: BoardResult,
        reaction_prescribed: [f64; 3],
        reaction_fixed: [f64; 3],
        kinetic_energy: f64,
    },
    Failed(Fault),
}

struct BoardCtx {
    index: usize,
    coords: [usize; 3],
    image: Vec<u8>,
    steps: u64,
    frame_every: u64,
    config: RuntimeConfig,
    progress: Arc<AtomicU64>,
    stop: Arc<std::sync::atomic::AtomicBool>,
}

/// Runs a worker's boards: each is polled in turn as far as its links allow; when no board
/// can move, the worker waits on its doorbell.
fn run_worker<T: WireReal, E: ElementRecord<T>>(
    boards: Vec<BoardCtx>,
    sizing: StorageSizing,
    links: &mut [Box<dyn Links + Send>],
    env: &mut ThreadEnv,
    out: &mpsc::Sender<Report>,
) -> Result<(), Fault> {
    let load_fault = |c: [usize; 3]| {
        move |e| Fault {
            board: c.map(|v| v as u8),
            step: 0,
            kind: pe_firmware::runtime::FaultKind::Image(e),
        }
    };
    let mut storages: Vec<HostStorage<T, E>> = Vec::with_capacity(boards.len());
    storages.resize_with(boards.len(), HostStorage::empty);
    let mut rts: Vec<Runtime<'_, T, E>> = Vec::with_capacity(boards.len());
    for (buf, ctx) in storages.iter_mut().zip(&boards) {
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
    let send_frame = |rt: &Runtime<'_, T, E>, step: u64| {
        let nodes = rt
            .nodes()
            .iter()
            .zip(rt.displacements())
            .filter(|(n, _)| n.owner)
            .map(|(n, u)| (n.global, u.map(|v| v.to_f64())))
            .collect();
        let _ = out.send(Report::Frame { step, nodes });
    };
    let mut done = vec![false; boards.len()];
    let mut idle_sweeps = 0u32;
    loop {
        let mut progressed = false;
        let mut all_done = true;
        for (i, ctx) in boards.iter().enumerate() {
            if done[i] {
                continue;
            }
            all_done = false;
            let rt = &mut rts[i];
            loop {
                if rt.step_index() >= ctx.steps {
                    send_frame(rt, rt.step_index());
                    let st: LinkStats = rt.stats;
                    let _ = out.send(Report::Done {
                        board: ctx.index,
                        result: BoardResult {
                            board: ctx.coords,
                            steps: rt.step_index(),
                            frames_sent: st.frames_sent,
                            bytes_sent: st.bytes_sent,
                            wait_s: st.wait_ns as f64 * 1e-9,
                            global: rt.global_stats(),
                        },
                        reaction_prescribed: rt.reaction_prescribed,
                        reaction_fixed: rt.reaction_fixed,
                        kinetic_energy: rt.kinetic_energy,
                    });
                    done[i] = true;
                    progressed = true;
                    break;
                }
                let before = rt.progress();
                let mut link: &mut (dyn Links + Send) = &mut *links[i];
                let complete = rt.poll_step(&mut link, env)?;
                if rt.progress() != before {
                    progressed = true;
                }
                if !complete {
                    break;
                }
                let s = rt.step_index();
                if ctx.index == 0 {
                    ctx.progress.store(s, Ordering::Relaxed);
                }
                if ctx.frame_every > 0 && s.is_multiple_of(ctx.frame_every) && s < ctx.steps {
                    send_frame(rt, s);
                }
            }
        }
        if all_done
            || boards
                .first()
                .is_some_and(|c| c.stop.load(Ordering::Relaxed))
        {
            return Ok(());
        }
        if progressed {
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

/// Reads every board's image named in the manifest, in board-index order, checking each
/// against its position and the machine (and, with `check_manifest`, the set against the
/// manifest: [`check_image_set`]); returns them with the first header.
fn read_images(
    dir: &Path,
    manifest: &Manifest,
    check_manifest: bool,
) -> Result<(Vec<Vec<u8>>, ImageHeader)> {
    let dims = manifest.machine;
    let count = dims.iter().product::<usize>();
    if manifest.boards.len() != count {
        bail!(
            "{}: manifest lists {} boards for a {}x{}x{} machine",
            dir.display(),
            manifest.boards.len(),
            dims[0],
            dims[1],
            dims[2]
        );
    }
    let mut files = Vec::with_capacity(count);
    for b in &manifest.boards {
        let [x, y, z] = b.board;
        let p = dir.join(image_file_name(b.board));
        if (0..3).any(|a| b.board[a] >= dims[a]) {
            bail!(
                "{}: board ({x},{y},{z}) is outside the {}x{}x{} machine",
                dir.join("manifest.json").display(),
                dims[0],
                dims[1],
                dims[2]
            );
        }
        let bytes = std::fs::read(&p).with_context(|| format!("reading {}", p.display()))?;
        let header = ImageReader::new(&bytes, Some(b.board.map(|c| c as u8)))
            .map_err(|e| anyhow!("board ({x},{y},{z}): {}: {e}", p.display()))?
            .header;
        if header.machine.map(|c| c as usize) != dims {
            let m = header.machine;
            bail!(
                "board ({x},{y},{z}): {}: image is for a {}x{}x{} machine, manifest.json says {}x{}x{}: the image is from another compilation",
                p.display(),
                m[0],
                m[1],
                m[2],
                dims[0],
                dims[1],
                dims[2]
            );
        }
        files.push(ImageFile {
            board: b.board,
            path: p,
            bytes,
            header,
        });
    }
    if check_manifest {
        check_image_set(manifest, &files)?;
    }
    let header = files
        .first()
        .map(|f| f.header)
        .ok_or_else(|| anyhow!("{}: no boards", dir.display()))?;
    let mut images = vec![Vec::new(); count];
    for f in files {
        let i = f.board[0] + dims[0] * (f.board[1] + dims[1] * f.board[2]);
        images[i] = f.bytes;
    }
    Ok((images, header))
}

fn add3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// What the collector gathers from the board threads.
struct Collected {
    steps: u64,
    n_nodes: usize,
    displacements: Vec<[f64; 3]>,
    /// Frames being assembled: step → (nodes received, displacements).
    pending: std::collections::BTreeMap<u64, (usize, Vec<[f64; 3]>)>,
    frames: Vec<(u64, Vec<[f64; 3]>)>,
    results: Vec<Option<BoardResult>>,
    /// Per board: prescribed and fixed reactions and kinetic energy, summed in board order
    /// at the end (so a report does not depend on which thread finished first).
    energies: Vec<([f64; 3], [f64; 3], f64)>,
    faults: Vec<Fault>,
}

impl Collected {
    fn new(steps: u64, n_nodes: usize, boards: usize) -> Self {
        Collected {
            steps,
            n_nodes,
            displacements: vec![[0.0; 3]; n_nodes],
            pending: Default::default(),
            frames: Vec::new(),
            results: vec![None; boards],
            energies: vec![([0.0; 3], [0.0; 3], 0.0); boards],
            faults: Vec::new(),
        }
    }

    fn file(&mut self, report: Report) {
        match report {
            Report::Frame { step, nodes } => {
                let n_nodes = self.n_nodes;
                let e = self
                    .pending
                    .entry(step)
                    .or_insert_with(|| (0, vec![[0.0; 3]; n_nodes]));
                for (g, u) in nodes {
                    if let Some(d) = e.1.get_mut(g as usize) {
                        *d = u;
                        e.0 += 1;
                    }
                }
                if e.0 == n_nodes {
                    if let Some((_, v)) = self.pending.remove(&step) {
                        if step == self.steps {
                            self.displacements = v;
                        } else {
                            self.frames.push((step, v));
                        }
                    }
                }
            }
            Report::Done {
                board,
                result,
                reaction_prescribed,
                reaction_fixed,
                kinetic_energy,
            } => {
                self.energies[board] = (reaction_prescribed, reaction_fixed, kinetic_energy);
                self.results[board] = Some(result);
            }
            Report::Failed(f) => self.faults.push(f),
        }
    }
}

/// Faults ordered root cause first: the earliest step; a timeout is a consequence of a
/// neighbour's fault.
fn root_cause_first(mut faults: Vec<Fault>) -> Vec<Fault> {
    faults.sort_by_key(|f: &Fault| {
        (
            f.step,
            matches!(f.kind, pe_firmware::runtime::FaultKind::LinkTimeout { .. }) as u8,
            f.board,
        )
    });
    faults
}

/// One thread per worker, each running its boards; a worker's first fault stops the run.
fn spawn_workers(
    per_worker: Vec<(Vec<BoardCtx>, Vec<BoxedLinks>)>,
    bells: &[Arc<links::Doorbell>],
    tx: &mpsc::Sender<Report>,
    stop: &Arc<std::sync::atomic::AtomicBool>,
    sizing: StorageSizing,
    header: &ImageHeader,
) -> Result<Vec<std::thread::JoinHandle<()>>> {
    let (p, i) = (header.precision, header.integration);
    let mut handles = Vec::new();
    for (w, (ctxs, mut ls)) in per_worker.into_iter().enumerate() {
        let out = tx.clone();
        let bell = bells[w].clone();
        let stop = stop.clone();
        let h = std::thread::Builder::new()
            .name(format!("board-worker-{w}"))
            .stack_size(16 << 20)
            .spawn(move || {
                let mut env = ThreadEnv::new(bell);
                if let Err(f) = dispatch(ctxs, sizing, &mut ls, &mut env, &out, p, i) {
                    stop.store(true, Ordering::Relaxed);
                    let _ = out.send(Report::Failed(f));
                }
            })
            .context("spawning a worker thread")?;
        handles.push(h);
    }
    Ok(handles)
}

/// Runs the compiled machine in `dir`. `on_progress(step, total)` is called from the
/// collector thread.
pub fn run(
    dir: &Path,
    opts: &SimOptions,
    on_progress: &mut dyn FnMut(u64, u64),
) -> Result<SimOutput> {
    let manifest = read_manifest(dir)?;
    let (images, header) = read_images(dir, &manifest, opts.check_manifest)?;
    let dims = manifest.machine;
    if let Some((b, step)) = opts.faults.as_ref().and_then(|f| f.stall) {
        if (0..3).any(|a| b[a] >= dims[a]) {
            bail!(
                "--faults stall={}.{}.{}@{step}: no board ({},{},{}) on this {}x{}x{} machine",
                b[0],
                b[1],
                b[2],
                b[0],
                b[1],
                b[2],
                dims[0],
                dims[1],
                dims[2]
            );
        }
    }
    let count = images.len();
    let steps = opts
        .steps
        .unwrap_or(header.params.steps)
        .min(header.params.steps.max(opts.steps.unwrap_or(0)));
    let n_nodes = header.scene_nodes as usize;
    let workers = opts
        .workers
        .unwrap_or_else(|| {
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(2)
        })
        .clamp(1, count);
    let bells: Vec<Arc<links::Doorbell>> = (0..workers)
        .map(|_| Arc::new(links::Doorbell::default()))
        .collect();
    let board_bells: Vec<Arc<links::Doorbell>> =
        (0..count).map(|b| bells[b % workers].clone()).collect();
    let (links, net) = build_links(dims, &board_bells);
    let (tx, rx) = mpsc::channel::<Report>();
    let progress = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let injected = Arc::new(Mutex::new(Vec::new()));
    let config = RuntimeConfig {
        link_timeout_ns: opts.link_timeout.as_nanos() as u64,
    };
    let start = Instant::now();
    let mut per_worker: Vec<(Vec<BoardCtx>, Vec<BoxedLinks>)> =
        (0..workers).map(|_| (Vec::new(), Vec::new())).collect();
    for (b, (image, link)) in images.into_iter().zip(links).enumerate() {
        let coords = [
            b % dims[0],
            (b / dims[0]) % dims[1],
            b / (dims[0] * dims[1]),
        ];
        let ctx = BoardCtx {
            index: b,
            coords,
            image,
            steps,
            frame_every: opts.frame_every,
            config,
            progress: progress.clone(),
            stop: stop.clone(),
        };
        let l: Box<dyn Links + Send> = match &opts.faults {
            Some(spec) => Box::new(FaultyLinks::new(
                link,
                coords,
                b,
                spec.clone(),
                injected.clone(),
            )),
            None => Box::new(link),
        };
        per_worker[b % workers].0.push(ctx);
        per_worker[b % workers].1.push(l);
    }
    let handles = spawn_workers(per_worker, &bells, &tx, &stop, opts.storage, &header)?;
    drop(tx);
    let mut c = Collected::new(steps, n_nodes, count);
    loop {
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(report) => c.file(report),
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        }
        on_progress(progress.load(Ordering::Relaxed), steps);
    }
    for h in handles {
        let _ = h.join();
    }
    let wall_s = start.elapsed().as_secs_f64();
    let injected = injected.lock().map(|v| v.clone()).unwrap_or_default();
    if !c.faults.is_empty() {
        let faults = root_cause_first(c.faults);
        return Err(SimFault { faults, injected }.into());
    }
    let boards = c
        .results
        .into_iter()
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| anyhow!("a board ended without a report"))?;
    c.frames.sort_by_key(|f| f.0);
    let tools = header.counts.tools as usize;
    let (graphics, tool_force) = collect_sinks(&net, steps, tools)?;
    Ok(SimOutput {
        graphics,
        tool_force,
        tools,
        dt_s: header.params.dt_s,
        manifest,
        steps,
        wall_s,
        displacements: c.displacements,
        frames: c.frames,
        boards,
        reaction_prescribed: c.energies.iter().fold([0.0; 3], |s, e| add3(s, e.0)),
        reaction_fixed: c.energies.iter().fold([0.0; 3], |s, e| add3(s, e.1)),
        kinetic_energy: c.energies.iter().fold(0.0, |s, e| s + e.2),
        injected,
    })
}

fn dispatch(
    ctx: Vec<BoardCtx>,
    sizing: StorageSizing,
    links: &mut [Box<dyn Links + Send>],
    env: &mut ThreadEnv,
    out: &mpsc::Sender<Report>,
    precision: Precision,
    integration: Integration,
) -> Result<(), Fault> {
    match (precision, integration) {
        (Precision::F64, Integration::Reduced) => {
            run_worker::<f64, HexReduced<f64>>(ctx, sizing, links, env, out)
        }
        (Precision::F64, Integration::Full) => {
            run_worker::<f64, HexFull<f64>>(ctx, sizing, links, env, out)
        }
        (Precision::F32, Integration::Reduced) => {
            run_worker::<f32, HexReduced<f32>>(ctx, sizing, links, env, out)
        }
        (Precision::F32, Integration::Full) => {
            run_worker::<f32, HexFull<f32>>(ctx, sizing, links, env, out)
        }
    }
}
