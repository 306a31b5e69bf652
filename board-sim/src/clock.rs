//! Time on the host: a worker's [`SweepClock`], read once per sweep over its boards, and
//! what each board sees of it: its runtime's [`ThreadEnv`] (time and waiting) and its link
//! recovery's [`SimClock`].
//!
//! A run's time is the host's wall clock ([`Clocking::Wall`], the default) or simulated
//! ([`Clocking::Simulated`], [`SimulatedTime`]): time that stands still while anything in
//! the machine can move and advances by a quantum only when nothing can, so that which
//! link times out first, and so which fault a stopped run is blamed on, does not depend on
//! how busy the host's cores are.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use pe_firmware::runtime::Environment;

use crate::fabric::Doorbell;

/// Where a run's time comes from (`board-sim run --clock`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Clocking {
    /// The host's wall clock: a board's wait lasts as long as its neighbour's thread takes,
    /// so a loaded host can make a healthy link look slow.
    #[default]
    Wall,
    /// [`SimulatedTime`] advancing `quantum_ns` at a time, only while every board waits.
    Simulated { quantum_ns: u64 },
}

impl Clocking {
    /// The simulated clock's default quantum: 100 us, a tenth of link recovery's 1 ms
    /// nack timer (`link_proto::recovery::face::ReliableConfig`).
    pub const QUANTUM_NS: u64 = 100_000;
}

/// A participant's slot in [`SimulatedTime::idle_at`] while it sweeps (or after it moved).
const BUSY: u64 = u64::MAX;
/// A participant's slot once it has ended: it holds no time back.
const RETIRED: u64 = u64::MAX - 1;
/// The low half of [`SimulatedTime::state`]: the activity count (wrapping, only compared
/// for equality); the high half: the quanta time has advanced by.
const ACTIVITY_MASK: u64 = 0xFFFF_FFFF;

/// Simulated time, shared by every participant of a run (its workers and the host's pose
/// sender).
///
/// Time advances by one quantum when every participant's latest sweep began after the
/// machine's latest activity and found nothing to do. Activity is anything that may let
/// another participant move: a board moving on ([`SweepClock::swept`]), a frame or packet
/// queued or taken ([`SimulatedTime::touch`], from the links' [`Doorbell`]s), a gate
/// raised. Both counts live in one word ([`SimulatedTime::state`]), so that a participant
/// reads a time and the activity it belongs to at once, and an advance is one
/// compare-and-swap that fails if anything happened since the sweeps it relies on began.
///
/// So a board's wait lasts, in simulated time, only as long as the machine as a whole is
/// stuck: a healthy neighbour that a loaded host runs slowly costs no simulated time, and
/// a fault (a stalled board, a frame held back) is found by the same link timeout on every
/// host. Which thread sweeps first can still change the order in which boards that time out
/// in the same quantum report; attribution orders observations by step, kind and board, not
/// by arrival (`crate::check::attribute`).
pub struct SimulatedTime {
    quantum_ns: u64,
    /// Quanta advanced (high 32 bits) and activity (low 32 bits).
    state: AtomicU64,
    /// Per participant: the state its latest sweep began at, when that sweep found nothing
    /// to do; [`BUSY`] while it sweeps; [`RETIRED`] once it has ended.
    idle_at: Vec<AtomicU64>,
}

impl SimulatedTime {
    /// Simulated time for `participants`, at 0, advancing `quantum_ns` at a time.
    pub fn new(participants: usize, quantum_ns: u64) -> Arc<SimulatedTime> {
        Arc::new(SimulatedTime {
            quantum_ns: quantum_ns.max(1),
            state: AtomicU64::new(0),
            idle_at: (0..participants).map(|_| AtomicU64::new(BUSY)).collect(),
        })
    }

    /// The time (ns) a state word stands for.
    fn time_of(&self, state: u64) -> u64 {
        (state >> 32).saturating_mul(self.quantum_ns)
    }

    /// The simulated time now (ns since the run began).
    pub fn now_ns(&self) -> u64 {
        self.time_of(self.state.load(Ordering::SeqCst))
    }

    /// Something happened that may let a participant move: counted, so that no advance
    /// relies on a sweep that began before it.
    pub fn touch(&self) {
        let _ = self
            .state
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |s| {
                Some((s & !ACTIVITY_MASK) | (s.wrapping_add(1) & ACTIVITY_MASK))
            });
    }

    /// Participant `p` begins a sweep: the state it sweeps at.
    fn begin(&self, p: usize) -> u64 {
        if let Some(slot) = self.idle_at.get(p) {
            slot.store(BUSY, Ordering::SeqCst);
        }
        self.state.load(Ordering::SeqCst)
    }

    /// Participant `p`'s sweep that began at `state` ended, having `moved` something or
    /// not; whether time advanced (by this participant: every other one's latest sweep also
    /// began at `state` and found nothing to do, and nothing happened since).
    fn end(&self, p: usize, state: u64, moved: bool) -> bool {
        if moved {
            self.touch();
            return false;
        }
        if let Some(slot) = self.idle_at.get(p) {
            slot.store(state, Ordering::SeqCst);
        }
        let all_idle = self.idle_at.iter().all(|slot| {
            let v = slot.load(Ordering::SeqCst);
            v == state || v == RETIRED
        });
        all_idle
            && self
                .state
                .compare_exchange(
                    state,
                    state.wrapping_add(1 << 32),
                    Ordering::SeqCst,
                    Ordering::SeqCst,
                )
                .is_ok()
    }

    /// Participant `p` has ended: it holds no time back.
    fn retire(&self, p: usize) {
        if let Some(slot) = self.idle_at.get(p) {
            slot.store(RETIRED, Ordering::SeqCst);
        }
    }
}

