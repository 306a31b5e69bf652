//! Board firmware library: physics, schedule image and runtime. `no_std`, allocation-free,
//! fixed capacities; the same code runs on the board and, through board-sim, on the host.
#![no_std]
#![forbid(unsafe_code)]

pub mod physics;
