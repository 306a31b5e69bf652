//! Coarsening a structured mesh: a voxel mesh (every cell an axis-aligned cube of one edge
//! `h`, its corners on one lattice `origin + h (i, j, k)`, as the voxelised organs of
//! `../shared/meshes` are) becomes the voxel mesh of edge `2h`.
//!
//! Each coarse cell covers a 2x2x2 block of fine lattice cells and is kept when at least
//! half of them ([`KEEP_MIN`] of 8) are cells of the fine mesh. Of the eight ways to pair
//! the lattice planes (the phase of the coarse lattice along each axis) the one whose
//! coarse cells differ from the fine mesh in the fewest fine cells is taken: fine cells
//! left out plus fine-cell volumes added, each counted in [`Coarsened`]. A coarse cell's
//! region is the one most of its fine cells have (the smaller tag on a tie). Cells that
//! the coarsening leaves apart from the largest piece (connected through shared nodes)
//! are left out and counted: a loose voxel would fall freely.
//!
//! A coarse node lies on a fine lattice point; a named node set keeps the coarse nodes
//! that are nodes of its set in the fine mesh (a set whose nodes all sit between coarse
//! lattice planes ends empty and is left out: a scene that names it is refused by name).
//! Geometric selections (boxes, spheres) are the scene's and select on the coarse mesh
//! as they did on the fine one.

use std::collections::{BTreeMap, HashMap};

use super::Mesh;

/// Fine cells (of 8) a coarse cell needs to be kept.
pub const KEEP_MIN: usize = 4;

/// Relative tolerance (of `h`) on a voxel's edges and on the lattice positions.
const LATTICE_TOL: f64 = 1e-4;

/// A voxel mesh's lattice: `origin + h_m (i, j, k)`, and each cell's lattice index (its
/// lowest corner).
#[derive(Clone, Debug, PartialEq)]
pub struct Lattice {
    pub origin: [f64; 3],
    pub h_m: f64,
    pub cells: Vec<[i64; 3]>,
}

/// The lattice of `mesh` if it is a voxel mesh: every cell an axis-aligned cube of one
/// edge length whose eight corners are its bounding box's, on one lattice (to
/// [`LATTICE_TOL`] of the edge). `None` otherwise (or for an empty mesh, or one with two
/// cells on the same voxel).
pub fn lattice(mesh: &Mesh) -> Option<Lattice> {
    let first = mesh.cells.first()?;
    let edge = |c: &[u32; 8]| -> Option<([f64; 3], [f64; 3])> {
        let x: Vec<[f64; 3]> = c
            .iter()
            .map(|&n| mesh.nodes.get(n as usize).copied())
            .collect::<Option<_>>()?;
        let lo: [f64; 3] =
            core::array::from_fn(|i| x.iter().map(|p| p[i]).fold(f64::INFINITY, f64::min));
        let hi: [f64; 3] =
            core::array::from_fn(|i| x.iter().map(|p| p[i]).fold(f64::NEG_INFINITY, f64::max));
        Some((lo, hi))
    };
    let (lo0, hi0) = edge(first)?;
    let h = hi0[0] - lo0[0];
    if !(h > 0.0 && h.is_finite()) {
        return None;
    }
    let tol = LATTICE_TOL * h;
    let origin: [f64; 3] = core::array::from_fn(|i| {
        mesh.nodes
            .iter()
            .map(|p| p[i])
            .fold(f64::INFINITY, f64::min)
    });
    let mut cells = Vec::with_capacity(mesh.cells.len());
    let mut seen = std::collections::HashSet::with_capacity(mesh.cells.len());
    for c in &mesh.cells {
        let (lo, hi) = edge(c)?;
        if (0..3).any(|i| (hi[i] - lo[i] - h).abs() > tol) {
            return None;
        }
        // The eight corners are the box's eight, each once.
        let mut corners = 0u8;
        for &n in c {
            let p = mesh.nodes[n as usize];
            let mut bit = 0;
            for i in 0..3 {
                if (p[i] - hi[i]).abs() <= tol {
                    bit |= 1 << i;
                } else if (p[i] - lo[i]).abs() > tol {
                    return None;
                }
            }
            corners |= 1 << bit;
        }
        if corners != u8::MAX {
            return None;
        }
        let mut idx = [0i64; 3];
        for i in 0..3 {
            let f = (lo[i] - origin[i]) / h;
            let r = f.round();
            if (f - r).abs() * h > tol {
                return None;
            }
            idx[i] = r as i64;
        }
        if !seen.insert(idx) {
            return None;
        }
        cells.push(idx);
    }
    Some(Lattice {
        origin,
        h_m: h,
        cells,
    })
}

