//! What a run produced: per board ([`BoardResult`], [`LinkRecovery`]) and in all
//! ([`SimOutput`], with the [`GraphicsFrame`]s the graphics engine assembled).

use host_tools::compile::Manifest;
use link_proto::recovery::FaceRecovery;
use link_proto::recovery::GlobalRecovery;
use pe_firmware::runtime::GlobalStats;

use crate::faults::Injected;

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
    /// Data envelopes sent the first time (each adds `recovery::OVERHEAD` bytes).
    pub data_frames: [u64; 6],
    /// What global recovery cost on the board's global port (with it on).
    pub global: Option<GlobalRecovery>,
}

impl LinkRecovery {
    pub(crate) fn from_faces(f: &[FaceRecovery; 6], global: Option<&GlobalRecovery>) -> Self {
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
        s(&self.data_frames) * link_proto::recovery::OVERHEAD as u64
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
