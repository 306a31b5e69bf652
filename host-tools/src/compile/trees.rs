//! The summation trees of the exchange: along which lines of boards a node is summed, the
//! transfers of each line's tree, and the root each line reduces to.
//!
//! A node held by a box of boards is reduced along x, then along y through the x roots,
//! and exchanged along z through both (its last axis runs the whole tree); the totals go
//! back along y, then x ([`for_box_lines`]). Every line of a box sends one vector each way
//! per link it crosses, whichever board is its root ([`box_vectors`]); the root decides
//! which lines of the later axes the node takes, so which links carry it. [`choose_roots`]
//! picks, per node, the roots that spread the links' loads.

use pe_firmware::image::Combine;

use link_proto::Machine;

/// One transfer of a node's value along an axis line: in `round`, from line position
/// `from` to `to` (adjacent), combined at the receiver by `combine`.
#[derive(Clone, Copy)]
pub(super) struct Transfer {
    pub round: usize,
    pub from: usize,
    pub to: usize,
    pub combine: Combine,
}

/// The board of a line of `m + 1` boards (positions 0..=m) that a node's summation tree
/// reduces to by default: the middle one (the low one of two).
pub fn line_root(m: usize) -> usize {
    m / 2
}

/// The roots a line of `m + 1` boards may reduce to in [`half_rounds`] rounds: the middle
/// board, or either middle one of an even count. Two boards sum `p0 + p1` whichever is the
/// root; four group the sum differently (`(p0 + p1) + (p2 + p3)` against
/// `((p0 + p1) + p2) + p3`), and every holder still ends with the root's bits.
pub fn root_choices(m: usize) -> core::ops::RangeInclusive<usize> {
    m / 2..=m.div_ceil(2)
}

/// A node's box of boards (low, high corner).
pub type BoardBox = ([usize; 3], [usize; 3]);

/// A node's root along each axis, as an offset from its box's low corner.
pub type Roots = [usize; 3];

/// The default roots ([`line_root`]) of a box of boards `lo..=hi`.
pub fn default_roots(lo: [usize; 3], hi: [usize; 3]) -> Roots {
    core::array::from_fn(|a| line_root(hi[a] - lo[a]))
}

/// Rounds the reduce half of a line's tree takes, and the broadcast half too, for any root
/// of [`root_choices`].
pub(super) fn half_rounds(m: usize) -> usize {
    m - line_root(m)
}

/// The reduce half of the summation tree of a line of `m + 1` boards: the left boards'
/// prefix sums `((p0 + p1) + …)` and the right ones' suffix sums go towards `root`, which
/// forms `(left + p_root) + right`. Rounds from 0.
fn line_reduce(m: usize, root: usize) -> Vec<Transfer> {
    let mut v: Vec<Transfer> = (0..root)
        .map(|i| Transfer {
            round: i,
            from: i,
            to: i + 1,
            combine: Combine::Before,
        })
        .collect();
    v.extend((root + 1..=m).map(|j| Transfer {
        round: m - j,
        from: j,
        to: j - 1,
        combine: Combine::After,
    }));
    v
}

/// The broadcast half: the root's total back along the line, replacing the partial sums.
/// Rounds from 0.
fn line_broadcast(m: usize, root: usize) -> Vec<Transfer> {
    let mut v: Vec<Transfer> = (1..=root)
        .map(|d| Transfer {
            round: d - 1,
            from: root - d + 1,
            to: root - d,
            combine: Combine::Replace,
        })
        .collect();
    v.extend((1..=m - root).map(|d| Transfer {
        round: d - 1,
        from: root + d - 1,
        to: root + d,
        combine: Combine::Replace,
    }));
    v
}

/// The whole summation tree of a line of `m + 1` boards, for a node's last axis.
/// Two boards: one symmetric exchange (`p0 + p1` on both, exact since `a + b = b + a`).
/// More: [`line_reduce`] to the default root, then [`line_broadcast`].
fn line_transfers(m: usize) -> Vec<Transfer> {
    if m == 1 {
        let t = |from, to, combine| Transfer {
            round: 0,
            from,
            to,
            combine,
        };
        return vec![t(0, 1, Combine::Before), t(1, 0, Combine::After)];
    }
    let root = line_root(m);
    let mut v = line_reduce(m, root);
    v.extend(line_broadcast(m, root).into_iter().map(|t| Transfer {
        round: t.round + half_rounds(m),
        ..t
    }));
    v
}

/// Rounds the whole tree of a line of `m + 1` boards needs.
pub fn line_rounds(m: usize) -> usize {
    match m {
        0 => 0,
        1 => 1,
        _ => 2 * half_rounds(m),
    }
}

