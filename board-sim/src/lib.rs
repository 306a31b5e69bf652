//! board-sim: one firmware runtime per board image, each on a host thread, connected by
//! emulated point-to-point links. It runs the firmware's own runtime
//! (`pe_firmware::runtime`), not a copy.

pub mod links;
pub mod qemu;
mod storage;
pub mod timing;

use std::path::Path;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use host_tools::compile::{check_image_set, image_file_name, read_manifest, ImageFile, Manifest};
use host_tools::solver::batched::board::{BoardBatches, BoardElements};
use host_tools::solver::batched::Isa;
use link_proto::reliable::{FaceRecovery, ReliableConfig};
use link_proto::reliable_global::{GlobalConfig, GlobalRecovery};
use link_proto::Links;
use pe_firmware::image::{
    ElementRecord, ImageError, ImageHeader, ImageReader, Integration, Precision,
};
use pe_firmware::physics::{HexFull, HexReduced};
use pe_firmware::runtime::{Fault, GlobalStats, LinkStats, Runtime, RuntimeConfig, WireReal};

use links::{build_links, BoardLinks, FaultSpec, FaultyLinks, Injected, Lower, ThreadEnv};
use storage::HostStorage;
pub use storage::{load_check, StorageSizing, VecShelf};

/// How long the other boards run on after the first fault (at most the link timeout).
pub const FAULT_GRACE: Duration = Duration::from_millis(250);

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
    /// and every image's compilation id; and, as the boards start, the id each board
    /// reports to the host (true by default). False leaves a mixed set to the boards' own
    /// check with their neighbours (the Hello frames), which tests exercise.
    pub check_manifest: bool,
    /// Link-level recovery (retransmission) above the emulated links and the fault
    /// injector; `None` runs without, so that every fault stops the run.
    pub recovery: Option<ReliableConfig>,
    /// Global-network recovery (`link_proto::reliable_global`) on every board's global port,
    /// and its receiving end in the graphics and host sinks; `None` runs without (a lost or
    /// damaged global packet then stops the run).
    pub global_recovery: Option<GlobalConfig>,
    /// Each board's element batches on the host's SIMD lanes
    /// (`host_tools::solver::batched::board`, the bits of the firmware's scalar loop), or
    /// the firmware's scalar loop itself (false).
    pub batched: bool,
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
            recovery: Some(ReliableConfig::default()),
            global_recovery: Some(GlobalConfig::default()),
            batched: true,
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
    /// What link recovery cost (with recovery on).
    pub recovery: Option<LinkRecovery>,
}

/// What link recovery cost on one board, per face (`Face::index` order: +x, −x, +y, −y,
/// +z, −z).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct LinkRecovery {
    /// Bytes of the envelopes of first transmissions (frames included).
    pub data_bytes: [u64; 6],
    pub retransmitted_frames: [u64; 6],
    pub retransmitted_bytes: [u64; 6],
    pub nacks_sent: [u64; 6],
    pub nacks_received: [u64; 6],
    pub acks_sent: [u64; 6],
    pub statuses_sent: [u64; 6],
    /// Bytes of acks, nacks and statuses.
    pub control_bytes: [u64; 6],
    /// Envelopes received damaged, beyond a gap, or twice.
    pub damaged: [u64; 6],
    pub gaps: [u64; 6],
    pub duplicates: [u64; 6],
    /// Data envelopes sent the first time (each adds `reliable::OVERHEAD` bytes).
    pub data_frames: [u64; 6],
    /// What global recovery cost on the board's global port (with it on).
    pub global: Option<GlobalRecovery>,
}

impl LinkRecovery {
    fn from_faces(f: &[FaceRecovery; 6], global: Option<&GlobalRecovery>) -> Self {
        let a = |g: fn(&FaceRecovery) -> u64| std::array::from_fn(|i| g(&f[i]));
        LinkRecovery {
            data_bytes: a(|x| x.data_bytes),
            retransmitted_frames: a(|x| x.retransmitted_frames),
            retransmitted_bytes: a(|x| x.retransmitted_bytes),
            nacks_sent: a(|x| x.nacks_sent),
            nacks_received: a(|x| x.nacks_received),
            acks_sent: a(|x| x.acks_sent),
            statuses_sent: a(|x| x.statuses_sent),
            control_bytes: a(|x| x.control_bytes),
            damaged: a(|x| x.damaged),
            gaps: a(|x| x.gaps),
            duplicates: a(|x| x.duplicates),
            data_frames: a(|x| x.data_frames),
            global: global.copied(),
        }
    }

