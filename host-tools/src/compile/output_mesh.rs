//! `DIR/mesh.json`: what the outputs of a run of the compiled images write and draw, so that
//! a reader of a compiled directory (board-sim, the QEMU harness) needs that directory only,
//! not the scene it was compiled from: the mesh (node coordinates and labels, cells and
//! their regions), the boundary surface the graphics engine draws, the nodes with a
//! prescribed displacement, and the tools on their paths (for pictures).
//!
//! Written by `pe compile` ([`super::compile_to_dir`]) from the problem it compiled, read
//! back as this type ([`OutputMesh::read`], which checks it).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use pe_firmware::physics::contact::Capsule;
use serde::{Deserialize, Serialize};

use crate::mesh::Mesh;
use crate::problem::{NodeKind, Problem};

/// The file's name in a compiled directory.
pub const OUTPUT_MESH_FILE: &str = "mesh.json";

/// `DIR/mesh.json` ([`OUTPUT_MESH_FILE`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutputMesh {
    /// Node coordinates (m), in mesh node order (the images' global node numbers), and
    /// each node's label in the mesh's source (what a nodes CSV names it by).
    pub nodes: Vec<[f64; 3]>,
    pub node_tags: Vec<u64>,
    /// Cells (node indices), their region tags and the regions' names.
    pub cells: Vec<[u32; 8]>,
    pub cell_regions: Vec<i32>,
    pub region_names: BTreeMap<i32, String>,
    /// The boundary quads (outward) the graphics engine draws, and the cell each bounds.
    pub surface_faces: Vec<[u32; 4]>,
    pub surface_face_cells: Vec<u32>,
    /// Nodes whose displacement is prescribed (a run reports their reaction).
    pub prescribed_nodes: usize,
    /// The tools: each one's capsule at time 0 and the displacement path it follows.
    pub tools: Vec<ToolTrack>,
}

/// A tool: its name (what a recorded session's poses name it by), and for pictures its
/// capsule at time 0, moved by a piecewise-linear path.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ToolTrack {
    pub name: String,
    pub capsule: Capsule,
    /// The point the tool pivots about in a live session (the scene's trocar), if any (m).
    #[serde(default)]
    pub trocar_m: Option<[f64; 3]>,
    /// `(t_s, displacement_m)` points, held constant outside them.
    pub path: Vec<(f64, [f64; 3])>,
}

impl ToolTrack {
    /// The capsule at time `t_s` (the path evaluated as the firmware does,
    /// [`pe_firmware::image::piecewise_linear`]).
    pub fn at(&self, t_s: f64) -> Capsule {
        let d = pe_firmware::image::piecewise_linear(t_s, self.path.len(), |k| self.path[k]);
        self.capsule.translated(d)
    }
}

impl OutputMesh {
    /// What the outputs of `problem`'s run need.
    pub fn of(problem: &Problem) -> OutputMesh {
        let m = &problem.mesh;
        let tools = problem.contact.as_ref().map_or(Vec::new(), |c| {
            c.tools
                .iter()
                .zip(&c.tool_names)
                .zip(&c.trocars)
                .map(|((t, name), trocar)| ToolTrack {
                    name: name.clone(),
                    capsule: t.capsule,
                    trocar_m: *trocar,
                    path: problem.paths[t.path as usize].points.clone(),
                })
                .collect()
        });
        OutputMesh {
            nodes: m.nodes.clone(),
            node_tags: m.node_tags.clone(),
            cells: m.cells.clone(),
            cell_regions: m.cell_regions.clone(),
            region_names: m.region_names.clone(),
            surface_faces: problem.surface_faces.clone(),
            surface_face_cells: problem.surface_face_cells.clone(),
            prescribed_nodes: (problem.node_kind.iter())
                .filter(|k| matches!(k, NodeKind::Prescribed(_)))
                .count(),
            tools,
        }
    }