/// Force vectors one node's tree sends along a line of `m + 1` boards: `m` towards the
/// root and `m` back (two boards: one each way).
pub fn line_vectors(m: usize) -> usize {
    2 * m
}

/// Force vectors per step of a node held by a box of boards spanning `span[a] + 1` boards
/// along each axis: the lines of [`for_box_lines`], axis `a` having
/// `(span[b] + 1)` lines for each later axis `b`:
/// `2 m_x (m_y + 1)(m_z + 1) + 2 m_y (m_z + 1) + 2 m_z`, whatever the roots.
pub fn box_vectors(span: [usize; 3]) -> usize {
    (0..3)
        .map(|a| line_vectors(span[a]) * (a + 1..3).map(|b| span[b] + 1).product::<usize>())
        .sum()
}

/// The last axis along which a box of boards spanning `span[a] + 1` boards per axis has
/// more than one board: the one whose tree runs whole ([`line_transfers`]); the earlier
/// axes reduce before it and broadcast after it.
pub(super) fn last_axis(span: [usize; 3]) -> Option<usize> {
    (0..3).rev().find(|&a| span[a] > 0)
}

/// Calls `f(axis, line)` for every line of boards along `axis` that a node held by the box
/// of boards `lo..=hi` is summed over (`line`: the line's board at `lo[axis]`), with its
/// roots `roots` (offsets from `lo`; [`default_roots`] or [`choose_roots`]). The node is
/// reduced axis by axis, x first: along every x line of its box; then along the y lines
/// through the x roots; then along the z line through the x and y roots. The last axis the
/// node spans runs its whole tree, which leaves the total on every board of its lines;
/// then the earlier axes' broadcasts, y then x, retrace their reductions. So an axis's
/// lines are those with the earlier axes at their roots and the later ones anywhere in the
/// box.
pub(super) fn for_box_lines(
    lo: [usize; 3],
    hi: [usize; 3],
    roots: Roots,
    mut f: impl FnMut(usize, [usize; 3]),
) {
    for a in 0..3 {
        if hi[a] == lo[a] {
            continue;
        }
        let mut l = lo;
        let mut h = hi;
        for b in 0..a {
            l[b] = lo[b] + roots[b];
            h[b] = l[b];
        }
        l[a] = lo[a];
        h[a] = lo[a];
        for z in l[2]..=h[2] {
            for y in l[1]..=h[1] {
                for x in l[0]..=h[0] {
                    f(a, [x, y, z]);
                }
            }
        }
    }
}

/// Calls `f(axis, board)` for every link a node of box `lo..=hi` with roots `roots` is sent
/// over, once per link (one vector each way): the link between `board` and its neighbour
/// one up along `axis`.
pub fn for_box_links(
    lo: [usize; 3],
    hi: [usize; 3],
    roots: Roots,
    mut f: impl FnMut(usize, [usize; 3]),
) {
    for_box_lines(lo, hi, roots, |a, start| {
        let mut at = start;
        for i in lo[a]..hi[a] {
            at[a] = i;
            f(a, at);
        }
    });
}

/// The trees of lines of `m + 1` boards, indexed by `m` (built once per plan): the whole
/// tree ([`line_transfers`]) and, per root of [`root_choices`] (from `m / 2`), its two
/// halves ([`line_reduce`], [`line_broadcast`]).
pub(super) struct LineTrees {
    pub whole: Vec<Vec<Transfer>>,
    reduce: Vec<[Vec<Transfer>; 2]>,
    broadcast: Vec<[Vec<Transfer>; 2]>,
}

impl LineTrees {
    /// Lines of up to `boards` boards.
    pub(super) fn new(boards: usize) -> LineTrees {
        let halves = |half: fn(usize, usize) -> Vec<Transfer>| {
            (0..boards)
                .map(|m| [half(m, m / 2), half(m, m.div_ceil(2))])
                .collect()
        };
        LineTrees {
            whole: (0..boards).map(line_transfers).collect(),
            reduce: halves(line_reduce),
            broadcast: halves(line_broadcast),
        }
    }

    /// The reduce half of a line of `m + 1` boards to `root` (one of [`root_choices`]).
    pub fn reduce(&self, m: usize, root: usize) -> &[Transfer] {
        &self.reduce[m][root - m / 2]
    }

    /// The broadcast half from `root`.
    pub fn broadcast(&self, m: usize, root: usize) -> &[Transfer] {
        &self.broadcast[m][root - m / 2]
    }
}

