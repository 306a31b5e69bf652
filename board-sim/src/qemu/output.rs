//! What an array run produced: each board's exit and bytes, the merged final state; or,
//! for a failed run, the boards' own account.

/// How one board's QEMU ended.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BoardRun {
    pub board: [usize; 3],
    /// Exit status (`None`: ended by a signal, e.g. killed).
    pub status: Option<i32>,
    /// Ended by the harness (`--kill`, the deadline or the watchdog).
    pub killed_by_harness: Option<String>,
    /// Seconds from the start to its exit.
    pub exit_s: f64,
    /// Its fault, as its console and its fault packet said.
    pub fault: Option<String>,
    /// Bytes it sent on each face (Face::index order) and on its global port.
    pub face_bytes_sent: [u64; 6],
    pub global_bytes_sent: u64,
}

/// What an array run produced.
#[derive(Debug)]
pub struct ArrayOutput {
    pub machine: [usize; 3],
    pub steps: u64,
    /// From the first QEMU's start to the last one's exit.
    pub wall_s: f64,
    pub boards: Vec<BoardRun>,
    /// Every mesh node's final displacement (the boards' reports merged).
    pub displacements: Vec<[f64; 3]>,
    /// Global packets routed between boards, and taken by the host and graphics sinks.
    pub packets_between_boards: u64,
    pub packets_to_sinks: u64,
    /// Surface frames the graphics engine assembled, and the host's per-step tool force.
    pub graphics_frames: usize,
    pub tool_force: Vec<[f64; 3]>,
    /// Tool-pose packets the host sent (a replay; 0 otherwise).
    pub pose_packets: u64,
}

/// The boards' own account of a failed run: what the harness did (a kill, the deadline),
/// then every board's fault ordered by step.
#[derive(Debug)]
pub struct ArrayFault {
    pub boards: Vec<BoardRun>,
    pub lines: Vec<String>,
}

impl std::fmt::Display for ArrayFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "the emulated array did not finish:")?;
        for l in &self.lines {
            writeln!(f, "  {l}")?;
        }
        Ok(())
    }
}

impl std::error::Error for ArrayFault {}
