//! The loads' ramps at one time, each evaluated once: a `[[load]]` spreads over its nodes,
//! each record naming the load's ramp (a path of the image); evaluated per node, a ramp of
//! `p` points costs a search through the points table and `O(p)` per loaded node and step.
//! [`RampValues`] keeps the value of each ramp met at this time, so a ramp is evaluated once
//! per [`crate::runtime::Runtime`] stage however many nodes share it, as the host's
//! `problem::curves::Curves` does once per step.
//!
//! The value is the same pure function of the points and `t` whichever node asks first, so
//! the bits do not change. Fixed capacity, no allocation: past [`RampValues::CACHED`]
//! distinct ramps at one time, the others are evaluated per node (the same bits, the old
//! cost).

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
}