/// Calls `f(axis, from, to, round, combine)` for every transfer of the summation tree of a
/// node held by the box of boards `lo..=hi` with roots `roots`: along each line of
/// [`for_box_lines`], the whole tree on the node's last axis, else the reduce half in the
/// axis's first rounds and the broadcast half after the `early[a]` rounds (so after the z
/// exchange). Round 0 of an axis holds the transfers that wait for no other board: the
/// first round of a node's first axis. The program sends it as soon as the axis's batch is
/// done, before the earlier axes' frames are received; the tree's round `r` is round
/// `r + 1` otherwise.
pub(super) fn for_node_transfers(
    trees: &LineTrees,
    early: [usize; 3],
    (lo, hi): BoardBox,
    roots: Roots,
    mut f: impl FnMut(usize, [usize; 3], [usize; 3], usize, Combine),
) {
    let span: [usize; 3] = core::array::from_fn(|a| hi[a] - lo[a]);
    let last = last_axis(span);
    let first = (0..3).find(|&a| span[a] > 0);
    let early_round = |a: usize, r: usize| if r == 0 && Some(a) == first { 0 } else { r + 1 };
    for_box_lines(lo, hi, roots, |a, start| {
        let m = span[a];
        let at = |t: usize| {
            let mut c = start;
            c[a] = lo[a] + t;
            c
        };
        let mut put = |round: usize, t: &Transfer| f(a, at(t.from), at(t.to), round, t.combine);
        if Some(a) == last {
            for t in &trees.whole[m] {
                put(early_round(a, t.round), t);
            }
        } else {
            for t in trees.reduce(m, roots[a]) {
                put(early_round(a, t.round), t);
            }
            for t in trees.broadcast(m, roots[a]) {
                put(early[a] + t.round, t);
            }
        }
    });
}

/// Passes of [`choose_roots`] at most; a pass that changes no root ends it earlier.
const ROOT_PASSES_MAX: usize = 8;

