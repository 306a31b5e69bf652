//! Time on the host: a worker's [`SweepClock`], read once per sweep over its boards, and
//! what each board sees of it: its runtime's [`ThreadEnv`] (time and waiting) and its link
//! recovery's [`SimClock`].

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use pe_firmware::runtime::Environment;

use crate::fabric::Doorbell;

/// A worker's clock: read once per sweep over its boards ([`SweepClock::tick`]) and seen by
/// all of them (their runtimes and their link recovery) until the next. A board that waits
/// is polled again only at a later sweep, so it sees every wait's end at the time the
/// worker saw it; and a clock read per link poll was 3-4% of the run.
pub struct SweepClock {
    start: Instant,
    now_ns: AtomicU64,
}

impl SweepClock {
    pub fn new() -> Arc<SweepClock> {
        Arc::new(SweepClock {
            start: Instant::now(),
            now_ns: AtomicU64::new(0),
        })
    }
    /// Reads the time (ns since the clock's start) for the sweep about to begin.
    pub fn tick(&self) {
        let t = self.start.elapsed().as_nanos() as u64;
        self.now_ns.store(t, Ordering::Relaxed);
    }
    /// The time of the current sweep.
    pub fn now_ns(&self) -> u64 {
        self.now_ns.load(Ordering::Relaxed)
    }
}

/// A board's clock for link recovery: its worker's [`SweepClock`], passed in.
pub struct SimClock(pub Arc<SweepClock>);

impl link_proto::Clock for SimClock {
    fn now_ns(&mut self) -> u64 {
        self.0.now_ns()
    }
}

/// Time and waiting for a board thread.
pub struct ThreadEnv {
    pub clock: Arc<SweepClock>,
    pub bell: Arc<Doorbell>,
    spins: u32,
}

impl ThreadEnv {
    pub fn new(bell: Arc<Doorbell>, clock: Arc<SweepClock>) -> Self {
        ThreadEnv {
            clock,
            bell,
            spins: 0,
        }
    }
}

impl link_proto::Clock for ThreadEnv {
    fn now_ns(&mut self) -> u64 {
        self.clock.now_ns()
    }
}

impl Environment for ThreadEnv {
    fn idle(&mut self) {
        // Spin briefly (a frame is often about to arrive), then park on the doorbell.
        self.spins += 1;
        if !self.spins.is_multiple_of(64) {
            std::hint::spin_loop();
            std::thread::yield_now();
        } else {
            self.bell.wait(Duration::from_millis(2));
        }
    }
}
