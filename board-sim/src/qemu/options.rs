//! How to run the emulated array.

use std::path::PathBuf;
use std::time::Duration;

use super::wiring::Connector;

/// How to run the array.
#[derive(Clone, Debug)]
pub struct ArrayOptions {
    /// The emulator (`qemu-system-arm`).
    pub qemu: PathBuf,
    /// The firmware ELF `pe image` copies per board (default: built with cargo for the
    /// manifest's precision and integration).
    pub firmware: Option<PathBuf>,
    /// Where the per-board ELFs and schedule blobs go (default `DIR/qemu`).
    pub images: Option<PathBuf>,
    /// The whole run's bound.
    pub deadline: Duration,
    /// End this board's QEMU this long after every board began (told the host its
    /// compilation id, before its step 0): a board dying mid-run.
    pub kill: Option<([usize; 3], Duration)>,
    /// Swap the far ends of the cables at these two connectors.
    pub cross: Option<[Connector; 2]>,
    /// Print the boards' fault reports as they arrive.
    pub quiet: bool,
    /// Tool poses to replay (`--replay`), held to their steps by the host's step gate
    /// ([`super::replay`]); none: the boards run free.
    pub poses: host_tools::solver::PoseSchedule,
}

impl Default for ArrayOptions {
    fn default() -> Self {
        ArrayOptions {
            qemu: "qemu-system-arm".into(),
            firmware: None,
            images: None,
            deadline: Duration::from_secs(1800),
            kill: None,
            cross: None,
            quiet: true,
            poses: Default::default(),
        }
    }
}
