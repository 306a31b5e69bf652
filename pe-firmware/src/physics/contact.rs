//! Penalty contact, shared by the serial solver and the board runtime.
//!
//! Two kinds, both frictionless:
//!
//! - **Rigid tools** (a capsule: the points within `radius_m` of a segment `a–b`) against
//!   the nodes of a declared tissue surface. A node at `x` inside the capsule by depth
//!   `p = r − |x − c(x)|` (`c(x)` the closest point of the axis) gets `f = k p n`,
//!   `n = (x − c)/|x − c|`; the tool takes `−f` (what a haptic device renders).
//! - **Tissue against tissue**, node to surface as in Székely et al.: the nodes of one
//!   surface (slave) against the faces of the other (master), then the roles flipped, each
//!   direction with half the penalty ("flipped and averaged"). A slave node below a master
//!   triangle's plane by `0 < p ≤ depth_max`, with its projection inside the triangle
//!   (or outside an edge by at most [`EDGE_TOLERANCE`], so a node on the rim of two equal
//!   bodies cannot slip between faces), penetrates it; of all the triangles it penetrates,
//!   the shallowest wins (depths within [`DEPTH_TIE_M`] are a tie, won by the lowest face
//!   index), so the answer depends neither on search order nor on round-off. The slave takes
//!   `F = ½ k p n` and the triangle's nodes `−wᵢ F` (barycentric `wᵢ`, `Σ wᵢ = 1`): each
//!   contact's forces sum to zero to round-off.
//!
//! `k` is the slave node's penalty stiffness, `β m / Δt²` (`m` its inertial mass): the
//! contact spring raises `(ω Δt)²` by at most `β`, so the explicit step stays stable.
//!
//! Everything is `f64` (positions `x = X + u`), whatever the element scalar. The search is
//! split: [`build_candidates`] every check interval (slave nodes within a margin of a
//! face's bounding box), [`evaluate_pairs`] every step over the candidates. As long as no
//! node moves farther than the margin allows between checks (checked every step by
//! [`check_travel`]), the candidates contain every contact, so the result is independent
//! of the search, of the partition and of the board the sum runs on. Forces are applied
//! only to nodes the caller accepts (`apply`): a board applies them to the nodes it owns,
//! in the same order as the serial solver, so both get the same bits.
//!
//! Nothing here panics: indices are checked and problems come back as [`PhysicsError`].

use serde::{Deserialize, Serialize};

use super::explicit::PhysicsError;

pub type V3 = [f64; 3];

/// Most declared contact surfaces (bits of [`ContactNode::surfaces`]).
pub const SURFACES_MAX: usize = 8;

#[inline]
fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline]
fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// A rigid capsule: every point within `radius_m` of the segment `a–b` (m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Capsule {
    pub a: V3,
    pub b: V3,
    pub radius_m: f64,
}

impl Capsule {
    /// The capsule moved by `d`.
    pub fn translated(&self, d: V3) -> Capsule {
        Capsule {
            a: [self.a[0] + d[0], self.a[1] + d[1], self.a[2] + d[2]],
            b: [self.b[0] + d[0], self.b[1] + d[1], self.b[2] + d[2]],
            radius_m: self.radius_m,
        }
    }

