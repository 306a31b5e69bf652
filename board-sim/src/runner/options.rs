//! How to run a compiled machine.

use std::time::Duration;

use link_proto::recovery::face::ReliableConfig;
use link_proto::recovery::global::GlobalConfig;

use crate::clock::Clocking;
use crate::faults::FaultSpec;
use crate::storage::StorageSizing;

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
    /// Global-network recovery (`link_proto::recovery::global`) on every board's global port,
    /// and its receiving end in the graphics and host sinks; `None` runs without (a lost or
    /// damaged global packet then stops the run).
    pub global_recovery: Option<GlobalConfig>,
    /// Each board's element batches on the host's SIMD lanes
    /// (`host_tools::solver::batched::board`, the bits of the firmware's scalar loop), or
    /// the firmware's scalar loop itself (false).
    pub batched: bool,
    /// Tool poses the host sends to the boards holding each tool, each to take effect at
    /// its step (a recorded live session replayed: `--replay`; see `runner::poses`).
    pub poses: host_tools::solver::PoseSchedule,
    /// The run's time: the wall clock, or simulated (link timeouts, link recovery's timers,
    /// the fault injector's delays and the grace after a first fault counted in time that
    /// advances only while every board waits; `crate::clock`).
    pub clocking: Clocking,
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
            poses: Default::default(),
            clocking: Clocking::Wall,
        }
    }
}
