//! The plan: which board computes which elements (batches x, y, z, inner), which nodes
//! each holds (owner and replicas), and the exchange rounds with their summation trees.
//!
//! A free node is held by every board of the box spanned by the boards whose elements touch
//! it, and exchanged along the box's lines. A held node (fixed or prescribed) is on the
//! boards whose elements touch it only, and never exchanged: its displacement is its
//! path's whatever the force, so each of those boards computes it alone, and adds its part
//! of the node's force to the reaction.

use anyhow::{bail, Result};
use pe_firmware::image::{Combine, STAGE_NOT_OWNED};

use super::partition::{
    cost_weights, exchanged_nodes, node_board_range, node_elements, partition_weighted, Machine,
};
use crate::problem::Problem;

/// Faces in image order.
pub use link_proto::link::FACE_NAMES;

/// One exchange round of one axis on one board: per face (+axis, −axis) the global nodes to
/// send and to receive (with how to combine), in wire order (ascending global id).
#[derive(Clone, Debug, Default)]
pub struct RoundPlan {
    pub send: [Vec<u32>; 2],
    pub recv: [Vec<(u32, Combine)>; 2],
}

/// One board's part of the schedule, in global numbering.
#[derive(Clone, Debug)]
pub struct BoardPlan {
    pub coords: [usize; 3],
    /// Global element ids in batch order.
    pub elements: Vec<u32>,
    /// Ends (exclusive) of batches x, y, z, inner in `elements`.
    pub batch_ends: [usize; 4],
    /// Global node ids, ascending: the local numbering.
    pub nodes: Vec<u32>,
    /// Whether this board owns each local node.
    pub owner: Vec<bool>,
    /// Distinct global nodes exchanged across each face (+x, −x, +y, −y, +z, −z).
    pub exchange: [Vec<u32>; 6],
    /// Exchange rounds per axis.
    pub rounds: [Vec<RoundPlan>; 3],
    /// Stage (0 = x, 1 = y, 2 = z, 3 = before the update) at which each owned node's
    /// external force is added; [`STAGE_NOT_OWNED`] for nodes this board does not own.
    pub ext_stage: Vec<u8>,
}

/// The whole machine's schedule.
#[derive(Clone, Debug)]
pub struct Plan {
    pub machine: Machine,
    pub element_board: Vec<u32>,
    /// Owner board of every node.
    pub node_owner: Vec<u32>,
    pub rounds: [usize; 3],
    pub boards: Vec<BoardPlan>,
    /// What the partition balances.
    pub balance: Balance,
}

/// What the partition keeps within [`super::partition::BALANCE_MAX`] of the mean: the
/// elements per board, or their cost ([`cost_weights`]: kernels and contact nodes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Balance {
    Elements,
    Cost,
}

impl Balance {
    pub fn name(self) -> &'static str {
        match self {
            Balance::Elements => "elements",
            Balance::Cost => "cost",
        }
    }
}

/// One transfer of a node's value along an axis line: in `round`, from line position
/// `from` to `to` (adjacent), combined at the receiver by `combine`.
struct Transfer {
    round: usize,
    from: usize,
    to: usize,
    combine: Combine,
}

/// The summation tree of a node held by `m + 1` boards in a line (positions 0..=m).
/// Two boards: one symmetric exchange (`p0 + p1` on both, exact since `a + b = b + a`).
/// More: reduce towards the middle board `r = m/2` (left prefix sums `((p0 + p1) + …)`, right
/// suffix sums), the middle forms `(left + p_r) + right`, then broadcasts the total back.
fn line_transfers(m: usize) -> Vec<Transfer> {
    let t = |round, from, to, combine| Transfer {
        round,
        from,
        to,
        combine,
    };
    if m == 1 {
        return vec![t(0, 0, 1, Combine::Before), t(0, 1, 0, Combine::After)];
    }
    let root = m / 2;
    let reduce = m - root;
    let mut v = Vec::new();
    for i in 0..root {
        v.push(t(i, i, i + 1, Combine::Before));
    }
    for j in root + 1..=m {
        v.push(t(m - j, j, j - 1, Combine::After));
    }
    for d in 1..=root {
        v.push(t(reduce + d - 1, root - d + 1, root - d, Combine::Replace));
    }
    for d in 1..=m - root {
        v.push(t(reduce + d - 1, root + d - 1, root + d, Combine::Replace));
    }
    v
}

