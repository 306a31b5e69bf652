//! Host side of the soft-tissue simulator: scenes, meshes, the serial reference solver and
//! the tools behind the `pe` command line.
// `!(x > y)` is deliberate: it is also true for NaN, which must be refused.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Index loops mirror the tensor formulas in the doc comments.
#![allow(clippy::needless_range_loop)]
pub mod analysis;
pub mod compare;
pub mod compile;
pub mod domain;
pub mod firmware;
pub mod flash;
pub mod geom;
pub mod live;
pub mod mesh;
pub mod output;
pub mod problem;
pub mod scene;
pub mod solver;
pub mod subnormals;
pub mod team;
