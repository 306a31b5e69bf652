//! Writing a [`Mesh`] as Gmsh MSH 2.2 ASCII, the form [`super::parse_msh`] reads back into
//! the same mesh: nodes in order (tags 1..N), hexahedra (type 5), prisms (type 6) and
//! tetrahedra (type 4, both from their degenerate-hexahedron forms) in order with their region as the physical tag, the
//! regions' names as dimension-3 `$PhysicalNames`, and every node set as points (type 15)
//! of a named dimension-0 physical group. Coordinates are written in Rust's shortest
//! round-trip form, so they read back bit for bit.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use crate::mesh::{as_tetrahedron, is_prism, Mesh};

/// The MSH 2.2 text of `mesh` with the node sets `node_sets` (names must not contain `"`).
pub fn to_msh22(mesh: &Mesh, node_sets: &BTreeMap<String, Vec<u32>>) -> String {
    let mut s = String::with_capacity(64 * (mesh.nodes.len() + mesh.cells.len()));
    s.push_str("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n");
    // Region names first, then node sets as point groups numbered after them.
    let set_tag = |k: usize| 1 + k as i32;
    let names = mesh.region_names.len() + node_sets.len();
    let _ = writeln!(s, "$PhysicalNames\n{names}");
    for (tag, name) in &mesh.region_names {
        let _ = writeln!(s, "3 {tag} \"{name}\"");
    }
    for (k, name) in node_sets.keys().enumerate() {
        let _ = writeln!(s, "0 {} \"{name}\"", set_tag(k));
    }
    s.push_str("$EndPhysicalNames\n");
    let _ = writeln!(s, "$Nodes\n{}", mesh.nodes.len());
    for (n, p) in mesh.nodes.iter().enumerate() {
        let _ = writeln!(s, "{} {:?} {:?} {:?}", n + 1, p[0], p[1], p[2]);
    }
    s.push_str("$EndNodes\n");
    let points: usize = node_sets.values().map(Vec::len).sum();
    let _ = writeln!(s, "$Elements\n{}", mesh.cells.len() + points);
    let mut tag = 0usize;
    for (c, &region) in mesh.cells.iter().zip(&mesh.cell_regions) {
        tag += 1;
        // Elementary entity = the region (one volume per region).
        if let Some(t) = as_tetrahedron(c) {
            let _ = write!(s, "{tag} 4 2 {region} {region}");
            for n in t {
                let _ = write!(s, " {}", n + 1);
            }
        } else if is_prism(c) {
            let p = [c[0], c[1], c[2], c[4], c[5], c[6]];
            let _ = write!(s, "{tag} 6 2 {region} {region}");
            for n in p {
                let _ = write!(s, " {}", n + 1);
            }
        } else {
            let _ = write!(s, "{tag} 5 2 {region} {region}");
            for n in c {
                let _ = write!(s, " {}", n + 1);
            }
        }
        s.push('\n');
    }
    for (k, nodes) in node_sets.values().enumerate() {
        let t = set_tag(k);
        for &n in nodes {
            tag += 1;
            let _ = writeln!(s, "{tag} 15 2 {t} {t} {}", n + 1);
        }
    }
    s.push_str("$EndElements\n");
    s
}
