//! Tissue against tissue: the node-to-surface forces over a check's candidates, each
//! slave's shallowest face winning.

use super::super::explicit::PhysicsError;
use super::super::vec3::scale;
use super::face::{
    clearly_outside, quad_penetration, shallower, FaceGeometry, FacePenetration, QuadBounds,
};
use super::search::{group_applies, group_len};
use super::{bad, Candidate, ContactModel, ContactStats, SURFACES_MAX, V3};

/// How the pair tests see the master faces at a step: each named face's state is refreshed
/// once per step ([`Self::refresh`]), then tested against many slaves
/// ([`Self::penetration`]). A board keeps the faces' bounds ([`FaceBounds`], 56 bytes a
/// face), the serial solver their geometry ([`FaceGeometries`], the normals too): both give
/// [`quad_penetration`]'s result, bit for bit.
pub trait FaceStates {
    /// Faces this holds a state for (a face beyond them is never refreshed).
    fn len(&self) -> usize;
    /// Whether it holds none.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The boxes a check's candidate search may write (its scratch: a board lends its
    /// bounds, which are refreshed after the search).
    fn search_boxes(&mut self) -> &mut [QuadBounds];
    /// Face `f`'s state at the positions `pos`.
    fn refresh(
        &mut self,
        m: &ContactModel<'_>,
        f: usize,
        pos: &impl Fn(usize) -> Option<V3>,
    ) -> Result<(), PhysicsError>;
    /// The penetration of a slave at `x` into face `f` (`None`: none, or a corner of the
    /// face is unknown).
    fn penetration(
        &self,
        m: &ContactModel<'_>,
        f: usize,
        x: V3,
        depth_max: f64,
        pos: &impl Fn(usize) -> Option<V3>,
    ) -> Result<Option<FacePenetration>, PhysicsError>;
}

/// Each master face's bounds at this state: `bounds[f]` is [`ContactModel::face_bounds`] of
/// face `f` (a face beyond them takes the full test). A candidate whose slave lies
/// [`clearly_outside`] its face's bounds is decided from them, without reading the face's
/// corners; the others take [`quad_penetration`], which makes the same test on the same
/// values first. So the result is the full test's, bit for bit, with 56 bytes per face (not
/// [`FaceGeometry`]'s 224). What it spares: on the built-in coarse scene a face is a
/// candidate of 4-5 slaves, most of them outside its bounds at a step, and reading a face's
/// four corners and bounding them for each was most of the pair tests' cost
/// (`scripts/contact-cost.sh` prints the stages). (Bounds rounded outward to f32, half the
/// bytes, cost 17 000 more instructions a step there than they spared, in the rounding:
/// measured.)
pub struct FaceBounds<'a>(pub &'a mut [QuadBounds]);

impl FaceStates for FaceBounds<'_> {
    fn len(&self) -> usize {
        self.0.len()
    }
    fn search_boxes(&mut self) -> &mut [QuadBounds] {
        self.0
    }
    #[inline(always)]
    fn refresh(
        &mut self,
        m: &ContactModel<'_>,
        f: usize,
        pos: &impl Fn(usize) -> Option<V3>,
    ) -> Result<(), PhysicsError> {
        if let Some(b) = self.0.get_mut(f) {
            *b = m.face_bounds(f, pos)?;
        }
        Ok(())
    }
    #[inline(always)]
    fn penetration(
        &self,
        m: &ContactModel<'_>,
        f: usize,
        x: V3,
        depth_max: f64,
        pos: &impl Fn(usize) -> Option<V3>,
    ) -> Result<Option<FacePenetration>, PhysicsError> {
        bounded_penetration(m, self.0, f, x, depth_max, pos)
    }
}

/// [`FaceBounds::penetration`] over bounds `bounds`.
#[inline(always)]
fn bounded_penetration(
    m: &ContactModel<'_>,
    bounds: &[QuadBounds],
    f: usize,
    x: V3,
    depth_max: f64,
    pos: &impl Fn(usize) -> Option<V3>,
) -> Result<Option<FacePenetration>, PhysicsError> {
    if bounds
        .get(f)
        .is_some_and(|b| clearly_outside(x, b, depth_max))
    {
        return Ok(None);
    }
    let mut q = [[0.0; 3]; 4];
    Ok(if m.face_points(f, pos, &mut q)? {
        quad_penetration(x, &q, depth_max)
    } else {
        None
    })
}

