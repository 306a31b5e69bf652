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

/// What link recovery cost on one board: link-proto's statistics as they are, per face
/// (`Face::index` order: +x, −x, +y, −y, +z, −z) and on the global port.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct LinkRecovery {
    pub faces: [FaceRecovery; 6],
    /// What global recovery cost on the board's global port (with it on).
    pub global: Option<GlobalRecovery>,
}

impl LinkRecovery {
    /// The sum of `stat` over the six faces.
    pub fn faces_sum(&self, stat: fn(&FaceRecovery) -> u64) -> u64 {
        self.faces.iter().map(stat).sum()
    }

    /// Bytes recovery added on this board's links: envelopes, retransmissions, control,
    /// on the faces and on the global port.
    pub fn overhead_bytes(&self) -> u64 {
        self.faces_sum(FaceRecovery::overhead_bytes)
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
