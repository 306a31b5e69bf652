//! Live sessions: a trainer drives the instruments and sees and feels the tissue while it
//! runs. An [`engine::Engine`] (the host solver, or board-sim's array) is paced to the wall
//! clock by the [`session`], which serves the trainer page and the WebSocket session over
//! one address ([`http`], [`ws`]) and OpenIGTLink. The protocol is documented in
//! `docs/live.md`; its types are in [`protocol`].

pub mod cli;
pub mod engine;
pub mod http;
pub mod hub;
pub mod igtl;
pub mod model;
pub mod pose;
pub mod protocol;
pub mod session;
pub mod solver_engine;
pub mod web;
pub mod ws;

pub use engine::{Engine, EngineInfo, Pose, SurfaceInfo, ToolInfo};
pub use solver_engine::{solver_engine, SolverEngine};
