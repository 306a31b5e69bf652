//! Faults as link wrappers: what to inject ([`FaultSpec`]), the random numbers every draw
//! comes from ([`Rng`], one printed seed), and the injector ([`FaultyLinks`]) that wraps a
//! board's emulated links and records what it [`Injected`].

mod inject;
mod rng;
mod spec;

pub use inject::{FaultyLinks, Injected};
pub use rng::Rng;
pub use spec::{FaultScope, FaultSpec};
