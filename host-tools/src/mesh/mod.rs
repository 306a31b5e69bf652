//! Volume meshes (hexahedra, prisms, tetrahedra) on the host: the common in-memory form every importer and
//! generator produces.

pub mod builtin;
pub mod coarsen;
pub mod grid;
pub mod io;
pub mod ovary;
pub mod seams;

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;

/// Everything that can go wrong when reading, checking or writing a mesh.
///
/// Every variant names the file (or the mesh's `source`) and, where there is one, the
/// offending item: a line number, an element tag, a node tag or a cell index.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The mesh file does not exist.
    #[error("{}: mesh file not found", .path.display())]
    NotFound { path: PathBuf },
    /// Reading or writing failed at the operating-system level.
    #[error("{}: {source}", .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file name's extension is not one the importer knows.
    #[error("{}: unsupported mesh file extension {ext:?} (expected .msh, .vtk or .vtu)", .path.display())]
    UnsupportedExtension { path: PathBuf, ext: String },
    /// The file does not follow its format.
    #[error("{}{}: {msg}", .path.display(), line_suffix(*.line))]
    Parse {
        path: PathBuf,
        line: Option<usize>,
        msg: String,
    },
    /// An element refers to a node tag that the file never defines.
    #[error("{}{}: element {element} references unknown node tag {node}", .path.display(), line_suffix(*.line))]
    UnknownNode {
        path: PathBuf,
        line: Option<usize>,
        element: u64,
        node: u64,
    },
    /// The file holds no volume cell at all (no hexahedron, no prism).
    #[error("{}: no volume cells (hexahedra, prisms or tetrahedra) found: {detail}", .path.display())]
    NoHexahedra { path: PathBuf, detail: String },
    /// Volume cells the solver has no element for (pyramids, quadratic cells):
    /// their types and counts.
    #[error("{}: the mesh has volume cells the solver cannot run: {detail} (hexahedra, prisms (wedges) and linear tetrahedra are supported; convert quadratic cells to linear ones, e.g. gmsh -3 with Mesh.ElementOrder = 1, and pyramids to tetrahedra or hexahedra)", .path.display())]
    UnsupportedCells { path: PathBuf, detail: String },
    /// A cell uses the same node twice (a collapsed hexahedron). `item` is
    /// "element <tag> (line <n>)" for Gmsh files and "cell <0-based index>" otherwise;
    /// `node` is the node's tag.
    #[error("{}: {item} uses node {node} more than once", .path.display())]
    RepeatedNode {
        path: PathBuf,
        item: String,
        node: u64,
    },
    /// A node coordinate is NaN or infinite.
    #[error("{}: node {node} has a non-finite coordinate {coords:?}", .path.display())]
    NonFiniteCoordinate {
        path: PathBuf,
        node: u64,
        coords: [f64; 3],
    },
    /// A cell refers to a node index past the end of the node list.
    #[error("{}: cell {cell} refers to node index {index}, but the mesh has {nodes} nodes", .path.display())]
    NodeIndexOutOfRange {
        path: PathBuf,
        cell: usize,
        index: u32,
        nodes: usize,
    },
    /// An argument is unusable (e.g. a non-finite frame time for the VTK writer).
    #[error("{}: {msg}", .path.display())]
    InvalidInput { path: PathBuf, msg: String },
    /// Two per-item arrays that must have the same length do not.
    #[error("{}: {what} has {got} entries, expected {expected}", .path.display())]
    LengthMismatch {
        path: PathBuf,
        what: String,
        expected: usize,
        got: usize,
    },
}

fn line_suffix(line: Option<usize>) -> String {
    match line {
        Some(l) => format!(":{l}"),
        None => String::new(),
    }
}

/// Outward faces of a hexahedron in Gmsh/VTK order, each counter-clockwise seen from
/// outside (so the right-hand normal points out of the cell when its Jacobian is positive).
/// In order: bottom (-zeta), top (+zeta), front (-eta), right (+xi), back (+eta), left (-xi).
/// (The firmware's table, defined once.)
pub const HEX_FACES: [[usize; 4]; 6] = pe_firmware::physics::element::hex::FACES;

