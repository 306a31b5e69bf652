//! What every reader does with a file's cells, whatever the format: hexahedra are cells,
//! prisms (wedges) become degenerate hexahedra, tetrahedra are stored as degenerate
//! hexahedra and run as tetrahedra, boundary cells (points, lines, triangles,
//! quadrilaterals) give the node sets of the groups they are tagged with, and any other
//! volume cell is refused, naming its type and count. Nothing is dropped without a note.

use std::collections::{BTreeMap, BTreeSet};

use super::*;
use crate::geom::{cross, dot, sub};
use crate::mesh::{prism_as_hexahedron, tetrahedron_as_hexahedron};

/// What a cell type of a file is to the importer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum CellKind {
    /// The 8-node hexahedron.
    Hexahedron,
    /// The 6-node prism (wedge), run as a degenerate hexahedron.
    Prism,
    /// The 4-node tetrahedron, stored by [`tetrahedron_as_hexahedron`].
    Tetrahedron,
    /// A cell of dimension 0, 1 or 2: its nodes join node sets.
    Boundary { dim: i32 },
    /// A volume cell the solver has no element for (tetrahedra, pyramids, quadratic cells).
    Unsupported,
}

/// The cells of a file as they are read, assembled into a [`Mesh`]'s cells, regions, node
/// sets and notes by [`CellCollector::finish`].
#[derive(Default)]
pub(super) struct CellCollector {
    pub cells: Vec<[u32; 8]>,
    pub cell_regions: Vec<i32>,
    prisms: usize,
    tetrahedra: usize,
    /// Tetrahedra given in the other orientation, turned over.
    tetrahedra_turned: usize,
    /// Prisms whose nodes came in the other orientation (VTK's wedge order), turned over.
    prisms_turned: usize,
    node_sets: BTreeMap<String, BTreeSet<u32>>,
    /// Boundary cells per type name that gave node sets / that no group names.
    boundary_used: BTreeMap<String, usize>,
    boundary_unused: BTreeMap<String, usize>,
    unsupported: BTreeMap<String, usize>,
}

impl CellCollector {
    /// A hexahedron in region `region`.
    pub fn hexahedron(&mut self, cell: [u32; 8], region: i32) {
        self.cells.push(cell);
        self.cell_regions.push(region);
    }

    /// A prism `p` (triangle `p0 p1 p2` under `p3 p4 p5`) in region `region`, stored by
    /// [`prism_as_hexahedron`]. Writers differ in the triangles' orientation (Gmsh: counter-
    /// clockwise seen from the top triangle; VTK: the opposite), so a prism whose volume
    /// comes out negative is turned over (`p0 p2 p1 p3 p5 p4`); one that is degenerate in
    /// both orientations is left for the geometry check to name.
    pub fn prism(&mut self, p: [u32; 6], region: i32, nodes: &[[f64; 3]]) {
        let signed = |q: [u32; 6]| {
            let x = q.map(|n| nodes.get(n as usize).copied().unwrap_or([0.0; 3]));
            let (d1, d2) = (sub(x[1], x[0]), sub(x[2], x[0]));
            let up: [f64; 3] = core::array::from_fn(|i| {
                (x[3][i] + x[4][i] + x[5][i] - x[0][i] - x[1][i] - x[2][i]) / 3.0
            });
            dot(cross(d1, d2), up)
        };
        let turned = [p[0], p[2], p[1], p[3], p[5], p[4]];
        let q = if signed(p) < 0.0 && signed(turned) > 0.0 {
            self.prisms_turned += 1;
            turned
        } else {
            p
        };
        self.prisms += 1;
        self.hexahedron(prism_as_hexahedron(q), region);
    }

    /// A tetrahedron `t` in region `region`, stored by [`tetrahedron_as_hexahedron`]: one
    /// whose volume comes out negative is turned over (`t0 t2 t1 t3`); a flat one is left
    /// for the geometry check to name.
    pub fn tetrahedron(&mut self, t: [u32; 4], region: i32, nodes: &[[f64; 3]]) {
        let x = t.map(|n| nodes.get(n as usize).copied().unwrap_or([0.0; 3]));
        let signed = dot(sub(x[1], x[0]), cross(sub(x[2], x[0]), sub(x[3], x[0])));
        let t = if signed < 0.0 {
            self.tetrahedra_turned += 1;
            [t[0], t[2], t[1], t[3]]
        } else {
            t
        };
        self.tetrahedra += 1;
        self.hexahedron(tetrahedron_as_hexahedron(t), region);
    }

