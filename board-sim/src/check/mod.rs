//! The host's checks and fault attribution: what the boards say they run
//! ([`HostCheck`]), what the sinks took ([`collect_sinks`]; damaged or missing packets as
//! observations), every board's [`Observed`] fault or wait, and the first cause of a
//! stopped run ([`attribute`], [`SimFault`]).

mod attribute;
mod host;
mod observed;
mod sinks;

pub use attribute::{attribute, Cause, SimFault};
pub use host::HostCheck;
pub use observed::{phase, Observed};
pub use sinks::{collect_sinks, missing_sink_packets, sink_observations};