/// One participant of a run's [`SimulatedTime`]: its slot, and the doorbells to ring when
/// it advances time (every participant sweeps again at the new time).
pub struct Participant {
    pub time: Arc<SimulatedTime>,
    pub index: usize,
    pub bells: Vec<Arc<Doorbell>>,
}

impl Participant {
    /// Begins a sweep: its state.
    pub fn begin(&self) -> u64 {
        self.time.begin(self.index)
    }
    /// Ends the sweep begun at `state`; whether time advanced.
    pub fn end(&self, state: u64, moved: bool) -> bool {
        let advanced = self.time.end(self.index, state, moved);
        if advanced {
            self.bells.iter().for_each(|b| b.wake());
        }
        advanced
    }
}

/// A worker's clock: read once per sweep over its boards ([`SweepClock::tick`]) and seen by
/// all of them (their runtimes, their link recovery and the fault injector) until the
/// next. A board that waits is polled again only at a later sweep, so it sees every wait's
/// end at the time the worker saw it; and a clock read per link poll was 3-4% of the run.
pub struct SweepClock {
    start: Instant,
    now_ns: AtomicU64,
    simulated: Option<Participant>,
}

/// A sweep begun by [`SweepClock::tick`], for [`SweepClock::swept`].
#[derive(Clone, Copy)]
pub struct Sweep(u64);

impl SweepClock {
    /// A wall clock, started now.
    pub fn new() -> Arc<SweepClock> {
        Arc::new(SweepClock {
            start: Instant::now(),
            now_ns: AtomicU64::new(0),
            simulated: None,
        })
    }
    /// A participant's view of simulated time.
    pub fn simulated(participant: Participant) -> Arc<SweepClock> {
        Arc::new(SweepClock {
            start: Instant::now(),
            now_ns: AtomicU64::new(0),
            simulated: Some(participant),
        })
    }
    /// Reads the time (ns since the clock's start) for the sweep about to begin.
    pub fn tick(&self) -> Sweep {
        let (t, sweep) = match &self.simulated {
            None => (self.start.elapsed().as_nanos() as u64, Sweep(0)),
            Some(p) => {
                let state = p.begin();
                (p.time.time_of(state), Sweep(state))
            }
        };
        self.now_ns.store(t, Ordering::Relaxed);
        sweep
    }
    /// The sweep begun by `sweep` ended, having moved a board or not; whether simulated
    /// time advanced (never on the wall clock).
    pub fn swept(&self, sweep: Sweep, moved: bool) -> bool {
        self.simulated
            .as_ref()
            .is_some_and(|p| p.end(sweep.0, moved))
    }
    /// The time of the current sweep.
    pub fn now_ns(&self) -> u64 {
        self.now_ns.load(Ordering::Relaxed)
    }
    /// This clock's participant has ended (its thread returns): it holds no simulated time
    /// back. See [`Retire`].
    pub fn retire(&self) {
        if let Some(p) = &self.simulated {
            p.time.retire(p.index);
        }
    }
}

/// Retires a clock's participant when dropped: as its thread returns, whichever way (a
/// thread that ended without retiring would hold simulated time still for ever).
pub struct Retire<'c>(pub &'c SweepClock);

impl Drop for Retire<'_> {
    fn drop(&mut self) {
        self.0.retire();
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Time advances one quantum when every participant's latest sweep began at the current
    /// state and found nothing; not while one sweeps, not after a touch since the sweeps
    /// began, and a retired participant holds nothing back.
    #[test]
    fn time_advances_only_when_every_participant_is_stuck() {
        let t = SimulatedTime::new(2, 100);
        assert_eq!(t.now_ns(), 0);
        // Participant 0 stuck; 1 has not swept: no advance.
        let s = t.begin(0);
        assert!(!t.end(0, s, false), "1 has not swept yet");
        // 1 sweeps and moves: activity, still no advance.
        let s1 = t.begin(1);
        assert!(!t.end(1, s1, true));
        assert_eq!(t.now_ns(), 0);
        // Both stuck at the same state: the last one advances.
        let (a, b) = (t.begin(0), t.begin(1));
        assert_eq!(a, b);
        assert!(!t.end(0, a, false));
        assert!(t.end(1, b, false), "both stuck: time advances");
        assert_eq!(t.now_ns(), 100);
        // A frame queued after the sweeps began: no advance on their word.
        let (a, b) = (t.begin(0), t.begin(1));
        t.touch();
        assert!(!t.end(0, a, false));
        assert!(!t.end(1, b, false), "a touch since the sweeps began");
        assert_eq!(t.now_ns(), 100);
        // One retired: the other alone decides.
        t.retire(1);
        let a = t.begin(0);
        assert!(t.end(0, a, false));
        assert_eq!(t.now_ns(), 200);
    }

    /// The activity count wraps within its half of the word: time is untouched by it.
    #[test]
    fn activity_wraps_without_moving_time() {
        let t = SimulatedTime::new(1, 7);
        t.state.store((3 << 32) | ACTIVITY_MASK, Ordering::SeqCst);
        t.touch();
        assert_eq!(t.state.load(Ordering::SeqCst), 3 << 32);
        assert_eq!(t.now_ns(), 21);
    }
}
