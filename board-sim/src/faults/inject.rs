//! The fault injector: a [`Links`] wrapper that drops, corrupts, delays or stalls what a
//! board sends, every draw from the run's seed mixed with the board (and, for a global
//! packet, its destination, kind, step and count), so that a run replays exactly, and that
//! records what it injected (the ground truth a stopped run's cause is checked against).

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};

use link_proto::{Face, Links, RecvError, SendError};

use super::rng::Rng;
use super::spec::{FaultScope, FaultSpec};
use crate::clock::SweepClock;
use crate::fabric::{frame_step, global_face, packet_header, packet_step};

/// Steps behind the latest that the fault injector keeps its per-step packet counts for.
const GLOBAL_COUNT_STEPS: u32 = 256;

/// An injected fault, as recorded by the injector.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Injected {
    pub board: [usize; 3],
    pub face: String,
    pub step: u32,
    pub what: String,
}

/// Wraps a board's links and injects faults into what it sends.
pub struct FaultyLinks<L> {
    pub inner: L,
    pub board: [usize; 3],
    spec: FaultSpec,
    rng: Rng,
    pub injected: Arc<Mutex<Vec<Injected>>>,
    /// Faces whose delay is recorded (at their first delayed frame).
    delayed: [bool; 6],
    /// Faces whose stall is recorded.
    stalled: [bool; 6],
    /// Frames held by the delay: (due, ns on `clock`; face; bytes), in sending order.
    held: VecDeque<(u64, Face, Vec<u8>)>,
    /// The board's worker's clock (wall or simulated), the delay's time.
    clock: Arc<SweepClock>,
    /// Step of the last data frame sent per face.
    last_step: [u32; 6],
    /// The seed of the global packets' draws (the frames' stream stays as without them).
    global_seed: u64,
    /// Per (destination, kind, step): how many packets were sent (retransmissions
    /// included); a packet's draws come from (seed, board, destination, kind, step, that
    /// count), so that they do not depend on the order packets to different destinations
    /// go out in (which depends on thread timing). Steps far behind are forgotten.
    global_counts: HashMap<(u8, u8, u32), u32>,
    /// The global packets sent through here are recovery envelopes
    /// (`link_proto::recovery::global`), not bare packets.
    pub global_envelopes: bool,
    /// The global stall is recorded.
    global_stalled: bool,
    /// Step of the last global packet whose step was readable.
    global_step: u32,
}

impl<L> FaultyLinks<L> {
    pub fn new(
        inner: L,
        board: [usize; 3],
        board_index: usize,
        spec: FaultSpec,
        injected: Arc<Mutex<Vec<Injected>>>,
        clock: Arc<SweepClock>,
    ) -> Self {
        let rng = Rng::new(spec.seed ^ (board_index as u64).wrapping_mul(0xA24B_AED4_963E_E407));
        let global_seed = spec.seed
            ^ 0x6C6F_6261_6C00_0000
            ^ (board_index as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93);
        FaultyLinks {
            inner,
            board,
            spec,
            rng,
            injected,
            delayed: [false; 6],
            stalled: [false; 6],
            held: VecDeque::new(),
            clock,
            last_step: [0; 6],
            global_seed,
            global_counts: Default::default(),
            global_envelopes: false,
            global_stalled: false,
            global_step: 0,
        }
    }
    fn record(&self, face: Face, step: u32, what: &str) {
        self.record_on(format!("{face:?}"), step, what);
    }
    fn record_on(&self, face: String, step: u32, what: &str) {
        if let Ok(mut v) = self.injected.lock() {
            v.push(Injected {
                board: self.board,
                face,
                step,
                what: what.into(),
            });
        }
    }

    /// Whether this board is stalled at `step` (it then sends nothing more).
    fn stalled_at(&self, step: u32) -> bool {
        self.spec
            .stall
            .is_some_and(|(b, s)| b == self.board && step as u64 >= s)
    }

    /// The draws of a global packet to `dst` of `kind` at `step`: its own stream, keyed
    /// by how many such packets went before it.
    fn global_draws(&mut self, dst: u8, kind: u8, step: u32) -> (f64, f64, u64) {
        if self.global_counts.len() > 4096 {
            self.global_counts
                .retain(|k, _| k.2.saturating_add(GLOBAL_COUNT_STEPS) >= step);
        }
        let c = self.global_counts.entry((dst, kind, step)).or_insert(0);
        *c += 1;
        let key = [dst, kind].map(u64::from);
        let mut rng = Rng::keyed(
            self.global_seed,
            &[key[0], key[1], u64::from(step), u64::from(*c)],
        );
        (rng.unit(), rng.unit(), rng.next_u64())
    }
}

/// `bytes` with bit `draw mod (8 len)` flipped; the bit's number.
fn flip_bit(bytes: &mut [u8], draw: u64) -> usize {
    let k = (draw % (bytes.len() as u64 * 8)) as usize;
    bytes[k / 8] ^= 1 << (k % 8);
    k
}

