//! Refinement of a partition by single-element moves between boards (Fiduccia–Mattheyses
//! passes), minimising the force vectors the exchange rounds send under the balance bound.
//!
//! The objective is exact: the sum over nodes of [`box_vectors`] of the node's box of boards
//! (what [`crate::compile::plan`] sends for it), plus [`RELAY_PENALTY`] per board a node
//! spans beyond two along an axis (relays cost exchange rounds). A move takes an element to
//! a board that holds one of its face neighbours; it is refused when the target would hold
//! more than the balance bound allows, when the source would be left empty, or when it
//! would split the source board's elements (face-connected) into more pieces. Each pass
//! moves every element at most once, taking the best move available even when it costs
//! (so a pass can climb out of a local minimum), and keeps the best prefix of its moves.
//! Ties go to the lowest element and board: the result is deterministic.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::Machine;
use crate::compile::plan::box_vectors;

/// Objective units per board a node spans beyond two along an axis (a relay): more than
/// any move's gain in vectors, so relays are removed first and never added for vectors.
pub const RELAY_PENALTY: i64 = 64;

/// The annealing's seed (printed in the compile report).
pub const ANNEAL_SEED: u64 = 1;

/// Moves the annealing tries per element, and at most in all (meshes of over 4000
/// elements get fewer per element).
const ANNEAL_TRIES_PER_ELEMENT: usize = 3000;
const ANNEAL_TRIES_MAX: usize = 12_000_000;

/// The annealing's starting temperature, in force vectors.
const ANNEAL_T0: f64 = 20.0;

/// Elements the connectivity test of a move walks at most.
const WALK_MAX: usize = 96;

/// Passes at most; a pass that gains nothing ends the refinement earlier.
const PASSES_MAX: usize = 40;

/// Moves a pass makes past its best prefix before giving up on the pass.
const UNPRODUCTIVE_MOVES_MAX: usize = 400;

/// The mesh's adjacency the refinement walks.
pub struct Adjacency<'a> {
    pub cells: &'a [[u32; 8]],
    /// Elements around each node.
    pub around: &'a [Vec<u32>],
    /// Elements sharing a face (four nodes) with each element.
    pub faces: Vec<Vec<u32>>,
}

impl<'a> Adjacency<'a> {
    pub fn new(cells: &'a [[u32; 8]], around: &'a [Vec<u32>]) -> Adjacency<'a> {
        let faces = cells
            .iter()
            .enumerate()
            .map(|(e, c)| {
                let mut shared: Vec<u32> = c
                    .iter()
                    .flat_map(|&n| around[n as usize].iter().copied())
                    .filter(|&o| o as usize != e)
                    .collect();
                shared.sort_unstable();
                let mut out = Vec::new();
                let mut i = 0;
                while i < shared.len() {
                    let j = shared[i..].iter().take_while(|&&o| o == shared[i]).count();
                    if j >= 4 {
                        out.push(shared[i]);
                    }
                    i += j;
                }
                out
            })
            .collect();
        Adjacency {
            cells,
            around,
            faces,
        }
    }
}

/// The objective of one node whose box of boards spans `span` (boards beyond the first per
/// axis).
pub fn node_cost(span: [usize; 3]) -> i64 {
    let relays: usize = span.iter().map(|&m| m.saturating_sub(1)).sum();
    box_vectors(span) as i64 + RELAY_PENALTY * relays as i64
}

struct State<'a> {
    adj: &'a Adjacency<'a>,
    coords: Vec<[usize; 3]>,
    board: Vec<u32>,
    count: Vec<usize>,
    /// Each element's weight, each board's load (the sum of its elements' weights) and the
    /// most a board may carry.
    weight: &'a [u64],
    load: Vec<u64>,
    cap: u64,
    node_cost: Vec<i64>,
    /// Walk marks of [`State::reaches_all`] (the walk's number, per element).
    visited: Vec<u64>,
    visit_mark: u64,
    /// Marks of the elements sharing a node with the element [`State::removable`] looks at.
    near: Vec<u64>,
    near_mark: u64,
}

