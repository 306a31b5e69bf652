//! The tool forces a haptic device renders: per millisecond of simulated time, the mean
//! over the steps in it of each tool's force. A step belongs to the millisecond its start
//! time falls in (`⌊1000 t⌋`); a millisecond is complete when a step ends in a later one.

/// The running means of the millisecond in progress.
#[derive(Clone, Debug)]
pub struct ForceMeans {
    ms: u64,
    sum_n: Vec<[f64; 3]>,
    steps: u32,
}

/// A completed millisecond: its end (s) and each tool's mean force (N).
#[derive(Clone, Debug, PartialEq)]
pub struct MsMean {
    pub time_s: f64,
    pub force_n: Vec<[f64; 3]>,
}

/// The millisecond `t_s` falls in.
fn ms_of(t_s: f64) -> u64 {
    (t_s * 1e3).floor().max(0.0) as u64
}

impl ForceMeans {
    pub fn new(tools: usize) -> ForceMeans {
        ForceMeans {
            ms: 0,
            sum_n: vec![[0.0; 3]; tools],
            steps: 0,
        }
    }

    /// A step from `start_s` to `end_s` whose tool forces were `force_n`: the mean of the
    /// millisecond it completes, if it completes one.
    pub fn add(&mut self, start_s: f64, end_s: f64, force_n: &[[f64; 3]]) -> Option<MsMean> {
        let ms = ms_of(start_s);
        if ms != self.ms {
            // A step longer than a millisecond skipped some: start over at this one.
            self.ms = ms;
            self.steps = 0;
            self.sum_n.iter_mut().for_each(|s| *s = [0.0; 3]);
        }
        for (s, f) in self.sum_n.iter_mut().zip(force_n) {
            for i in 0..3 {
                s[i] += f[i];
            }
        }
        self.steps += 1;
        if ms_of(end_s) == ms {
            return None;
        }
        let n = self.steps as f64;
        let mean = MsMean {
            time_s: (ms + 1) as f64 * 1e-3,
            force_n: self.sum_n.iter().map(|s| s.map(|v| v / n)).collect(),
        };
        self.ms = ms_of(end_s);
        self.steps = 0;
        self.sum_n.iter_mut().for_each(|s| *s = [0.0; 3]);
        Some(mean)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// dt = 0.3 ms: the first millisecond holds the steps starting at 0, 0.3, 0.6 and 0.9
    /// ms (the last ends at 1.2 ms and completes it); forces 1, 2, 3, 4 N give 2.5 N.
    #[test]
    fn a_millisecond_is_the_mean_of_the_steps_that_start_in_it() {
        let mut m = ForceMeans::new(1);
        let dt = 0.3e-3;
        let mut out = Vec::new();
        for k in 0..10u32 {
            let (t0, t1) = (k as f64 * dt, (k + 1) as f64 * dt);
            if let Some(x) = m.add(t0, t1, &[[k as f64 + 1.0, 0.0, -1.0]]) {
                out.push((k, x));
            }
        }
        assert_eq!(out.len(), 2, "{out:?}");
        assert_eq!(out[0].0, 3);
        assert_eq!(out[0].1.time_s, 1e-3);
        assert!((out[0].1.force_n[0][0] - 2.5).abs() < 1e-12);
        assert_eq!(out[0].1.force_n[0][2], -1.0);
        // Second millisecond: steps 4..=6 start at 1.2, 1.5, 1.8 ms (forces 5, 6, 7).
        assert_eq!(out[1].0, 6);
        assert!((out[1].1.force_n[0][0] - 6.0).abs() < 1e-12);
    }
}