    /// Bytes recovery added on this board's links: envelopes, retransmissions, control,
    /// on the faces and on the global port.
    pub fn overhead_bytes(&self) -> u64 {
        let s = |v: &[u64; 6]| v.iter().sum::<u64>();
        s(&self.data_frames) * link_proto::reliable::OVERHEAD as u64
            + s(&self.retransmitted_bytes)
            + s(&self.control_bytes)
            + self
                .global
                .as_ref()
                .map_or(0, GlobalRecovery::overhead_bytes)
    }
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
    /// What the receiving end of global recovery cost in the graphics and host sinks (acks
    /// and nacks they sent), with global recovery on.
    pub sink_recovery: Option<GlobalRecovery>,
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
pub(crate) fn collect_sinks(
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
        match r.kind {
            link_proto::PacketKind::ToolForce => {}
            // Checked as they arrive (`HostCheck`).
            link_proto::PacketKind::Hello => continue,
            k => bail!(
                "host: unexpected packet {k:?} from address {} (tool forces and hellos only)",
                r.src
            ),
        }
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

/// The host's check of what the boards say they run: each board's [`PacketKind::Hello`]
/// packet (before its step 0) must carry the manifest's compilation id; every board must
/// have said it by the end. Catches a board that runs another image than the host loaded
/// (flashed from another compile), a board with no neighbour to compare with included.
///
/// [`PacketKind::Hello`]: link_proto::PacketKind::Hello
pub(crate) struct HostCheck {
    expected: String,
    dims: [usize; 3],
    /// Host packets already looked at.
    seen: usize,
    /// Boards (x fastest) that have said hello.
    said: Vec<bool>,
}

impl HostCheck {
    pub(crate) fn new(expected: &str, dims: [usize; 3]) -> Self {
        HostCheck {
            expected: expected.to_ascii_lowercase(),
            dims,
            seen: 0,
            said: vec![false; dims.iter().product()],
        }
    }

    /// The board (coordinates) at a global address, if it is one of this machine's.
    fn coords(&self, address: u8) -> Option<[usize; 3]> {
        link_proto::Machine::from_address(address)
            .filter(|&c| c.iter().zip(self.dims).all(|(&c, d)| c < d))
    }

    /// Looks at the host packets that arrived since the last call.
    fn poll(&mut self, net: &links::GlobalNet) -> Result<()> {
        use link_proto::payload::HelloPayload;
        let new: Vec<Vec<u8>> = match net.host.lock() {
            Ok(v) => v.get(self.seen..).map(<[_]>::to_vec).unwrap_or_default(),
            Err(_) => bail!("host: the packet sink was poisoned"),
        };
        self.seen += new.len();
        for p in new {
            let Ok(r) = link_proto::PacketRepr::parse_bytes(&p) else {
                continue; // named by `collect_sinks`
            };
            if r.kind != link_proto::PacketKind::Hello {
                continue;
            }
            let Some(c) = self.coords(r.src) else {
                bail!(
                    "host: a hello from address {}, which is no board of this {}x{}x{} machine",
                    r.src,
                    self.dims[0],
                    self.dims[1],
                    self.dims[2]
                );
            };
            let h = HelloPayload::parse(r.payload).map_err(|e| {
                anyhow!(
                    "host: bad hello from board ({},{},{}): {e}",
                    c[0],
                    c[1],
                    c[2]
                )
            })?;
            let id = pe_firmware::image::CompilationId(h.compilation).to_string();
            if id != self.expected {
                bail!(
                    "board ({},{},{}) runs an image of compilation {id}, but the host loaded compilation {} (the manifest's): the board was flashed from another compile",
                    c[0], c[1], c[2], self.expected
                );
            }
            let b = c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2]);
            if let Some(s) = self.said.get_mut(b) {
                *s = true;
            }
        }
        Ok(())
    }

    /// At the end of a run: every board has said hello.
    pub(crate) fn finish(&mut self, net: &links::GlobalNet) -> Result<()> {
        self.poll(net)?;
        let silent: Vec<String> = (0..self.said.len())
            .filter(|&b| !self.said[b])
            .map(|b| {
                let d = self.dims;
                format!("({},{},{})", b % d[0], (b / d[0]) % d[1], b / (d[0] * d[1]))
            })
            .collect();
        if !silent.is_empty() {
            bail!(
                "host: {} board(s) never reported their compilation id: {}",
                silent.len(),
                silent.join(" ")
            );
        }
        Ok(())
    }
}

