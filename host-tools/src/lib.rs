//! Host side of the soft-tissue simulator: scenes, meshes, the serial reference solver and
//! the tools behind the `pe` command line.
pub mod builtin;
pub mod mesh;
