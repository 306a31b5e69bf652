//! Structured hexahedral grids: `cells[0] x cells[1] x cells[2]` hexahedra on the lattice of
//! node indices `(i, j, k)`, each node placed by the caller. The one generator behind the
//! scene's generated box ([`crate::mesh::grid::generate_box`]) and the hourglass study's
//! grids ([`crate::analysis::hourglass::Grid`]).

use super::Mesh;

/// The numbering of a structured grid: `cells` hexahedra per axis, nodes and cells
/// numbered with the axes in `order`, slowest first (`[2, 1, 0]`: x fastest, then y, then
/// z; `[0, 1, 2]`: z fastest).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridNumbering {
    pub cells: [usize; 3],
    pub order: [usize; 3],
}

/// A cell's corners as lattice offsets, Gmsh/VTK order: the face of lowest `k`
/// counter-clockwise, then the face above it.
const CORNERS: [[usize; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [1, 1, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [1, 1, 1],
    [0, 1, 1],
];

impl GridNumbering {
    /// The index of node `(i, j, k)`.
    pub fn node(&self, p: [usize; 3]) -> usize {
        let [a, b, c] = self.order;
        let (nb, nc) = (self.cells[b] + 1, self.cells[c] + 1);
        p[c] + nc * (p[b] + nb * p[a])
    }

    /// Every lattice point of `0..=limit[axis]` in numbering order (slowest axis outermost).
    fn points(&self, limit: [usize; 3]) -> Vec<[usize; 3]> {
        let [a, b, c] = self.order;
        let mut out = Vec::with_capacity((limit[a] + 1) * (limit[b] + 1) * (limit[c] + 1));
        for x in 0..=limit[a] {
            for y in 0..=limit[b] {
                for z in 0..=limit[c] {
                    let mut p = [0; 3];
                    (p[a], p[b], p[c]) = (x, y, z);
                    out.push(p);
                }
            }
        }
        out
    }

    /// The grid's mesh: node `(i, j, k)` at `point([i, j, k])`, nodes and cells in this
    /// numbering, node tags 1-based, every cell in region 1 (unnamed: the caller names it,
    /// and says where the mesh comes from in `source`). Node indices are `u32`: counts past
    /// 2^32 nodes are beyond this generator, and beyond memory anyway.
    pub fn mesh(&self, mut point: impl FnMut([usize; 3]) -> [f64; 3]) -> Mesh {
        let mut mesh = Mesh::default();
        mesh.nodes = self
            .points(self.cells)
            .into_iter()
            .map(&mut point)
            .collect();
        mesh.node_tags = (1..=mesh.nodes.len() as u64).collect();
        if self.cells.contains(&0) {
            return mesh;
        }
        let last = self.cells.map(|n| n - 1);
        mesh.cells = self
            .points(last)
            .into_iter()
            .map(|p| CORNERS.map(|d| self.node([p[0] + d[0], p[1] + d[1], p[2] + d[2]]) as u32))
            .collect();
        mesh.cell_regions = vec![1; mesh.cells.len()];
        mesh
    }
}

/// A structured box of `cells[0] x cells[1] x cells[2]` hexahedra spanning from the origin to
/// `size` (metres). Nodes are numbered x fastest, then y, then z; node tags are 1-based;
/// every cell is in region 1, named "box". With positive `size` every cell has a positive
/// Jacobian. A zero cell count in any direction gives an empty mesh.
pub fn generate_box(size: [f64; 3], cells: [usize; 3]) -> Mesh {
    let source = format!("generate_box(size = {size:?}, cells = {cells:?})");
    if cells.contains(&0) {
        return Mesh {
            source,
            ..Mesh::default()
        };
    }
    let numbering = GridNumbering {
        cells,
        order: [2, 1, 0],
    };
    let mut mesh =
        numbering.mesh(|p| core::array::from_fn(|a| size[a] * p[a] as f64 / cells[a] as f64));
    mesh.source = source;
    mesh.region_names.insert(1, "box".to_string());
    mesh
}

/// The Kuhn (Freudenthal) split of a structured grid's hexahedra into tetrahedra: each cell
/// into the six around its diagonal from corner 0 to corner 6, one per order of the three
/// axes, each oriented positively (stored by [`crate::mesh::tetrahedron_as_hexahedron`]).
/// Neighbouring cells of one grid cut their shared face along the same diagonal, so the
/// tetrahedra are conforming; the nodes, regions and node sets are the grid's.
pub fn split_into_tetrahedra(mesh: &Mesh) -> Mesh {
    // Corner index of each lattice offset (CORNERS' inverse).
    let corner = |d: [usize; 3]| CORNERS.iter().position(|c| *c == d).unwrap_or_default();
    let mut out = Mesh {
        cells: Vec::with_capacity(6 * mesh.cells.len()),
        cell_regions: Vec::with_capacity(6 * mesh.cells.len()),
        source: format!("{} split into tetrahedra", mesh.source),
        ..mesh.clone()
    };
    for (c, &region) in mesh.cells.iter().zip(&mesh.cell_regions) {
        for axes in [
            [0, 1, 2],
            [0, 2, 1],
            [1, 0, 2],
            [1, 2, 0],
            [2, 0, 1],
            [2, 1, 0],
        ] {
            let mut d = [0; 3];
            let mut t = [c[0]; 4];
            for (s, &axis) in axes.iter().enumerate() {
                d[axis] = 1;
                t[s + 1] = c[corner(d)];
            }
            let x = t.map(|n| mesh.nodes[n as usize]);
            let e = [1, 2, 3].map(|a| crate::geom::sub(x[a], x[0]));
            if crate::geom::dot(e[0], crate::geom::cross(e[1], e[2])) < 0.0 {
                t.swap(1, 2);
            }
            out.cells.push(super::tetrahedron_as_hexahedron(t));
            out.cell_regions.push(region);
        }
    }
    out
}