/// What a board reported when the run stopped: a fault, or (`waiting`) the link it was
/// still waiting on.
#[derive(Clone, Debug, PartialEq)]
pub struct Observed {
    /// For a waiting board: the timeout its wait would have become.
    pub fault: Fault,
    /// Where in the step ([`phase`]), comparable across boards.
    pub phase: u32,
    /// The board was still waiting, not yet timed out, when the run was stopped.
    pub waiting: bool,
    /// Observed by a sink (the graphics engine or the host, by address), not a board: the
    /// fault's board is then the board whose packets arrived damaged or are missing.
    pub sink: Option<u8>,
}

impl Observed {
    /// A wait (a timeout, or a board stopped while waiting): a consequence of a fault
    /// elsewhere when there is one.
    pub fn is_wait(&self) -> bool {
        use pe_firmware::runtime::FaultKind as K;
        self.waiting
            || matches!(
                self.fault.kind,
                K::LinkTimeout { .. } | K::GlobalTimeout { .. }
            )
    }

    /// The link the observation names, if any.
    pub fn face(&self) -> Option<link_proto::Face> {
        use pe_firmware::runtime::FaultKind as K;
        match self.fault.kind {
            K::LinkTimeout { face }
            | K::LinkError { face, .. }
            | K::SendFailed { face, .. }
            | K::UnexpectedFrame { face, .. }
            | K::BadFrame { face, .. } => Some(face),
            _ => None,
        }
    }

    /// Ordering across boards and workers: by step; in a step faults before waits (a
    /// timeout is a consequence of a fault elsewhere when there is one), then by phase and
    /// board.
    fn key(&self) -> (u64, bool, u32, [u8; 3]) {
        (
            self.fault.step,
            self.is_wait(),
            self.phase,
            self.fault.board,
        )
    }
}

impl std::fmt::Display for Observed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if let Some(sink) = self.sink {
            let [x, y, z] = self.fault.board;
            let what = match self.fault.kind {
                pe_firmware::runtime::FaultKind::BadPacket { error } => {
                    format!("a damaged packet ({error})")
                }
                _ => "fewer packets than the board sent: some were lost".to_string(),
            };
            return write!(
                f,
                "{} received from board ({x},{y},{z}) (step {}) {what}",
                links::address_name(sink),
                self.fault.step
            );
        }
        if self.waiting {
            let [x, y, z] = self.fault.board;
            match self.face() {
                Some(face) => write!(
                    f,
                    "board ({x},{y},{z}) step {}: link {face:?}: still waiting when the run stopped",
                    self.fault.step
                ),
                None => write!(f, "{} (still waiting when the run stopped)", self.fault),
            }
        } else {
            write!(f, "{}", self.fault)
        }
    }
}

/// Where in a step an operation lies, in the order every board's step program runs them
/// (graphics, contact, batch 0, then per axis: external, send round 0, batch, and per round
/// its sends and receives; last the update): comparable across boards whose programs
/// differ in length.
pub fn phase(op: Option<pe_firmware::runtime::Op>) -> u32 {
    use pe_firmware::runtime::Op;
    let axis = |a: u8, k: u32| 3 + 100 * a as u32 + k;
    match op {
        Some(Op::Graphics) => 0,
        Some(Op::Contact) => 1,
        Some(Op::Batch(0)) => 2,
        Some(Op::External(a)) => axis(a, 0),
        Some(Op::Batch(b)) => axis(b - 1, 2),
        Some(Op::Send(a, 0, _)) => axis(a, 1),
        Some(Op::Send(a, r, _)) => axis(a, 3 + 3 * r as u32),
        Some(Op::Recv(a, r, f)) => axis(a, 4 + 3 * r as u32 + (1 - f.min(1)) as u32),
        Some(Op::Update) => axis(3, 1),
        None => u32::MAX,
    }
}

/// The first cause of a stopped run.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Cause {
    /// The board at fault: for an injected fault the board that sent the damaged frame; for
    /// an observed one the board that observed it.
    pub board: [usize; 3],
    /// Its link (`PosX` ...), if the cause is on one.
    pub face: Option<String>,
    pub step: u64,
    pub what: String,
    /// The cause is an injected fault (known ground truth) that explains `detected`.
    pub injected: bool,
    /// The observation that detected it (index into [`SimFault::observed`]).
    pub detected: usize,
}

impl std::fmt::Display for Cause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.board;
        write!(f, "board ({x},{y},{z})")?;
        if let Some(face) = &self.face {
            write!(f, " link {face}")?;
        }
        write!(f, " step {}: {}", self.step, self.what)
    }
}

/// A run that stopped on a fault: the first cause, every board's observation (ordered by
/// step, faults before waits, then by phase and board) and what was injected.
#[derive(Debug)]
pub struct SimFault {
    pub cause: Cause,
    pub observed: Vec<Observed>,
    pub injected: Vec<Injected>,
}

