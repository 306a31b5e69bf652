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

use link_proto::Machine;

use super::partition::{
    cost_weights, exchanged_nodes, node_board_range, node_elements, partition_weighted,
};
use super::trees::{
    choose_roots, for_node_transfers, half_rounds, last_axis, line_rounds, BoardBox, LineTrees,
    Roots,
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
    /// Exchange rounds per axis, of which the last `late_rounds` run after the z exchange
    /// (the x and y broadcasts of [`crate::compile::trees::for_box_lines`]; none along z). Of the first ones,
    /// round 0 holds what waits for no other board and round 1 what waits for the earlier
    /// axes (see `trees::for_node_transfers`); the program, [`pe_firmware::runtime::Program::new`], runs
    /// them in that order.
    pub rounds: [usize; 3],
    pub late_rounds: [usize; 3],
    pub boards: Vec<BoardPlan>,
    /// What the partition balances.
    pub balance: Balance,
}

/// What the partition keeps within [`super::partition::BALANCE_MAX`] of the mean: the
/// elements per board, or their cost ([`cost_weights`]: kernels and contact nodes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
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

/// The whole machine's schedule for `problem` on `machine`, the partition balancing the
/// elements per board.
pub fn plan(problem: &Problem, machine: Machine) -> Result<Plan> {
    plan_balanced(problem, machine, Balance::Elements)
}

/// Refuses a problem the boards cannot run yet: tetrahedra run on the host only (`pe
/// solve`, `pe live`); the boards have no tetrahedron kernel, image record or nodal
/// pressure exchange. Names the count and the first cell.
pub fn refuse_tetrahedra(problem: &Problem) -> Result<()> {
    let mut tets = problem
        .mesh
        .cells
        .iter()
        .enumerate()
        .filter(|(_, c)| crate::mesh::is_tetrahedron(c));
    if let Some((first, _)) = tets.next() {
        anyhow::bail!(
            "mesh {}: {} tetrahedra (the first is cell {first}): the boards have no tetrahedron kernel yet; tetrahedral and mixed meshes run on the host (pe solve, pe live), or remesh with hexahedra to compile",
            problem.mesh.source,
            tets.count() + 1
        );
    }
    Ok(())
}

/// The whole machine's schedule for `problem` on `machine`, the partition balancing
/// `balance`.
pub fn plan_balanced(problem: &Problem, machine: Machine, balance: Balance) -> Result<Plan> {
    refuse_tetrahedra(problem)?;
    let mesh = &problem.mesh;
    let weight = match balance {
        Balance::Elements => vec![1; mesh.cells.len()],
        Balance::Cost => cost_weights(problem),
    };
    let exchanged = exchanged_nodes(problem);
    let element_board = partition_weighted(mesh, machine, &weight, &exchanged)?;
    let around = node_elements(mesh);
    let (node_box, node_owner, trees) =
        node_boxes(problem, machine, &element_board, &around, &exchanged)?;
    let late_rounds = trees.late;
    // Round 0 of an axis goes first (see `trees::for_node_transfers`).
    let early = trees.early.map(|r| if r > 0 { r + 1 } else { 0 });
    let rounds: [usize; 3] = core::array::from_fn(|a| early[a] + late_rounds[a]);
    let trees = LineTrees::new(machine.dims().iter().copied().max().unwrap_or(1));
    let roots = choose_roots(machine, &trees, early, &node_box, &exchanged);
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
    for (n, &node_box) in node_box.iter().enumerate() {
        if exchanged[n] {
            place_node(
                machine,
                &mut boards,
                &trees,
                early,
                (n as u32, node_owner[n]),
                node_box,
                roots[n],
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
        late_rounds,
        boards,
        balance,
    })
}

/// The rounds per axis the nodes' trees need: their reduce halves and whole trees, and
/// their broadcast halves after the z exchange.
struct TreeRounds {
    early: [usize; 3],
    late: [usize; 3],
}

/// Per node: the box of boards whose elements touch it and its owner (the lowest such
/// board); the rounds each axis needs for the nodes `exchanged` marks, before the z
/// exchange's end and after it (the broadcasts). `around`: the elements around each node
/// ([`node_elements`]).
fn node_boxes(
    problem: &Problem,
    machine: Machine,
    element_board: &[u32],
    around: &[Vec<u32>],
    exchanged: &[bool],
) -> Result<(Vec<BoardBox>, Vec<u32>, TreeRounds)> {
    let mesh = &problem.mesh;
    let mut node_box = Vec::with_capacity(mesh.nodes.len());
    let mut early = [0usize; 3];
    let mut late = [0usize; 3];
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
            let span: [usize; 3] = core::array::from_fn(|a| hi[a] - lo[a]);
            let last = last_axis(span);
            for a in (0..3).filter(|&a| span[a] > 0) {
                if Some(a) == last {
                    early[a] = early[a].max(line_rounds(span[a]));
                } else {
                    early[a] = early[a].max(half_rounds(span[a]));
                    late[a] = late[a].max(half_rounds(span[a]));
                }
            }
        }
        node_owner[n] = els
            .iter()
            .map(|&e| element_board[e as usize])
            .min()
            .unwrap_or(0);
        node_box.push((lo, hi));
    }
    Ok((node_box, node_owner, TreeRounds { early, late }))
}

/// Puts node `n` (owned by board `owner`) on every board of its box and its summation tree
/// (with `roots`) into the rounds ([`for_node_transfers`]).
fn place_node(
    machine: Machine,
    boards: &mut [BoardPlan],
    trees: &LineTrees,
    early: [usize; 3],
    (n, owner): (u32, u32),
    (lo, hi): BoardBox,
    roots: Roots,
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
    for_node_transfers(
        trees,
        early,
        (lo, hi),
        roots,
        |a, from, to, round, combine| {
            // face index within the axis: 0 = +axis, 1 = −axis
            let (send_face, recv_face) = if to[a] > from[a] { (0, 1) } else { (1, 0) };
            boards[machine.index(from)].rounds[a][round].send[send_face].push(n);
            boards[machine.index(to)].rounds[a][round].recv[recv_face].push((n, combine));
        },
    );
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
