//! Host side of the soft-tissue simulator: scenes, meshes, the serial reference solver and
//! the tools behind the `pe` command line.
pub mod mesh;
pub mod mesh_io;
pub mod vtk_out;