    /// Writes `DIR/mesh.json`.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let p = dir.join(OUTPUT_MESH_FILE);
        crate::output::file::write_atomic(&p, serde_json::to_string(self)?)
    }

    /// Reads `DIR/mesh.json`, as the type that wrote it, and checks it ([`Self::check`]).
    pub fn read(dir: &Path) -> Result<OutputMesh> {
        let p = dir.join(OUTPUT_MESH_FILE);
        let m: OutputMesh = super::manifest::read_json(&p)?;
        m.check().with_context(|| format!("{}", p.display()))?;
        Ok(m)
    }

    /// The mesh part as a [`Mesh`] (for the writers that take one), named `source`.
    pub fn mesh(&self, source: &str) -> Mesh {
        Mesh {
            nodes: self.nodes.clone(),
            node_tags: self.node_tags.clone(),
            cells: self.cells.clone(),
            cell_regions: self.cell_regions.clone(),
            region_names: self.region_names.clone(),
            source: source.to_string(),
            ..Mesh::default()
        }
    }

    /// True for the nodes on the drawn surface (as [`Problem::surface_node_mask`]).
    pub fn surface_node_mask(&self) -> Vec<bool> {
        let mut m = vec![false; self.nodes.len()];
        for q in &self.surface_faces {
            for &n in q {
                if let Some(s) = m.get_mut(n as usize) {
                    *s = true;
                }
            }
        }
        m
    }

    /// Every length and index consistent: the mesh's (its own check), each surface quad's
    /// nodes and cell, each tool's path (at least one point, finite).
    pub fn check(&self) -> Result<()> {
        self.mesh("mesh.json").validate()?;
        if self.surface_face_cells.len() != self.surface_faces.len() {
            bail!(
                "{} surface faces but {} surface face cells",
                self.surface_faces.len(),
                self.surface_face_cells.len()
            );
        }
        let faces = self.surface_faces.iter().zip(&self.surface_face_cells);
        for (k, (q, &c)) in faces.enumerate() {
            if let Some(n) = q.iter().find(|&&n| n as usize >= self.nodes.len()) {
                bail!(
                    "surface face {k}: node {n} past the {} nodes",
                    self.nodes.len()
                );
            }
            if c as usize >= self.cells.len() {
                bail!(
                    "surface face {k}: cell {c} past the {} cells",
                    self.cells.len()
                );
            }
        }
        if self.prescribed_nodes > self.nodes.len() {
            bail!(
                "{} prescribed nodes of {} nodes",
                self.prescribed_nodes,
                self.nodes.len()
            );
        }
        for (k, t) in self.tools.iter().enumerate() {
            let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
            if t.path.is_empty() || !t.path.iter().all(|(s, d)| s.is_finite() && finite(d)) {
                bail!("tool {k}: its path needs finite (time, displacement) points");
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The built-in coarse scene's outputs mesh goes through the file unchanged (every
    /// coordinate's bits: JSON keeps an f64 exactly), a tool's capsule at a time is its
    /// path's displacement from the capsule at 0, and a face naming a node past the mesh
    /// is refused naming it.
    #[test]
    fn the_outputs_mesh_reads_back_as_written() {
        let scene = crate::scene::builtin::builtin_scene("coarse").expect("scene");
        let p = Problem::from_scene(&scene, Path::new(".")).expect("problem");
        let m = OutputMesh::of(&p);
        assert!(
            m.nodes.len() > 100 && m.surface_faces.len() > 100,
            "not trivial"
        );
        assert!(!m.tools.is_empty(), "the built-in scene has a probe");
        let dir = std::env::temp_dir().join(format!("pe-output-mesh-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        m.write(&dir).expect("writes");
        let back = OutputMesh::read(&dir).expect("reads");
        assert_eq!(back.nodes.len(), p.mesh.nodes.len());
        assert_eq!(back, m);
        assert_eq!(back.surface_node_mask(), p.surface_node_mask());
        let t = &m.tools[0];
        // The probe's name and trocar travel too (a live session of the compiled array
        // pivots the probe about it).
        assert_eq!(t.name, "probe");
        assert_eq!(t.trocar_m, p.contact.as_ref().and_then(|c| c.trocars[0]));
        assert!(t.trocar_m.is_some(), "the built-in probe has a trocar");
        let (t_s, d) = *t.path.last().expect("a point");
        let moved = t.at(t_s + 1.0);
        for i in 0..3 {
            assert_eq!(moved.a[i], t.capsule.a[i] + d[i]);
        }
        let mut bad = m.clone();
        bad.surface_faces[3][2] = m.nodes.len() as u32;
        let e = bad.check().unwrap_err().to_string();
        assert!(
            e.contains("surface face 3") && e.contains("past the"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
