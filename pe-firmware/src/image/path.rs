//! Prescribed paths and load ramps: piecewise-linear functions of time, evaluated the same
//! way by the host solver and the board runtime (so they compute the same bits).

use super::PathPoint;

/// Value at time `t` of a piecewise-linear path through `(t_k, v_k)`, held constant before
/// the first and after the last point: `v = a + s (b − a)`, `s = (t − t0)/(t1 − t0)`.
/// The host solver and the board runtime both call this, so they compute the same bits.
pub fn piecewise_linear(t: f64, len: usize, point: impl Fn(usize) -> (f64, [f64; 3])) -> [f64; 3] {
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
    let (t0, a) = point(k - 1);
    let (t1, b) = point(k);
    let s = (t - t0) / (t1 - t0);
    [
        a[0] + s * (b[0] - a[0]),
        a[1] + s * (b[1] - a[1]),
        a[2] + s * (b[2] - a[2]),
    ]
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
    piecewise_linear(t, len, |k| (run[k].t_s, run[k].value))
}
