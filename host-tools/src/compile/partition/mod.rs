//! Partitioning the elements onto a logical X×Y×Z board mesh.
//!
//! Board coordinates are logical (the seed's Fig. 2). The start is geometric ([`slabs`]):
//! elements sorted by centroid into X slabs along x with equal counts, each slab into Y
//! columns along y, each column into Z boards along z (±1 element), so neighbouring boards
//! hold neighbouring tissue. With few elements per board those boards are thinner than an
//! element in places, so a node may touch boards more than one apart along an axis (relays,
//! extra exchange rounds) and the cut surfaces are ragged.
//!
//! [`refine`] then moves single elements between boards holding face neighbours to
//! minimise the force vectors the exchange rounds send (the exact count of
//! [`crate::compile::plan`]'s scheme) and the relays, keeping every board at most
//! [`BALANCE_MAX`] times the mean number of elements, non-empty, and its pieces as
//! connected as they were: simulated annealing from a fixed seed, then greedy passes. The
//! result is the same on every machine.

use anyhow::{bail, Result};

use crate::mesh::Mesh;

pub mod refine;

/// Most elements a board may hold, over the mean (the load balance the partition keeps).
pub const BALANCE_MAX: f64 = 1.05;

/// Machine size (boards per axis).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Machine {
    pub dims: [usize; 3],
}

impl Machine {
    pub fn parse(s: &str) -> Result<Machine> {
        let parts: Vec<&str> = s.split(['x', 'X']).collect();
        let dims: Vec<usize> = parts.iter().filter_map(|p| p.trim().parse().ok()).collect();
        if parts.len() != 3 || dims.len() != 3 || dims.iter().any(|&d| d == 0 || d > 16) {
            bail!("--boards {s:?}: expected X x Y x Z with 1..16 boards per axis, e.g. 4x4x4");
        }
        Ok(Machine {
            dims: [dims[0], dims[1], dims[2]],
        })
    }
    pub fn count(&self) -> usize {
        self.dims.iter().product()
    }
    /// Linear index of board coordinates (x fastest).
    pub fn index(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }
    pub fn coords(&self, i: usize) -> [usize; 3] {
        [
            i % self.dims[0],
            (i / self.dims[0]) % self.dims[1],
            i / (self.dims[0] * self.dims[1]),
        ]
    }
}

impl std::fmt::Display for Machine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}x{}", self.dims[0], self.dims[1], self.dims[2])
    }
}

/// Splits `items` (sorted by key) into `parts` runs of equal length (±1).
fn split_even<T: Copy>(items: &[T], parts: usize) -> Vec<Vec<T>> {
    (0..parts)
        .map(|p| items[p * items.len() / parts..(p + 1) * items.len() / parts].to_vec())
        .collect()
}

fn centroid(mesh: &Mesh, e: usize) -> [f64; 3] {
    let mut c = [0.0; 3];
    for &n in &mesh.cells[e] {
        for (i, v) in mesh.nodes[n as usize].iter().enumerate() {
            c[i] += v / 8.0;
        }
    }
    c
}

/// Board (linear index) of every element: the slab partition, refined (see [`refine`]).
pub fn partition(mesh: &Mesh, machine: Machine) -> Result<Vec<u32>> {
    let mut board = slabs(mesh, machine)?;
    let around = node_elements(mesh);
    let adj = refine::Adjacency::new(&mesh.cells, &around);
    let mean = mesh.cells.len() as f64 / machine.count() as f64;
    let cap = ((BALANCE_MAX * mean).floor() as usize).max(mean.ceil() as usize);
    refine::refine(&adj, machine, &mut board, cap);
    Ok(board)
}

/// Elements sorted by centroid into X slabs along x with equal counts, each slab into Y
/// columns along y, each column into Z boards along z (±1 element).
pub fn slabs(mesh: &Mesh, machine: Machine) -> Result<Vec<u32>> {
    let n = mesh.cells.len();
    if n < machine.count() {
        bail!(
            "{} elements cannot fill {} boards ({machine}): every board needs at least one",
            n,
            machine.count()
        );
    }
    let cents: Vec<[f64; 3]> = (0..n).map(|e| centroid(mesh, e)).collect();
    let sorted = |mut v: Vec<usize>, axis: usize| {
        v.sort_by(|&a, &b| cents[a][axis].total_cmp(&cents[b][axis]).then(a.cmp(&b)));
        v
    };
    let mut board = vec![0u32; n];
    let all = sorted((0..n).collect(), 0);
    for (x, slab) in split_even(&all, machine.dims[0]).into_iter().enumerate() {
        for (y, col) in split_even(&sorted(slab, 1), machine.dims[1])
            .into_iter()
            .enumerate()
        {
            for (z, part) in split_even(&sorted(col, 2), machine.dims[2])
                .into_iter()
                .enumerate()
            {
                let b = machine.index([x, y, z]) as u32;
                for e in part {
                    board[e] = b;
                }
            }
        }
    }
    Ok(board)
}

/// Elements around each node.
pub fn node_elements(mesh: &Mesh) -> Vec<Vec<u32>> {
    let mut v = vec![Vec::new(); mesh.nodes.len()];
    for (e, c) in mesh.cells.iter().enumerate() {
        for &n in c {
            v[n as usize].push(e as u32);
        }
    }
    v
}

/// Boards (coordinates) whose elements touch node `n`, min and max along each axis.
pub fn node_board_range(
    machine: Machine,
    board: &[u32],
    around: &[u32],
) -> ([usize; 3], [usize; 3]) {
    let mut lo = [usize::MAX; 3];
    let mut hi = [0; 3];
    for &e in around {
        let c = machine.coords(board[e as usize] as usize);
        for a in 0..3 {
            lo[a] = lo[a].min(c[a]);
            hi[a] = hi[a].max(c[a]);
        }
    }
    (lo, hi)
}
