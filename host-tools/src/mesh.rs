//! Hexahedral volume meshes on the host: the common in-memory form every importer and
//! generator produces.

use std::collections::BTreeMap;

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
}