impl<L: Links> FaultyLinks<L> {
    /// Delivers the held frames that are due, in order (a frame the link refuses now waits
    /// with those behind it).
    fn release(&mut self) {
        let now = self.clock.now_ns();
        while let Some((due, face, bytes)) = self.held.front() {
            if *due > now || self.inner.try_send(*face, bytes).is_err() {
                break;
            }
            self.held.pop_front();
        }
    }

    /// Sends after the held frames (none are held without a delay).
    fn flush_then(&mut self, face: Face, bytes: &[u8]) -> Result<(), SendError> {
        self.release();
        if !self.held.is_empty() {
            return Err(SendError::WouldBlock);
        }
        self.inner.try_send(face, bytes)
    }

    /// Holds a (perhaps corrupted) frame for the delay.
    fn hold(&mut self, face: Face, step: u32, bytes: Vec<u8>) {
        if !self.delayed[face.index()] {
            self.delayed[face.index()] = true;
            self.record(face, step, &format!("delay {} ms", self.spec.delay_ms));
        }
        let due =
            (self.clock.now_ns()).saturating_add(self.spec.delay_ms.saturating_mul(1_000_000));
        self.held.push_back((due, face, bytes));
        self.release();
    }

    /// What a global send carries: the packet (unwrapped from its recovery envelope) and
    /// whether it is a recovery control envelope instead (an ack or a nack).
    fn global_packet<'p>(&self, p: &'p [u8]) -> (&'p [u8], bool) {
        if !self.global_envelopes {
            return (p, false);
        }
        match link_proto::recovery::global::data_packet(p) {
            Some(packet) => (packet, false),
            None => (p, true),
        }
    }
}

impl<L: Links> Links for FaultyLinks<L> {
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        // A control envelope belongs to the step of the last data frame on its link.
        let step = match frame_step(frame) {
            Some(s) => {
                self.last_step[face.index()] = s;
                s
            }
            None => self.last_step[face.index()],
        };
        if self.stalled_at(step) {
            // A stalled board sends nothing more (and says it did); each link's stall is
            // recorded at its first frame not sent.
            if !self.stalled[face.index()] {
                self.stalled[face.index()] = true;
                self.record(face, step, "stall");
            }
            return Ok(());
        }
        let (u_drop, u_corrupt, bit) = (self.rng.unit(), self.rng.unit(), self.rng.next_u64());
        let (u_drop, u_corrupt) = if self.spec.on == FaultScope::Global {
            (1.0, 1.0)
        } else {
            (u_drop, u_corrupt)
        };
        if u_drop < self.spec.drop {
            self.record(face, step, "drop");
            return Ok(());
        }
        if u_corrupt >= self.spec.corrupt && self.spec.delay_ms == 0 {
            return self.inner.try_send(face, frame);
        }
        let mut bytes = frame.to_vec();
        if u_corrupt < self.spec.corrupt {
            let k = flip_bit(&mut bytes, bit);
            self.record(face, step, &format!("corrupt bit {k}"));
        }
        if self.spec.delay_ms > 0 {
            self.hold(face, step, bytes);
            return Ok(());
        }
        self.flush_then(face, &bytes)
    }
    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.release();
        self.inner.try_recv(face, buf)
    }
    fn poll(&mut self) {
        self.release();
        self.inner.poll();
    }
    /// Faults hit frames as they are sent: the head of a link is what a receive would take.
    fn peek(&mut self, face: Face) -> link_proto::Peek {
        self.release();
        self.inner.peek(face)
    }
    /// The same drop and corrupt as frames (from the global stream), and the stall; recorded
    /// on `global to <destination>` at the packet's step (a recovery control envelope at
    /// the last packet's step).
    fn try_send_global(&mut self, p: &[u8]) -> Result<(), SendError> {
        // Packets and envelopes alike carry their destination first.
        let dst = link_proto::recovery::global::destination(p).unwrap_or(u8::MAX);
        let (packet, is_control) = self.global_packet(p);
        if !is_control {
            if let Some(s) = packet_step(packet) {
                self.global_step = s;
            }
        }
        let step = self.global_step;
        if self.stalled_at(step) {
            if !self.global_stalled {
                self.global_stalled = true;
                self.record_on(global_face(dst), step, "stall");
            }
            return Ok(());
        }
        let kind = if is_control {
            link_proto::recovery::global::envelope_type(p).unwrap_or(0)
        } else {
            packet_header(packet).map_or(0, |h| h.kind().code())
        };
        let (u_drop, u_corrupt, bit) = self.global_draws(dst, kind, step);
        if self.spec.on == FaultScope::Links {
            return self.inner.try_send_global(p);
        }
        if u_drop < self.spec.drop {
            self.record_on(global_face(dst), step, "drop");
            return Ok(());
        }
        if u_corrupt >= self.spec.corrupt || p.is_empty() {
            return self.inner.try_send_global(p);
        }
        let mut bytes = p.to_vec();
        let k = flip_bit(&mut bytes, bit);
        self.record_on(global_face(dst), step, &format!("corrupt bit {k}"));
        match self.inner.try_send_global(&bytes) {
            // A destination corrupted into no address: the network loses the packet.
            Err(SendError::NoLink) => Ok(()),
            r => r,
        }
    }
    fn try_recv_global(&mut self, b: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.inner.try_recv_global(b)
    }
}
