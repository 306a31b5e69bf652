//! Nodes a solver cannot use as given: nodes in no element (no mass: the first step divides
//! by zero; [`Mesh::unused_nodes`]), and distinct nodes at one position (an unmerged seam: two parts that look
//! joined move apart, silently changing the result). [`check_nodes`] refuses both, naming
//! the nodes by tag and position, before any work.

use std::collections::HashMap;

use anyhow::{bail, Result};

use super::Mesh;

/// Pairs of distinct nodes (indices, the lower first) closer than `1e-9` of the mesh's
/// bounding-box diagonal: a grid of cells of that size, each node compared with those of
/// its own and the 26 neighbouring cells.
pub fn coincident_nodes(mesh: &Mesh) -> Vec<(usize, usize)> {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in &mesh.nodes {
        for i in 0..3 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }
    let diagonal = (0..3).map(|i| (hi[i] - lo[i]).powi(2)).sum::<f64>().sqrt();
    let tol = 1e-9 * diagonal.max(f64::MIN_POSITIVE);
    let key = |p: &[f64; 3]| -> [i64; 3] {
        std::array::from_fn(|i| ((p[i] - lo[i]) / tol).floor() as i64)
    };
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (n, p) in mesh.nodes.iter().enumerate() {
        grid.entry(key(p)).or_default().push(n);
    }
    let mut pairs = Vec::new();
    for (n, p) in mesh.nodes.iter().enumerate() {
        let k = key(p);
        for d in 0..27 {
            let cell = [k[0] + d % 3 - 1, k[1] + (d / 3) % 3 - 1, k[2] + d / 9 - 1];
            for &m in grid.get(&cell).map_or(&[][..], Vec::as_slice) {
                let q = &mesh.nodes[m];
                let close = (0..3).map(|i| (p[i] - q[i]).powi(2)).sum::<f64>().sqrt() <= tol;
                if m > n && close {
                    pairs.push((n, m));
                }
            }
        }
    }
    pairs.sort_unstable();
    pairs
}

/// Refuses a mesh with nodes in no element or distinct nodes at one position, naming the
/// first few by tag and position and saying how to fix it.
pub fn check_nodes(mesh: &Mesh) -> Result<()> {
    let tag = |n: usize| mesh.node_tags.get(n).copied().unwrap_or(n as u64 + 1);
    let orphans = mesh.unused_nodes();
    if !orphans.is_empty() {
        let named: Vec<String> = orphans
            .iter()
            .take(5)
            .map(|&n| format!("{} at {:?}", tag(n as usize), mesh.nodes[n as usize]))
            .collect();
        bail!(
            "mesh {}: {} nodes belong to no element (they would have no mass): node {}{}; remove them (export only the volume's elements and their nodes)",
            mesh.source,
            orphans.len(),
            named.join(", node "),
            if orphans.len() > 5 { ", ..." } else { "" },
        );
    }
    let pairs = coincident_nodes(mesh);
    if !pairs.is_empty() {
        let named: Vec<String> = pairs
            .iter()
            .take(5)
            .map(|&(a, b)| format!("nodes {} and {} at {:?}", tag(a), tag(b), mesh.nodes[a]))
            .collect();
        bail!(
            "mesh {}: {} pairs of distinct nodes at one position (an unmerged seam: the parts would move apart): {}{}; merge them (Gmsh: `Coherence Mesh;`), or move the parts apart if they are meant to be separate",
            mesh.source,
            pairs.len(),
            named.join("; "),
            if pairs.len() > 5 { "; ..." } else { "" },
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two cubes sharing a face: merged, they pass; with the shared face's four nodes
    /// duplicated (an unmerged seam) the four pairs are named; an extra node in no element
    /// is named by its tag.
    #[test]
    fn seams_and_orphans_are_named() {
        let mut mesh = crate::mesh::grid::generate_box([2.0, 1.0, 1.0], [2, 1, 1]);
        assert_eq!((mesh.nodes.len(), mesh.cells.len()), (12, 2));
        assert!(check_nodes(&mesh).is_ok(), "merged cubes pass");
        assert!(coincident_nodes(&mesh).is_empty());
        // The second cube's x = 1 face on four new nodes at the same places.
        let mut seam = mesh.clone();
        let face: Vec<u32> = (0..12)
            .filter(|&n| seam.nodes[n as usize][0] == 1.0)
            .collect();
        assert_eq!(face.len(), 4);
        for (k, &n) in face.iter().enumerate() {
            let new = seam.nodes.len() as u32;
            let p = seam.nodes[n as usize];
            seam.nodes.push(p);
            seam.node_tags.push(100 + k as u64);
            let second = seam
                .cells
                .iter()
                .position(|c| c.iter().any(|&v| seam.nodes[v as usize][0] == 2.0));
            let second = second.expect("the cube at x in [1, 2]");
            for v in seam.cells[second].iter_mut().filter(|v| **v == n) {
                *v = new;
            }
        }
        assert!(seam.validate().is_ok());
        assert_eq!(coincident_nodes(&seam).len(), 4, "the four seam pairs");
        let e = check_nodes(&seam).unwrap_err().to_string();
        assert!(e.contains("4 pairs") && e.contains("and 100 at"), "{e}");
        mesh.nodes.push([5.0, 5.0, 5.0]);
        mesh.node_tags.push(77);
        let e = check_nodes(&mesh).unwrap_err().to_string();
        assert!(
            e.contains("1 nodes belong to no element") && e.contains("node 77 at [5.0, 5.0, 5.0]"),
            "{e}"
        );
    }
}