/// Each master face's geometry at this state: `geometry[f]` is [`FaceGeometry::new`] of
/// face `f`'s corner positions (`None` where one is unknown), for every face a candidate
/// names (a face beyond them is an index error). The same result as the full test, bit
/// for bit, with the corners and normals computed once per face instead of once per
/// candidate (a face is a candidate of about ten slaves). `search_boxes`: the candidate
/// search's scratch, one per face.
pub struct FaceGeometries<'a> {
    pub geometry: &'a mut [Option<FaceGeometry>],
    pub search_boxes: &'a mut [QuadBounds],
}

impl FaceStates for FaceGeometries<'_> {
    fn len(&self) -> usize {
        self.geometry.len()
    }
    fn search_boxes(&mut self) -> &mut [QuadBounds] {
        self.search_boxes
    }
    fn refresh(
        &mut self,
        m: &ContactModel<'_>,
        f: usize,
        pos: &impl Fn(usize) -> Option<V3>,
    ) -> Result<(), PhysicsError> {
        let g = m.face_geometry(f, pos)?;
        if let Some(slot) = self.geometry.get_mut(f) {
            *slot = g;
        }
        Ok(())
    }
    fn penetration(
        &self,
        _m: &ContactModel<'_>,
        f: usize,
        x: V3,
        depth_max: f64,
        _pos: &impl Fn(usize) -> Option<V3>,
    ) -> Result<Option<FacePenetration>, PhysicsError> {
        match self.geometry.get(f) {
            Some(g) => Ok(g.as_ref().and_then(|g| g.penetration(x, depth_max))),
            None => Err(bad(f)),
        }
    }
}

/// Node-to-surface forces over `candidates` (in [`super::search::build_candidates`]
/// order): for each slave, the winning face; `F = ½ k p n` on the slave and `−wᵢ F` on the
/// face's nodes, added to `force[c]` for the contact nodes with `apply(c)`. A slave or face
/// whose positions are unknown is skipped (the caller's search guarantees that those never
/// matter for the nodes it applies). `tolerance_m`: a penetration deeper than this on an
/// applied slave node is an error (the penalty is too soft for the load). Every face takes
/// the full test (the reference the faces' states are held to).
#[cfg(test)]
pub(super) fn evaluate_pairs(
    m: &ContactModel<'_>,
    candidates: &[Candidate],
    pos: impl Fn(usize) -> Option<V3>,
    apply: impl Fn(usize) -> bool,
    tolerance_m: f64,
    force: &mut [V3],
    stats: &mut ContactStats,
) -> Result<(), PhysicsError> {
    // No bounds held: every candidate takes the full test.
    evaluate_pairs_bounded(m, candidates, pos, &[], apply, tolerance_m, force, stats)
}

/// [`evaluate_pairs`] with the faces' bounds ([`FaceBounds`]).
#[cfg(test)]
#[allow(clippy::too_many_arguments)]
pub(super) fn evaluate_pairs_bounded(
    m: &ContactModel<'_>,
    candidates: &[Candidate],
    pos: impl Fn(usize) -> Option<V3>,
    bounds: &[QuadBounds],
    apply: impl Fn(usize) -> bool,
    tolerance_m: f64,
    force: &mut [V3],
    stats: &mut ContactStats,
) -> Result<(), PhysicsError> {
    let face_test = |f, x, depth_max| bounded_penetration(m, bounds, f, x, depth_max, &pos);
    evaluate_pairs_with(
        m,
        candidates,
        &pos,
        apply,
        tolerance_m,
        force,
        stats,
        face_test,
        false,
    )
}

/// [`evaluate_pairs_bounded`] over candidates that [`super::search::keep_applied_groups`]
/// kept for the same `apply` (what a step evaluates: [`super::step::contact_step`]).
#[cfg(test)]
#[allow(clippy::too_many_arguments)]
pub(super) fn evaluate_kept_pairs_bounded(
    m: &ContactModel<'_>,
    candidates: &[Candidate],
    pos: impl Fn(usize) -> Option<V3>,
    bounds: &[QuadBounds],
    apply: impl Fn(usize) -> bool,
    tolerance_m: f64,
    force: &mut [V3],
    stats: &mut ContactStats,
) -> Result<(), PhysicsError> {
    let face_test = |f, x, depth_max| bounded_penetration(m, bounds, f, x, depth_max, &pos);
    evaluate_pairs_with(
        m,
        candidates,
        &pos,
        apply,
        tolerance_m,
        force,
        stats,
        face_test,
        true,
    )
}

