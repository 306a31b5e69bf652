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
//! [`crate::compile::trees`]' scheme, in which a held node is not exchanged), the relays
//! and the busiest links' loads, keeping every board within [`BALANCE_MAX`] times the mean
//! load, non-empty, and its pieces as connected as they
//! were: simulated annealing from a fixed seed, then greedy passes. The result is the same
//! on every machine.
//!
//! The load is what a board computes per step: with [`cost_weights`] each element weighs
//! its kernel's measured instructions plus its share of its contact nodes' (the slabs
//! then split by weight, not count); a mesh alone ([`partition`]) weighs every element
//! one, and the load is the element count.

use anyhow::{bail, Result};

use crate::mesh::Mesh;
use crate::problem::elements::kind_of;
use crate::problem::{NodeKind, Problem};

pub mod refine;

/// Most elements a board may hold, over the mean (the load balance the partition keeps).
pub const BALANCE_MAX: f64 = 1.05;

/// The board array (its one home is [`link_proto::machine`]).
pub use link_proto::Machine;

/// Splits `items` (sorted by key) into `parts` runs of equal length (±1).
fn split_even<T: Copy>(items: &[T], parts: usize) -> Vec<Vec<T>> {
    (0..parts)
        .map(|p| items[p * items.len() / parts..(p + 1) * items.len() / parts].to_vec())
        .collect()
}

