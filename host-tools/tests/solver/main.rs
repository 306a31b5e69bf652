//! The tests that run the solver, in one test binary.
//!
//! Each of these modules was its own binary, and each compiled the solver's generic code
//! (the scalar type, the batched kernels' instruction sets) again: an optimised build of
//! one took 270 to 370 s on 2 cores (`cargo test --release --no-run --timings`), the six
//! about 32 CPU-minutes, half of CI's build. One binary compiles that code once. Run one
//! module with a filter: `cargo test --release -p host-tools --test solver stability::`.

#[path = "../common/mod.rs"]
mod common;

mod batched;
mod batched_tets;
mod f32_statics;
mod gravity_ramp;
mod hourglass;
mod mesh_formats;
mod serial;
mod stability;
mod tetrahedra;
