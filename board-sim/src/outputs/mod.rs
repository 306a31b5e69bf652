//! A run's output files: the nodes CSV, the ParaView series and PNG of what the graphics
//! engine received ([`graphics`]), the tool forces; the flags that ask for them ([`args`]).

pub mod args;
pub mod graphics;

use std::path::Path;

use anyhow::{Context, Result};
use host_tools::compile::Manifest;
use host_tools::output::write_nodes_csv;
use host_tools::problem::Problem;
use host_tools::scene::builtin::builtin_scene;
use host_tools::scene::Scene;

pub use args::{OutputArgs, ResultArgs};
use graphics::SurfaceFrame;

use crate::results::SimOutput;

/// Nodes CSV, ParaView series, PNG of the last frame and tool forces, as asked; returns the
/// number of frames in the ParaView series (None without `--vtk`).
pub fn write_outputs(
    a: &OutputArgs,
    problem: &Problem,
    out: &SimOutput,
    frames: &[SurfaceFrame],
    manifest: &Manifest,
    graphics_stream: bool,
) -> Result<Option<usize>> {
    if let Some(p) = &a.result.output_nodes {
        write_nodes_csv(p, &problem.mesh, &out.displacements)?;
    }
    let mut written = None;
    if let Some(d) = &a.vtk {
        written = Some(if graphics_stream {
            // What the graphics engine received.
            graphics::write_surface_series(d, problem, frames)?
        } else {
            graphics::write_volume_series(d, problem, out, manifest.dt_s)?
        });
    }
    if let Some(p) = &a.png {
        if let Some(last) = frames.last() {
            graphics::render_frame(p, problem, last, out)?;
        }
    }
    if let Some(p) = &a.tool_force {
        write_tool_force(p, out)?;
    }
    Ok(written)
}

/// step,time_s,tool,fx_n,fy_n,fz_n: the force on each tool every step (N).
fn write_tool_force(p: &Path, out: &SimOutput) -> Result<()> {
    let rows = out.tool_force.iter().enumerate().map(|(k, f)| {
        let (step, t) = (k / out.tools.max(1), k % out.tools.max(1));
        [
            step.to_string(),
            format!("{:e}", step as f64 * out.dt_s),
            t.to_string(),
            format!("{:e}", f[0]),
            format!("{:e}", f[1]),
            format!("{:e}", f[2]),
        ]
    });
    host_tools::output::write_csv(p, &["step", "time_s", "tool", "fx_n", "fy_n", "fz_n"], rows)
}

/// The problem of the scene the manifest names (built-in or a file), for the outputs.
pub fn manifest_problem(manifest: &Manifest) -> Result<Problem> {
    let scene = match manifest.scene_source.strip_prefix("builtin:") {
        Some(level) => builtin_scene(level)?,
        None => Scene::from_file(Path::new(&manifest.scene_source))?,
    };
    let sdir = Path::new(&manifest.scene_source)
        .parent()
        .map(|p| p.to_path_buf())
        .unwrap_or_default();
    Problem::from_scene(&scene, &sdir)
        .with_context(|| format!("loading scene {} for outputs", manifest.scene_source))
}
