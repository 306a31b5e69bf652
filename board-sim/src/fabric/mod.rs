//! The emulated machine: point-to-point links between board threads (bounded queues with
//! the receiver's doorbell), the global network with its graphics and host sinks, and what
//! an observer reads of the traffic. Nothing here injects faults or recovers from them
//! (`crate::faults`, and link-proto's recovery in `crate::runner::stack`).

mod channel;
mod global;
mod links;
mod observe;

pub use channel::{Channel, Doorbell};
pub use global::{GlobalNet, SinkFault, GLOBAL_QUEUE_PACKETS};
pub use links::{build_links, EmuLinks, LINK_QUEUE_FRAMES};
pub use observe::{address_name, frame_step, global_face, packet_header, packet_step};
