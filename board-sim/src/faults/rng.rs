//! The fault injection's random numbers: SplitMix64 from the run's one printed seed. The
//! fault wrappers and the fault campaign draw from this one type.

/// SplitMix64: small, fast and good enough for fault injection.
pub struct Rng(u64);

/// SplitMix64's increment (the golden ratio), also the multiplier that spreads a key.
const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    /// A stream for one key under `seed`: each value of `key` in turn spreads the state by
    /// a draw, so the stream depends on the key, not on the order keys are drawn in.
    pub fn keyed(seed: u64, key: &[u64]) -> Rng {
        Rng::new(
            key.iter()
                .fold(seed, |h, v| Rng::new(h ^ v.wrapping_mul(GOLDEN)).next_u64()),
        )
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(GOLDEN);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// A draw in [0, 1) (53 bits).
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}