/// A linear hexahedral mesh in metres.
///
/// Cell node order is the Gmsh/VTK hexahedron order: nodes 0-1-2-3 the bottom face
/// (counter-clockwise seen from above), 4-5-6-7 the top face above them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Node coordinates, in mesh node order.
    pub nodes: Vec<[f64; 3]>,
    /// The node's label in its source (Gmsh node tag, or 1-based index for VTK/generated).
    pub node_tags: Vec<u64>,
    /// Cells as 0-based indices into `nodes`.
    pub cells: Vec<[u32; 8]>,
    /// Physical group (region) tag of each cell; 0 when the source has none.
    pub cell_regions: Vec<i32>,
    /// Region tag to name (Gmsh `$PhysicalNames`, or the generator's names).
    pub region_names: BTreeMap<i32, String>,
    /// Where the mesh came from (a path or a generator description), for error messages.
    pub source: String,
    /// Named node sets the file provides (Gmsh physical points, curves and surfaces; VTK
    /// point-data tags and tagged boundary cells): sorted, de-duplicated node indices.
    pub node_sets: BTreeMap<String, Vec<u32>>,
    /// What the reader did that the user should know: prisms read as degenerate hexahedra,
    /// boundary cells turned into node sets or left unused, a unit conversion. Printed when
    /// the scene is loaded.
    pub notes: Vec<String>,
}

/// A prism (wedge) `p` with triangles `p0 p1 p2` (counter-clockwise seen from the other
/// triangle) and `p3 p4 p5` above them, as the degenerate hexahedron explicit codes use:
/// `[p0, p1, p2, p2, p3, p4, p5, p5]` (corner 3 collapsed onto 2, corner 7 onto 6).
pub fn prism_as_hexahedron(p: [u32; 6]) -> [u32; 8] {
    [p[0], p[1], p[2], p[2], p[3], p[4], p[5], p[5]]
}

/// Whether `c` is a prism stored by [`prism_as_hexahedron`]: corners 3 = 2 and 7 = 6, the
/// six others distinct.
pub fn is_prism(c: &[u32; 8]) -> bool {
    let six = [c[0], c[1], c[2], c[4], c[5], c[6]];
    c[3] == c[2] && c[7] == c[6] && (1..6).all(|a| !six[..a].contains(&six[a]))
}

/// A tetrahedron `t` (Gmsh/VTK order: `t0 t1 t2` counter-clockwise seen from `t3`) as a
/// degenerate hexahedron `[t0, t1, t2, t2, t3, t3, t3, t3]`: its hexahedral faces are the
/// tetrahedron's four triangles (outward) and two faces without area, so every tool that
/// reads cells' faces reads a tetrahedron's. It runs as a tetrahedron
/// ([`pe_firmware::physics::Tet4`]), never as a hexahedron.
pub fn tetrahedron_as_hexahedron(t: [u32; 4]) -> [u32; 8] {
    [t[0], t[1], t[2], t[2], t[3], t[3], t[3], t[3]]
}

/// Whether `c` is a tetrahedron stored by [`tetrahedron_as_hexahedron`], and its nodes.
pub fn as_tetrahedron(c: &[u32; 8]) -> Option<[u32; 4]> {
    let t = [c[0], c[1], c[2], c[4]];
    let pattern = c[3] == c[2] && c[5] == c[4] && c[6] == c[4] && c[7] == c[4];
    let distinct = (1..4).all(|a| !t[..a].contains(&t[a]));
    (pattern && distinct).then_some(t)
}

/// Whether `c` is a tetrahedron stored by [`tetrahedron_as_hexahedron`].
pub fn is_tetrahedron(c: &[u32; 8]) -> bool {
    as_tetrahedron(c).is_some()
}

/// The key under which two cells' faces are the same face: the face's distinct nodes,
/// sorted, padded with `u32::MAX` (so a prism's triangle matches its neighbour's whichever
/// node repeats), and how many distinct nodes it has (fewer than 3: no area, not a face).
pub fn face_key(f: [u32; 4]) -> ([u32; 4], usize) {
    let mut k = f;
    k.sort_unstable();
    let mut out = [u32::MAX; 4];
    let mut n = 0;
    for v in k {
        if n == 0 || out[n - 1] != v {
            out[n] = v;
            n += 1;
        }
    }
    (out, n)
}