impl SimFault {
    /// The observations other than the one that detected the cause.
    pub fn consequences(&self) -> impl Iterator<Item = &Observed> {
        let d = self.cause.detected;
        self.observed
            .iter()
            .enumerate()
            .filter(move |(k, _)| *k != d)
            .map(|(_, o)| o)
    }
}

impl std::fmt::Display for SimFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "the run stopped on a fault:")?;
        writeln!(
            f,
            "  cause: {}{}",
            self.cause,
            if self.cause.injected {
                " (injected)"
            } else {
                ""
            }
        )?;
        if let Some(d) = self.observed.get(self.cause.detected) {
            writeln!(f, "  detected: {d}")?;
        }
        let rest: Vec<&Observed> = self.consequences().collect();
        if !rest.is_empty() {
            writeln!(f, "  consequences ({}):", rest.len())?;
        }
        for x in rest.iter().take(8) {
            writeln!(f, "    {x}")?;
        }
        if rest.len() > 8 {
            writeln!(f, "    ... and {} more", rest.len() - 8)?;
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

/// The board across `face` of `board` on a `dims` machine.
fn neighbour(dims: [usize; 3], board: [u8; 3], face: link_proto::Face) -> Option<[usize; 3]> {
    link_proto::Machine::new(dims)?.neighbour(board.map(usize::from), face)
}

/// The damaged packets the sinks received (without global recovery), as observations (taken
/// from the net: each is reported once).
fn sink_observations(net: &links::GlobalNet) -> Vec<Observed> {
    let faults = match net.sink_faults.lock() {
        Ok(mut f) => std::mem::take(&mut *f),
        Err(_) => return Vec::new(),
    };
    faults
        .into_iter()
        .map(|f| Observed {
            fault: Fault {
                board: link_proto::Machine::from_address(f.src)
                    .map_or([u8::MAX; 3], |c| c.map(|v| v as u8)),
                step: f.step.map_or(0, u64::from),
                kind: pe_firmware::runtime::FaultKind::BadPacket { error: f.error },
            },
            phase: phase(Some(pe_firmware::runtime::Op::Graphics)),
            waiting: false,
            sink: Some(f.sink),
        })
        .collect()
}

/// The sinks' check of a finished run: every board's graphics and tool-force packets (as
/// the board counted them sent) and its hello arrived at the graphics engine and the host. A missing one
/// is a wrong output, not a smaller one: an observation per board and sink (at the run's
/// last step: which packet is missing the sink cannot tell).
fn missing_sink_packets(
    net: &links::GlobalNet,
    boards: &[BoardResult],
    steps: u64,
) -> Vec<Observed> {
    use link_proto::packet::{ADDR_GRAPHICS, ADDR_HOST};
    let count = |m: &std::sync::Mutex<Vec<Vec<u8>>>, src: u8| {
        m.lock()
            .map(|v| v.iter().filter(|p| p.get(1) == Some(&src)).count() as u64)
            .unwrap_or(0)
    };
    let mut out = Vec::new();
    for b in boards {
        let Some(addr) = link_proto::Machine::address(b.board) else {
            continue;
        };
        for (sink, m, sent) in [
            (ADDR_GRAPHICS, &net.graphics, b.global.graphics_packets),
            // Tool forces and the one hello every board sends before step 0.
            (ADDR_HOST, &net.host, b.global.tool_packets + 1),
        ] {
            if count(m, addr) != sent {
                out.push(Observed {
                    fault: Fault {
                        board: b.board.map(|c| c as u8),
                        step: steps,
                        kind: pe_firmware::runtime::FaultKind::GlobalTimeout { src: addr },
                    },
                    phase: phase(None),
                    waiting: false,
                    sink: Some(sink),
                });
            }
        }
    }
    out
}

/// The injected global fault that explains an observation on the global network: for a
/// sink's observation one on the board's packets to that sink; for a board's wait for
/// board `src` one on `src`'s packets to it (or a stall of `src`); for a damaged packet one
/// corrupting a packet to the observing board (else any corrupted global packet: its
/// destination may have been hit); for recovery giving up a flow one on the packets
/// between the board and that peer, either way. The latest such at the observed step or
/// the one after (a partner runs at most a step ahead).
fn explains_global<'a>(o: &Observed, injected: &'a [Injected]) -> Option<&'a Injected> {
    use pe_firmware::runtime::FaultKind as K;
    let to_usize = |b: [u8; 3]| b.map(|v| v as usize);
    let me = o.fault.board;
    let me_addr = link_proto::Machine::address(me.map(usize::from));
    let coords = link_proto::Machine::from_address;
    let in_time = |i: &&Injected| i.step as u64 <= o.fault.step + 1 && i.face.starts_with("global");
    let latest = |f: &dyn Fn(&Injected) -> bool| {
        injected
            .iter()
            .filter(in_time)
            .filter(|i| f(i))
            .max_by_key(|i| i.step)
    };
    let corrupt = |i: &Injected| i.what.starts_with("corrupt");
    if let Some(sink) = o.sink {
        let face = links::global_face(sink);
        let from = to_usize(me);
        return match o.fault.kind {
            K::BadPacket { .. } => latest(&|i| i.board == from && i.face == face && corrupt(i))
                .or_else(|| latest(&|i| i.face == face && corrupt(i)))
                .or_else(|| latest(&|i| corrupt(i))),
            _ => latest(&|i| i.board == from && i.face == face),
        };
    }
    let me_face = links::global_face(me_addr?);
    // This board's packets to `peer` first, else `peer`'s to it (its acks).
    let between = |peer: u8| {
        let pf = links::global_face(peer);
        latest(&|i| i.board == to_usize(me) && i.face == pf).or_else(|| {
            let pc = coords(peer);
            latest(&|i| Some(i.board) == pc && (i.face == me_face || i.what == "stall"))
        })
    };
    match o.fault.kind {
        K::GlobalTimeout { src } => match coords(src) {
            Some(from) => latest(&|i| i.board == from && (i.face == me_face || i.what == "stall")),
            // Not waiting for a board's packet (its own sends blocked: with recovery,
            // unacknowledged packets fill its window): a fault on its own packets.
            None => latest(&|i| i.board == to_usize(me)),
        },
        K::BadPacket { .. } => {
            latest(&|i| i.face == me_face && corrupt(i)).or_else(|| latest(&|i| corrupt(i)))
        }
        K::GlobalError {
            error: link_proto::RecvError::GlobalRetriesExhausted { peer, .. },
        } => between(peer),
        K::GlobalSendFailed { dst, .. } => between(dst),
        _ => None,
    }
}

