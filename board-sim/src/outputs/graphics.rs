//! The host-side graphics engine of board-sim: assembles the surface frames the boards send
//! over the global network, writes them as a ParaView series and draws the last one.

use std::path::Path;

use anyhow::Result;
use host_tools::compile::OutputMesh;
use host_tools::output::vtk::{SurfaceSeriesWriter, VtkSeriesWriter};
use pe_firmware::physics::vec3::norm;

/// A frame the graphics engine assembled: time and displacement of every mesh node it
/// received (others zero), or None if some surface node is missing.
pub struct SurfaceFrame {
    pub time_s: f64,
    pub u: Vec<[f64; 3]>,
}

/// The frames of a run the graphics engine could assemble (every surface node present).
pub fn surface_frames(pr: &OutputMesh, out: &crate::results::SimOutput) -> Vec<SurfaceFrame> {
    let surface = pr.surface_node_mask();
    let needed = surface.iter().filter(|s| **s).count();
    out.graphics
        .iter()
        .filter(|f| f.nodes.len() == needed)
        .map(|f| {
            let mut u = vec![[0.0; 3]; pr.nodes.len()];
            for (n, d) in &f.nodes {
                if let Some(x) = u.get_mut(*n as usize) {
                    *x = d.map(|v| v as f64);
                }
            }
            SurfaceFrame {
                time_s: f.steps.0 as f64 * out.manifest.dt_s,
                u,
            }
        })
        .collect()
}

/// The assembled surface frames as a ParaView series in `d`; returns the number of frames.
pub fn write_surface_series(d: &Path, pr: &OutputMesh, frames: &[SurfaceFrame]) -> Result<usize> {
    std::fs::create_dir_all(d)?;
    let (local, quads) = surface_numbering(pr);
    let reference: Vec<[f64; 3]> = local.iter().map(|&g| pr.nodes[g as usize]).collect();
    let regions = surface_regions(pr);
    let mut w = SurfaceSeriesWriter::new(d, reference, quads, regions, &pr.region_names)?;
    for f in frames {
        let u: Vec<[f64; 3]> = local.iter().map(|&g| f.u[g as usize]).collect();
        w.write_frame(f.time_s, &u)?;
    }
    let n = w.frame_count();
    w.finish()?;
    Ok(n)
}

/// Surface nodes (mesh indices, ascending) and the boundary quads in that numbering.
fn surface_numbering(pr: &OutputMesh) -> (Vec<u32>, Vec<[u32; 4]>) {
    let mask = pr.surface_node_mask();
    let local: Vec<u32> = (0..mask.len() as u32)
        .filter(|&n| mask[n as usize])
        .collect();
    let index: std::collections::HashMap<u32, u32> = local
        .iter()
        .enumerate()
        .map(|(i, &g)| (g, i as u32))
        .collect();
    let quads = pr
        .surface_faces
        .iter()
        .map(|q| q.map(|n| index[&n]))
        .collect();
    (local, quads)
}

/// Region of each boundary quad: the region tag of the cell it bounds (named by the mesh's
/// `region_names`).
fn surface_regions(pr: &OutputMesh) -> Vec<i32> {
    pr.surface_face_cells
        .iter()
        .map(|c| pr.cell_regions.get(*c as usize).copied().unwrap_or(0))
        .collect()
}

/// Colour group of each boundary quad for the picture: its region, as a small index.
fn surface_groups(pr: &OutputMesh) -> Vec<u8> {
    surface_regions(pr)
        .into_iter()
        .map(|r| r.clamp(0, 255) as u8)
        .collect()
}

/// PNG of surface frame `f` with the tools at their positions at its time.
pub fn render_frame(
    p: &Path,
    pr: &OutputMesh,
    f: &SurfaceFrame,
    out: &crate::results::SimOutput,
) -> Result<()> {
    use host_tools::output::render::{render_surface_png, CapsuleOverlay, SurfaceImage, View};
    let positions: Vec<[f64; 3]> = pr
        .nodes
        .iter()
        .zip(&f.u)
        .map(|(x, u)| core::array::from_fn(|i| x[i] + u[i]))
        .collect();
    let values: Vec<f64> = f.u.iter().map(|u| norm(*u)).collect();
    let tools: Vec<CapsuleOverlay> = pr
        .tools
        .iter()
        .map(|t| {
            let cap = t.at(f.time_s);
            CapsuleOverlay {
                a: cap.a,
                b: cap.b,
                radius_m: cap.radius_m,
            }
        })
        .collect();
    let title = format!(
        "t = {:.3} s: the graphics stream from {} boards",
        f.time_s,
        out.boards.len()
    );
    render_surface_png(
        p,
        &SurfaceImage {
            positions: &positions,
            quads: &pr.surface_faces,
            quad_groups: &surface_groups(pr),
            node_values: &values,
            value_label: "displacement (mm)",
            value_scale: 1e3,
            tools: &tools,
            title: &title,
            view: View {
                azimuth_deg: -60.0,
                elevation_deg: 30.0,
            },
            size_px: (1200, 900),
        },
    )
}

/// Without a graphics stream: the whole mesh every `frame_every` steps (the frames board-sim
/// kept), from rest to the final state, as a ParaView series in `d` (times: steps × the
/// manifest's dt); returns the number of frames.
pub fn write_volume_series(
    d: &Path,
    pr: &OutputMesh,
    out: &crate::results::SimOutput,
) -> Result<usize> {
    std::fs::create_dir_all(d)?;
    let dt_s = out.manifest.dt_s;
    let mut w = VtkSeriesWriter::new(d, &pr.mesh(super::OUTPUT_MESH_SOURCE))?;
    w.write_frame(0.0, &vec![[0.0; 3]; pr.nodes.len()])?;
    for (s, u) in &out.frames {
        w.write_frame(*s as f64 * dt_s, u)?;
    }
    w.write_frame(out.steps as f64 * dt_s, &out.displacements)?;
    let n = w.frame_count();
    w.finish()?;
    Ok(n)
}
