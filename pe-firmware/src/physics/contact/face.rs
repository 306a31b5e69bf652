//! The node-face kernel: a slave node's penetration into a master quad (two triangles), the
//! quad's bounds that decide most candidates without the triangle tests, and the quad's
//! geometry computed once for many nodes.

use serde::{Deserialize, Serialize};

use super::super::vec3::{cross, dot, scale, sub};
use super::V3;

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
pub(super) fn shallower(d: f64, best: f64) -> bool {
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
    pub(super) lo: V3,
    pub(super) hi: V3,
    pub(super) edge_slack: f64,
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
    pub(super) fn new(q: &[V3; 4]) -> QuadBounds {
        let (mut lo, mut hi) = (q[0], q[0]);
        for p in &q[1..] {
            QuadBounds::include(&mut lo, &mut hi, p);
        }
        QuadBounds::from_extent(lo, hi)
    }

    /// `lo` and `hi` grown to hold corner `p` (the one fold of the corners: the bounds'
    /// bits depend on its order, and [`ContactModel::face_bounds`] goes through it too).
    #[inline(always)]
    pub(super) fn include(lo: &mut V3, hi: &mut V3, p: &V3) {
        for i in 0..3 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }

    /// The bounds of corners whose least and greatest coordinates are `lo` and `hi`.
    #[inline(always)]
    pub(super) fn from_extent(lo: V3, hi: V3) -> QuadBounds {
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
pub(super) fn clearly_outside(x: V3, b: &QuadBounds, depth_max: f64) -> bool {
    let grow = 1.01 * (depth_max + b.edge_slack);
    (0..3).any(|i| x[i] < b.lo[i] - grow || x[i] > b.hi[i] + grow)
}

/// Penetration of `x` into the quad `q` (split along the diagonal 0–2 into triangles
/// (0,1,2) and (0,2,3), nodes ordered counter-clockwise seen from outside): the shallower
/// of the two triangles it penetrates.
pub(super) fn quad_penetration(x: V3, q: &[V3; 4], depth_max: f64) -> Option<FacePenetration> {
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

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::format;

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
}
