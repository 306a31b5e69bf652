//! Functions of time: a prescribed path or a load ramp ([`Path1`], linear or smooth from
//! point to point), and those that many nodes share, kept once: the loads' ramps (the
//! solver evaluates each once per step; the compiler writes each once into the path table).
//!
//! A `[[load]]` spreads over its nodes, each with the load's ramp; evaluated per node, a
//! ramp of `p` points costs `O(p)` per loaded node and step (a smooth 161-point ramp on
//! 1331 loaded nodes of the seed's box doubled the run). [`Curves`] keeps each distinct
//! curve once and its value at the step's time, so a step costs `O(p)` per curve. The
//! value is [`Path1::at`]'s, the board's `piecewise`, on the same inputs: the same
//! bits as evaluating it per node.

use pe_firmware::image::Segment;

/// A function of time through `(t, value)` points, each segment linear or smooth
/// ([`Segment`]), held constant outside.
#[derive(Clone, Debug, PartialEq)]
pub struct Path1<const N: usize> {
    pub points: Vec<(f64, [f64; N])>,
    /// How every segment goes from one point to the next.
    pub segment: Segment,
}

impl<const N: usize> Path1<N> {
    /// Through `points`, straight from one to the next.
    pub fn linear(points: Vec<(f64, [f64; N])>) -> Path1<N> {
        Path1 {
            points,
            segment: Segment::Linear,
        }
    }

    /// Value at `t` (the firmware's [`pe_firmware::image::piecewise`], so host and board
    /// interpolate to the same bits).
    pub fn at(&self, t: f64) -> [f64; N] {
        let v = pe_firmware::image::piecewise(t, self.points.len(), |k| {
            let (tk, p) = self.points[k];
            let mut q = [0.0; 3];
            q[..N].copy_from_slice(&p);
            (tk, q, self.segment)
        });
        core::array::from_fn(|i| v[i])
    }
}

/// The distinct curves of a list of users (each `None` or one curve), and their values at
/// the last time evaluated.
#[derive(Clone, Debug, Default)]
pub struct Curves<const N: usize> {
    curves: Vec<Path1<N>>,
    /// Each user's curve (an index into `curves`).
    of_user: Vec<Option<usize>>,
    at: Vec<[f64; N]>,
}

impl<const N: usize> Curves<N> {
    /// The curves of `users`, equal curves kept once.
    pub fn of<'a>(users: impl Iterator<Item = Option<&'a Path1<N>>>) -> Curves<N> {
        let mut c = Curves {
            curves: Vec::new(),
            of_user: Vec::new(),
            at: Vec::new(),
        };
        for u in users {
            let k = u.map(|curve| match c.curves.iter().position(|q| q == curve) {
                Some(k) => k,
                None => {
                    c.curves.push(curve.clone());
                    c.curves.len() - 1
                }
            });
            c.of_user.push(k);
        }
        c.at = vec![[0.0; N]; c.curves.len()];
        c
    }

    /// The distinct curves, in the order their first users come.
    pub fn curves(&self) -> &[Path1<N>] {
        &self.curves
    }

    /// User `k`'s curve (an index into [`Self::curves`]; `None`: it has none).
    pub fn index(&self, k: usize) -> Option<usize> {
        self.of_user.get(k).copied().flatten()
    }

    /// Evaluates every curve at `t`.
    pub fn evaluate(&mut self, t: f64) {
        for (v, curve) in self.at.iter_mut().zip(&self.curves) {
            *v = curve.at(t);
        }
    }

    /// User `k`'s curve's value at the last [`Self::evaluate`] (`None`: it has none).
    pub fn value(&self, k: usize) -> Option<[f64; N]> {
        self.index(k).map(|c| self.at[c])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(points: &[(f64, f64)]) -> Path1<1> {
        Path1::linear(points.iter().map(|&(t, v)| (t, [v])).collect())
    }

    #[test]
    fn equal_curves_are_kept_once_and_give_each_users_bits() {
        let smooth: Vec<(f64, f64)> = (0..161)
            .map(|k| {
                let s = k as f64 / 160.0;
                (
                    0.5 * s,
                    10.0 * s.powi(3) - 15.0 * s.powi(4) + 6.0 * s.powi(5),
                )
            })
            .collect();
        let (a, b) = (ramp(&smooth), ramp(&[(0.0, 0.0), (0.1, 1.0)]));
        let users = [Some(&a), None, Some(&b), Some(&a.clone()), Some(&a)];
        let mut c = Curves::of(users.iter().copied());
        assert_eq!(
            c.curves.len(),
            2,
            "the smooth ramp once, the linear one once"
        );
        for t in [0.0, 0.0371, 0.0999, 0.25, 0.4999, 0.7] {
            c.evaluate(t);
            for (k, u) in users.iter().enumerate() {
                // Each user's value is its own curve's, bit for bit.
                let want = u.map(|r| r.at(t)[0].to_bits());
                assert_eq!(
                    c.value(k).map(|v| v[0].to_bits()),
                    want,
                    "user {k} at t = {t}"
                );
            }
        }
        c.evaluate(0.25);
        let mid = c.value(0).map(|v| v[0]);
        assert!(
            mid.is_some_and(|v| (v - 0.5).abs() < 1e-12),
            "POLY345 at half time: {mid:?}"
        );
        assert_eq!(c.value(99), None);
    }
}