    /// The point of the axis segment closest to `x`: `a + t (b − a)`, `t` clamped to [0, 1].
    pub fn closest_axis_point(&self, x: V3) -> V3 {
        let ab = sub(self.b, self.a);
        let l2 = dot(ab, ab);
        let t = if l2 > 0.0 {
            (dot(sub(x, self.a), ab) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        [
            self.a[0] + t * ab[0],
            self.a[1] + t * ab[1],
            self.a[2] + t * ab[2],
        ]
    }

    /// Depth `p = r − |x − c| > 0` of a point inside the capsule and the outward unit
    /// normal; `None` outside (or on the surface). A point exactly on the axis is pushed
    /// out perpendicular to the axis, along the coordinate direction the axis leans on least.
    pub fn penetration(&self, x: V3) -> Option<(f64, V3)> {
        let c = self.closest_axis_point(x);
        let d = sub(x, c);
        let dist = libm::sqrt(dot(d, d));
        let depth = self.radius_m - dist;
        if !(depth > 0.0) {
            return None;
        }
        let n = if dist > 1e-300 {
            scale(d, 1.0 / dist)
        } else {
            let ab = sub(self.b, self.a);
            let k = (0..3)
                .min_by(|&i, &j| libm::fabs(ab[i]).total_cmp(&libm::fabs(ab[j])))
                .unwrap_or(0);
            let mut e = [0.0; 3];
            e[k] = 1.0;
            let p = cross(ab, e);
            let l = libm::sqrt(dot(p, p));
            if l > 0.0 {
                scale(p, 1.0 / l)
            } else {
                [0.0, 0.0, 1.0]
            }
        };
        Some((depth, n))
    }

    /// Axis-aligned bounding box.
    pub fn bounds(&self) -> [V3; 2] {
        let r = self.radius_m;
        [
            core::array::from_fn(|i| self.a[i].min(self.b[i]) - r),
            core::array::from_fn(|i| self.a[i].max(self.b[i]) + r),
        ]
    }
}

/// A slave node's penetration into a master face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FacePenetration {
    /// Depth below the face (m), `> 0`.
    pub depth_m: f64,
    /// Outward unit normal of the master triangle.
    pub normal: V3,
    /// Barycentric weights on the quad's four nodes (one is zero), summing to 1.
    pub weights: [f64; 4],
}

/// How far outside a master triangle (in barycentric weight) a slave's projection may
/// fall and still count: a node on the rim of a body pressed against an equal one lies on
/// the master's edge, and round-off must not let it slip through.
pub const EDGE_TOLERANCE: f64 = 0.02;

/// Depths closer than this are a tie, won by the first face (or triangle) in table order.
/// A node over a vertex or an edge shared by faces tilted alike is at exactly equal depths
/// in exact arithmetic; which one wins must not depend on the round-off of the position
/// (which differs between the serial run and boards that sum forces in another order),
/// because the faces' normals differ. A picometre is five orders above that round-off and
/// six below any penetration that matters.
pub const DEPTH_TIE_M: f64 = 1e-12;

/// Whether depth `d` beats the best so far, `best`: shallower by more than a tie.
fn shallower(d: f64, best: f64) -> bool {
    d < best - DEPTH_TIE_M
}

/// Whether `d · n` is positive by far more than its round-off (`1e-9` of `Σ |dᵢ nᵢ|`, where
/// the round-off is below `1e-15` of it): then the signed distance `d · (n / |n|)` that
/// [`triangle_penetration`] computes is positive too, and it returns `None` without the
/// square root. Most candidates are above their face (not in contact), so this decides
/// them; the others (and any NaN) take the full test, whose result is unchanged.
#[inline(always)]
fn clearly_above(d: V3, n: V3) -> bool {
    let p = [d[0] * n[0], d[1] * n[1], d[2] * n[2]];
    let (g, s) = (
        p[0] + p[1] + p[2],
        libm::fabs(p[0]) + libm::fabs(p[1]) + libm::fabs(p[2]),
    );
    g > 1e-9 * s
}

/// Penetration of point `x` into the triangle `t` (outward normal `(t1 − t0) × (t2 − t0)`)
/// if `0 < depth ≤ depth_max` and its projection lies inside, or outside an edge by at most
/// [`EDGE_TOLERANCE`].
fn triangle_penetration(x: V3, t: [V3; 3], depth_max: f64) -> Option<(f64, V3, [f64; 3])> {
    let n = triangle_normal(t);
    triangle_penetration_normal(x, t, n, dot(n, n), depth_max)
}

/// The (unnormalised) normal `n = (t1 − t0) × (t2 − t0)` of triangle `t`.
#[inline(always)]
fn triangle_normal(t: [V3; 3]) -> V3 {
    cross(sub(t[1], t[0]), sub(t[2], t[0]))
}

/// [`triangle_penetration`] with the triangle's normal `n = (t1 − t0) × (t2 − t0)` and
/// `n2 = n · n` given (computed once for many points: [`FaceGeometry`]).
#[inline(always)]
fn triangle_penetration_normal(
    x: V3,
    t: [V3; 3],
    n: V3,
    n2: f64,
    depth_max: f64,
) -> Option<(f64, V3, [f64; 3])> {
    if !(n2 > 0.0) {
        return None;
    }
    if clearly_above(sub(x, t[0]), n) {
        return None;
    }
    let inv = 1.0 / libm::sqrt(n2);
    let nh = scale(n, inv);
    let g = dot(sub(x, t[0]), nh);
    if !(g < 0.0) || -g > depth_max {
        return None;
    }
    // Signed sub-areas: the projection's offset along n drops out of (tⱼ − x)×(tₖ − x)·n.
    let (a, b, c) = (sub(t[0], x), sub(t[1], x), sub(t[2], x));
    let w0 = dot(cross(b, c), n) / n2;
    let w1 = dot(cross(c, a), n) / n2;
    let w2 = 1.0 - w0 - w1;
    if w0 < -EDGE_TOLERANCE || w1 < -EDGE_TOLERANCE || w2 < -EDGE_TOLERANCE {
        return None;
    }
    // Just outside an edge (a node on the rim of two touching bodies, or over a crease):
    // the force goes to the nearest edge, weights clipped to the triangle, still summing to 1.
    let (c0, c1, c2) = (w0.max(0.0), w1.max(0.0), w2.max(0.0));
    let sum = c0 + c1 + c2;
    Some((-g, nh, [c0 / sum, c1 / sum, c2 / sum]))
}

/// The quad's two triangles, (0,1,2) and (0,2,3).
#[inline(always)]
fn quad_triangles(q: &[V3; 4]) -> [[V3; 3]; 2] {
    [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
}

/// The shallower of the quad's two triangle penetrations (the first on a tie), as the
/// quad's: triangle (0,1,2)'s weights go to nodes 0, 1, 2 and (0,2,3)'s to 0, 2, 3.
#[inline(always)]
fn quad_result(
    t1: Option<(f64, V3, [f64; 3])>,
    t2: Option<(f64, V3, [f64; 3])>,
) -> Option<FacePenetration> {
    let t1 = t1.map(|(d, n, w)| FacePenetration {
        depth_m: d,
        normal: n,
        weights: [w[0], w[1], w[2], 0.0],
    });
    let t2 = t2.map(|(d, n, w)| FacePenetration {
        depth_m: d,
        normal: n,
        weights: [w[0], 0.0, w[1], w[2]],
    });
    match (t1, t2) {
        (Some(a), Some(b)) => Some(if shallower(b.depth_m, a.depth_m) {
            b
        } else {
            a
        }),
        (a, b) => a.or(b),
    }
}

/// A quad's axis-aligned bounds: per axis the least and greatest corner coordinate, and
/// the edge tolerance's share of [`clearly_outside`]'s growth, `2 EDGE_TOLERANCE e` with `e`
/// the largest extent (computed once with the bounds, not once per point tested). A board
/// keeps one per contact face for a step ([`evaluate_pairs_bounded`]; hence the serde
/// derives, for its storage's zeroed records).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct QuadBounds {
    lo: V3,
    hi: V3,
    edge_slack: f64,
}

impl QuadBounds {
    /// The bounds of a face one of whose corners is unknown at this step: NaN, which
    /// [`clearly_outside`] never rejects (the face then takes the full test, which skips
    /// it).
    pub const UNKNOWN: QuadBounds = QuadBounds {
        lo: [f64::NAN; 3],
        hi: [f64::NAN; 3],
        edge_slack: f64::NAN,
    };

    #[inline(always)]
    fn new(q: &[V3; 4]) -> QuadBounds {
        let (mut lo, mut hi) = (q[0], q[0]);
        for p in &q[1..] {
            QuadBounds::include(&mut lo, &mut hi, p);
        }
        QuadBounds::from_extent(lo, hi)
    }

    /// `lo` and `hi` grown to hold corner `p` (the one fold of the corners: the bounds'
    /// bits depend on its order, and [`ContactModel::face_bounds`] goes through it too).
    #[inline(always)]
    fn include(lo: &mut V3, hi: &mut V3, p: &V3) {
        for i in 0..3 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }

    /// The bounds of corners whose least and greatest coordinates are `lo` and `hi`.
    #[inline(always)]
    fn from_extent(lo: V3, hi: V3) -> QuadBounds {
        let e = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(hi[2] - lo[2]);
        QuadBounds {
            lo,
            hi,
            edge_slack: 2.0 * EDGE_TOLERANCE * e,
        }
    }
}

/// Whether `x` is so far outside the quad's bounds that neither triangle can hold it, so
/// [`quad_penetration`] is `None` without its two tests. A triangle takes `x` only if
/// `x = p − g n̂` with `p` in the triangle's plane at barycentric weights of at least
/// `−EDGE_TOLERANCE` (at most two negative, so `p` lies within the triangle's bounds grown
/// by `2 EDGE_TOLERANCE` times their largest extent `e`) and `0 < −g ≤ depth_max` (each
/// coordinate of `g n̂` at most `depth_max`): `x` lies within the quad's bounds grown by
/// `depth_max + 2 EDGE_TOLERANCE e`. The bound used is 1% wider than that (round-off in the
/// tests it stands for is some 1e-15 of it on a face of fair shape), so a point it rejects
/// is one the full test rejects: the result is the same, bit for bit. (Only in a triangle so
/// thin that its weights' round-off exceeds that 1% could the full test have taken a point
/// this rejects: there its answer is round-off.) Every solver, serial and on the boards, goes
/// through it. Most candidates of a search beside their face are decided here. A NaN
/// anywhere is never rejected (it takes the full test).
#[inline(always)]
fn clearly_outside(x: V3, b: &QuadBounds, depth_max: f64) -> bool {
    let grow = 1.01 * (depth_max + b.edge_slack);
    (0..3).any(|i| x[i] < b.lo[i] - grow || x[i] > b.hi[i] + grow)
}

/// Penetration of `x` into the quad `q` (split along the diagonal 0–2 into triangles
/// (0,1,2) and (0,2,3), nodes ordered counter-clockwise seen from outside): the shallower
/// of the two triangles it penetrates.
pub fn quad_penetration(x: V3, q: &[V3; 4], depth_max: f64) -> Option<FacePenetration> {
    if clearly_outside(x, &QuadBounds::new(q), depth_max) {
        return None;
    }
    let [a, b] = quad_triangles(q);
    let t1 = triangle_penetration(x, a, depth_max);
    let t2 = triangle_penetration(x, b, depth_max);
    quad_result(t1, t2)
}

/// A master quad at one state, for testing many slave nodes against it: its corners and
/// its triangles' normals `n = (t1 − t0) × (t2 − t0)` with `n · n`, what
/// [`quad_penetration`] computes first for every node. [`FaceGeometry::penetration`] gives
/// [`quad_penetration`]'s result, bit for bit (the same operations on the same values).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FaceGeometry {
    pub corners: [V3; 4],
    normals: [V3; 2],
    normals_squared: [f64; 2],
    bounds: QuadBounds,
}