/// Splits `items` (sorted by key) into `parts` runs of about equal weight: run `p` starts
/// at the first item whose middle lies past `p / parts` of the total weight, moved so that
/// every run keeps at least `min_len` items (when there are that many).
fn split_by_weight(
    items: &[usize],
    parts: usize,
    min_len: usize,
    weight: &[u64],
) -> Vec<Vec<usize>> {
    let n = items.len();
    let total: u128 = items.iter().map(|&i| weight[i] as u128).sum();
    let mut starts = vec![n; parts + 1];
    starts[0] = 0;
    let mut before = 0u128;
    let mut p = 1;
    for (k, &i) in items.iter().enumerate() {
        // Middle of item k, doubled: 2 W_k + w_k; run p starts where it passes 2 p W / parts.
        let mid = 2 * before + weight[i] as u128;
        while p < parts && mid * parts as u128 > 2 * p as u128 * total {
            starts[p] = k;
            p += 1;
        }
        before += weight[i] as u128;
    }
    if n >= parts * min_len {
        for p in 1..parts {
            starts[p] = starts[p]
                .max(starts[p - 1] + min_len)
                .min(n - (parts - p) * min_len);
        }
    }
    (0..parts)
        .map(|p| items[starts[p]..starts[p + 1].max(starts[p])].to_vec())
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

/// What each element of `problem` costs a board per step, in the firmware's measured
/// instructions ([`pe_firmware::profile::measured_cost`] for its precision and
/// integration): its kernel's (parallelepiped or general) plus, for each of its nodes on a
/// contact surface, that node's contact cost over the elements around it,
/// `w_e = k_e + Σ_{n ∈ e, n in contact} c / |elements around n|`, rounded. Node updates are
/// left out (every board updates about as many nodes per element). Equal kernels and no
/// contact give equal weights: the partition by count.
pub fn cost_weights(problem: &Problem) -> Vec<u64> {
    let cost =
        pe_firmware::profile::measured_cost(problem.solver.precision, problem.solver.integration);
    let around = node_elements(&problem.mesh);
    let mut on_contact = vec![false; problem.mesh.nodes.len()];
    if let Some(c) = &problem.contact {
        for &n in &c.node_globals {
            on_contact[n as usize] = true;
        }
    }
    problem
        .mesh
        .cells
        .iter()
        .enumerate()
        .map(|(e, cell)| {
            // Tetrahedra never get here (`plan::refuse_tetrahedra`); costed as general cells.
            let kernel = cost.element_step(
                kind_of(problem, e).unwrap_or(crate::problem::elements::ElementKind::HexReduced),
            );
            let contact: f64 = cell
                .iter()
                .filter(|&&n| on_contact[n as usize])
                .map(|&n| cost.per_contact_node as f64 / around[n as usize].len() as f64)
                .sum();
            ((kernel as f64 + contact).round() as u64).max(1)
        })
        .collect()
}

/// Board (linear index) of every element, every element weighing one and every node
/// exchanged: the slab partition, refined (see [`refine`]).
pub fn partition(mesh: &Mesh, machine: Machine) -> Result<Vec<u32>> {
    let exchanged = vec![true; mesh.nodes.len()];
    partition_weighted(mesh, machine, &vec![1; mesh.cells.len()], &exchanged)
}

/// Whether each node of `problem` is exchanged: a held node (fixed or prescribed) is not,
/// since its displacement is its path's whatever the force (every board that holds it
/// computes it; see [`crate::compile::plan`]).
pub fn exchanged_nodes(problem: &Problem) -> Vec<bool> {
    problem
        .node_kind
        .iter()
        .map(|k| *k == NodeKind::Free)
        .collect()
}

/// Board of every element, balancing the elements' `weight`, the exchange counting the
/// nodes `exchanged` marks (see the module doc).
pub fn partition_weighted(
    mesh: &Mesh,
    machine: Machine,
    weight: &[u64],
    exchanged: &[bool],
) -> Result<Vec<u32>> {
    if weight.len() != mesh.cells.len() || weight.contains(&0) {
        bail!(
            "{} element weights for {} elements (each at least 1)",
            weight.len(),
            mesh.cells.len()
        );
    }
    if exchanged.len() != mesh.nodes.len() {
        bail!(
            "{} exchange marks for {} nodes",
            exchanged.len(),
            mesh.nodes.len()
        );
    }
    let mut board = slabs_weighted(mesh, machine, weight)?;
    let around = node_elements(mesh);
    let adj = refine::Adjacency::new(&mesh.cells, &around, exchanged);
    let cap = load_cap(machine, &board, weight);
    refine::refine(&adj, machine, &mut board, weight, cap);
    Ok(board)
}

/// Every element weighs the same: the partition is by count.
pub fn equal_weights(weight: &[u64]) -> bool {
    weight.iter().all(|w| Some(w) == weight.first())
}

/// The most a board may weigh: [`BALANCE_MAX`] times the mean (at least the mean rounded
/// up, in whole elements when they weigh the same), or the slab start's heaviest board if
/// whole elements could not split more evenly.
pub fn load_cap(machine: Machine, board: &[u32], weight: &[u64]) -> u64 {
    let total: u64 = weight.iter().sum();
    let mut load = vec![0u64; machine.count()];
    for (&b, &w) in board.iter().zip(weight) {
        load[b as usize] += w;
    }
    let start = load.iter().copied().max().unwrap_or(0);
    let w0 = weight.first().copied().unwrap_or(1);
    let cap = if equal_weights(weight) {
        let mean = weight.len() as f64 / machine.count() as f64;
        ((BALANCE_MAX * mean).floor() as u64).max(mean.ceil() as u64) * w0
    } else {
        (BALANCE_MAX * total as f64 / machine.count() as f64).floor() as u64
    };
    cap.max(start)
}

/// Elements sorted by centroid into X slabs along x with equal counts, each slab into Y
/// columns along y, each column into Z boards along z (±1 element).
pub fn slabs(mesh: &Mesh, machine: Machine) -> Result<Vec<u32>> {
    slabs_weighted(mesh, machine, &vec![1; mesh.cells.len()])
}

/// [`slabs`] by weight: each split puts the same weight (to within an element) on each
/// side; with equal weights, the same split as by count.
pub fn slabs_weighted(mesh: &Mesh, machine: Machine, weight: &[u64]) -> Result<Vec<u32>> {
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
    let uniform = equal_weights(weight);
    // Each run keeps enough elements for the boards it is split into.
    let split = |items: &[usize], parts: usize, min_len: usize| {
        if uniform {
            split_even(items, parts)
        } else {
            split_by_weight(items, parts, min_len, weight)
        }
    };
    let [_, dy, dz] = machine.dims();
    let all = sorted((0..n).collect(), 0);
    for (x, slab) in split(&all, machine.dims()[0], dy * dz)
        .into_iter()
        .enumerate()
    {
        for (y, col) in split(&sorted(slab, 1), dy, dz).into_iter().enumerate() {
            for (z, part) in split(&sorted(col, 2), dz, 1).into_iter().enumerate() {
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