/// The roots of every node's tree (`node_box`: each node's box of boards; only the nodes
/// `exchanged` marks are sent), chosen among [`root_choices`] on the axes before a node's
/// last so that no link, and no round's frame, carries much more than the others. The
/// loads: each link's vectors per step (one each way per line crossing it), and each link
/// direction's vectors in each round (the frame a round sends: the step model waits for
/// it). Starting from [`default_roots`], each pass takes every node in turn and gives it
/// the roots that least increase `Σ L²` over both kinds of load; ties keep the current
/// roots, then take the first in x-fastest order. The total vectors do not change
/// ([`box_vectors`]), nor do the rounds; every holder of a node still ends with the same
/// bits.
///
/// Measured on 4x4x4, the step model's step (`pe compile`'s report) against the default
/// roots: the seed box 278.1 -> 220.5 us in f32 and 487.0 -> 372.4 us in f64. Against the
/// links' loads alone (the frames' loads alone): 260.4 (228.1) us and 463.7 (387.2) us; the
/// built-in medium scene 636.6 (668.1) us against 652.8 us here, `scenes/liver.toml`
/// 658.2 (533.6) against 556.6 us. Counting each direction's frames in the cost, at the PE
/// board's figures, left every node at its default roots: the first node to move always
/// opens a frame.
pub(super) fn choose_roots(
    machine: Machine,
    trees: &LineTrees,
    early: [usize; 3],
    node_box: &[BoardBox],
    exchanged: &[bool],
) -> Vec<Roots> {
    let count = machine.count();
    // Rounds per axis: the first ones, then the broadcasts (at most half a line's).
    let rounds_max = early.iter().max().copied().unwrap_or(0)
        + machine.dims().iter().max().copied().unwrap_or(1);
    // The loads a node with roots `r` adds to: its links (`3 * count` of them), then its
    // transfers' directions (+axis, −axis of each link) and rounds.
    let keys = |b: BoardBox, r: Roots, out: &mut Vec<usize>| {
        out.clear();
        for_box_links(b.0, b.1, r, |a, c| out.push(a * count + machine.index(c)));
        for_node_transfers(trees, early, b, r, |a, from, to, round, _| {
            let low = if to[a] > from[a] { from } else { to };
            let d = 2 * (a * count + machine.index(low)) + usize::from(to[a] < from[a]);
            out.push(3 * count + d * rounds_max + round);
        });
    };
    let mut roots: Vec<Roots> = node_box
        .iter()
        .map(|&(lo, hi)| default_roots(lo, hi))
        .collect();
    let mut load = vec![0i64; 3 * count + 6 * count * rounds_max];
    let shift = |load: &mut [i64], k: &[usize], by: i64| k.iter().for_each(|&i| load[i] += by);
    let mut k = Vec::new();
    for (n, &b) in node_box.iter().enumerate() {
        if exchanged[n] {
            keys(b, roots[n], &mut k);
            shift(&mut load, &k, 1);
        }
    }
    // The roots each node may take: the choices of its axes before its last.
    let options: Vec<(usize, Vec<Roots>)> = node_box
        .iter()
        .enumerate()
        .filter(|&(n, _)| exchanged[n])
        .filter_map(|(n, &(lo, hi))| {
            let span: [usize; 3] = core::array::from_fn(|a| hi[a] - lo[a]);
            let last = last_axis(span)?;
            let mut all = vec![[0usize; 3]];
            for a in 0..last {
                all = all
                    .into_iter()
                    .flat_map(|r| {
                        root_choices(span[a]).map(move |c| {
                            let mut r = r;
                            r[a] = c;
                            r
                        })
                    })
                    .collect();
            }
            (all.len() > 1).then_some((n, all))
        })
        .collect();
    for _ in 0..ROOT_PASSES_MAX {
        let mut changed = false;
        for (n, all) in &options {
            let b = node_box[*n];
            keys(b, roots[*n], &mut k);
            shift(&mut load, &k, -1);
            let mut cost = |r: Roots| {
                keys(b, r, &mut k);
                k.iter().map(|&i| 2 * load[i] + 1).sum::<i64>()
            };
            let mut best = (cost(roots[*n]), roots[*n]);
            for &r in all {
                let c = cost(r);
                if c < best.0 {
                    best = (c, r);
                }
            }
            changed |= best.1 != roots[*n];
            roots[*n] = best.1;
            keys(b, roots[*n], &mut k);
            shift(&mut load, &k, 1);
        }
        if !changed {
            break;
        }
    }
    roots
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Nodes all held by the same 2x2 block of boards (x and y): with the default roots
    /// every one is exchanged along y through the x = 0 column; the chosen roots send half
    /// of them through each column's y link, the least `Σ L²`.
    #[test]
    fn chosen_roots_spread_a_block_over_both_columns() {
        let machine = Machine::parse("2x2x1").expect("machine");
        let nodes = 10;
        let boxes = vec![([0, 0, 0], [1, 1, 0]); nodes];
        let loads = |roots: &[Roots]| {
            let mut load = vec![0usize; 3 * machine.count()];
            for (r, &(lo, hi)) in roots.iter().zip(&boxes) {
                for_box_links(lo, hi, *r, |a, c| {
                    load[a * machine.count() + machine.index(c)] += 1
                });
            }
            load
        };
        let default: Vec<Roots> = boxes
            .iter()
            .map(|&(lo, hi)| default_roots(lo, hi))
            .collect();
        // x: reduce (rounds 0, 1) and broadcast (round 2); y: the whole tree.
        let (trees, early) = (LineTrees::new(2), [2, 2, 0]);
        let chosen = choose_roots(machine, &trees, early, &boxes, &vec![true; nodes]);
        assert_eq!(chosen.len(), nodes);
        let (before, after) = (loads(&default), loads(&chosen));
        assert_eq!(before.len(), after.len());
        // y links: the one at x = 0 and the one at x = 1 (index 4 + board).
        assert_eq!((before[4], before[5]), (nodes, 0), "{before:?}");
        assert_eq!((after[4], after[5]), (nodes / 2, nodes / 2), "{after:?}");
        // Both x links carry every node either way, and the totals agree.
        assert_eq!((after[0], after[2]), (nodes, nodes));
        assert_eq!(before.iter().sum::<usize>(), after.iter().sum::<usize>());
        // A node not exchanged keeps its default roots and loads nothing.
        let held = choose_roots(machine, &trees, early, &boxes, &vec![false; nodes]);
        assert_eq!(held, default);
    }

    /// The vector count the partitioner minimises is what the summation trees send, for
    /// every root a line may take.
    #[test]
    fn line_vectors_counts_the_trees_transfers() {
        let trees = LineTrees::new(16);
        for m in 0..16 {
            assert_eq!(
                line_transfers(m).len(),
                line_vectors(m),
                "line of {} boards",
                m + 1
            );
            for root in root_choices(m) {
                let (r, b) = (trees.reduce(m, root), trees.broadcast(m, root));
                assert_eq!(
                    r.len() + b.len(),
                    line_vectors(m),
                    "line of {} boards, root {root}",
                    m + 1
                );
                let rounds = r.iter().chain(b).map(|t| t.round + 1).max().unwrap_or(0);
                assert!(
                    rounds <= half_rounds(m),
                    "line of {} boards, root {root}: {rounds} rounds",
                    m + 1
                );
            }
        }
    }
}