impl Mesh {
    pub fn cell_coords(&self, cell: usize) -> [[f64; 3]; 8] {
        let c = &self.cells[cell];
        core::array::from_fn(|a| self.nodes[c[a] as usize])
    }

    /// Axis-aligned bounding box (min, max).
    pub fn bounding_box(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.nodes {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// Topological sanity: node indices in range, no node repeated within a cell (except a
    /// prism's collapsed corners, see [`prism_as_hexahedron`], and a tetrahedron's, see
    /// [`tetrahedron_as_hexahedron`]), one region per cell, one tag
    /// per node, finite coordinates and node sets within the nodes. Geometry (inverted cells) is not
    /// checked here; see [`Mesh::min_scaled_jacobian`].
    pub fn validate(&self) -> Result<(), MeshError> {
        let path = PathBuf::from(&self.source);
        if self.node_tags.len() != self.nodes.len() {
            return Err(MeshError::LengthMismatch {
                path,
                what: "node_tags".into(),
                expected: self.nodes.len(),
                got: self.node_tags.len(),
            });
        }
        if self.cell_regions.len() != self.cells.len() {
            return Err(MeshError::LengthMismatch {
                path,
                what: "cell_regions".into(),
                expected: self.cells.len(),
                got: self.cell_regions.len(),
            });
        }
        for (i, p) in self.nodes.iter().enumerate() {
            if !p.iter().all(|x| x.is_finite()) {
                return Err(MeshError::NonFiniteCoordinate {
                    path,
                    node: self.node_tags[i],
                    coords: *p,
                });
            }
        }
        let n = self.nodes.len();
        for (ci, cell) in self.cells.iter().enumerate() {
            for (a, &idx) in cell.iter().enumerate() {
                if idx as usize >= n {
                    return Err(MeshError::NodeIndexOutOfRange {
                        path,
                        cell: ci,
                        index: idx,
                        nodes: n,
                    });
                }
                if cell[..a].contains(&idx) && !is_prism(cell) && !is_tetrahedron(cell) {
                    return Err(MeshError::RepeatedNode {
                        path,
                        item: format!("cell {ci}"),
                        node: self.node_tags[idx as usize],
                    });
                }
            }
        }
        // Two different nodes of a cell at the same point: an unmerged duplicate node (the
        // cell would be degenerate, or a prism whose collapsed corners could come apart).
        for (ci, cell) in self.cells.iter().enumerate() {
            for a in 0..8 {
                for b in 0..a {
                    let (i, j) = (cell[a], cell[b]);
                    if i != j && self.nodes[i as usize] == self.nodes[j as usize] {
                        let (ti, tj) = (self.node_tags[i as usize], self.node_tags[j as usize]);
                        return Err(MeshError::InvalidInput {
                            path,
                            msg: format!(
                                "cell {ci}: nodes {} and {} are different nodes at the same point {:?} (duplicate nodes not merged?)",
                                ti.min(tj), ti.max(tj), self.nodes[i as usize]
                            ),
                        });
                    }
                }
            }
        }
        for (name, set) in &self.node_sets {
            if let Some(&idx) = set.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::InvalidInput {
                    path,
                    msg: format!(
                        "node set {name:?} refers to node index {idx}, but the mesh has {n} nodes"
                    ),
                });
            }
        }
        Ok(())
    }

    /// Faces that belong to exactly one cell, with that cell's index, in cell order then
    /// [`HEX_FACES`] order, as the cell lists them (outward for a cell with positive
    /// Jacobian). A prism's triangles come as quadrilaterals with one node repeated; its
    /// collapsed face (two distinct nodes, no area) is never a face. Assumes
    /// [`Mesh::validate`] passed.
    pub fn boundary_faces_with_cells(&self) -> Vec<([u32; 4], u32)> {
        let faces = |c: &[u32; 8]| HEX_FACES.map(|f| f.map(|a| c[a]));
        let mut count: HashMap<[u32; 4], u32> = HashMap::with_capacity(self.cells.len() * 4);
        for c in &self.cells {
            for f in faces(c) {
                let (k, distinct) = face_key(f);
                if distinct >= 3 {
                    *count.entry(k).or_insert(0) += 1;
                }
            }
        }
        let mut out = Vec::new();
        for (ci, c) in self.cells.iter().enumerate() {
            for f in faces(c) {
                let (k, distinct) = face_key(f);
                if distinct >= 3 && count.get(&k) == Some(&1) {
                    out.push((f, ci as u32));
                }
            }
        }
        out
    }