    /// A volume cell of `kind` (hexahedron: 8 nodes, prism: 6, tetrahedron: 4) in region `region`;
    /// `coords` the mesh's node coordinates.
    pub fn volume(&mut self, kind: CellKind, nodes: &[u32], region: i32, coords: &[[f64; 3]]) {
        match (kind, nodes.len()) {
            (CellKind::Hexahedron, 8) => {
                self.hexahedron(core::array::from_fn(|a| nodes[a]), region)
            }
            (CellKind::Prism, 6) => self.prism(core::array::from_fn(|a| nodes[a]), region, coords),
            (CellKind::Tetrahedron, 4) => {
                self.tetrahedron(core::array::from_fn(|a| nodes[a]), region, coords)
            }
            _ => self.unsupported(format!("{kind:?} cells of {} nodes", nodes.len()), 1),
        }
    }

    /// A boundary cell of type `type_name` with nodes `nodes`, in the node sets `groups`
    /// (none: it is counted and said unused).
    pub fn boundary(&mut self, type_name: &str, nodes: &[u32], groups: &[String]) {
        let count = if groups.is_empty() {
            &mut self.boundary_unused
        } else {
            &mut self.boundary_used
        };
        *count.entry(type_name.to_string()).or_insert(0) += 1;
        for g in groups {
            self.node_sets
                .entry(g.clone())
                .or_default()
                .extend(nodes.iter().copied());
        }
    }

    /// A node set given directly (VTK point-data tags).
    pub fn node_set(&mut self, name: String, nodes: impl IntoIterator<Item = u32>) {
        self.node_sets.entry(name).or_default().extend(nodes);
    }

    /// `n` cells of a volume type the solver does not have.
    pub fn unsupported(&mut self, type_name: String, n: usize) {
        *self.unsupported.entry(type_name).or_insert(0) += n;
    }