/// Rounds the line of `m + 1` boards needs.
pub fn line_rounds(m: usize) -> usize {
    match m {
        0 => 0,
        1 => 1,
        _ => 2 * (m - m / 2),
    }
}

/// Force vectors one node's summation tree sends along a line of `m + 1` boards
/// ([`line_transfers`]): `m` towards the middle board and `m` back (two boards: one each way).
pub fn line_vectors(m: usize) -> usize {
    2 * m
}

/// Force vectors per step of a node held by a box of boards spanning `span[a] + 1` boards
/// along each axis: every line of the box along an axis runs that axis's tree, and the
/// box has `(span[b] + 1) (span[c] + 1)` lines along axis `a` (`b`, `c` the other axes).
pub fn box_vectors(span: [usize; 3]) -> usize {
    (0..3)
        .map(|a| line_vectors(span[a]) * (span[(a + 1) % 3] + 1) * (span[(a + 2) % 3] + 1))
        .sum()
}

/// The whole machine's schedule for `problem` on `machine`, the partition balancing the
/// elements per board.
pub fn plan(problem: &Problem, machine: Machine) -> Result<Plan> {
    plan_balanced(problem, machine, Balance::Elements)
}

/// The whole machine's schedule for `problem` on `machine`, the partition balancing
/// `balance`.
pub fn plan_balanced(problem: &Problem, machine: Machine, balance: Balance) -> Result<Plan> {
    let mesh = &problem.mesh;
    let weight = match balance {
        Balance::Elements => vec![1; mesh.cells.len()],
        Balance::Cost => cost_weights(problem),
    };
    let exchanged = exchanged_nodes(problem);
    let element_board = partition_weighted(mesh, machine, &weight, &exchanged)?;
    let around = node_elements(mesh);
    let (node_box, node_owner, rounds) =
        node_boxes(problem, machine, &element_board, &around, &exchanged)?;
    let mut boards: Vec<BoardPlan> = (0..machine.count())
        .map(|b| BoardPlan {
            coords: machine.coords(b),
            elements: Vec::new(),
            batch_ends: [0; 4],
            nodes: Vec::new(),
            owner: Vec::new(),
            exchange: Default::default(),
            rounds: core::array::from_fn(|a| vec![RoundPlan::default(); rounds[a]]),
            ext_stage: Vec::new(),
        })
        .collect();
    let trees: Vec<Vec<Transfer>> = (0..machine.dims.iter().copied().max().unwrap_or(1))
        .map(line_transfers)
        .collect();
    for (n, &(lo, hi)) in node_box.iter().enumerate() {
        if exchanged[n] {
            place_node(
                machine,
                &mut boards,
                &trees,
                n as u32,
                node_owner[n],
                lo,
                hi,
            );
        } else {
            place_held_node(
                &mut boards,
                &element_board,
                &around[n],
                n as u32,
                node_owner[n],
            );
        }
    }
    for (e, &b) in element_board.iter().enumerate() {
        boards[b as usize].elements.push(e as u32);
    }
    for bp in &mut boards {
        order_board(problem, bp);
    }
    Ok(Plan {
        machine,
        element_board,
        node_owner,
        rounds,
        boards,
        balance,
    })
}

/// A node's box of boards (low, high corner).
type BoardBox = ([usize; 3], [usize; 3]);

/// Per node: the box of boards whose elements touch it and its owner (the lowest such
/// board); the rounds each axis needs for the nodes `exchanged` marks. `around`: the
/// elements around each node ([`node_elements`]).
fn node_boxes(
    problem: &Problem,
    machine: Machine,
    element_board: &[u32],
    around: &[Vec<u32>],
    exchanged: &[bool],
) -> Result<(Vec<BoardBox>, Vec<u32>, [usize; 3])> {
    let mesh = &problem.mesh;
    let mut node_box = Vec::with_capacity(mesh.nodes.len());
    let mut rounds = [0usize; 3];
    let mut node_owner = vec![0u32; mesh.nodes.len()];
    for (n, els) in around.iter().enumerate() {
        if els.is_empty() {
            bail!(
                "node {} of mesh {} belongs to no cell",
                mesh.node_tags[n],
                mesh.source
            );
        }
        let (lo, hi) = node_board_range(machine, element_board, els);
        if exchanged[n] {
            for a in 0..3 {
                rounds[a] = rounds[a].max(line_rounds(hi[a] - lo[a]));
            }
        }
        node_owner[n] = els
            .iter()
            .map(|&e| element_board[e as usize])
            .min()
            .unwrap_or(0);
        node_box.push((lo, hi));
    }
    Ok((node_box, node_owner, rounds))
}