    /// [`Mesh::boundary_faces_with_cells`] without the cells.
    pub fn boundary_faces(&self) -> Vec<[u32; 4]> {
        self.boundary_faces_with_cells()
            .into_iter()
            .map(|(f, _)| f)
            .collect()
    }

    /// Indices of nodes that no cell uses (ascending). An explicit solver gives such nodes
    /// zero lumped mass, so they must be removed (see [`Mesh::remove_unused_nodes`]) or
    /// handled before time stepping. Assumes [`Mesh::validate`] passed.
    pub fn unused_nodes(&self) -> Vec<u32> {
        let mut used = vec![false; self.nodes.len()];
        for &i in self.cells.iter().flatten() {
            used[i as usize] = true;
        }
        (0..self.nodes.len() as u32)
            .filter(|&i| !used[i as usize])
            .collect()
    }

    /// Drop the nodes no cell uses, keeping the order (and tags) of the others and
    /// renumbering the cells. Returns how many nodes were removed. Assumes
    /// [`Mesh::validate`] passed.
    pub fn remove_unused_nodes(&mut self) -> usize {
        let unused = self.unused_nodes();
        if unused.is_empty() {
            return 0;
        }
        let mut new_index = vec![u32::MAX; self.nodes.len()];
        let mut next = 0u32;
        let mut drop = unused.iter().peekable();
        for (i, slot) in new_index.iter_mut().enumerate() {
            if drop.peek() == Some(&&(i as u32)) {
                drop.next();
            } else {
                *slot = next;
                next += 1;
            }
        }
        let keep = |i: usize| new_index[i] != u32::MAX;
        let mut k = 0;
        self.nodes.retain(|_| {
            k += 1;
            keep(k - 1)
        });
        let mut k = 0;
        self.node_tags.retain(|_| {
            k += 1;
            keep(k - 1)
        });
        for c in &mut self.cells {
            for i in c.iter_mut() {
                *i = new_index[*i as usize];
            }
        }
        for set in self.node_sets.values_mut() {
            set.retain(|&i| keep(i as usize));
            for i in set.iter_mut() {
                *i = new_index[*i as usize];
            }
        }
        unused.len()
    }

    /// Sorted, de-duplicated indices of the nodes on [`Mesh::boundary_faces`].
    pub fn boundary_nodes(&self) -> Vec<u32> {
        let mut v: Vec<u32> = self.boundary_faces().into_iter().flatten().collect();
        v.sort_unstable();
        v.dedup();
        v
    }

    /// Scaled Jacobian of one cell: the minimum over the eight corners of
    /// `det[e1 e2 e3] / (|e1| |e2| |e3|)` with `e` the corner's three edges. 1 for a cube,
    /// <= 0 for an inverted or degenerate corner.
    pub fn scaled_jacobian(&self, cell: usize) -> f64 {
        crate::geom::scaled_jacobian(&self.cell_coords(cell))
    }

    /// Minimum [`Mesh::scaled_jacobian`] over all cells (`+inf` for a mesh without cells).
    /// A cheap quality check; the physics does its own inversion checks.
    pub fn min_scaled_jacobian(&self) -> f64 {
        (0..self.cells.len())
            .map(|c| self.scaled_jacobian(c))
            .fold(f64::INFINITY, f64::min)
    }
}

/// A cube of edge `edge` at the origin, corners in VTK hexahedron order, and its six faces
/// (the tests' smallest surface).
#[cfg(test)]
pub(crate) fn cube_surface(edge: f64) -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
    let corners = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 1.0, 1.0],
        [0.0, 1.0, 1.0],
    ];
    let nodes = corners.iter().map(|c| c.map(|x| x * edge)).collect();
    let quads = HEX_FACES
        .iter()
        .map(|f| [f[0] as u32, f[1] as u32, f[2] as u32, f[3] as u32])
        .collect();
    (nodes, quads)
}