    /// Fills the mesh's cells, regions, node sets and notes; an error naming the types and
    /// counts of unsupported volume cells, or when there is no volume cell at all (`format`:
    /// the file's format, for that message).
    pub fn finish(self, path: &Path, mesh: &mut Mesh, format: &str) -> Result<(), MeshError> {
        let list = |m: &BTreeMap<String, usize>| {
            m.iter()
                .map(|(t, n)| format!("{n} {t}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        if !self.unsupported.is_empty() {
            return Err(MeshError::UnsupportedCells {
                path: path.to_path_buf(),
                detail: list(&self.unsupported),
            });
        }
        if self.cells.is_empty() {
            let mut other = self.boundary_used.clone();
            for (t, n) in &self.boundary_unused {
                *other.entry(t.clone()).or_insert(0) += n;
            }
            let detail = if other.is_empty() {
                format!("the {format} file has no cells")
            } else {
                format!(
                    "the {format} file has only boundary cells ({})",
                    list(&other)
                )
            };
            return Err(MeshError::NoHexahedra {
                path: path.to_path_buf(),
                detail,
            });
        }
        if self.prisms > 0 {
            let turned = if self.prisms_turned > 0 {
                format!(
                    "; {} given in the other orientation were turned over",
                    self.prisms_turned
                )
            } else {
                String::new()
            };
            mesh.notes.push(format!(
                "{} prisms (wedges) run as degenerate hexahedra (corner 3 on 2, 7 on 6){turned}",
                self.prisms
            ));
        }
        if self.tetrahedra > 0 {
            let turned = if self.tetrahedra_turned > 0 {
                format!(
                    "; {} given in the other orientation were turned over",
                    self.tetrahedra_turned
                )
            } else {
                String::new()
            };
            mesh.notes.push(format!(
                "{} tetrahedra run as linear tetrahedra (T4; [solver] tetrahedron chooses the nodal-pressure or plain form){turned}",
                self.tetrahedra
            ));
        }
        if !self.boundary_used.is_empty() {
            mesh.notes.push(format!(
                "boundary cells ({}) give the node sets {:?}",
                list(&self.boundary_used),
                self.node_sets.keys().collect::<Vec<_>>()
            ));
        }
        if !self.boundary_unused.is_empty() {
            mesh.notes.push(format!(
                "boundary cells in no named group are not used ({})",
                list(&self.boundary_unused)
            ));
        }
        mesh.cells = self.cells;
        mesh.cell_regions = self.cell_regions;
        for (name, set) in self.node_sets {
            mesh.node_sets.insert(name, set.into_iter().collect());
        }
        Ok(())
    }
}

/// Gmsh element types: what each is to the importer, its node count and a readable name
/// (the common types; enough to read or skip any block of a volume mesh).
pub(super) fn gmsh_type(t: i32) -> Option<(CellKind, usize, &'static str)> {
    use CellKind::*;
    let b = |dim| Boundary { dim };
    Some(match t {
        15 => (b(0), 1, "points (Gmsh type 15)"),
        1 => (b(1), 2, "lines (Gmsh type 1)"),
        8 => (b(1), 3, "quadratic lines (Gmsh type 8)"),
        26 => (b(1), 4, "cubic lines (Gmsh type 26)"),
        27 => (b(1), 5, "quartic lines (Gmsh type 27)"),
        28 => (b(1), 6, "quintic lines (Gmsh type 28)"),
        2 => (b(2), 3, "triangles (Gmsh type 2)"),
        3 => (b(2), 4, "quadrangles (Gmsh type 3)"),
        9 => (b(2), 6, "quadratic triangles (Gmsh type 9)"),
        10 => (b(2), 9, "9-node quadrangles (Gmsh type 10)"),
        16 => (b(2), 8, "8-node quadrangles (Gmsh type 16)"),
        20 => (b(2), 9, "cubic incomplete triangles (Gmsh type 20)"),
        21 => (b(2), 10, "cubic triangles (Gmsh type 21)"),
        22 => (b(2), 12, "quartic incomplete triangles (Gmsh type 22)"),
        23 => (b(2), 15, "quartic triangles (Gmsh type 23)"),
        24 => (b(2), 15, "quintic incomplete triangles (Gmsh type 24)"),
        25 => (b(2), 21, "quintic triangles (Gmsh type 25)"),
        5 => (Hexahedron, 8, "hexahedra (Gmsh type 5)"),
        6 => (Prism, 6, "prisms (Gmsh type 6)"),
        4 => (Tetrahedron, 4, "tetrahedra (Gmsh type 4)"),
        7 => (Unsupported, 5, "pyramids (Gmsh type 7)"),
        11 => (Unsupported, 10, "10-node tetrahedra (Gmsh type 11)"),
        12 => (Unsupported, 27, "27-node hexahedra (Gmsh type 12)"),
        13 => (Unsupported, 18, "18-node prisms (Gmsh type 13)"),
        14 => (Unsupported, 14, "14-node pyramids (Gmsh type 14)"),
        17 => (Unsupported, 20, "20-node hexahedra (Gmsh type 17)"),
        18 => (Unsupported, 15, "15-node prisms (Gmsh type 18)"),
        19 => (Unsupported, 13, "13-node pyramids (Gmsh type 19)"),
        29 => (Unsupported, 20, "cubic tetrahedra (Gmsh type 29)"),
        30 => (Unsupported, 35, "quartic tetrahedra (Gmsh type 30)"),
        31 => (Unsupported, 56, "quintic tetrahedra (Gmsh type 31)"),
        92 => (Unsupported, 64, "cubic hexahedra (Gmsh type 92)"),
        93 => (Unsupported, 125, "quartic hexahedra (Gmsh type 93)"),
        _ => return None,
    })
}

/// VTK cell types: what each is to the importer, its fixed node count (`None`: any, for
/// poly-vertices, poly-lines, strips and polygons) and a readable name.
pub(super) fn vtk_type(t: u8) -> (CellKind, Option<usize>, String) {
    use CellKind::*;
    let b = |dim| Boundary { dim };
    let (kind, n, name) = match t {
        1 => (b(0), Some(1), "VTK_VERTEX"),
        2 => (b(0), None, "VTK_POLY_VERTEX"),
        3 => (b(1), Some(2), "VTK_LINE"),
        4 => (b(1), None, "VTK_POLY_LINE"),
        5 => (b(2), Some(3), "VTK_TRIANGLE"),
        6 => (b(2), None, "VTK_TRIANGLE_STRIP"),
        7 => (b(2), None, "VTK_POLYGON"),
        8 => (b(2), Some(4), "VTK_PIXEL"),
        9 => (b(2), Some(4), "VTK_QUAD"),
        21 => (b(1), Some(3), "VTK_QUADRATIC_EDGE"),
        22 => (b(2), Some(6), "VTK_QUADRATIC_TRIANGLE"),
        23 => (b(2), Some(8), "VTK_QUADRATIC_QUAD"),
        28 => (b(2), Some(9), "VTK_BIQUADRATIC_QUAD"),
        12 => (Hexahedron, Some(8), "VTK_HEXAHEDRON"),
        13 => (Prism, Some(6), "VTK_WEDGE"),
        10 => (Tetrahedron, Some(4), "VTK_TETRA"),
        11 => (Unsupported, Some(8), "VTK_VOXEL"),
        14 => (Unsupported, Some(5), "VTK_PYRAMID"),
        24 => (Unsupported, Some(10), "VTK_QUADRATIC_TETRA"),
        25 => (Unsupported, Some(20), "VTK_QUADRATIC_HEXAHEDRON"),
        26 => (Unsupported, Some(15), "VTK_QUADRATIC_WEDGE"),
        27 => (Unsupported, Some(13), "VTK_QUADRATIC_PYRAMID"),
        29 => (Unsupported, Some(27), "VTK_TRIQUADRATIC_HEXAHEDRON"),
        _ => (Unsupported, None, "cells of an unknown VTK type"),
    };
    let name = if kind == Unsupported || matches!(kind, Boundary { .. }) {
        format!("{name} ({t})")
    } else {
        name.to_string()
    };
    (kind, n, name)
}
