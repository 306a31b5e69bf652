//! The run report (JSON) of `board-sim run`: as `pe solve`'s, plus per-link traffic,
//! waiting and the link model ([`write_report`]); of a run stopped on a fault
//! ([`write_fault_report`]); link recovery's totals ([`recovery`]), the global network's
//! figures ([`global`]) and the emulated array's reports ([`array`]).

pub mod array;
pub mod global;
mod json;
pub mod recovery;
mod run;

pub use global::{global_summary, GlobalSummary};
pub use recovery::recovery_summary;
pub use run::{write_fault_report, write_report, RunFacts};