/// Puts node `n` on every board of its box and its summation tree into the rounds: every
/// line of the box along an axis runs the same tree.
fn place_node(
    machine: Machine,
    boards: &mut [BoardPlan],
    trees: &[Vec<Transfer>],
    n: u32,
    owner: u32,
    lo: [usize; 3],
    hi: [usize; 3],
) {
    for z in lo[2]..=hi[2] {
        for y in lo[1]..=hi[1] {
            for x in lo[0]..=hi[0] {
                let b = machine.index([x, y, z]);
                boards[b].nodes.push(n);
                boards[b].owner.push(b as u32 == owner);
            }
        }
    }
    for a in 0..3 {
        let m = hi[a] - lo[a];
        if m == 0 {
            continue;
        }
        let (o1, o2) = ((a + 1) % 3, (a + 2) % 3);
        for p in lo[o1]..=hi[o1] {
            for q in lo[o2]..=hi[o2] {
                let at = |t: usize| {
                    let mut c = [0; 3];
                    c[a] = lo[a] + t;
                    c[o1] = p;
                    c[o2] = q;
                    machine.index(c)
                };
                for tr in &trees[m] {
                    // face index within the axis: 0 = +axis, 1 = −axis
                    let (send_face, recv_face) = if tr.to > tr.from { (0, 1) } else { (1, 0) };
                    boards[at(tr.from)].rounds[a][tr.round].send[send_face].push(n);
                    boards[at(tr.to)].rounds[a][tr.round].recv[recv_face].push((n, tr.combine));
                }
            }
        }
    }
}

/// Puts held node `n` (fixed or prescribed) on the boards whose elements touch it, and on
/// no other: its displacement is its path's whatever the force, so each of them computes
/// it from its own elements' nodes and nothing is exchanged for it.
fn place_held_node(
    boards: &mut [BoardPlan],
    element_board: &[u32],
    around: &[u32],
    n: u32,
    owner: u32,
) {
    let mut on: Vec<u32> = around.iter().map(|&e| element_board[e as usize]).collect();
    on.sort_unstable();
    on.dedup();
    for b in on {
        boards[b as usize].nodes.push(n);
        boards[b as usize].owner.push(b == owner);
    }
}

/// A board's exchanged nodes per face, its elements in batches (x, y, z border, inner) and
/// the stage at which each owned node's external force is added.
fn order_board(problem: &Problem, bp: &mut BoardPlan) {
    for a in 0..3 {
        for f in 0..2 {
            let mut all: Vec<u32> = bp.rounds[a]
                .iter()
                .flat_map(|r| {
                    r.send[f]
                        .iter()
                        .copied()
                        .chain(r.recv[f].iter().map(|x| x.0))
                })
                .collect();
            all.sort_unstable();
            all.dedup();
            bp.exchange[2 * a + f] = all;
        }
    }
    let axis_nodes: [std::collections::HashSet<u32>; 3] = core::array::from_fn(|a| {
        bp.exchange[2 * a]
            .iter()
            .chain(&bp.exchange[2 * a + 1])
            .copied()
            .collect()
    });
    let stage_of_element = |e: u32| {
        let cell = &problem.mesh.cells[e as usize];
        (0..3)
            .find(|&a| cell.iter().any(|n| axis_nodes[a].contains(n)))
            .unwrap_or(3)
    };
    let mut staged: Vec<(usize, u32)> = bp
        .elements
        .iter()
        .map(|&e| (stage_of_element(e), e))
        .collect();
    staged.sort();
    for s in 0..4 {
        bp.batch_ends[s] = staged.iter().filter(|(st, _)| *st <= s).count();
    }
    bp.elements = staged.into_iter().map(|(_, e)| e).collect();
    bp.ext_stage = bp
        .nodes
        .iter()
        .zip(&bp.owner)
        .map(|(n, own)| {
            if !own {
                STAGE_NOT_OWNED
            } else {
                (0..3).find(|&a| axis_nodes[a].contains(n)).unwrap_or(3) as u8
            }
        })
        .collect();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vector count the partitioner minimises is what the summation trees send.
    #[test]
    fn line_vectors_counts_the_trees_transfers() {
        for m in 0..16 {
            assert_eq!(
                line_transfers(m).len(),
                line_vectors(m),
                "line of {} boards",
                m + 1
            );
        }
    }
}
