//! Host side of the soft-tissue simulator: scenes, meshes, the serial reference solver and
//! the tools behind the `pe` command line.
// `!(x > y)` is deliberate: it is also true for NaN, which must be refused.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Index loops mirror the tensor formulas in the doc comments.
#![allow(clippy::needless_range_loop)]
pub mod bench;
pub mod builtin;
pub mod compile;
pub mod contact;
pub mod firmware;
pub mod mesh;
pub mod mesh_io;
pub mod output;
pub mod ovary;
pub mod problem;
pub mod render;
pub mod scene;
pub mod scene_mesh;
pub mod solver;
pub mod stability;
pub mod tradeoff;
pub mod vtk_out;