/// The injected fault that explains an observation: one on the frames the observing board
/// receives on that link (sent by the neighbour across it), at the observed step or the
/// one before (a lost or damaged frame is noticed in its step, a lost last frame of a step
/// perhaps only once the next one arrives), or at any earlier step for a stall or delay
/// (which go on); the latest such.
fn explains<'a>(dims: [usize; 3], o: &Observed, injected: &'a [Injected]) -> Option<&'a Injected> {
    if let Some(i) = explains_global(o, injected) {
        return Some(i);
    }
    let face = o.face()?;
    let from = neighbour(dims, o.fault.board, face)?;
    let link = format!("{:?}", face.opposite());
    injected
        .iter()
        .filter(|i| i.board == from && i.face == link && i.step as u64 <= o.fault.step)
        .filter(|i| {
            i.what == "stall" || i.what.starts_with("delay") || i.step as u64 + 1 >= o.fault.step
        })
        .max_by_key(|i| i.step)
}

/// Orders the observations and names the first cause: the first observation when an
/// injected fault explains it or it is not a wait; otherwise (the first is a wait, a
/// consequence) the first observation an injected fault explains; otherwise the first.
fn attribute(dims: [usize; 3], mut observed: Vec<Observed>, injected: Vec<Injected>) -> SimFault {
    observed.sort_by_key(Observed::key);
    let pick = match observed.first() {
        Some(first) if explains(dims, first, &injected).is_some() || !first.is_wait() => 0,
        _ => observed
            .iter()
            .position(|o| explains(dims, o, &injected).is_some())
            .unwrap_or(0),
    };
    let cause = match observed.get(pick) {
        Some(o) => match explains(dims, o, &injected) {
            Some(i) => Cause {
                board: i.board,
                face: Some(i.face.clone()),
                step: i.step as u64,
                what: format!("injected {}", i.what),
                injected: true,
                detected: pick,
            },
            None => Cause {
                board: o.fault.board.map(|v| v as usize),
                face: o.face().map(|f| format!("{f:?}")),
                step: o.fault.step,
                what: o.to_string(),
                injected: false,
                detected: pick,
            },
        },
        None => Cause {
            board: [0; 3],
            face: None,
            step: 0,
            what: "no board reported a fault".into(),
            injected: false,
            detected: 0,
        },
    };
    SimFault {
        cause,
        observed,
        injected,
    }
}

