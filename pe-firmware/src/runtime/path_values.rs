//! The image's paths at one time, each evaluated once.
//!
//! A `[[load]]` spreads over its nodes, each record naming the load's ramp (a path of the
//! image), and gravity names its ramp once; a `[[prescribed]]` motion spreads over its held
//! nodes, each naming its path. Evaluated per node, a path of `p` points costs a search
//! through the points table and `O(p)` per node and step. [`RampValues`] keeps the value of
//! each ramp met at one time, so a ramp is evaluated once per [`crate::runtime::Runtime`]
//! stage however many nodes share it; [`PathsAt`] holds every motion path's value at the
//! node update's time, evaluated once before the nodes, as the host's `problem::curves::Curves`
//! and its `path_at` do once per step.
//!
//! The value is the same pure function of the points and `t` whichever node asks first, so
//! the bits do not change. Fixed capacity, no allocation: past [`RampValues::CACHED`]
//! distinct ramps at one time, or a path numbered [`PathsAt::PATHS`] or more, the others are
//! evaluated per node (the same bits, the old cost).

use crate::image::path::path_value;
use crate::image::PathPoint;

/// The values of the ramps evaluated so far at one time.
pub(crate) struct RampValues {
    at: [(u16, f64); RampValues::CACHED],
    len: usize,
    /// Evaluations done (lookups that missed), for the tests.
    evaluations: u32,
}

impl RampValues {
    /// Distinct ramps kept at one time (scenes have a handful of load curves).
    pub(crate) const CACHED: usize = 8;

    pub(crate) const fn new() -> Self {
        RampValues {
            at: [(0, 0.0); Self::CACHED],
            len: 0,
            evaluations: 0,
        }
    }

    /// Ramp `path`'s factor at `t` (the first component of the path's value), evaluated
    /// the first time this `RampValues` is asked for it. All calls on one `RampValues` must
    /// pass the same `points` and `t`.
    #[inline]
    pub(crate) fn factor(&mut self, points: &[PathPoint], path: u16, t: f64) -> f64 {
        if let Some(&(_, v)) = self.at[..self.len].iter().find(|(p, _)| *p == path) {
            return v;
        }
        self.evaluations += 1;
        let v = path_value(points, path, t)[0];
        if let Some(slot) = self.at.get_mut(self.len) {
            *slot = (path, v);
            self.len += 1;
        }
        v
    }

    /// How many times a ramp was evaluated.
    #[cfg(test)]
    pub(crate) fn evaluations(&self) -> u32 {
        self.evaluations
    }
}

/// Every path's value at one time `t` (the paths numbered below [`Self::PATHS`]), evaluated
/// once when made; the node update reads its held nodes' targets from it. One reference in
/// the update's loop, where the points table and `t` took three registers: the free nodes'
/// loop keeps its values in registers.
pub(crate) struct PathsAt<'a> {
    points: &'a [PathPoint],
    t: f64,
    values: [[f64; 3]; PathsAt::PATHS],
    /// Bit `p`: path `p` has points, its value is in `values[p]`.
    known: u16,
}

impl<'a> PathsAt<'a> {
    /// Paths held (prescribed motions come first in the table; scenes have a handful).
    pub(crate) const PATHS: usize = 16;

    /// Each path of `points` numbered below [`Self::PATHS`] at `t`: [`path_value`], once per
    /// path (at the first point of the path, the run `path_value` reads).
    pub(crate) fn new(points: &'a [PathPoint], t: f64) -> Self {
        let mut at = PathsAt {
            points,
            t,
            values: [[0.0; 3]; Self::PATHS],
            known: 0,
        };
        for p in points {
            let k = p.path as usize;
            if k < Self::PATHS && at.known & (1 << k) == 0 {
                at.values[k] = path_value(points, p.path, t);
                at.known |= 1 << k;
            }
        }
        at
    }

    /// Path `path`'s value at this time: [`path_value`]'s bits.
    #[inline]
    pub(crate) fn value(&self, path: u16) -> [f64; 3] {
        let k = path as usize;
        match self.values.get(k) {
            Some(v) if self.known & (1 << k) != 0 => *v,
            _ => path_value(self.points, path, self.t),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Segment;

    /// `n` paths, each of `len` points through (k·0.1 s, (path+1)·k), POLY345 segments.
    fn paths(n: u16, len: usize) -> heapless::Vec<PathPoint, 256> {
        let mut v = heapless::Vec::new();
        for path in 0..n {
            for k in 0..len {
                let point = PathPoint {
                    path,
                    t_s: 0.1 * k as f64,
                    value: [(path + 1) as f64 * k as f64, 0.0, 0.0],
                    segment: Segment::Poly345,
                };
                assert!(v.push(point).is_ok());
            }
        }
        v
    }

    /// 300 loaded nodes over 3 ramps: 3 evaluations, and every factor is `path_value`'s
    /// bits (at a time inside a smooth segment, where the factor is far from 0 and 1).
    #[test]
    fn each_ramp_is_evaluated_once_and_gives_path_values_bits() {
        let points = paths(3, 20);
        let t = 0.537;
        let mut r = RampValues::new();
        for node in 0..300u16 {
            let path = node % 3;
            let want = path_value(&points, path, t)[0];
            assert!(want > 1.0, "a value, not a zero: {want}");
            assert_eq!(r.factor(&points, path, t).to_bits(), want.to_bits());
        }
        assert_eq!(r.evaluations(), 3);
    }

    /// More distinct ramps than are kept: still each one's bits; the ones past the capacity
    /// are evaluated per call.
    #[test]
    fn ramps_past_the_capacity_are_evaluated_each_time() {
        let n = RampValues::CACHED as u16 + 2;
        let points = paths(n, 4);
        let t = 0.15;
        let mut r = RampValues::new();
        for _ in 0..2 {
            for path in 0..n {
                let want = path_value(&points, path, t)[0];
                assert_eq!(r.factor(&points, path, t).to_bits(), want.to_bits());
            }
        }
        assert_eq!(
            r.evaluations(),
            n as u32 + 2,
            "the two past the capacity, twice"
        );
    }

    /// Motion paths of three components at one time: every value is `path_value`'s bits,
    /// far from zero, for the paths below the capacity, past it (evaluated per call) and
    /// for a path the table does not hold (`path_value`'s zero).
    #[test]
    fn paths_at_one_time_give_path_values_bits() {
        let n = PathsAt::PATHS as u16 + 2;
        let mut points = paths(n, 4);
        for p in points.iter_mut() {
            p.value = [p.value[0], 2.0 * p.value[0] + 1.0, -p.value[0] - 1.0];
        }
        let t = 0.15;
        let at = PathsAt::new(&points, t);
        assert_eq!(at.known.count_ones() as usize, PathsAt::PATHS);
        for path in 0..n {
            let want = path_value(&points, path, t);
            assert!(want.iter().all(|v| v.abs() > 0.1), "{want:?}");
            assert_eq!(at.value(path).map(f64::to_bits), want.map(f64::to_bits));
        }
        assert_eq!(at.value(n + 5), [0.0; 3], "no such path: path_value's zero");
    }
}
