//! A run's output files: the nodes CSV, the ParaView series and PNG of what the graphics
//! engine received ([`graphics`]), the tool forces; the flags that ask for them ([`args`]).
//! The mesh they write and draw is the compiled directory's (`DIR/mesh.json`,
//! [`OutputMesh`]), never the scene reloaded; times are steps × the manifest's dt.

pub mod args;
pub mod graphics;

use std::path::Path;

use anyhow::Result;
use host_tools::compile::OutputMesh;
use host_tools::output::write_nodes_csv;

pub use args::{OutputArgs, ResultArgs};
use graphics::SurfaceFrame;

use crate::results::SimOutput;

/// The name the outputs give the compiled directory's mesh (`DIR/mesh.json`).
pub const OUTPUT_MESH_SOURCE: &str = host_tools::compile::OUTPUT_MESH_FILE;

/// Nodes CSV, ParaView series, PNG of the last frame and tool forces, as asked; returns the
/// number of frames in the ParaView series (None without `--vtk`).
pub fn write_outputs(
    a: &OutputArgs,
    mesh: &OutputMesh,
    out: &SimOutput,
    frames: &[SurfaceFrame],
    graphics_stream: bool,
) -> Result<Option<usize>> {
    if let Some(p) = &a.run.result.output_nodes {
        write_nodes_csv(p, &mesh.mesh(OUTPUT_MESH_SOURCE), &out.displacements)?;
    }
    let mut written = None;
    if let Some(d) = &a.run.vtk {
        written = Some(if graphics_stream {
            // What the graphics engine received.
            graphics::write_surface_series(d, mesh, frames)?
        } else {
            graphics::write_volume_series(d, mesh, out)?
        });
    }
    if let Some(p) = &a.png {
        if let Some(last) = frames.last() {
            graphics::render_frame(p, mesh, last, out)?;
        }
    }
    if let Some(p) = &a.run.tool_force {
        write_tool_force(p, out)?;
    }
    Ok(written)
}

/// step,time_s,tool,fx_n,fy_n,fz_n: the force on each tool every step (N).
fn write_tool_force(p: &Path, out: &SimOutput) -> Result<()> {
    let dt = out.manifest.dt_s;
    host_tools::output::tool_force::write_tool_force_csv(p, &out.tool_force, out.tools, |s| {
        s as f64 * dt
    })
}