/// A coarsened voxel mesh and what the coarsening changed.
#[derive(Clone, Debug)]
pub struct Coarsened {
    pub mesh: Mesh,
    /// The fine mesh's voxel edge and the coarse one's (2x).
    pub h_fine_m: f64,
    pub h_coarse_m: f64,
    /// Fine cells not covered by a kept coarse cell, and fine-cell volumes the kept coarse
    /// cells add where the fine mesh has none.
    pub fine_cells_left_out: usize,
    pub fine_cells_added: usize,
    /// Coarse cells left out because they were apart from the largest piece.
    pub loose_cells_left_out: usize,
    /// Named node sets left out because no coarse node is in them.
    pub sets_left_out: Vec<String>,
}

impl Coarsened {
    /// The coarse mesh's volume over the fine one's.
    pub fn volume_ratio(&self, fine_cells: usize) -> f64 {
        8.0 * self.mesh.cells.len() as f64 / fine_cells.max(1) as f64
    }
}

/// Fine cells by the coarse cell (lattice index) that covers them.
type Blocks = HashMap<[i64; 3], Vec<usize>>;

/// A coarse cell's corners on the fine lattice, as multiples of 2: coarse cell `K` of
/// phase `p` spans `2K - p` to `2K - p + 2`.
const CORNERS: [[i64; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [1, 1, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [1, 1, 1],
    [0, 1, 1],
];

/// Corner `c` ([`CORNERS`]) of coarse cell `k` at phase `p`, on the fine lattice.
fn corner(p: [i64; 3], k: &[i64; 3], c: &[i64; 3]) -> [i64; 3] {
    core::array::from_fn(|i| 2 * k[i] - p[i] + 2 * c[i])
}

/// Union-find root.
fn root(parent: &mut [usize], mut a: usize) -> usize {
    while parent[a] != a {
        parent[a] = parent[parent[a]];
        a = parent[a];
    }
    a
}

/// `mesh` coarsened 2x if it is a voxel mesh ([`lattice`]); `None` otherwise, or when no
/// coarse cell would be kept.
pub fn coarsen(mesh: &Mesh) -> Option<Coarsened> {
    let lat = lattice(mesh)?;
    let (p, blocks) = best_phase(&lat)?;
    let mut kept: Vec<([i64; 3], &Vec<usize>)> = blocks
        .iter()
        .filter(|(_, v)| v.len() >= KEEP_MIN)
        .map(|(k, v)| (*k, v))
        .collect();
    if kept.is_empty() {
        return None;
    }
    // Lattice order (z slowest), so that the result does not depend on the map's order.
    kept.sort_by_key(|(k, _)| [k[2], k[1], k[0]]);
    let fine_cells_added: usize = kept.iter().map(|(_, v)| 8 - v.len()).sum();
    let covered: usize = kept.iter().map(|(_, v)| v.len()).sum();
    let fine_cells_left_out = lat.cells.len() - covered;
    let before = kept.len();
    let kept = largest_piece(p, kept)?;
    let loose_cells_left_out = before - kept.len();
    let mut out = Mesh {
        source: format!(
            "{} coarsened 2x (voxels of {:e} m)",
            mesh.source,
            2.0 * lat.h_m
        ),
        region_names: mesh.region_names.clone(),
        ..Mesh::default()
    };
    let node_at = coarse_cells(mesh, &lat, p, &kept, &mut out);
    out.node_tags = (1..=out.nodes.len() as u64).collect();
    let sets_left_out = coarse_sets(mesh, &lat, &node_at, &mut out);
    out.notes.push(format!(
        "coarsened 2x: {} voxels of {:.3} mm from {} of {:.3} mm ({} fine cells left out, {} fine-cell volumes added, {} loose cells left out)",
        out.cells.len(),
        2e3 * lat.h_m,
        mesh.cells.len(),
        1e3 * lat.h_m,
        fine_cells_left_out,
        fine_cells_added,
        loose_cells_left_out
    ));
    Some(Coarsened {
        mesh: out,
        h_fine_m: lat.h_m,
        h_coarse_m: 2.0 * lat.h_m,
        fine_cells_left_out,
        fine_cells_added,
        loose_cells_left_out,
        sets_left_out,
    })
}

/// Of the eight phases of the coarse lattice, the one whose kept coarse cells change the
/// fewest fine cells (the first on a tie), and its fine cells by coarse cell.
fn best_phase(lat: &Lattice) -> Option<([i64; 3], Blocks)> {
    let mut best: Option<(usize, [i64; 3], Blocks)> = None;
    for phase in 0..8 {
        let p: [i64; 3] = core::array::from_fn(|i| (phase >> i) & 1);
        let mut blocks = Blocks::new();
        for (c, idx) in lat.cells.iter().enumerate() {
            let key = core::array::from_fn(|i| (idx[i] + p[i]).div_euclid(2));
            blocks.entry(key).or_default().push(c);
        }
        let changed: usize = blocks
            .values()
            .map(|v| {
                if v.len() >= KEEP_MIN {
                    8 - v.len()
                } else {
                    v.len()
                }
            })
            .sum();
        if best.as_ref().is_none_or(|b| changed < b.0) {
            best = Some((changed, p, blocks));
        }
    }
    best.map(|(_, p, blocks)| (p, blocks))
}

/// The kept coarse cells of the largest piece (connected through shared corners; on a tie
/// the piece of the lowest root), in order.
fn largest_piece(
    p: [i64; 3],
    kept: Vec<([i64; 3], &Vec<usize>)>,
) -> Option<Vec<([i64; 3], &Vec<usize>)>> {
    let mut parent: Vec<usize> = (0..kept.len()).collect();
    let mut first_at: HashMap<[i64; 3], usize> = HashMap::new();
    for (c, (k, _)) in kept.iter().enumerate() {
        for off in &CORNERS {
            let at = corner(p, k, off);
            match first_at.get(&at) {
                Some(&o) => {
                    let (a, b) = (root(&mut parent, c), root(&mut parent, o));
                    if a != b {
                        parent[a.max(b)] = a.min(b);
                    }
                }
                None => {
                    first_at.insert(at, c);
                }
            }
        }
    }
    let mut size: HashMap<usize, usize> = HashMap::new();
    for c in 0..kept.len() {
        *size.entry(root(&mut parent, c)).or_default() += 1;
    }
    let largest = size
        .iter()
        .max_by_key(|(r, n)| (**n, std::cmp::Reverse(**r)))
        .map(|(r, _)| *r)?;
    let in_largest: Vec<bool> = (0..kept.len())
        .map(|c| root(&mut parent, c) == largest)
        .collect();
    Some(
        kept.into_iter()
            .zip(in_largest)
            .filter_map(|(k, keep)| keep.then_some(k))
            .collect(),
    )
}

/// The coarse cells (their nodes, created in order, and regions) into `out`; returns the
/// coarse node at each fine lattice point.
fn coarse_cells(
    mesh: &Mesh,
    lat: &Lattice,
    p: [i64; 3],
    kept: &[([i64; 3], &Vec<usize>)],
    out: &mut Mesh,
) -> HashMap<[i64; 3], u32> {
    let mut node_at: HashMap<[i64; 3], u32> = HashMap::new();
    for (k, fine) in kept {
        let cell: [u32; 8] = core::array::from_fn(|c| {
            let at = corner(p, k, &CORNERS[c]);
            *node_at.entry(at).or_insert_with(|| {
                out.nodes.push(core::array::from_fn(|i| {
                    lat.origin[i] + lat.h_m * at[i] as f64
                }));
                (out.nodes.len() - 1) as u32
            })
        });
        out.cells.push(cell);
        let mut count: BTreeMap<i32, usize> = BTreeMap::new();
        for &f in fine.iter() {
            *count
                .entry(mesh.cell_regions.get(f).copied().unwrap_or(0))
                .or_default() += 1;
        }
        // The most cells; on a tie, the smaller tag (the map's order).
        let region = count
            .iter()
            .fold((0, 0), |b, (&r, &n)| if n > b.1 { (r, n) } else { b })
            .0;
        out.cell_regions.push(region);
    }
    node_at
}

/// The fine mesh's named node sets on the coarse nodes (into `out`); returns the names of
/// those left empty, left out.
fn coarse_sets(
    mesh: &Mesh,
    lat: &Lattice,
    node_at: &HashMap<[i64; 3], u32>,
    out: &mut Mesh,
) -> Vec<String> {
    // Fine nodes by lattice point.
    let point_of = |x: [f64; 3]| -> [i64; 3] {
        core::array::from_fn(|i| ((x[i] - lat.origin[i]) / lat.h_m).round() as i64)
    };
    let mut sets_left_out = Vec::new();
    for (name, set) in &mesh.node_sets {
        let mut s: Vec<u32> = set
            .iter()
            .filter_map(|&n| mesh.nodes.get(n as usize))
            .filter_map(|&x| node_at.get(&point_of(x)).copied())
            .collect();
        s.sort_unstable();
        s.dedup();
        if s.is_empty() {
            sets_left_out.push(name.clone());
        } else {
            out.node_sets.insert(name.clone(), s);
        }
    }
    sets_left_out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::grid::generate_box;

    /// A 4x4x4 box of 1 cm voxels coarsens to 2x2x2 voxels of 2 cm, with the same volume
    /// and bounds, and every coarse node on the fine mesh's nodes.
    #[test]
    fn a_box_of_voxels_halves_along_each_axis() {
        let fine = generate_box([0.04, 0.04, 0.04], [4, 4, 4]);
        let lat = lattice(&fine).expect("a voxel mesh");
        assert!((lat.h_m - 0.01).abs() < 1e-12);
        let c = coarsen(&fine).expect("coarsens");
        assert_eq!(c.mesh.cells.len(), 8);
        assert_eq!(c.mesh.nodes.len(), 27);
        assert_eq!((c.fine_cells_left_out, c.fine_cells_added), (0, 0));
        assert_eq!(c.mesh.bounding_box(), fine.bounding_box());
        assert!(c.mesh.validate().is_ok());
        assert!(c.mesh.min_scaled_jacobian() > 0.999);
        for x in &c.mesh.nodes {
            assert!(fine
                .nodes
                .iter()
                .any(|y| (0..3).all(|i| (x[i] - y[i]).abs() < 1e-12)));
        }
        let again = lattice(&c.mesh).expect("still a voxel mesh");
        assert!((again.h_m - 0.02).abs() < 1e-12);
    }

    /// An odd count: 3x2x2 voxels pair along x as (0 1)(2) or (0)(1 2); either way one
    /// coarse cell is a full block and one holds half of its block (4 of 8, kept): 2
    /// coarse cells, 4 fine-cell volumes added, none left out.
    #[test]
    fn an_odd_count_keeps_the_half_blocks() {
        let fine = generate_box([0.03, 0.02, 0.02], [3, 2, 2]);
        let c = coarsen(&fine).expect("coarsens");
        assert_eq!(c.mesh.cells.len(), 2);
        assert_eq!((c.fine_cells_left_out, c.fine_cells_added), (0, 4));
        assert!((c.volume_ratio(fine.cells.len()) - 16.0 / 12.0).abs() < 1e-12);
    }

    /// Not a voxel mesh: a stretched box (cells 1 x 2 cm) or a sheared cell.
    #[test]
    fn other_meshes_are_not_voxels() {
        assert!(lattice(&generate_box([0.02, 0.04, 0.02], [2, 2, 2])).is_none());
        let mut m = generate_box([0.02, 0.02, 0.02], [2, 2, 2]);
        m.nodes[13][0] += 0.001;
        assert!(lattice(&m).is_none());
        assert!(coarsen(&Mesh::default()).is_none());
    }

    /// A piece left apart by the coarsening is left out and counted, and a node set keeps
    /// the coarse nodes that were its nodes: 8x2x2 voxels without columns 4 and 5 coarsen
    /// to blocks 0, 1 and 3 (x), and block 3 touches the others nowhere.
    #[test]
    fn loose_cells_are_left_out_and_sets_follow_their_nodes() {
        let mut fine = generate_box([0.08, 0.02, 0.02], [8, 2, 2]);
        let keep: Vec<usize> = (0..fine.cells.len())
            .filter(|&c| !matches!(c % 8, 4 | 5))
            .collect();
        assert_eq!(keep.len(), 24);
        fine.cells = keep.iter().map(|&c| fine.cells[c]).collect();
        fine.cell_regions = vec![1; fine.cells.len()];
        fine.remove_unused_nodes();
        // Node 0 is at the origin (a coarse lattice point), node 1 at x = 1 cm (not one).
        assert_eq!(fine.nodes[0], [0.0; 3]);
        assert!((fine.nodes[1][0] - 0.01).abs() < 1e-12);
        fine.node_sets.insert("origin".into(), vec![0]);
        fine.node_sets.insert("middle".into(), vec![1]);
        let c = coarsen(&fine).expect("coarsens");
        assert_eq!(c.mesh.cells.len(), 2);
        assert_eq!(c.loose_cells_left_out, 1);
        assert_eq!((c.fine_cells_left_out, c.fine_cells_added), (0, 0));
        let origin = c.mesh.node_sets.get("origin").expect("kept");
        assert_eq!(origin.len(), 1);
        assert_eq!(c.mesh.nodes[origin[0] as usize], [0.0; 3]);
        assert_eq!(c.sets_left_out, vec!["middle".to_string()]);
        assert!(c.mesh.bounding_box().1[0] < 0.04 + 1e-12);
    }
}
