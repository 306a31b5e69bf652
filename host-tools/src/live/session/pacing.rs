//! The wall clock a session keeps to: simulated time never runs ahead of wall time since
//! the start; behind, the session steps as fast as it can and, past `max_lag_s`, lets its
//! clock slip (the anchor moves forward by the lag: time slows rather than lag piling up).
//! Time is passed in (`now`), so the policy is tested without waiting.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// The session's clock and its record of how it kept up.
#[derive(Clone, Debug)]
pub struct Pacer {
    start: Instant,
    /// The instant simulated time 0 corresponds to (moved forward by each slip).
    anchor: Instant,
    pace: bool,
    max_lag_s: f64,
    lag_s: f64,
    pub lag_max_s: f64,
    pub slips: u64,
    pub slipped_s: f64,
    /// (wall, simulated time) samples over the last second, for the real-time factor.
    window: VecDeque<(Instant, f64)>,
}

/// How often the real-time factor's window takes a sample.
const SAMPLE_EVERY: Duration = Duration::from_millis(50);
/// The real-time factor's window.
const WINDOW: Duration = Duration::from_secs(1);

impl Pacer {
    /// A clock started at `now`; `pace` false runs as fast as possible (tests, benchmarks).
    pub fn new(now: Instant, pace: bool, max_lag_s: f64) -> Pacer {
        Pacer {
            start: now,
            anchor: now,
            pace,
            max_lag_s,
            lag_s: 0.0,
            lag_max_s: 0.0,
            slips: 0,
            slipped_s: 0.0,
            window: VecDeque::from([(now, 0.0)]),
        }
    }

    /// How long to wait before a step that ends at simulated time `end_s`: `None` when it
    /// is due (wall time has reached it) or the session is not paced.
    pub fn wait(&self, end_s: f64, now: Instant) -> Option<Duration> {
        if !self.pace {
            return None;
        }
        let due = self.anchor + Duration::from_secs_f64(end_s.max(0.0));
        due.checked_duration_since(now).filter(|d| !d.is_zero())
    }

    /// After a step that reached simulated time `sim_s`: the lag, and a slip when it is
    /// past the bound (returns the time slipped).
    pub fn after_step(&mut self, sim_s: f64, now: Instant) -> Option<f64> {
        let wall = now.saturating_duration_since(self.anchor).as_secs_f64();
        self.lag_s = wall - sim_s;
        if self.window.back().is_none_or(|w| now >= w.0 + SAMPLE_EVERY) {
            self.window.push_back((now, sim_s));
            while self.window.len() > 2 && self.window[1].0 + WINDOW <= now {
                self.window.pop_front();
            }
        }
        if !self.pace {
            return None;
        }
        self.lag_max_s = self.lag_max_s.max(self.lag_s);
        if self.lag_s > self.max_lag_s {
            let slip = self.lag_s;
            self.anchor += Duration::from_secs_f64(slip);
            self.slips += 1;
            self.slipped_s += slip;
            self.lag_s = 0.0;
            return Some(slip);
        }
        None
    }

    /// Wall time less simulated time at the last step (s), after any slip.
    pub fn lag_s(&self) -> f64 {
        self.lag_s
    }

    /// Wall time since the start (s).
    pub fn wall_s(&self, now: Instant) -> f64 {
        now.saturating_duration_since(self.start).as_secs_f64()
    }

    /// Simulated over wall time over the last second (or since the start).
    pub fn real_time_factor(&self) -> f64 {
        match (self.window.front(), self.window.back()) {
            (Some(a), Some(b)) if b.0 > a.0 => (b.1 - a.1) / (b.0 - a.0).as_secs_f64(),
            _ => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(t: f64) -> Duration {
        Duration::from_secs_f64(t * 1e-3)
    }

    #[test]
    fn a_step_waits_for_the_wall_clock_and_never_runs_ahead() {
        let t0 = Instant::now();
        let p = Pacer::new(t0, true, 0.1);
        assert_eq!(p.wait(0.002, t0 + ms(0.5)), Some(ms(1.5)));
        assert_eq!(p.wait(0.002, t0 + ms(2.0)), None);
        assert_eq!(p.wait(0.002, t0 + ms(3.0)), None);
        let free = Pacer::new(t0, false, 0.1);
        assert_eq!(free.wait(10.0, t0), None);
    }

    /// Behind by 50 ms: no slip (below 0.1 s), the lag reported; behind by 150 ms: one
    /// slip of 150 ms, the lag back to 0 and the next step due 150 ms later.
    #[test]
    fn past_the_bound_the_clock_slips_by_the_lag() {
        let t0 = Instant::now();
        let mut p = Pacer::new(t0, true, 0.1);
        assert_eq!(p.after_step(0.010, t0 + ms(60.0)), None);
        assert!((p.lag_s() - 0.050).abs() < 1e-9);
        let slip = p.after_step(0.020, t0 + ms(170.0)).unwrap();
        assert!((slip - 0.150).abs() < 1e-9, "{slip}");
        assert_eq!((p.slips, p.lag_s()), (1, 0.0));
        assert!((p.lag_max_s - 0.150).abs() < 1e-9);
        // Simulated 0.021 s is now due at 0.021 + 0.150 s of wall time.
        let w = p.wait(0.021, t0 + ms(170.0)).unwrap();
        assert!((w.as_secs_f64() - 0.001).abs() < 1e-6, "{w:?}");
    }

    #[test]
    fn the_real_time_factor_is_over_the_last_second() {
        let t0 = Instant::now();
        let mut p = Pacer::new(t0, false, 0.1);
        // Half speed for 2 s, then real time for 1 s: the window sees only the last.
        for k in 1..=40 {
            p.after_step(0.025 * k as f64, t0 + Duration::from_millis(50 * k));
        }
        assert!((p.real_time_factor() - 0.5).abs() < 1e-6);
        for k in 1..=20 {
            p.after_step(
                1.0 + 0.05 * k as f64,
                t0 + Duration::from_millis(2000 + 50 * k),
            );
        }
        assert!(
            (p.real_time_factor() - 1.0).abs() < 1e-6,
            "{}",
            p.real_time_factor()
        );
    }
}