/// A board's links as the worker threads hold them.
type BoxedLinks = Box<BoardLinks>;

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
    Failed(Observed),
    /// What link recovery cost on a board's faces and global port, at the end.
    Recovery {
        board: usize,
        faces: [FaceRecovery; 6],
        global: Option<GlobalRecovery>,
    },
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
    /// Boards that finished or stopped on a fault, of `total`.
    finished: Arc<AtomicUsize>,
    total: usize,
    /// Element batches on the host's lanes ([`SimOptions::batched`]).
    batched: bool,
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
    // Each board's element batches, packed for the host's lanes (or the scalar loop).
    let mut kernels: Vec<BoardBatches<T, E>> = Vec::with_capacity(rts.len());
    for (rt, ctx) in rts.iter().zip(&boards) {
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
            kind: pe_firmware::runtime::FaultKind::Physics(e),
        })?);
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
    // Per board: running, finished its steps (draining: until every global packet it sent
    // is acknowledged; done), or stopped on a fault. A board that finished keeps its links
    // polled (a neighbour may still need a frame again) until every board has finished or
    // the run is stopped.
    #[derive(Clone, Copy, PartialEq)]
    enum State {
        Running,
        Draining,
        Done,
        Failed,
    }
    let mut discard = vec![0u8; link_proto::PACKET_LEN_MAX];
    let mut state = vec![State::Running; boards.len()];
    let mut idle_sweeps = 0u32;
    let Some(shared) = boards
        .first()
        .map(|c| (c.stop.clone(), c.finished.clone(), c.total))
    else {
        return Ok(());
    };
    let (stop, finished, total) = shared;
    let failed = |rt: &Runtime<'_, T, E>, f: Fault| {
        let _ = out.send(Report::Failed(Observed {
            fault: f,
            phase: phase(rt.current_op()),
            waiting: false,
            sink: None,
        }));
        finished.fetch_add(1, Ordering::Relaxed);
    };
    loop {
        let mut progressed = false;
        env.clock.tick();
        for (i, ctx) in boards.iter().enumerate() {
            if matches!(state[i], State::Done | State::Draining) {
                links[i].poll();
                // A finished firmware reads no more packets: taken (and acknowledged) here.
                while let Ok(Some(_)) = links[i].try_recv_global(&mut discard) {}
            }
            if matches!(state[i], State::Running | State::Draining) {
                if let Some((peer, seq, requests)) = links[i].global_failure() {
                    let rt = &rts[i];
                    failed(
                        rt,
                        Fault {
                            board: ctx.coords.map(|c| c as u8),
                            step: rt.step_index(),
                            kind: pe_firmware::runtime::FaultKind::GlobalError {
                                error: link_proto::RecvError::GlobalRetriesExhausted {
                                    peer,
                                    seq,
                                    requests,
                                },
                            },
                        },
                    );
                    state[i] = State::Failed;
                    progressed = true;
                    continue;
                }
            }
            if state[i] == State::Draining && links[i].global_unacknowledged() == 0 {
                state[i] = State::Done;
                finished.fetch_add(1, Ordering::Relaxed);
                progressed = true;
            }
            if state[i] != State::Running {
                continue;
            }
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
                            recovery: None,
                        },
                        reaction_prescribed: rt.reaction_prescribed,
                        reaction_fixed: rt.reaction_fixed,
                        kinetic_energy: rt.kinetic_energy,
                    });
                    state[i] = State::Draining;
                    progressed = true;
                    break;
                }
                let before = rt.progress();
                let mut link: &mut (dyn Links + Send) = &mut *links[i];
                let complete = match rt.poll_step_with(&mut link, env, &kernels[i]) {
                    Ok(c) => c,
                    Err(f) => {
                        failed(rt, f);
                        state[i] = State::Failed;
                        progressed = true;
                        break;
                    }
                };
                if rt.progress() != before {
                    progressed = true;
                }
                if !complete {
                    // Waiting (perhaps on the global network): the links still answer
                    // (link recovery's acks and retransmissions), as `Runtime::step` does.
                    links[i].poll();
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
        let exiting = stop.load(Ordering::Relaxed) || finished.load(Ordering::Relaxed) >= total;
        if exiting {
            for (ctx, l) in boards.iter().zip(links.iter()) {
                let (faces, global) = (l.recovery(), l.global_recovery());
                if faces.is_some() || global.is_some() {
                    let _ = out.send(Report::Recovery {
                        board: ctx.index,
                        faces: faces.unwrap_or_default(),
                        global,
                    });
                }
            }
        }
        if stop.load(Ordering::Relaxed) {
            // Where every board still running stood: the consequences of the fault, and
            // evidence of where it came from.
            let now = link_proto::Clock::now_ns(env);
            for (i, rt) in rts.iter().enumerate() {
                if state[i] != State::Running {
                    continue;
                }
                if let Some((fault, _)) = rt.waiting(now) {
                    let _ = out.send(Report::Failed(Observed {
                        fault,
                        phase: phase(rt.current_op()),
                        waiting: true,
                        sink: None,
                    }));
                }
            }
            return Ok(());
        }
        if finished.load(Ordering::Relaxed) >= total {
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
/// manifest: [`check_image_set`]); returns them with the first header and the scene's tool
/// count.
fn read_images(
    dir: &Path,
    manifest: &Manifest,
    check_manifest: bool,
) -> Result<(Vec<Vec<u8>>, ImageHeader, usize)> {
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
    // The scene's tools: the most any image holds (a board that owns no contact node
    // carries no contact tables).
    let tools = files
        .iter()
        .map(|f| f.header.counts.tools as usize)
        .max()
        .unwrap_or(0);
    let mut images = vec![Vec::new(); count];
    for f in files {
        let i = f.board[0] + dims[0] * (f.board[1] + dims[1] * f.board[2]);
        images[i] = f.bytes;
    }
    Ok((images, header, tools))
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
    faults: Vec<Observed>,
    recovery: Vec<Option<LinkRecovery>>,
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
            recovery: vec![None; boards],
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
            Report::Recovery {
                board,
                faces,
                global,
            } => {
                if let Some(r) = self.recovery.get_mut(board) {
                    *r = Some(LinkRecovery::from_faces(&faces, global.as_ref()));
                }
            }
        }
    }
}

