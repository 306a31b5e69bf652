//! The bodies of board-sim's subcommands (`main.rs` holds the command line only): `run`,
//! `live`, `builtin`, `bench`, `qemu`; `campaign` is [`crate::campaign`].

pub mod bench;
pub mod builtin;
pub mod live;
pub mod qemu;
pub mod run;

pub use bench::bench;
pub use builtin::builtin;
pub use live::{live, LiveArgs};
pub use qemu::{qemu_array, QemuArgs};
pub use run::{execute, RunArgs};