impl FaceGeometry {
    pub fn new(corners: [V3; 4]) -> FaceGeometry {
        let t = quad_triangles(&corners);
        let normals = t.map(triangle_normal);
        FaceGeometry {
            corners,
            normals,
            normals_squared: normals.map(|n| dot(n, n)),
            bounds: QuadBounds::new(&corners),
        }
    }

    /// [`quad_penetration`] of `x` into this quad.
    pub fn penetration(&self, x: V3, depth_max: f64) -> Option<FacePenetration> {
        if clearly_outside(x, &self.bounds, depth_max) {
            return None;
        }
        let [a, b] = quad_triangles(&self.corners);
        let (n, n2) = (self.normals, self.normals_squared);
        let t1 = triangle_penetration_normal(x, a, n[0], n2[0], depth_max);
        let t2 = triangle_penetration_normal(x, b, n[1], n2[1], depth_max);
        quad_result(t1, t2)
    }
}

/// A node of a contact surface (the table is the same on every board).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactNode {
    /// Index of the node in the scene's mesh.
    pub global: u32,
    /// Initial position (m).
    pub reference: V3,
    /// Penalty stiffness `β m_inertial / Δt²` when this node is the slave (N/m).
    pub penalty_n_per_m: f64,
    /// Bit `s` set: the node belongs to surface `s`.
    pub surfaces: u8,
}

/// A face of a contact surface: four contact-node indices, counter-clockwise seen from
/// outside the body it bounds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ContactFace {
    pub nodes: [u32; 4],
    pub surface: u8,
}

/// Two surfaces that may touch; each is slave against the other's faces.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactPair {
    pub a: u8,
    pub b: u8,
    /// Deepest penetration still taken as contact (m): below it a node is taken to be on
    /// the far side of a thin master, not in it. Less than half the master's thickness.
    pub depth_max_m: f64,
}

/// A rigid tool: a capsule (at time 0) moved by a displacement path, touching the nodes of
/// one surface.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tool {
    pub capsule: Capsule,
    /// Index of the displacement path (in the path table) the tool follows.
    pub path: u16,
    pub surface: u8,
}

/// A candidate of the search: slave node against master face, in direction
/// `2 · pair + (0: a's nodes on b's faces, 1: b's nodes on a's faces)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Candidate {
    pub direction: u16,
    pub slave: u32,
    pub face: u32,
}

/// What a step of contact found (for reports and checkers).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactStats {
    /// Active node-face and node-tool contacts applied.
    pub active: u32,
    /// Deepest penetration among the applied contacts (m).
    pub max_depth_m: f64,
    /// Per pair: the sum of all forces of its contacts (zero to round-off), and the sum
    /// of their magnitudes (the scale).
    pub pair_sum_n: [V3; SURFACES_MAX],
    pub pair_magnitude_n: [f64; SURFACES_MAX],
}

/// The contact problem: tables shared by every board.
#[derive(Clone, Copy, Debug)]
pub struct ContactModel<'a> {
    pub nodes: &'a [ContactNode],
    pub faces: &'a [ContactFace],
    pub pairs: &'a [ContactPair],
    pub tools: &'a [Tool],
}

fn bad(index: usize) -> PhysicsError {
    PhysicsError::BadContactIndex {
        index: index as u32,
    }
}

