//! The domains of command-line numbers, checked as the options are parsed (before any
//! work): clap's `value_parser` for every count, step count, duration, rate and tolerance of
//! `pe` and board-sim. A value outside its domain is refused naming the option and the
//! domain (`error: invalid value '0' for '--threads <THREADS>': must be at least 1`); 0,
//! negative values, NaN and infinities never reach a run.

/// A count of things that must exist (threads, workers, runs, elements, steps): an integer
/// of at least 1.
pub fn count(s: &str) -> Result<usize, String> {
    match s.trim().parse::<usize>() {
        Ok(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(_) => Err("expected a whole number of at least 1".into()),
    }
}

/// A count as `u64` (time steps, runs): an integer of at least 1.
pub fn steps(s: &str) -> Result<u64, String> {
    count(s).map(|n| n as u64)
}

/// A finite number above 0 (a duration, a rate, a bandwidth, a timeout).
pub fn positive(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        Ok(_) => Err("must be a finite number above 0".into()),
        Err(_) => Err("expected a number above 0".into()),
    }
}

/// A finite number of at least 0 (a latency, a tolerance).
pub fn non_negative(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        Ok(_) => Err("must be a finite number of at least 0".into()),
        Err(_) => Err("expected a number of at least 0".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The edges of each domain: the least accepted value, and 0, negatives, NaN, infinity
    /// and words refused with a message saying the domain.
    #[test]
    fn domains_accept_their_edges_and_refuse_the_rest() {
        assert_eq!(count("1"), Ok(1));
        assert_eq!(steps("400"), Ok(400));
        assert_eq!(positive("1e-9"), Ok(1e-9));
        assert_eq!(non_negative("0"), Ok(0.0));
        for bad in ["0", "-1", "1.5", "two", ""] {
            assert!(count(bad).unwrap_err().contains("at least 1"), "{bad}");
            assert!(steps(bad).is_err(), "{bad}");
        }
        for bad in ["0", "-0.1", "NaN", "inf", "-inf", "x"] {
            assert!(positive(bad).unwrap_err().contains("above 0"), "{bad}");
        }
        for bad in ["-1e-12", "NaN", "inf", "x"] {
            assert!(
                non_negative(bad).unwrap_err().contains("at least 0"),
                "{bad}"
            );
        }
    }
}
