//! The pose-to-force latency: from the instant a transport read a pose to the send of the
//! first force message whose millisecond includes the step the pose took effect at.
//! Samples go into 10 µs bins up to 100 ms (the percentiles are bin upper edges; the
//! largest is kept exactly), so a long session's statistics cost a fixed size.

use std::time::Instant;

use crate::live::protocol::LatencyMs;

const BIN_S: f64 = 10e-6;
const BINS: usize = 10_000;

#[derive(Clone, Debug)]
pub struct Latency {
    /// Poses that took effect and whose force was not sent yet: (step, received).
    pending: Vec<(u64, Instant)>,
    bins: Vec<u64>,
    /// Samples past the last bin.
    over: u64,
    samples: u64,
    max_s: f64,
}

impl Default for Latency {
    fn default() -> Self {
        Latency {
            pending: Vec::new(),
            bins: vec![0; BINS],
            over: 0,
            samples: 0,
            max_s: 0.0,
        }
    }
}

impl Latency {
    /// A pose read at `received` took effect at step `step`.
    pub fn took_effect(&mut self, step: u64, received: Instant) {
        self.pending.push((step, received));
    }

    /// The force messages of the millisecond whose last step is `last_step` were sent at
    /// `now`: every pose that took effect at or before it is a sample.
    pub fn forces_sent(&mut self, last_step: u64, now: Instant) {
        let mut k = 0;
        while k < self.pending.len() {
            let (step, received) = self.pending[k];
            if step <= last_step {
                self.pending.swap_remove(k);
                self.add(now.saturating_duration_since(received).as_secs_f64());
            } else {
                k += 1;
            }
        }
    }

    fn add(&mut self, s: f64) {
        let bin = (s / BIN_S) as usize;
        match self.bins.get_mut(bin) {
            Some(b) => *b += 1,
            None => self.over += 1,
        }
        self.samples += 1;
        self.max_s = self.max_s.max(s);
    }

    /// The upper edge of the bin holding the `p`-quantile (s).
    fn quantile_s(&self, p: f64) -> f64 {
        let want = ((p * self.samples as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (k, n) in self.bins.iter().enumerate() {
            seen += n;
            if seen >= want {
                return ((k + 1) as f64 * BIN_S).min(self.max_s);
            }
        }
        self.max_s
    }

    pub fn stats(&self) -> LatencyMs {
        if self.samples == 0 {
            return LatencyMs::default();
        }
        LatencyMs {
            samples: self.samples,
            p50: 1e3 * self.quantile_s(0.5),
            p99: 1e3 * self.quantile_s(0.99),
            max: 1e3 * self.max_s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    /// 100 poses with latencies 0.1, 0.2, ... 10 ms: the median is 5.0 ms and the 99th
    /// percentile 9.9 ms, each to the 10 µs bin; the largest exactly 10 ms.
    #[test]
    fn percentiles_are_read_from_the_bins() {
        let mut l = Latency::default();
        let t0 = Instant::now();
        for k in 1..=100u64 {
            l.took_effect(k, t0);
            l.forces_sent(k, t0 + Duration::from_micros(100 * k));
        }
        let s = l.stats();
        assert_eq!(s.samples, 100);
        assert!((s.p50 - 5.0).abs() <= 0.0101, "{s:?}");
        assert!((s.p99 - 9.9).abs() <= 0.0101, "{s:?}");
        assert!((s.max - 10.0).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn a_pose_waits_for_the_millisecond_of_its_step() {
        let mut l = Latency::default();
        let t0 = Instant::now();
        l.took_effect(10, t0);
        l.forces_sent(9, t0 + Duration::from_millis(1));
        assert_eq!(l.stats().samples, 0);
        l.forces_sent(12, t0 + Duration::from_millis(2));
        assert_eq!(l.stats().samples, 1);
        assert!((l.stats().max - 2.0).abs() < 1e-9);
    }
}