/// The node-to-surface forces over `candidates` (in [`super::search::build_candidates`]
/// order), with `face_test(f, x, depth_max)` the penetration of a slave at `x` into face
/// `f` (`Ok(None)`: none, or the face's position is unknown): for each slave, the winning
/// face; `F = ½ k p n` on the slave and `−wᵢ F` on the face's nodes, added to `force[c]`
/// for the contact nodes with `apply(c)`. A slave or face whose positions are unknown is
/// skipped (the caller's search guarantees that those never matter for the nodes it
/// applies). `tolerance_m`: a penetration deeper than this on an applied slave node is an
/// error (the penalty is too soft for the load). `kept`: the groups are
/// [`super::search::keep_applied_groups`]'s for the same `apply` (every group gives a node
/// with `apply` a force and its indices were checked there, so neither is tested again: a
/// board evaluates its kept list at every step until the next check; on a board of a
/// partition most slaves are not its own); otherwise a group none of whose nodes has
/// `apply` is skipped here. The same forces and statistics either way, bit for bit.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn evaluate_pairs_with(
    m: &ContactModel<'_>,
    candidates: &[Candidate],
    pos: &impl Fn(usize) -> Option<V3>,
    apply: impl Fn(usize) -> bool,
    tolerance_m: f64,
    force: &mut [V3],
    stats: &mut ContactStats,
    face_test: impl Fn(usize, V3, f64) -> Result<Option<FacePenetration>, PhysicsError>,
    kept: bool,
) -> Result<(), PhysicsError> {
    // The shallowest penetration so far of a slave at `x`, with face `c.face`'s.
    let closer = |best: &mut Option<(usize, FacePenetration)>,
                  c: &Candidate,
                  x: V3,
                  depth_max: f64|
     -> Result<(), PhysicsError> {
        if let Some(p) = face_test(c.face as usize, x, depth_max)? {
            if best.is_none_or(|(_, b)| shallower(p.depth_m, b.depth_m)) {
                *best = Some((c.face as usize, p));
            }
        }
        Ok(())
    };
    let mut i = 0;
    while i < candidates.len() {
        let (direction, slave) = (candidates[i].direction, candidates[i].slave);
        let s = slave as usize;
        let (_, _, depth_max) = m.roles(direction as usize).ok_or(bad(direction as usize))?;
        let node = m.nodes.get(s).ok_or(bad(s))?;
        let mut best: Option<(usize, FacePenetration)> = None;
        if kept {
            let Some(x) = pos(s) else {
                i += group_len(&candidates[i..]);
                continue;
            };
            // One pass: the group's end is found as its faces are tested.
            while let Some(c) = candidates.get(i) {
                if c.direction != direction || c.slave != slave {
                    break;
                }
                closer(&mut best, c, x, depth_max)?;
                i += 1;
            }
        } else {
            let j = i + group_len(&candidates[i..]);
            let group = &candidates[i..j];
            i = j;
            let Some(x) = pos(s) else { continue };
            // A group none of whose nodes gets a force here (another board's contact):
            // skipped before the penetration tests, with the same result (nothing added, no
            // statistic) and its indices still checked.
            if !group_applies(m, s, group, &apply)? {
                continue;
            }
            for c in group {
                closer(&mut best, c, x, depth_max)?;
            }
        }
        let Some((f, p)) = best else { continue };
        let face_nodes = m.faces[f].nodes;
        let applied_here = apply(s) || face_nodes.iter().any(|&c| apply(c as usize));
        if !applied_here {
            continue;
        }
        let mag = 0.5 * node.penalty_n_per_m * p.depth_m;
        let fs = scale(p.normal, mag);
        if apply(s) {
            if p.depth_m > tolerance_m {
                return Err(PhysicsError::Penetration {
                    node: node.global,
                    depth_m: p.depth_m,
                    tolerance_m,
                });
            }
            let t = force.get_mut(s).ok_or(bad(s))?;
            for k in 0..3 {
                t[k] += fs[k];
            }
        }
        let pair = (direction / 2) as usize;
        let mut sum = fs;
        for (w, &c) in p.weights.iter().zip(&face_nodes) {
            let fm = scale(fs, -w);
            for k in 0..3 {
                sum[k] += fm[k];
            }
            if apply(c as usize) {
                let t = force.get_mut(c as usize).ok_or(bad(c as usize))?;
                for k in 0..3 {
                    t[k] += fm[k];
                }
            }
        }
        stats.active += 1;
        stats.max_depth_m = stats.max_depth_m.max(p.depth_m);
        if pair < SURFACES_MAX {
            for k in 0..3 {
                stats.pair_sum_n[pair][k] += sum[k];
            }
            stats.pair_magnitude_n[pair] += 2.0 * mag;
        }
    }
    Ok(())
}
