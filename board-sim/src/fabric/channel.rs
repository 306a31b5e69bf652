//! One directed link between board threads: a bounded queue of frames (or packets) and the
//! receiving board's doorbell, rung as a frame arrives so that a waiting board can park
//! instead of spinning.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

use link_proto::{Peek, RecvError, SendError};

use crate::clock::SimulatedTime;

/// A board's doorbell: rung when a frame arrives for it.
#[derive(Default)]
pub struct Doorbell {
    /// Rung since the last wait, and how many threads are parked in [`Doorbell::wait`].
    state: Mutex<Bell>,
    cv: Condvar,
    /// With simulated time: every frame queued or taken through this bell's links is
    /// activity ([`SimulatedTime::touch`]).
    activity: Option<Arc<SimulatedTime>>,
}

#[derive(Default)]
struct Bell {
    rung: bool,
    parked: u32,
}

impl Doorbell {
    /// A doorbell whose links' frames count as `time`'s activity.
    pub fn counting(time: Arc<SimulatedTime>) -> Doorbell {
        Doorbell {
            activity: Some(time),
            ..Default::default()
        }
    }
    /// A frame was queued (rings) or taken: activity for simulated time.
    pub fn touch(&self) {
        if let Some(t) = &self.activity {
            t.touch();
        }
    }
    /// Rings, as something arrived: activity ([`Doorbell::touch`]), and a wake-up.
    pub fn ring(&self) {
        self.touch();
        self.wake();
    }
    /// Wakes: a parked waiter wakes, a later wait returns at once. Wakes (a system call)
    /// only when a waiter is parked: most frames arrive while their board's worker is busy
    /// or spinning, and a ring per frame was a system call per frame.
    pub fn wake(&self) {
        let parked = match self.state.lock() {
            Ok(mut b) => {
                b.rung = true;
                b.parked > 0
            }
            Err(_) => true,
        };
        if parked {
            self.cv.notify_one();
        }
    }
    /// Waits until rung (or `timeout`), and clears it; whether a ring ended it (false when
    /// the timeout did). The count of parked waiters changes under the lock that `ring`
    /// reads it under, so no ring is missed.
    pub fn wait(&self, timeout: Duration) -> bool {
        let Ok(mut b) = self.state.lock() else {
            return false;
        };
        if !b.rung {
            b.parked += 1;
            match self.cv.wait_timeout(b, timeout) {
                Ok((g, waited)) => {
                    b = g;
                    b.parked -= 1;
                    if waited.timed_out() {
                        b.rung = false;
                        return false;
                    }
                }
                Err(_) => return false,
            }
        }
        std::mem::replace(&mut b.rung, false)
    }

    /// Threads parked in [`Doorbell::wait`] now.
    #[cfg(test)]
    fn parked(&self) -> u32 {
        self.state.lock().map(|b| b.parked).unwrap_or(0)
    }
}

/// A link's frames in flight, and the buffers of frames taken, kept for the next frames
/// (a link carries millions of frames in a run: no allocation each).
#[derive(Default)]
struct Queue {
    frames: VecDeque<Vec<u8>>,
    spare: Vec<Vec<u8>>,
}

impl Queue {
    fn len(&self) -> usize {
        self.frames.len()
    }
    fn push_back(&mut self, bytes: &[u8]) {
        let mut v = self.spare.pop().unwrap_or_default();
        v.clear();
        v.extend_from_slice(bytes);
        self.frames.push_back(v);
    }
}

/// One directed link: a bounded queue of frames plus the receiver's doorbell.
pub struct Channel {
    queue: Mutex<Queue>,
    /// Frames in `queue`, kept beside it so that a receiver polling an empty link does not
    /// take the lock (a board polls its links far more often than frames arrive).
    len: AtomicUsize,
    bell: Arc<Doorbell>,
}

impl Channel {
    /// An empty link whose frames ring `bell`.
    pub(crate) fn new(bell: Arc<Doorbell>) -> Arc<Channel> {
        Arc::new(Channel {
            queue: Mutex::new(Queue::default()),
            len: AtomicUsize::new(0),
            bell,
        })
    }

    /// Queues `frame` (at most `max` in flight) and rings the receiver.
    pub(crate) fn push(&self, frame: &[u8], max: usize) -> Result<(), SendError> {
        let mut q = self.queue.lock().map_err(|_| SendError::NoLink)?;
        if q.len() >= max {
            return Err(SendError::WouldBlock);
        }
        q.push_back(frame);
        self.len.store(q.len(), Ordering::Release);
        drop(q);
        self.bell.ring();
        Ok(())
    }

    /// Takes the oldest frame into `buf`: its length, or None when the queue is empty
    /// (seen without the lock; a frame pushed meanwhile is taken at the next poll, which
    /// its doorbell brings).
    pub(crate) fn pop_into(&self, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        if self.len.load(Ordering::Acquire) == 0 {
            return Ok(None);
        }
        let mut q = self.queue.lock().map_err(|_| RecvError::NoLink)?;
        let front = q.frames.pop_front();
        self.len.store(q.len(), Ordering::Release);
        if front.is_some() {
            // A queue with room again may let its sender move.
            self.bell.touch();
        }
        match front {
            None => Ok(None),
            Some(f) => {
                let n = f.len();
                let copied = buf.get_mut(..n).map(|dst| dst.copy_from_slice(&f));
                q.spare.push(f);
                copied.ok_or(RecvError::BufferTooSmall { needed: n })?;
                Ok(Some(n))
            }
        }
    }

    /// The first byte of the frame at the head of the queue, without taking it.
    pub(crate) fn peek(&self) -> Peek {
        if self.len.load(Ordering::Acquire) == 0 {
            return Peek::Nothing;
        }
        let Ok(q) = self.queue.lock() else {
            return Peek::Unknown;
        };
        match q.frames.front() {
            None => Peek::Nothing,
            Some(f) => f.first().map_or(Peek::Unknown, |&b| Peek::First(b)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ring with no one parked is kept for the next wait, and a ring while a thread is
    /// parked wakes it: its wait reports the ring, not the end of its 20 s timeout (which
    /// is what a ring that skipped the wake-up would leave it to). The waiter waits again
    /// after a spurious wake-up (the ring then finds it unparked and is kept for it).
    #[test]
    fn a_ring_wakes_a_parked_waiter_and_is_kept_when_none_is_parked() {
        let bell = Arc::new(Doorbell::default());
        bell.ring();
        assert!(
            bell.wait(Duration::from_secs(60)),
            "the ring before the wait is kept"
        );
        assert_eq!(bell.parked(), 0);
        let b = bell.clone();
        let waiter = std::thread::spawn(move || (0..3).any(|_| b.wait(Duration::from_secs(20))));
        while bell.parked() == 0 {
            std::thread::yield_now();
        }
        bell.ring();
        assert!(
            waiter.join().unwrap_or(false),
            "the parked waiter saw the ring"
        );
        assert_eq!(bell.parked(), 0);
    }
}
