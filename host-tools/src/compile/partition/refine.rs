//! Refinement of a partition by single-element moves between boards (Fiduccia–Mattheyses
//! passes), minimising the force vectors the exchange rounds send under the balance bound.
//!
//! The objective is exact: the sum over exchanged nodes (held ones are not) of
//! [`box_vectors`] of the node's box of boards (what [`crate::compile::plan`] sends for
//! it), plus [`RELAY_PENALTY`] per board a node spans beyond two along an axis (relays cost
//! exchange rounds), plus a term in the square of each link's load ([`LINK_LOAD_SCALE`]:
//! the busiest link decides whether the exchange fits the step). A move takes an element to
//! a board that holds one of its face neighbours; it is refused when the target would hold
//! more than the balance bound allows, when the source would be left empty, or when it
//! would split the source board's elements (face-connected) into more pieces. Each pass
//! moves every element at most once, taking the best move available even when it costs
//! (so a pass can climb out of a local minimum), and keeps the best prefix of its moves.
//! Ties go to the lowest element and board: the result is deterministic.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::compile::trees::{box_vectors, default_roots, for_box_links};
use link_proto::Machine;

/// Objective units per board a node spans beyond two along an axis (a relay): more than
/// any move's gain in vectors, so relays are removed first and never added for vectors.
pub const RELAY_PENALTY: i64 = 64;

/// The links' term of the objective: each link direction's load `L` (vectors per step)
/// costs `L² / LINK_LOAD_SCALE`, so that of two partitions sending as many vectors, the
/// one with the busier links (whose time decides whether the exchange fits the step) costs
/// more: a vector moved from a link of load `L` to one of load `L' < L` gains about
/// `(L - L') / 16` vectors' worth. (Measured on 4x4x4: the seed box's busiest link 27
/// vectors against 31 without the term; `L²/64` and `L²/16` did worse.)
const LINK_LOAD_SCALE: i64 = 32;

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
    /// Whether each node's force is exchanged (a held node's is not: it costs nothing).
    pub exchanged: &'a [bool],
}

impl<'a> Adjacency<'a> {
    pub fn new(
        cells: &'a [[u32; 8]],
        around: &'a [Vec<u32>],
        exchanged: &'a [bool],
    ) -> Adjacency<'a> {
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
            exchanged,
        }
    }
}

/// A node's box of boards: the lowest and the highest board coordinates along each axis.
type Span = ([usize; 3], [usize; 3]);

fn span_of((lo, hi): Span) -> [usize; 3] {
    core::array::from_fn(|a| hi[a] - lo[a])
}

/// The objective of one node whose box of boards spans `span` (boards beyond the first per
/// axis).
pub fn node_cost(span: [usize; 3]) -> i64 {
    let relays: usize = span.iter().map(|&m| m.saturating_sub(1)).sum();
    box_vectors(span) as i64 + RELAY_PENALTY * relays as i64
}

struct State<'a> {
    adj: &'a Adjacency<'a>,
    machine: Machine,
    coords: Vec<[usize; 3]>,
    board: Vec<u32>,
    count: Vec<usize>,
    /// Each element's weight, each board's load (the sum of its elements' weights) and the
    /// most a board may carry.
    weight: &'a [u64],
    load: Vec<u64>,
    cap: u64,
    node_cost: Vec<i64>,
    /// Each node's box of boards (lowest and highest coordinates per axis).
    node_box: Vec<Span>,
    /// Force vectors each link carries per step and direction ([`State::link_index`]): the
    /// nodes whose box holds both its boards.
    link_load: Vec<i64>,
    /// Scratch of [`State::delta`]: (link, change in its load).
    link_change: std::cell::RefCell<Vec<(u32, i64)>>,
    /// Walk marks of [`State::reaches_all`] (the walk's number, per element).
    visited: Vec<u64>,
    visit_mark: u64,
    /// Marks of the elements sharing a node with the element [`State::removable`] looks at.
    near: Vec<u64>,
    near_mark: u64,
}

impl State<'_> {
    /// The node's box of boards with element `moved` on board `to` (or as it is, for
    /// `None`); a single board's (no exchange) for a node that is not exchanged.
    fn box_with(&self, n: u32, moved: Option<(u32, u32)>) -> Span {
        if !self.adj.exchanged[n as usize] {
            return ([0; 3], [0; 3]);
        }
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
        (lo, hi)
    }

    /// The link between board `c` and its neighbour one up along `axis`.
    fn link_index(&self, axis: usize, c: [usize; 3]) -> u32 {
        (axis * self.machine.count() + self.machine.index(c)) as u32
    }

    /// Calls `f` with every link a node of box `b` is sent over with its default roots
    /// (each way once per step; see [`box_vectors`]). The plan then chooses each node's
    /// roots to spread the loads ([`crate::compile::trees::choose_roots`]).
    fn for_links(&self, (lo, hi): Span, mut f: impl FnMut(u32)) {
        for_box_links(lo, hi, default_roots(lo, hi), |a, at| {
            f(self.link_index(a, at))
        });
    }

    /// What a link direction carrying `load` vectors per step costs ([`LINK_LOAD_SCALE`]).
    fn link_cost(load: i64) -> i64 {
        load * load / LINK_LOAD_SCALE
    }

    /// Objective change of moving element `e` to board `to`.
    fn delta(&self, e: u32, to: u32) -> i64 {
        let mut d = 0;
        let mut change = self.link_change.borrow_mut();
        change.clear();
        for &n in &self.adj.cells[e as usize] {
            let new = self.box_with(n, Some((e, to)));
            let old = self.node_box[n as usize];
            if new == old {
                continue;
            }
            d += node_cost(span_of(new)) - self.node_cost[n as usize];
            self.for_links(old, |l| change.push((l, -1)));
            self.for_links(new, |l| change.push((l, 1)));
        }
        if change.is_empty() {
            return d;
        }
        change.sort_unstable();
        let mut i = 0;
        while i < change.len() {
            let l = change[i].0;
            let mut by = 0;
            while i < change.len() && change[i].0 == l {
                by += change[i].1;
                i += 1;
            }
            let load = self.link_load[l as usize];
            d += Self::link_cost(load + by) - Self::link_cost(load);
        }
        d
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
            self.set_box(n as usize, self.box_with(n, None));
        }
    }

    /// Records node `n`'s box (its cost and the links it loads).
    fn set_box(&mut self, n: usize, b: Span) {
        let old = self.node_box[n];
        if old == b {
            return;
        }
        let mut load = std::mem::take(&mut self.link_load);
        self.for_links(old, |l| load[l as usize] -= 1);
        self.for_links(b, |l| load[l as usize] += 1);
        self.link_load = load;
        self.node_box[n] = b;
        self.node_cost[n] = node_cost(span_of(b));
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

    /// The objective: the nodes' costs and the links'.
    fn total(&self) -> i64 {
        self.node_cost.iter().sum::<i64>()
            + self
                .link_load
                .iter()
                .map(|&l| Self::link_cost(l))
                .sum::<i64>()
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
        machine,
        coords,
        board: std::mem::take(board),
        count,
        weight,
        load,
        cap,
        node_cost: vec![0; adj.around.len()],
        node_box: vec![([0; 3], [0; 3]); adj.around.len()],
        link_load: vec![0; 3 * machine.count()],
        link_change: Default::default(),
        visited: vec![0; adj.cells.len()],
        visit_mark: 0,
        near: vec![0; adj.cells.len()],
        near_mark: 0,
    };
    for n in 0..adj.around.len() {
        let b = s.box_with(n as u32, None);
        s.set_box(n, b);
    }
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
