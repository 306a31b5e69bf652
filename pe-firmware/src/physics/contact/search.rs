//! The candidate search of a check step: every slave node within a margin of a master
//! face's bounding box, and the groups of them that give a board's nodes a force.

use super::super::explicit::PhysicsError;
use super::face::QuadBounds;
use super::{bad, Candidate, ContactModel, V3};

/// Finds the candidates: for every pair, both directions, every slave node whose position
/// is known (ascending), every master face whose nodes are all known (ascending) and whose
/// bounding box, grown by `margin_m`, holds the node. A face that shares a node with the
/// slave is skipped. Writes them to `out` in that order; returns how many, or
/// `Err(needed)` if `out` is too small.
///
/// The search writes the grown boxes of the master surface's faces (those with every
/// corner known), one after another, to `boxes` (the caller's scratch: a board lends its
/// step's face bounds, which it computes again after the check; one shorter than the
/// master's faces is filled and searched a part of them at a time), then tests each slave
/// against them, so that a node-face test is a box test on contiguous boxes, and only
/// against the faces it could meet (not the other surfaces'). Each box keeps its face's
/// index in its `edge_slack` (a box test does not read it). Each face's corners and box are
/// computed once per direction, not once per slave. What it found is then sorted into that
/// order (a total order on distinct candidates, so the list does not depend on how the
/// search ran). Out of line: a check step's work, kept out of the code of every other
/// step's evaluation.
#[inline(never)]
pub(super) fn build_candidates(
    m: &ContactModel<'_>,
    pos: impl Fn(usize) -> Option<V3>,
    margin_m: f64,
    boxes: &mut [QuadBounds],
    out: &mut [Candidate],
) -> Result<usize, usize> {
    const EMPTY: QuadBounds = QuadBounds {
        lo: [f64::INFINITY; 3],
        hi: [f64::NEG_INFINITY; 3],
        edge_slack: 0.0,
    };
    let mut one = [EMPTY];
    let boxes = if boxes.is_empty() {
        &mut one[..]
    } else {
        boxes
    };
    let mut n = 0usize;
    let mut needed = 0usize;
    for direction in 0..2 * m.pairs.len() {
        let Some((slave, master, _)) = m.roles(direction) else {
            continue;
        };
        // The next face to look at for a box.
        let mut next = 0;
        while next < m.faces.len() {
            let mut filled = 0;
            while filled < boxes.len() && next < m.faces.len() {
                let f = next;
                next += 1;
                let mut q = [[0.0; 3]; 4];
                let known = m.faces.get(f).is_some_and(|face| face.surface == master)
                    && m.face_points(f, &pos, &mut q) == Ok(true);
                if !known {
                    continue;
                }
                // The face's bounds grown by the margin, once for all its slaves.
                let (mut lo, mut hi) = (q[0], q[0]);
                for p in &q[1..] {
                    QuadBounds::include(&mut lo, &mut hi, p);
                }
                if let Some(b) = boxes.get_mut(filled) {
                    *b = QuadBounds {
                        lo: core::array::from_fn(|i| lo[i] - margin_m),
                        hi: core::array::from_fn(|i| hi[i] + margin_m),
                        edge_slack: f as f64,
                    };
                    filled += 1;
                }
            }
            let boxes = &boxes[..filled];
            if boxes.is_empty() {
                continue;
            }
            for (s, node) in m.nodes.iter().enumerate() {
                if node.surfaces & (1 << slave) == 0 {
                    continue;
                }
                let Some(x) = pos(s) else { continue };
                for b in boxes {
                    let inside = (0..3).all(|i| x[i] >= b.lo[i] && x[i] <= b.hi[i]);
                    if !inside {
                        continue;
                    }
                    let f = b.edge_slack as usize;
                    let shares = m
                        .faces
                        .get(f)
                        .is_none_or(|face| face.nodes.contains(&(s as u32)));
                    if !shares {
                        needed += 1;
                        if let Some(c) = out.get_mut(n) {
                            *c = Candidate {
                                direction: direction as u16,
                                slave: s as u32,
                                face: f as u32,
                            };
                            n += 1;
                        }
                    }
                }
            }
        }
    }
    if needed > n {
        return Err(needed);
    }
    if let Some(found) = out.get_mut(..n) {
        found.sort_unstable_by_key(|c| (c.direction, c.slave, c.face));
    }
    Ok(n)
}

/// The node-face box tests [`build_candidates`] makes on `m` with every position known:
/// per direction, the slave surface's nodes times the master surface's faces. What the
/// compile report charges a check step for, at the measured cost of a test
/// ([`crate::profile::FirmwareCost::per_search_test`]).
pub fn search_tests(m: &ContactModel<'_>) -> usize {
    (0..2 * m.pairs.len())
        .filter_map(|direction| m.roles(direction))
        .map(|(slave, master, _)| {
            let slaves = m
                .nodes
                .iter()
                .filter(|n| n.surfaces & (1 << slave) != 0)
                .count();
            slaves * m.faces.iter().filter(|f| f.surface == master).count()
        })
        .sum()
}

/// How many candidates at the front of `candidates` form its first group (one slave in one
/// direction: [`build_candidates`] writes them together).
#[inline(always)]
pub(super) fn group_len(candidates: &[Candidate]) -> usize {
    let Some(first) = candidates.first() else {
        return 0;
    };
    candidates
        .iter()
        .take_while(|c| c.direction == first.direction && c.slave == first.slave)
        .count()
}

/// Whether the group of `slave` (its candidates `group`) gives a node with `apply` a force:
/// the slave or some node of some face has it. A face or node index out of the model's
/// tables is an error (checked unless the slave applies).
#[inline(always)]
pub(super) fn group_applies(
    m: &ContactModel<'_>,
    slave: usize,
    group: &[Candidate],
    apply: &impl Fn(usize) -> bool,
) -> Result<bool, PhysicsError> {
    if apply(slave) {
        return Ok(true);
    }
    let mut here = false;
    for c in group {
        let face = m.faces.get(c.face as usize).ok_or(bad(c.face as usize))?;
        for &n in &face.nodes {
            if n as usize >= m.nodes.len() {
                return Err(bad(n as usize));
            }
            here |= apply(n as usize);
        }
    }
    Ok(here)
}

/// Keeps, in order, the groups of `candidates` (a slave's run of faces in one direction, in
/// [`build_candidates`] order) that [`evaluate_pairs`] would not skip: those whose slave or
/// some node of some face has `apply`. Returns how many candidates are kept (at the front).
/// Done once at a check, it spares a board the skipped groups at every step until the next
/// check (on a board of a partition most groups are another board's); the forces and
/// statistics are the same. An index out of the model's tables is an error, as there.
pub(super) fn keep_applied_groups(
    m: &ContactModel<'_>,
    candidates: &mut [Candidate],
    apply: impl Fn(usize) -> bool,
) -> Result<usize, PhysicsError> {
    let (mut i, mut kept) = (0, 0);
    while i < candidates.len() {
        let j = i + group_len(&candidates[i..]);
        let slave = candidates[i].slave as usize;
        if group_applies(m, slave, &candidates[i..j], &apply)? {
            candidates.copy_within(i..j, kept);
            kept += j - i;
        }
        i = j;
    }
    Ok(kept)
}
