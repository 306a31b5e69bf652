//! board-sim: one firmware runtime per board image, each on a host thread, connected by
//! emulated point-to-point links. It runs the firmware's own runtime
//! (`pe_firmware::runtime`), not a copy.
//!
//! The rooms, bottom up (a room uses only those above it in this list):
//! - [`fabric`]: the emulated machine: links between board threads, the global network and
//!   its graphics and host sinks; [`clock`]: a worker's time; [`storage`]: a board's storage
//!   on the host; [`timing`]: the link timing model of a compiled directory.
//! - [`faults`]: faults as link wrappers, their spec and their random numbers.
//! - [`results`]: what a run produced.
//! - [`check`]: the host's checks (compilation ids, the sinks' packets) and fault
//!   attribution.
//! - [`runner`]: the boards on worker threads (each board's link stack, the collector).
//! - [`live`]: the running array as a live session's engine (`board-sim live`).
//! - [`qemu`]: the firmware itself on an emulated array of QEMUs.
//! - [`report`], [`outputs`]: the run report and the output files.
//! - [`campaign`], [`commands`]: the subcommands' bodies (`main.rs` is the command line).
//!
//! The precision x integration dispatch: [`storage::load_check`] and the runner's worker
//! (`runner/worker.rs`, `dispatch`).

pub mod campaign;
pub mod check;
pub mod clock;
pub mod commands;
pub mod fabric;
pub mod faults;
pub mod live;
pub mod outputs;
pub mod qemu;
pub mod report;
pub mod results;
pub mod runner;
pub mod storage;
pub mod timing;

pub use check::{phase, Cause, Observed, SimFault};
pub use results::{BoardResult, GraphicsFrame, LinkRecovery, SimOutput};
pub use runner::{run, SimOptions, FAULT_GRACE};
pub use storage::{load_check, StorageSizing, VecShelf};