impl State<'_> {
    /// The node's cost with element `moved` on board `to` (or as it is, for `None`).
    fn cost_with(&self, n: u32, moved: Option<(u32, u32)>) -> i64 {
        let mut lo = [usize::MAX; 3];
        let mut hi = [0; 3];
        for &e in &self.adj.around[n as usize] {
            let b = match moved {
                Some((m, to)) if m == e => to,
                _ => self.board[e as usize],
            };
            let c = self.coords[b as usize];
            for a in 0..3 {
                lo[a] = lo[a].min(c[a]);
                hi[a] = hi[a].max(c[a]);
            }
        }
        node_cost(core::array::from_fn(|a| hi[a] - lo[a]))
    }

    /// Objective change of moving element `e` to board `to`.
    fn delta(&self, e: u32, to: u32) -> i64 {
        self.adj.cells[e as usize]
            .iter()
            .map(|&n| self.cost_with(n, Some((e, to))) - self.node_cost[n as usize])
            .sum()
    }

    fn apply(&mut self, e: u32, to: u32) {
        let from = self.board[e as usize];
        self.count[from as usize] -= 1;
        self.count[to as usize] += 1;
        let w = self.weight[e as usize];
        self.load[from as usize] -= w;
        self.load[to as usize] += w;
        self.board[e as usize] = to;
        for &n in &self.adj.cells[e as usize] {
            self.node_cost[n as usize] = self.cost_with(n, None);
        }
    }

    /// Boards of `e`'s face neighbours other than its own, ascending.
    fn targets(&self, e: u32) -> Vec<u32> {
        let own = self.board[e as usize];
        let mut t: Vec<u32> = self.adj.faces[e as usize]
            .iter()
            .map(|&o| self.board[o as usize])
            .filter(|&b| b != own)
            .collect();
        t.sort_unstable();
        t.dedup();
        t
    }

    /// Whether taking `e` off its board keeps the board's other pieces as connected as they
    /// were: `e`'s face neighbours on the board still reach each other without `e`, looked
    /// for among the elements sharing a node with `e` first, then over at most
    /// [`WALK_MAX`] elements of the board (a move that needs a longer way round is refused).
    fn removable(&mut self, e: u32) -> bool {
        let b = self.board[e as usize];
        let same: Vec<u32> = self.adj.faces[e as usize]
            .iter()
            .copied()
            .filter(|&o| self.board[o as usize] == b)
            .collect();
        if same.len() <= 1 {
            return true;
        }
        self.near_mark += 1;
        for &n in &self.adj.cells[e as usize] {
            for &o in &self.adj.around[n as usize] {
                self.near[o as usize] = self.near_mark;
            }
        }
        self.reaches_all(e, &same, true) || self.reaches_all(e, &same, false)
    }

    /// Whether a walk over face neighbours on `e`'s board, avoiding `e` (and, if `local`,
    /// staying among the elements marked near it), gets from `same[0]` to every element of
    /// `same`.
    fn reaches_all(&mut self, e: u32, same: &[u32], local: bool) -> bool {
        let b = self.board[e as usize];
        self.visit_mark += 1;
        let mark = self.visit_mark;
        self.visited[same[0] as usize] = mark;
        let mut stack = vec![same[0]];
        let mut left = same.len() - 1;
        let mut walked = 0;
        while let Some(x) = stack.pop() {
            walked += 1;
            if walked > WALK_MAX {
                return false;
            }
            for &o in &self.adj.faces[x as usize] {
                let ou = o as usize;
                if o == e
                    || self.board[ou] != b
                    || self.visited[ou] == mark
                    || (local && self.near[ou] != self.near_mark)
                {
                    continue;
                }
                self.visited[ou] = mark;
                if same.contains(&o) {
                    left -= 1;
                    if left == 0 {
                        return true;
                    }
                }
                stack.push(o);
            }
        }
        false
    }

    fn allowed(&mut self, e: u32, to: u32) -> bool {
        let from = self.board[e as usize] as usize;
        self.fits(e, to) && self.count[from] > 1 && self.removable(e)
    }

    /// Board `to` can take element `e` within the cap.
    fn fits(&self, e: u32, to: u32) -> bool {
        self.load[to as usize] + self.weight[e as usize] <= self.cap
    }

    fn total(&self) -> i64 {
        self.node_cost.iter().sum()
    }
}

/// The annealing's random numbers: xorshift64* from [`ANNEAL_SEED`] (the same moves on
/// every machine; acceptance is decided in integers against [`libm::exp`] tables).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in `0..n` (n > 0; the modulo bias is irrelevant here).
    fn below(&mut self, n: usize) -> usize {
        (self.next() >> 32) as usize % n
    }
}