impl ContactModel<'_> {
    /// Master and slave surfaces of a direction.
    fn roles(&self, direction: usize) -> Option<(u8, u8, f64)> {
        let p = self.pairs.get(direction / 2)?;
        Some(if direction.is_multiple_of(2) {
            (p.a, p.b, p.depth_max_m)
        } else {
            (p.b, p.a, p.depth_max_m)
        })
    }

    /// Face `f`'s [`FaceGeometry`] at the positions `pos` (`None` if one is unknown), for
    /// [`evaluate_pairs_at`].
    pub fn face_geometry(
        &self,
        f: usize,
        pos: &impl Fn(usize) -> Option<V3>,
    ) -> Result<Option<FaceGeometry>, PhysicsError> {
        let mut q = [[0.0; 3]; 4];
        Ok(if self.face_points(f, pos, &mut q)? {
            Some(FaceGeometry::new(q))
        } else {
            None
        })
    }

    /// Face `f`'s [`QuadBounds`] at the positions `pos` ([`QuadBounds::UNKNOWN`] if one is
    /// unknown), for [`evaluate_pairs_bounded`].
    pub fn face_bounds(
        &self,
        f: usize,
        pos: &impl Fn(usize) -> Option<V3>,
    ) -> Result<QuadBounds, PhysicsError> {
        // `QuadBounds::new` of `face_points`' corners, the same operations in the same
        // order, folded into the reading of the corners (no array of the four corners
        // kept: on the board it was spilled and read back, about half of the cost).
        let face = self.faces.get(f).ok_or(bad(f))?;
        let (mut lo, mut hi) = ([0.0; 3], [0.0; 3]);
        for (k, &c) in face.nodes.iter().enumerate() {
            if c as usize >= self.nodes.len() {
                return Err(bad(c as usize));
            }
            let Some(p) = pos(c as usize) else {
                return Ok(QuadBounds::UNKNOWN);
            };
            if k == 0 {
                (lo, hi) = (p, p);
            } else {
                QuadBounds::include(&mut lo, &mut hi, &p);
            }
        }
        Ok(QuadBounds::from_extent(lo, hi))
    }

    /// The positions of face `f`'s nodes into `q`: `Ok(false)` if one is unknown. (Into
    /// the caller's array: a returned one is copied out through memory.)
    #[inline(always)]
    fn face_points(
        &self,
        f: usize,
        pos: &impl Fn(usize) -> Option<V3>,
        q: &mut [V3; 4],
    ) -> Result<bool, PhysicsError> {
        let face = self.faces.get(f).ok_or(bad(f))?;
        for (k, &c) in face.nodes.iter().enumerate() {
            if c as usize >= self.nodes.len() {
                return Err(bad(c as usize));
            }
            match pos(c as usize) {
                Some(x) => q[k] = x,
                None => return Ok(false),
            }
        }
        Ok(true)
    }
}

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
pub fn build_candidates(
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
fn group_len(candidates: &[Candidate]) -> usize {
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
fn group_applies(
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
pub fn keep_applied_groups(
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

/// Node-to-surface forces over `candidates` (in [`build_candidates`] order): for each
/// slave, the winning face; `F = ½ k p n` on the slave and `−wᵢ F` on the face's nodes,
/// added to `force[c]` for the contact nodes with `apply(c)`. A slave or face whose
/// positions are unknown is skipped (the caller's search guarantees that those never
/// matter for the nodes it applies). `tolerance_m`: a penetration deeper than this on an
/// applied slave node is an error (the penalty is too soft for the load).
pub fn evaluate_pairs(
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

/// [`evaluate_pairs`] with each master face's bounds at this state computed beforehand:
/// `bounds[f]` is [`ContactModel::face_bounds`] of face `f` (a face beyond `bounds` takes
/// the full test). A candidate whose slave lies [`clearly_outside`] its face's bounds is
/// decided from them, without reading the face's corners; the others take
/// [`quad_penetration`], which makes the same test on the same values first. So the result
/// is [`evaluate_pairs`]'s, bit for bit, with 56 bytes per face (not [`FaceGeometry`]'s
/// 224). What it spares: on the built-in coarse scene a face is a candidate of 4-5 slaves,
/// most of them outside its bounds at a step, and reading a face's four corners and
/// bounding them for each was most of the pair tests' cost (`scripts/contact-cost.sh`
/// prints the stages). (Bounds rounded outward to f32, half the bytes, cost 17 000 more
/// instructions a step there than they spared, in the rounding: measured.)
#[allow(clippy::too_many_arguments)]
pub fn evaluate_pairs_bounded(
    m: &ContactModel<'_>,
    candidates: &[Candidate],
    pos: impl Fn(usize) -> Option<V3>,
    bounds: &[QuadBounds],
    apply: impl Fn(usize) -> bool,
    tolerance_m: f64,
    force: &mut [V3],
    stats: &mut ContactStats,
) -> Result<(), PhysicsError> {
    evaluate_bounded(
        m,
        candidates,
        pos,
        bounds,
        apply,
        tolerance_m,
        force,
        stats,
        false,
    )
}

/// [`evaluate_pairs_bounded`] over candidates that [`keep_applied_groups`] kept for the
/// same `apply`: every group gives a node with `apply` a force and its indices were
/// checked there, so neither is tested again (a board evaluates its kept list at every step
/// until the next check; on a board of a partition most slaves are not its own, and the
/// test read each such group's faces). The same forces and statistics, bit for bit.
#[allow(clippy::too_many_arguments)]
pub fn evaluate_kept_pairs_bounded(
    m: &ContactModel<'_>,
    candidates: &[Candidate],
    pos: impl Fn(usize) -> Option<V3>,
    bounds: &[QuadBounds],
    apply: impl Fn(usize) -> bool,
    tolerance_m: f64,
    force: &mut [V3],
    stats: &mut ContactStats,
) -> Result<(), PhysicsError> {
    evaluate_bounded(
        m,
        candidates,
        pos,
        bounds,
        apply,
        tolerance_m,
        force,
        stats,
        true,
    )
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn evaluate_bounded(
    m: &ContactModel<'_>,
    candidates: &[Candidate],
    pos: impl Fn(usize) -> Option<V3>,
    bounds: &[QuadBounds],
    apply: impl Fn(usize) -> bool,
    tolerance_m: f64,
    force: &mut [V3],
    stats: &mut ContactStats,
    kept: bool,
) -> Result<(), PhysicsError> {
    let face_test = |f: usize, x: V3, depth_max: f64| {
        if bounds
            .get(f)
            .is_some_and(|b| clearly_outside(x, b, depth_max))
        {
            return Ok(None);
        }
        let mut q = [[0.0; 3]; 4];
        Ok(if m.face_points(f, &pos, &mut q)? {
            quad_penetration(x, &q, depth_max)
        } else {
            None
        })
    };
    evaluate_pairs_with(
        m,
        candidates,
        &pos,
        apply,
        tolerance_m,
        force,
        stats,
        face_test,
        kept,
    )
}

/// [`evaluate_pairs`] with each master face's geometry at this state computed beforehand:
/// `geometry[f]` is [`FaceGeometry::new`] of face `f`'s corner positions (`None` where one
/// is unknown), for every face a candidate names. The same result, bit for bit, with the
/// corners and normals computed once per face instead of once per candidate (a face is a
/// candidate of about ten slaves).
#[allow(clippy::too_many_arguments)]
pub fn evaluate_pairs_at(
    m: &ContactModel<'_>,
    candidates: &[Candidate],
    pos: impl Fn(usize) -> Option<V3>,
    geometry: &[Option<FaceGeometry>],
    apply: impl Fn(usize) -> bool,
    tolerance_m: f64,
    force: &mut [V3],
    stats: &mut ContactStats,
) -> Result<(), PhysicsError> {
    let face_test = |f: usize, x: V3, depth_max: f64| match geometry.get(f) {
        Some(g) => Ok(g.as_ref().and_then(|g| g.penetration(x, depth_max))),
        None => Err(bad(f)),
    };
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

/// The loop of [`evaluate_pairs`], with `face_test(f, x, depth_max)` the penetration of a
/// slave at `x` into face `f` (`Ok(None)`: none, or the face's position is unknown);
/// `kept`: the groups are [`keep_applied_groups`]'s (not tested again).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn evaluate_pairs_with(
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

#[allow(clippy::too_many_arguments)]
/// Tool forces: every node of tool `t`'s surface with `apply(c)` (ascending) inside the
/// tool's capsule at its current place `capsules[t]` gets `k p n`; `tool_force[t]` takes
/// the sum of `−k p n` (the force of the tissue on the tool).
pub fn evaluate_tools(
    m: &ContactModel<'_>,
    capsules: &[Capsule],
    pos: impl Fn(usize) -> Option<V3>,
    apply: impl Fn(usize) -> bool,
    tolerance_m: f64,
    force: &mut [V3],
    tool_force: &mut [V3],
    stats: &mut ContactStats,
) -> Result<(), PhysicsError> {
    for (t, tool) in m.tools.iter().enumerate() {
        let cap = capsules.get(t).ok_or(bad(t))?;
        let b = cap.bounds();
        for (c, node) in m.nodes.iter().enumerate() {
            if node.surfaces & (1 << tool.surface) == 0 || !apply(c) {
                continue;
            }
            let Some(x) = pos(c) else { continue };
            if (0..3).any(|i| x[i] < b[0][i] || x[i] > b[1][i]) {
                continue;
            }
            if let Some((depth, n)) = cap.penetration(x) {
                if depth > tolerance_m {
                    return Err(PhysicsError::Penetration {
                        node: node.global,
                        depth_m: depth,
                        tolerance_m,
                    });
                }
                let f = scale(n, node.penalty_n_per_m * depth);
                let dst = force.get_mut(c).ok_or(bad(c))?;
                let tf = tool_force.get_mut(t).ok_or(bad(t))?;
                for k in 0..3 {
                    dst[k] += f[k];
                    tf[k] -= f[k];
                }
                stats.active += 1;
                stats.max_depth_m = stats.max_depth_m.max(depth);
            }
        }
    }
    Ok(())
}

/// The speed bound behind the search interval: no node of a pair surface with `apply(c)`
/// may have moved farther than `travel_max_m` from where it was at the last check
/// (`at_check`). A faster node could reach a face the search did not list, so a violation
/// is an error naming the node.
pub fn check_travel(
    m: &ContactModel<'_>,
    pos: impl Fn(usize) -> Option<V3>,
    at_check: &[V3],
    apply: impl Fn(usize) -> bool,
    pair_surfaces: u8,
    travel_max_m: f64,
) -> Result<(), PhysicsError> {
    // A surface moving at exactly the bound covers `travel_max_m` up to round-off.
    let lim = travel_max_m * (1.0 + 1e-9);
    let lim2 = lim * lim;
    for (c, node) in m.nodes.iter().enumerate() {
        if node.surfaces & pair_surfaces == 0 || !apply(c) {
            continue;
        }
        let (Some(x), Some(x0)) = (pos(c), at_check.get(c)) else {
            continue;
        };
        let d = sub(x, *x0);
        let d2 = dot(d, d);
        if !(d2 <= lim2) {
            return Err(PhysicsError::ContactSpeedBound {
                node: node.global,
                moved_m: libm::sqrt(d2),
                allowed_m: travel_max_m,
            });
        }
    }
    Ok(())
}

/// Bit mask of the surfaces that take part in some pair.
pub fn pair_surface_mask(pairs: &[ContactPair]) -> u8 {
    pairs.iter().fold(0u8, |m, p| {
        m | 1u8.checked_shl(p.a as u32).unwrap_or(0) | 1u8.checked_shl(p.b as u32).unwrap_or(0)
    })
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::{format, vec, vec::Vec};

    #[test]
    fn capsule_depth_and_normal_match_the_geometry() {
        let c = Capsule {
            a: [0.0, 0.0, 0.0],
            b: [0.0, 0.0, 1.0],
            radius_m: 0.1,
        };
        // 0.04 from the axis beside the segment: depth 0.06, normal +x.
        let (d, n) = c.penetration([0.04, 0.0, 0.5]).expect("inside");
        assert!((d - 0.06).abs() < 1e-15 && (n[0] - 1.0).abs() < 1e-15);
        // Beyond the end cap: distance to the end point.
        let (d, n) = c.penetration([0.0, 0.0, 1.05]).expect("inside the cap");
        assert!((d - 0.05).abs() < 1e-15 && (n[2] - 1.0).abs() < 1e-15);
        assert!(c.penetration([0.2, 0.0, 0.5]).is_none());
        // On the axis: pushed out perpendicular to it.
        let (_, n) = c.penetration([0.0, 0.0, 0.5]).expect("on the axis");
        assert!(n[2].abs() < 1e-15 && (dot(n, n) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn quad_penetration_weights_reproduce_the_projection() {
        // Unit square in z = 0, outward +z; a point 0.01 below at (0.3, 0.6).
        let q = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let p = quad_penetration([0.3, 0.6, -0.01], &q, 0.1).expect("penetrates");
        assert!((p.depth_m - 0.01).abs() < 1e-15);
        assert!((p.normal[2] - 1.0).abs() < 1e-15);
        let proj: V3 = core::array::from_fn(|i| (0..4).map(|k| p.weights[k] * q[k][i]).sum());
        assert!((proj[0] - 0.3).abs() < 1e-15 && (proj[1] - 0.6).abs() < 1e-15);
        assert!((p.weights.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        // Above the face, too deep, or outside the face: no contact.
        assert!(quad_penetration([0.3, 0.6, 0.01], &q, 0.1).is_none());
        assert!(quad_penetration([0.3, 0.6, -0.2], &q, 0.1).is_none());
        assert!(quad_penetration([1.3, 0.6, -0.01], &q, 0.1).is_none());
    }

    /// Asserts that two penetration results are the same, bit for bit (both none, or equal
    /// depth, normal and weights); `Some` says they penetrate. `at` names the case.
    fn same_penetration_bits(
        a: Option<FacePenetration>,
        b: Option<FacePenetration>,
        at: impl Fn() -> std::string::String,
    ) -> bool {
        match (a, b) {
            (None, None) => false,
            (Some(a), Some(b)) => {
                assert_eq!(a.depth_m.to_bits(), b.depth_m.to_bits(), "{}", at());
                assert_eq!(
                    a.normal.map(f64::to_bits),
                    b.normal.map(f64::to_bits),
                    "{}",
                    at()
                );
                assert_eq!(
                    a.weights.map(f64::to_bits),
                    b.weights.map(f64::to_bits),
                    "{}",
                    at()
                );
                true
            }
            (a, b) => panic!("{}: {a:?} against {b:?}", at()),
        }
    }

    /// [`FaceGeometry::penetration`] is [`quad_penetration`] with the normals computed
    /// once: the same result to the bit, on warped quads (the two triangles tilted apart)
    /// and points above, below, beside, on edges and too deep. At least a quarter of the
    /// points must penetrate, so the comparison covers the weights and normals, not only
    /// `None = None`.
    #[test]
    fn face_geometry_gives_quad_penetration_bits() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let (mut hits, mut total) = (0, 0);
        for _ in 0..200 {
            let q: [V3; 4] = [
                [0.0, 0.0, 0.0],
                [1.0 + 0.2 * rnd(), 0.1 * rnd(), 0.1 * rnd()],
                [1.0 + 0.2 * rnd(), 1.0 + 0.2 * rnd(), 0.2 * rnd()],
                [0.1 * rnd(), 1.0 + 0.2 * rnd(), 0.1 * rnd()],
            ];
            let g = FaceGeometry::new(q);
            for _ in 0..20 {
                let x = [0.5 + 1.3 * rnd(), 0.5 + 1.3 * rnd(), 0.08 * rnd() - 0.02];
                let (a, b) = (quad_penetration(x, &q, 0.05), g.penetration(x, 0.05));
                total += 1;
                if same_penetration_bits(a, b, || format!("at {x:?}")) {
                    hits += 1;
                }
            }
        }
        assert!(4 * hits >= total, "only {hits} of {total} points penetrate");
    }

    /// The bounds test in front of the two triangle tests changes no result. On skewed quads
    /// turned about two axes (so a depth along the normal moves every coordinate), points
    /// are drawn where the full test is decided by a hair: projections from inside to
    /// 1.5 EDGE_TOLERANCE outside a triangle (weights down to -0.03), depths from above the
    /// face to 1.2 depth_max below it, plus points far to the side. The answer must be the
    /// full test's (`quad_result` of both triangles), bit for bit; and the draw must reach
    /// both sides (full-test hits, and misses the bounds alone decide), or it shows nothing.
    #[test]
    fn the_bounds_test_changes_no_penetration() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut hits, mut decided_by_bounds, mut total) = (0, 0, 0);
        let depth_max = 0.3;
        for _ in 0..300 {
            let (a, b) = (6.0 * rnd(), 6.0 * rnd());
            let turn = |p: V3| {
                let (ca, sa, cb, sb) = (libm::cos(a), libm::sin(a), libm::cos(b), libm::sin(b));
                let y = [p[0], ca * p[1] - sa * p[2], sa * p[1] + ca * p[2]];
                [cb * y[0] - sb * y[1], sb * y[0] + cb * y[1], y[2]]
            };
            let q: [V3; 4] = [
                [0.0, 0.0, 0.0],
                [1.0 + 0.4 * rnd(), 0.3 * rnd() - 0.15, 0.2 * rnd() - 0.1],
                [1.0 + 0.4 * rnd(), 1.0 + 0.4 * rnd(), 0.3 * rnd() - 0.15],
                [0.3 * rnd() - 0.15, 1.0 + 0.4 * rnd(), 0.2 * rnd() - 0.1],
            ]
            .map(turn);
            let tris = quad_triangles(&q);
            for k in 0..60 {
                let x = if k % 4 == 3 {
                    // Far to the side: what most candidates of a search are.
                    core::array::from_fn(|i| q[0][i] + 8.0 * rnd() - 4.0)
                } else {
                    let t = tris[k % 2];
                    let w0 = 1.06 * rnd() - 0.03;
                    let w1 = (1.03 - w0) * rnd() - 0.03;
                    let w2 = 1.0 - w0 - w1;
                    let p: V3 =
                        core::array::from_fn(|i| w0 * t[0][i] + w1 * t[1][i] + w2 * t[2][i]);
                    let n = triangle_normal(t);
                    let nh = scale(n, 1.0 / libm::sqrt(dot(n, n)));
                    let depth = depth_max * (1.4 * rnd() - 0.2);
                    core::array::from_fn(|i| p[i] - depth * nh[i])
                };
                let full = quad_result(
                    triangle_penetration(x, tris[0], depth_max),
                    triangle_penetration(x, tris[1], depth_max),
                );
                let fast = quad_penetration(x, &q, depth_max);
                total += 1;
                if clearly_outside(x, &QuadBounds::new(&q), depth_max) {
                    decided_by_bounds += 1;
                }
                if same_penetration_bits(full, fast, || format!("at {x:?} in {q:?}")) {
                    hits += 1;
                }
            }
        }
        assert_eq!(total, 300 * 60);
        assert!(5 * hits >= total, "only {hits} of {total} points penetrate");
        assert!(
            5 * decided_by_bounds >= total,
            "the bounds decided only {decided_by_bounds} of {total}"
        );
    }

    /// Two overlapping grids of quads (surface 0 facing +z at z = 0, surface 1 facing -z at
    /// z = -0.02, shifted half a cell, nodes jittered): every node of each is 0.02 deep in
    /// the other. Nodes, faces and the pair (depth_max 0.05).
    fn overlapping_grids() -> (Vec<ContactNode>, Vec<ContactFace>, [ContactPair; 1]) {
        let mut seed = 0x5851_f42d_4c95_7f2du64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let (side, h) = (6usize, 0.1);
        let mut nodes = Vec::new();
        let mut faces = Vec::new();
        for (surface, z, shift) in [(0u8, 0.0, 0.0), (1u8, -0.02, 0.5 * h)] {
            let base = nodes.len() as u32;
            for j in 0..side {
                for i in 0..side {
                    nodes.push(ContactNode {
                        global: nodes.len() as u32,
                        reference: [
                            i as f64 * h + shift + 0.01 * rnd(),
                            j as f64 * h + shift + 0.01 * rnd(),
                            z + 0.002 * rnd(),
                        ],
                        penalty_n_per_m: 1e3,
                        surfaces: 1 << surface,
                    });
                }
            }
            for j in 0..side - 1 {
                for i in 0..side - 1 {
                    let k = |a: usize, b: usize| base + (b * side + a) as u32;
                    let up = [k(i, j), k(i + 1, j), k(i + 1, j + 1), k(i, j + 1)];
                    let down = [up[0], up[3], up[2], up[1]];
                    faces.push(ContactFace {
                        nodes: if surface == 0 { up } else { down },
                        surface,
                    });
                }
            }
        }
        let pairs = [ContactPair {
            a: 0,
            b: 1,
            depth_max_m: 0.05,
        }];
        (nodes, faces, pairs)
    }

    /// On [`overlapping_grids`], with a board's share of the nodes applied (a third, by
    /// index), the groups [`keep_applied_groups`] keeps give the same forces and
    /// statistics, bit for bit, as the whole list (which [`evaluate_pairs`] filters per
    /// step), and so does [`evaluate_kept_pairs_bounded`] over them with bounds for only
    /// the faces they name (as a board computes them); and the check means something:
    /// forces are applied, groups are dropped and some are kept, some faces are not named.
    #[test]
    fn keeping_the_applied_groups_changes_no_force() {
        let (nodes, faces, pairs) = overlapping_grids();
        let m = ContactModel {
            nodes: &nodes,
            faces: &faces,
            pairs: &pairs,
            tools: &[],
        };
        let pos = |c: usize| nodes.get(c).map(|n| n.reference);
        let mut all = vec![Candidate::default(); 4096];
        let mut boxes = vec![QuadBounds::default(); faces.len()];
        let n =
            build_candidates(&m, pos, 0.03, &mut boxes, &mut all).expect("room for the candidates");
        all.truncate(n);
        let apply = |c: usize| c.is_multiple_of(3);
        let mut kept = all.clone();
        let k = keep_applied_groups(&m, &mut kept, apply).expect("valid indices");
        kept.truncate(k);
        assert!(0 < k && k < n, "kept {k} of {n} candidates");
        let run = |cands: &[Candidate]| {
            let mut force = vec![[0.0; 3]; nodes.len()];
            let mut stats = ContactStats::default();
            evaluate_pairs(&m, cands, pos, apply, 1.0, &mut force, &mut stats).expect("no error");
            (force, stats)
        };
        let ((f_all, s_all), (f_kept, s_kept)) = (run(&all), run(&kept));
        assert_eq!(f_all.len(), nodes.len());
        assert_eq!(f_kept.len(), nodes.len());
        let applied = f_all.iter().filter(|f| f.iter().any(|&v| v != 0.0)).count();
        assert!(applied > 10, "only {applied} nodes got a force");
        assert!(s_all.active > 10, "only {} contacts", s_all.active);
        for (a, b) in f_all.iter().zip(&f_kept) {
            assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
        }
        assert_eq!(s_all, s_kept);
        // The board's way: the kept groups without their test again, with bounds only for
        // the faces they name. The other faces' bounds hold a box far away that rejects
        // every slave: were one read, its face's contacts would be lost.
        let named: Vec<bool> = (0..faces.len())
            .map(|f| kept.iter().any(|c| c.face as usize == f))
            .collect();
        let unnamed = named.iter().filter(|&&u| !u).count();
        assert!(
            0 < unnamed && unnamed < faces.len(),
            "the kept groups name {} of {} faces",
            faces.len() - unnamed,
            faces.len()
        );
        let far = QuadBounds {
            lo: [1e9; 3],
            hi: [1e9; 3],
            edge_slack: 0.0,
        };
        let bounds: Vec<QuadBounds> = (0..faces.len())
            .map(|f| match named[f] {
                true => m.face_bounds(f, &pos).expect("valid face"),
                false => far,
            })
            .collect();
        let mut f_board = vec![[0.0; 3]; nodes.len()];
        let mut s_board = ContactStats::default();
        evaluate_kept_pairs_bounded(
            &m,
            &kept,
            pos,
            &bounds,
            apply,
            1.0,
            &mut f_board,
            &mut s_board,
        )
        .expect("no error");
        assert_eq!(f_board.len(), f_all.len());
        for (a, b) in f_all.iter().zip(&f_board) {
            assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
        }
        assert_eq!(s_all, s_board);
    }

    /// [`evaluate_pairs_bounded`] gives [`evaluate_pairs`]'s forces and statistics, bit for
    /// bit, on [`overlapping_grids`] with a wide search margin (so that many candidates lie
    /// outside their face's bounds): with every position known and with every seventh
    /// unknown (a partner's node not received: those faces' bounds are
    /// [`QuadBounds::UNKNOWN`]), with bounds for every face and for only the first half
    /// (the rest take the full test). The check means something: forces are applied, and
    /// the bounds decide at least a third of the candidates.
    #[test]
    fn the_face_bounds_change_no_force() {
        let (nodes, faces, pairs) = overlapping_grids();
        let m = ContactModel {
            nodes: &nodes,
            faces: &faces,
            pairs: &pairs,
            tools: &[],
        };
        for unknown_every in [0usize, 7] {
            let pos = |c: usize| {
                let known = unknown_every == 0 || !c.is_multiple_of(unknown_every);
                nodes.get(c).filter(|_| known).map(|n| n.reference)
            };
            let mut cands = vec![Candidate::default(); 8192];
            let mut boxes = vec![QuadBounds::default(); faces.len()];
            let n = build_candidates(&m, pos, 0.15, &mut boxes, &mut cands)
                .expect("room for the candidates");
            cands.truncate(n);
            let bounds: Vec<QuadBounds> = (0..faces.len())
                .map(|f| m.face_bounds(f, &pos).expect("valid face"))
                .collect();
            assert_eq!(bounds.len(), faces.len());
            // `face_bounds` folds the corners' bounds into their reading: the bounds of the
            // four corners read first, bit for bit, and unknown where a corner is.
            let mut known = 0;
            for (f, b) in bounds.iter().enumerate() {
                let mut q = [[0.0; 3]; 4];
                if m.face_points(f, &pos, &mut q).expect("valid face") {
                    let r = QuadBounds::new(&q);
                    let bits = |b: &QuadBounds| {
                        (
                            b.lo.map(f64::to_bits),
                            b.hi.map(f64::to_bits),
                            b.edge_slack.to_bits(),
                        )
                    };
                    assert_eq!(bits(b), bits(&r), "face {f}");
                    assert!(r.edge_slack > 0.0, "face {f} has an extent");
                    known += 1;
                } else {
                    assert!(b.edge_slack.is_nan(), "face {f} has an unknown corner");
                }
            }
            // Every face when all nodes are known; with every seventh node unknown about
            // half of them have a corner unknown.
            let least = if unknown_every == 0 {
                faces.len()
            } else {
                faces.len() / 3
            };
            assert!(known >= least, "{known} of {} faces known", faces.len());
            let depth_max = pairs[0].depth_max_m;
            let decided = cands
                .iter()
                .filter(|c| {
                    pos(c.slave as usize)
                        .is_some_and(|x| clearly_outside(x, &bounds[c.face as usize], depth_max))
                })
                .count();
            assert!(
                3 * decided >= n,
                "the bounds decide {decided} of {n} candidates"
            );
            let run = |bounds: Option<&[QuadBounds]>| {
                let mut force = vec![[0.0; 3]; nodes.len()];
                let mut stats = ContactStats::default();
                let all = |_| true;
                match bounds {
                    None => evaluate_pairs(&m, &cands, pos, all, 1.0, &mut force, &mut stats),
                    Some(b) => {
                        evaluate_pairs_bounded(&m, &cands, pos, b, all, 1.0, &mut force, &mut stats)
                    }
                }
                .expect("no error");
                (force, stats)
            };
            let (f_ref, s_ref) = run(None);
            assert_eq!(f_ref.len(), nodes.len());
            let applied = f_ref.iter().filter(|f| f.iter().any(|&v| v != 0.0)).count();
            assert!(applied > 10, "only {applied} nodes got a force");
            for b in [&bounds[..], &bounds[..bounds.len() / 2]] {
                let (f, st) = run(Some(b));
                assert_eq!(f.len(), f_ref.len());
                for (a, b) in f_ref.iter().zip(&f) {
                    assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
                }
                assert_eq!(s_ref, st);
            }
        }
    }

    /// [`search_tests`] counts what the search's doc says it tests: the grids have 6x6 nodes
    /// and 5x5 faces per surface, so each direction tests 36 slaves against the master's 25
    /// faces (1800 in all, not 3600: the slave's own surface's faces are not tested);
    /// without the faces of surface 1 the direction whose master it is tests nothing, and
    /// the other 36 slaves against the 25 faces left.
    #[test]
    fn the_search_tests_are_counted_as_the_search_runs() {
        let (nodes, faces, pairs) = overlapping_grids();
        assert_eq!((nodes.len(), faces.len()), (72, 50));
        let m = ContactModel {
            nodes: &nodes,
            faces: &faces,
            pairs: &pairs,
            tools: &[],
        };
        assert_eq!(search_tests(&m), 2 * 36 * 25);
        let only_0: Vec<ContactFace> = faces.iter().filter(|f| f.surface == 0).copied().collect();
        let m = ContactModel {
            faces: &only_0,
            ..m
        };
        assert_eq!(search_tests(&m), 36 * 25);
    }

    /// [`build_candidates`] searches over boxes written per part of the faces and sorts;
    /// the list must be the one of the search as its doc states it, node by node (written
    /// out here, the slave-major loop over the faces' corners): the same candidates in the
    /// same order, on [`overlapping_grids`] at three margins, with every node's position
    /// known and with every seventh unknown (a partner's node not received), with boxes for
    /// every face, for 7 or 1 at a time, or none lent. Non-trivial: candidates are found,
    /// and fewer than all node-face pairs. With too little room it reports the same number
    /// needed.
    #[test]
    fn the_face_major_search_gives_the_slave_major_list() {
        let (nodes, faces, pairs) = overlapping_grids();
        let m = ContactModel {
            nodes: &nodes,
            faces: &faces,
            pairs: &pairs,
            tools: &[],
        };
        let slave_major = |pos: &dyn Fn(usize) -> Option<V3>, margin: f64| {
            let mut out = Vec::new();
            for direction in 0..2 * pairs.len() {
                let (slave, master, _) = m.roles(direction).expect("a direction");
                for (s, node) in nodes.iter().enumerate() {
                    let Some(x) = pos(s) else { continue };
                    if node.surfaces & (1 << slave) == 0 {
                        continue;
                    }
                    for (f, face) in faces.iter().enumerate() {
                        if face.surface != master || face.nodes.contains(&(s as u32)) {
                            continue;
                        }
                        let q: Option<Vec<V3>> =
                            face.nodes.iter().map(|&c| pos(c as usize)).collect();
                        let Some(q) = q else { continue };
                        let inside = (0..3).all(|i| {
                            let lo = q.iter().map(|p| p[i]).fold(f64::INFINITY, f64::min);
                            let hi = q.iter().map(|p| p[i]).fold(f64::NEG_INFINITY, f64::max);
                            x[i] >= lo - margin && x[i] <= hi + margin
                        });
                        if inside {
                            out.push(Candidate {
                                direction: direction as u16,
                                slave: s as u32,
                                face: f as u32,
                            });
                        }
                    }
                }
            }
            out
        };
        let known = |c: usize| nodes.get(c).map(|n| n.reference);
        let some_unknown = |c: usize| {
            if c % 7 == 3 {
                None
            } else {
                nodes.get(c).map(|n| n.reference)
            }
        };
        let all_pairs = nodes.len() * faces.len();
        for margin in [0.025, 0.05, 0.12] {
            for (name, pos) in [
                ("known", &known as &dyn Fn(usize) -> Option<V3>),
                ("some unknown", &some_unknown),
            ] {
                let want = slave_major(pos, margin);
                assert!(
                    20 < want.len() && want.len() < all_pairs / 2,
                    "{name}, margin {margin}: {} candidates",
                    want.len()
                );
                assert!(faces.len() > 7, "the parts of 7 faces split the faces");
                for lent in [faces.len(), 7, 1, 0] {
                    let mut boxes = vec![QuadBounds::default(); lent];
                    let mut got = vec![Candidate::default(); all_pairs];
                    let n = build_candidates(&m, pos, margin, &mut boxes, &mut got).expect("room");
                    got.truncate(n);
                    assert_eq!(
                        got.len(),
                        want.len(),
                        "{name}, margin {margin}, {lent} boxes"
                    );
                    assert_eq!(got, want, "{name}, margin {margin}, {lent} boxes");
                    let mut small = vec![Candidate::default(); want.len() - 1];
                    assert_eq!(
                        build_candidates(&m, pos, margin, &mut boxes, &mut small),
                        Err(want.len()),
                        "{name}, margin {margin}, {lent} boxes"
                    );
                }
            }
        }
    }

    /// Just outside an edge (within [`EDGE_TOLERANCE`] of the triangle's weights) still
    /// counts, with the force moved onto the edge (weights clipped, summing to 1 to
    /// 1e-15); farther out it does not.
    #[test]
    fn a_node_just_outside_an_edge_is_caught_on_the_edge() {
        let q = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let p = quad_penetration([1.005, 0.5, -0.01], &q, 0.1).expect("caught");
        assert!(p.weights.iter().all(|&w| w >= 0.0));
        assert!((p.weights.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        let proj: V3 = core::array::from_fn(|i| (0..4).map(|k| p.weights[k] * q[k][i]).sum());
        assert!((proj[0] - 1.0).abs() < 1e-12, "on the edge x = 1: {proj:?}");
        assert!(quad_penetration([1.0 + 3.0 * EDGE_TOLERANCE, 0.5, -0.01], &q, 0.1).is_none());
    }

    /// A node under the ridge of two faces tilted alike is at equal depths in exact
    /// arithmetic: the lower face index wins whichever way round-off tips the depths
    /// (a shift of 1e-13 m across the ridge changes the depths by 2e-14 m), so the serial run and the boards agree.
    #[test]
    fn equal_depths_are_a_tie_won_by_the_lower_face() {
        // A roof: faces 0 (x ≤ 0) and 1 (x ≥ 0) rising to a ridge along y at z = 0.1.
        let nodes: [V3; 6] = [
            [-1.0, 0.0, 0.0],
            [0.0, 0.0, 0.1],
            [0.0, 1.0, 0.1],
            [-1.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
        ];
        let table: [ContactNode; 7] = core::array::from_fn(|i| ContactNode {
            global: i as u32,
            reference: if i < 6 { nodes[i] } else { [0.0; 3] },
            penalty_n_per_m: 1.0,
            surfaces: if i < 6 { 1 } else { 2 },
        });
        let faces = [
            ContactFace {
                nodes: [0, 1, 2, 3],
                surface: 0,
            },
            ContactFace {
                nodes: [1, 4, 5, 2],
                surface: 0,
            },
        ];
        let pairs = [ContactPair {
            a: 1,
            b: 0,
            depth_max_m: 0.5,
        }];
        let m = ContactModel {
            nodes: &table,
            faces: &faces,
            pairs: &pairs,
            tools: &[],
        };
        let candidates = [
            Candidate {
                direction: 0,
                slave: 6,
                face: 0,
            },
            Candidate {
                direction: 0,
                slave: 6,
                face: 1,
            },
        ];
        for shift in [-1e-13, 0.0, 1e-13] {
            let slave = [shift, 0.5, 0.05];
            let pos = |c: usize| Some(if c < 6 { nodes[c] } else { slave });
            let mut force = [[0.0; 3]; 7];
            let mut stats = ContactStats::default();
            evaluate_pairs(&m, &candidates, pos, |_| true, 1.0, &mut force, &mut stats)
                .expect("evaluates");
            // Face 0's outward normal leans to −x: the slave is pushed that way.
            assert!(force[6][0] < 0.0, "shift {shift:e}: {:?}", force[6]);
            assert_eq!(force[4], [0.0; 3], "face 1's own node takes nothing");
        }
    }
}
