//! Board firmware library: physics, schedule image and runtime. `no_std`, allocation-free,
//! fixed capacities; the same code runs on the board and, through board-sim, on the host.
// `!(x > y)` is deliberate: it is also true for NaN, which must be refused.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Index loops mirror the tensor formulas in the doc comments.
#![allow(clippy::needless_range_loop)]
#![no_std]
#![forbid(unsafe_code)]

pub mod image;
pub mod physics;
pub mod profile;
pub mod runtime;