/// Simulated annealing by single-element moves to a face neighbour's board: a move that
/// costs `d > 0` is taken with probability `exp(-d / T)`, `T` falling linearly from
/// [`ANNEAL_T0`] to zero over the moves tried.
fn anneal(s: &mut State, tries: usize) {
    let n = s.board.len();
    const STAGES: usize = 64;
    // Acceptance thresholds (of 2^32) per stage and cost 1..=D_MAX; dearer moves never.
    const D_MAX: usize = 48;
    let tables: Vec<[u64; D_MAX + 1]> = (0..STAGES)
        .map(|k| {
            let t = ANNEAL_T0 * (STAGES - k) as f64 / STAGES as f64;
            core::array::from_fn(|d| (libm::exp(-(d as f64) / t) * 4_294_967_296.0) as u64)
        })
        .collect();
    let mut rng = Rng(ANNEAL_SEED);
    for i in 0..tries {
        let table = &tables[i * STAGES / tries];
        let e = rng.below(n) as u32;
        let faces = &s.adj.faces[e as usize];
        if faces.is_empty() {
            continue;
        }
        let to = s.board[faces[rng.below(faces.len())] as usize];
        let from = s.board[e as usize];
        if to == from || !s.fits(e, to) || s.count[from as usize] <= 1 {
            continue;
        }
        let d = s.delta(e, to);
        let take = d <= 0 || (d as usize <= D_MAX && (rng.next() >> 32) < table[d as usize]);
        if take && s.removable(e) {
            s.apply(e, to);
        }
    }
}

/// One candidate move in the heap: smallest delta first, then lowest element and board.
type Candidate = Reverse<(i64, u32, u32, u32)>;

/// One Fiduccia–Mattheyses pass; returns the objective gained (kept moves only).
fn pass(s: &mut State) -> i64 {
    let n = s.board.len();
    let mut locked = vec![false; n];
    let mut stamp = vec![0u32; n];
    let mut heap: BinaryHeap<Candidate> = BinaryHeap::new();
    let push = |s: &State, heap: &mut BinaryHeap<Candidate>, e: u32, st: u32| {
        for t in s.targets(e) {
            heap.push(Reverse((s.delta(e, t), e, t, st)));
        }
    };
    for e in 0..n as u32 {
        push(s, &mut heap, e, 0);
    }
    let mut moves: Vec<(u32, u32)> = Vec::new();
    let (mut cum, mut best, mut best_len) = (0i64, 0i64, 0usize);
    while let Some(Reverse((d, e, t, st))) = heap.pop() {
        let eu = e as usize;
        if locked[eu] || st != stamp[eu] || s.board[eu] == t || !s.allowed(e, t) {
            continue;
        }
        // The heap's delta is current: every move re-stamps its neighbours' entries.
        let from = s.board[eu];
        s.apply(e, t);
        locked[eu] = true;
        moves.push((e, from));
        cum += d;
        if cum < best {
            best = cum;
            best_len = moves.len();
        } else if moves.len() - best_len > UNPRODUCTIVE_MOVES_MAX {
            break;
        }
        let mut near: Vec<u32> = s.adj.cells[eu]
            .iter()
            .flat_map(|&m| s.adj.around[m as usize].iter().copied())
            .filter(|&o| !locked[o as usize])
            .collect();
        near.sort_unstable();
        near.dedup();
        for o in near {
            stamp[o as usize] += 1;
            push(s, &mut heap, o, stamp[o as usize]);
        }
    }
    for &(e, from) in moves[best_len..].iter().rev() {
        s.apply(e, from);
    }
    -best
}

/// Refines `board` (element → board) in place; `weight` is each element's weight and `cap`
/// the most a board's elements may weigh together (the initial partition must respect
/// it). Returns the objective before and after.
pub fn refine(
    adj: &Adjacency,
    machine: Machine,
    board: &mut Vec<u32>,
    weight: &[u64],
    cap: u64,
) -> (i64, i64) {
    let coords = (0..machine.count()).map(|b| machine.coords(b)).collect();
    let mut count = vec![0; machine.count()];
    let mut load = vec![0; machine.count()];
    for (&b, &w) in board.iter().zip(weight) {
        count[b as usize] += 1;
        load[b as usize] += w;
    }
    let mut s = State {
        adj,
        coords,
        board: std::mem::take(board),
        count,
        weight,
        load,
        cap,
        node_cost: Vec::new(),
        visited: vec![0; adj.cells.len()],
        visit_mark: 0,
        near: vec![0; adj.cells.len()],
        near_mark: 0,
    };
    s.node_cost = (0..adj.around.len() as u32)
        .map(|n| s.cost_with(n, None))
        .collect();
    let before = s.total();
    let tries = (ANNEAL_TRIES_PER_ELEMENT * s.board.len()).min(ANNEAL_TRIES_MAX);
    anneal(&mut s, tries);
    for _ in 0..PASSES_MAX {
        if pass(&mut s) <= 0 {
            break;
        }
    }
    let after = s.total();
    *board = s.board;
    (before, after)
}
