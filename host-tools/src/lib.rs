//! Host side of the soft-tissue simulator: scenes, meshes, the serial reference solver and
//! the tools behind the `pe` command line.
pub mod bench;
pub mod builtin;
pub mod mesh;
pub mod mesh_io;
pub mod output;
pub mod problem;
pub mod scene;
pub mod scene_mesh;
pub mod solver;
pub mod vtk_out;