/// One thread per worker, each running its boards; a fault stops its board, and the run
/// stops (see [`run`]) a grace period after the first.
fn spawn_workers(
    per_worker: Vec<(Vec<BoardCtx>, Vec<BoxedLinks>)>,
    bells: &[Arc<links::Doorbell>],
    clocks: &[Arc<links::SweepClock>],
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
        let clock = clocks[w].clone();
        let stop = stop.clone();
        let h = std::thread::Builder::new()
            .name(format!("board-worker-{w}"))
            .stack_size(16 << 20)
            .spawn(move || {
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

/// Runs the compiled machine in `dir`. `on_progress(step, total)` is called from the
/// collector thread.
pub fn run(
    dir: &Path,
    opts: &SimOptions,
    on_progress: &mut dyn FnMut(u64, u64),
) -> Result<SimOutput> {
    let manifest = read_manifest(dir)?;
    let (images, header, tools) = read_images(dir, &manifest, opts.check_manifest)?;
    let dims = manifest.machine;
    if let Some(spec) = &opts.faults {
        spec.check(dims)?;
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
    // Contiguous blocks of boards (x fastest) per worker: most links join boards of one
    // worker, whose frames need no other core.
    let worker_of = |b: usize| b * workers / count;
    let bells: Vec<Arc<links::Doorbell>> = (0..workers)
        .map(|_| Arc::new(links::Doorbell::default()))
        .collect();
    let clocks: Vec<Arc<links::SweepClock>> =
        (0..workers).map(|_| links::SweepClock::new()).collect();
    let board_bells: Vec<Arc<links::Doorbell>> =
        (0..count).map(|b| bells[worker_of(b)].clone()).collect();
    let (links, net) = build_links(dims, &board_bells, opts.global_recovery.is_some());
    let (tx, rx) = mpsc::channel::<Report>();
    let progress = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let finished = Arc::new(AtomicUsize::new(0));
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
            finished: finished.clone(),
            total: count,
            batched: opts.batched,
        };
        let lower = match &opts.faults {
            Some(spec) => {
                let mut f = FaultyLinks::new(link, coords, b, spec.clone(), injected.clone());
                f.global_envelopes = opts.global_recovery.is_some();
                Lower::Faulty(Box::new(f))
            }
            None => Lower::Clean(link),
        };
        let l = Box::new(
            BoardLinks::new(
                lower,
                clocks[worker_of(b)].clone(),
                opts.recovery,
                opts.global_recovery,
            )
            .map_err(|e| {
                anyhow!(
                    "link recovery {:?} / global recovery {:?}: {e}",
                    opts.recovery,
                    opts.global_recovery
                )
            })?,
        );
        per_worker[worker_of(b)].0.push(ctx);
        per_worker[worker_of(b)].1.push(l);
    }
    let handles = spawn_workers(
        per_worker,
        &bells,
        &clocks,
        &tx,
        &stop,
        opts.storage,
        &header,
    )?;
    drop(tx);
    let mut c = Collected::new(steps, n_nodes, count);
    // After the first fault the other boards run on for a grace period, so that every board
    // reports its own fault or where it waits: the evidence the cause is found from.
    let grace = opts.link_timeout.min(FAULT_GRACE);
    let mut first_fault: Option<Instant> = None;
    let mut host_check = opts
        .check_manifest
        .then(|| HostCheck::new(&manifest.compilation, dims));
    loop {
        match rx.recv_timeout(Duration::from_millis(20)) {
            Ok(report) => c.file(report),
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        }
        if let Some(Err(e)) = host_check.as_mut().map(|h| h.poll(&net)) {
            stop.store(true, Ordering::Relaxed);
            for h in handles {
                let _ = h.join();
            }
            return Err(e);
        }
        c.faults.extend(sink_observations(&net));
        if !c.faults.is_empty() {
            let t = *first_fault.get_or_insert_with(Instant::now);
            if t.elapsed() >= grace {
                stop.store(true, Ordering::Relaxed);
            }
        }
        on_progress(progress.load(Ordering::Relaxed), steps);
    }
    for h in handles {
        let _ = h.join();
    }
    let wall_s = start.elapsed().as_secs_f64();
    let injected = injected.lock().map(|v| v.clone()).unwrap_or_default();
    c.faults.extend(sink_observations(&net));
    if !c.faults.is_empty() {
        return Err(attribute(dims, c.faults, injected).into());
    }
    let mut boards = c
        .results
        .into_iter()
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| anyhow!("a board ended without a report"))?;
    let missing = missing_sink_packets(&net, &boards, steps);
    if !missing.is_empty() {
        return Err(attribute(dims, missing, injected).into());
    }
    for (b, r) in boards.iter_mut().zip(c.recovery) {
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
    Ok(SimOutput {
        sink_recovery,
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
    links: &mut [BoxedLinks],
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

#[cfg(test)]
mod tests {
    use super::*;
    use link_proto::payload::HelloPayload;
    use link_proto::{PacketKind, PacketRepr};

    fn hello(src: u8, id: [u8; 8]) -> Vec<u8> {
        let mut payload = [0u8; HelloPayload::LEN];
        HelloPayload { compilation: id }
            .emit(&mut payload)
            .expect("payload");
        let r = PacketRepr {
            dst: link_proto::packet::ADDR_HOST,
            src,
            msg_id: 0,
            kind: PacketKind::Hello,
            payload: &payload,
        };
        let mut buf = vec![0u8; r.buffer_len()];
        r.emit(&mut buf).expect("packet");
        buf
    }

    /// The host names a board whose hello carries another compilation's id, and the boards
    /// that never said hello; a set whose every board said the manifest's id passes.
    #[test]
    fn the_host_checks_what_every_board_says_it_runs() {
        let dims = [2, 2, 1];
        let bells: Vec<Arc<links::Doorbell>> = (0..4).map(|_| Default::default()).collect();
        let (_, net) = build_links(dims, &bells, false);
        let ours = [0x57, 0xdc, 1, 2, 3, 4, 5, 6];
        let expected = pe_firmware::image::CompilationId(ours).to_string();
        assert_eq!(expected.len(), 16, "16 hex digits: {expected}");
        let mut check = HostCheck::new(&expected, dims);
        let push = |p: Vec<u8>| net.host.lock().expect("sink").push(p);
        // Boards (0,0,0), (1,0,0) and (0,1,0) (addresses 0, 1, 4) say the right id.
        for a in [0u8, 1, 4] {
            push(hello(a, ours));
        }
        check.poll(&net).expect("right ids pass");
        let e = check
            .finish(&net)
            .expect_err("board (1,1,0) never said hello");
        let m = format!("{e:#}");
        assert!(m.contains("1 board(s)") && m.contains("(1,1,0)"), "{m}");
        // Board (1,1,0) (address 5) says another compilation's id.
        let mut theirs = ours;
        theirs[7] ^= 0x80;
        push(hello(5, theirs));
        let e = check
            .poll(&net)
            .expect_err("another compilation's id is refused");
        let m = format!("{e:#}");
        let theirs_hex = pe_firmware::image::CompilationId(theirs).to_string();
        assert!(
            m.contains("board (1,1,0)") && m.contains(&theirs_hex) && m.contains(&expected),
            "names the board and both ids: {m}"
        );
        // A hello from an address outside the machine.
        let (_, net) = build_links(dims, &bells, false);
        let mut check = HostCheck::new(&expected, dims);
        net.host.lock().expect("sink").push(hello(16, ours));
        let e = check
            .poll(&net)
            .expect_err("address 16 is board (0,0,1): not on 2x2x1");
        assert!(format!("{e:#}").contains("address 16"), "{e:#}");
    }
}
