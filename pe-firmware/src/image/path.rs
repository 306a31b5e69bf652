//! Prescribed paths and load ramps: piecewise functions of time through points, each
//! segment linear or smooth ([`Segment`]), evaluated the same way by the host solver and
//! the board runtime (so they compute the same bits).

use serde::{Deserialize, Serialize};

use super::PathPoint;

/// How a path goes from one point to the next, as a function of the segment's fraction of
/// time `s = (t − t₀)/(t₁ − t₀)` in `[0, 1]`: the value is `a + w(s) (b − a)`.
/// In a scene: `shape = "linear"` or `shape = "poly345"`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Segment {
    /// `w(s) = s`: a straight line (a kink, so a jump in velocity, at each point).
    #[default]
    Linear,
    /// NiftySim's `POLY345` smooth step, `w(s) = s³ (10 − 15 s + 6 s²)`: velocity and
    /// acceleration zero at both ends, so a load or path that starts and stops along it
    /// sends no jolt through the tissue (`w(0) = 0`, `w(1) = 1`, `w'` and `w''` zero at both
    /// ends).
    Poly345,
}

impl Segment {
    /// `w(s)`, in a fixed order of operations (no fused multiply-add on either side):
    /// `s·s·s · (10 + s·(−15 + s·6))`.
    #[inline]
    pub fn weight(self, s: f64) -> f64 {
        match self {
            Segment::Linear => s,
            Segment::Poly345 => s * s * s * (10.0 + s * (-15.0 + s * 6.0)),
        }
    }
}

/// Value at time `t` of a path through `(t_k, v_k)` reached along `segment_k` from the
/// point before, held constant before the first and after the last point:
/// `v = a + w(s) (b − a)`, `s = (t − t0)/(t1 − t0)` ([`Segment::weight`]). The host solver
/// and the board runtime both call this, so they compute the same bits.
pub fn piecewise(
    t: f64,
    len: usize,
    point: impl Fn(usize) -> (f64, [f64; 3], Segment),
) -> [f64; 3] {
    if len == 0 {
        return [0.0; 3];
    }
    let mut k = 0;
    while k < len && point(k).0 <= t {
        k += 1;
    }
    if k == len {
        return point(len - 1).1;
    }
    if k == 0 {
        return point(0).1;
    }
    let (t0, a, _) = point(k - 1);
    let (t1, b, segment) = point(k);
    let s = segment.weight((t - t0) / (t1 - t0));
    [
        a[0] + s * (b[0] - a[0]),
        a[1] + s * (b[1] - a[1]),
        a[2] + s * (b[2] - a[2]),
    ]
}

/// [`piecewise`] with every segment linear.
pub fn piecewise_linear(t: f64, len: usize, point: impl Fn(usize) -> (f64, [f64; 3])) -> [f64; 3] {
    piecewise(t, len, |k| {
        let (t, v) = point(k);
        (t, v, Segment::Linear)
    })
}

/// Value of path `path` in a table of [`PathPoint`]s (points of one path are contiguous).
pub fn path_value(points: &[PathPoint], path: u16, t: f64) -> [f64; 3] {
    let first = points
        .iter()
        .position(|p| p.path == path)
        .unwrap_or(points.len());
    let len = points[first..]
        .iter()
        .take_while(|p| p.path == path)
        .count();
    let run = &points[first..first + len];
    piecewise(t, len, |k| (run[k].t_s, run[k].value, run[k].segment))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// POLY345 against its closed form's properties: the ends (0 and 1 exactly), the
    /// middle (1/2 exactly: 10/8 − 15/16 + 6/32), symmetry `w(1 − s) = 1 − w(s)` to
    /// round-off (1e-14: ten operations on values up to 10, each within 2⁻⁵³ of its
    /// size, and s itself rounded), and the first and second derivatives by central differences: zero at
    /// both ends (below 1e-6 with h = 1e-4, where a linear ramp's slope is 1) and
    /// `w'(1/2) = 30/16 = 1.875`.
    #[test]
    fn poly345_is_the_smooth_step() {
        let w = |s: f64| Segment::Poly345.weight(s);
        assert_eq!(w(0.0), 0.0);
        assert_eq!(w(1.0), 1.0);
        assert_eq!(w(0.5), 0.5);
        for k in 0..=100 {
            let s = k as f64 / 100.0;
            let asym = (w(1.0 - s) - (1.0 - w(s))).abs();
            assert!(asym < 1e-14, "symmetry at {s}: {asym:e}");
            assert!((0.0..=1.0).contains(&w(s)), "w({s}) = {} in [0, 1]", w(s));
        }
        let h = 1e-4;
        let d1 = |s: f64| (w(s + h) - w(s - h)) / (2.0 * h);
        let d2 = |s: f64| (w(s + h) - 2.0 * w(s) + w(s - h)) / (h * h);
        for s in [0.0, 1.0] {
            assert!(d1(s).abs() < 1e-6, "w'({s}) = {}", d1(s));
            assert!(d2(s).abs() < 1e-3, "w''({s}) = {}", d2(s));
        }
        assert!((d1(0.5) - 1.875).abs() < 1e-6, "w'(1/2) = {}", d1(0.5));
        assert_eq!(Segment::Linear.weight(0.3), 0.3);
    }

    /// A path of two smooth segments, through the table as the board reads it: held before
    /// and after, the points themselves exact, and between them `a + w(s)(b − a)` (computed
    /// here from the closed form `10s³ − 15s⁴ + 6s⁵`, to 1e-15 relative).
    #[test]
    fn a_smooth_path_passes_its_points_and_follows_the_curve_between() {
        let pt = |t_s: f64, v: f64, segment| PathPoint {
            path: 3,
            t_s,
            value: [v, -2.0 * v, 0.0],
            segment,
        };
        let other = PathPoint {
            path: 1,
            t_s: 0.0,
            value: [9.0; 3],
            segment: Segment::Linear,
        };
        let table = [
            other,
            pt(0.1, 0.0, Segment::Linear),
            pt(0.5, 2.0, Segment::Poly345),
            pt(0.9, 1.0, Segment::Poly345),
        ];
        assert_eq!(path_value(&table, 3, 0.0), [0.0, 0.0, 0.0]);
        assert_eq!(path_value(&table, 3, 0.5), [2.0, -4.0, 0.0]);
        assert_eq!(path_value(&table, 3, 2.0), [1.0, -2.0, 0.0]);
        for (t, (t0, a, t1, b)) in [(0.2, (0.1, 0.0, 0.5, 2.0)), (0.8, (0.5, 2.0, 0.9, 1.0))] {
            let s: f64 = (t - t0) / (t1 - t0);
            let w = 10.0 * s.powi(3) - 15.0 * s.powi(4) + 6.0 * s.powi(5);
            let want = a + w * (b - a);
            let got = path_value(&table, 3, t);
            assert!(want.abs() > 0.1, "a value far from zero: {want}");
            assert!(
                (got[0] - want).abs() <= 1e-15 * want.abs(),
                "{got:?} vs {want}"
            );
            assert!((got[1] + 2.0 * want).abs() <= 2e-15 * want.abs());
        }
    }
}
