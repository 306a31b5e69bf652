//! Global recovery, on the global network: a [`Links`] wrapper that numbers the packets of
//! every (source, destination) flow, acknowledges them, and retransmits a packet lost or
//! damaged, within bounded retries. The faces pass through untouched (stack it on
//! [`crate::recovery::face::Reliable`] for the point-to-point links).
//!
//! Every global packet goes out in an envelope (little-endian):
//!
//! | offset  | size | field                                                               |
//! |---------|------|---------------------------------------------------------------------|
//! | 0       | 1    | destination address (the network routes on byte 0, as on a packet) |
//! | 1       | 1    | source address                                                      |
//! | 2       | 1    | type: `0xB1` data, `0xB2` ack, `0xB3` nack                          |
//! | 3       | 1    | reserved (0)                                                        |
//! | 4       | 2    | seq (u16): data: its number in the flow; ack: the next expected (all before it arrived); nack: the number wanted (all before it arrived) |
//! | 6       | `n`  | (data) the packet ([`crate::packet`]), ending with its own CRC-32   |
//! | 6 + `n` | 4    | CRC-32 of bytes `0 .. 6` followed by (data) the packet's last four  |
//!
//! [`OVERHEAD`] = 10 bytes per packet; an ack or nack is [`OVERHEAD`] bytes. As on the
//! links ([`crate::recovery::face`]; the length and the CRC rule are
//! [`crate::recovery::envelope`]'s), the packet's own CRC protects the packet and the envelope's
//! its header and the packet's CRC; a receiver (a board or a sink) checks both.
//!
//! The protocol, per flow (go-back-N with a window of `window` packets):
//! - The sender keeps every packet until it is acknowledged, at most `window` per
//!   destination and `tx_slots` in all (slots shared by the peers); a send beyond that is
//!   [`SendError::WouldBlock`] (flow control).
//! - The receiver delivers a flow in order only. The next expected packet is delivered
//!   and acknowledged (one cumulative ack per service of the port); a duplicate is dropped
//!   and acknowledged again; a packet beyond the next expected (one was lost) is dropped,
//!   the first beyond a gap answered with a nack of the next expected (again only after
//!   `retransmit_after_ns`); an envelope failing its CRC is dropped (its source is not
//!   trusted: the sender's timer recovers it).
//! - The sender retransmits every unacknowledged packet from the one asked for on a nack
//!   (a nack for the same packet again is ignored until the window moves or the timer
//!   fires: no storm of retransmissions from a burst of nacks), and from the oldest when
//!   the oldest has waited `retransmit_after_ns` for its ack,
//!   doubling with every retransmission up to `retransmit_backoff_max_ns`. An ack that
//!   moves the window on starts the count again. After `retries` retransmissions without
//!   an ack the flow is given up: [`GlobalReliable::failure`] names the peer, and
//!   [`Links::try_recv_global`] returns [`RecvError::GlobalRetriesExhausted`] (and every
//!   later send [`SendError::NoLink`]).
//! - Peer state is kept only for the addresses a board talks to: `peers_max` slots, each
//!   taken at the first packet to or from a new address. A send to a new address with
//!   every slot taken is [`SendError::NoLink`]; a packet from one is dropped (counted in
//!   [`GlobalRecovery::refused`]).
//! - Broadcast ([`ADDR_BROADCAST`]) has no flow to acknowledge: a send to it is refused
//!   with [`SendError::NoLink`] rather than sent unprotected.
//!
//! The receiving half alone (for a sink such as a graphics engine that only receives) is
//! [`FlowRx`] with [`parse`] and [`control`] ([`flow`]: the envelope on the wire).
//!
//! Cost: [`OVERHEAD`] bytes per packet plus one ack ([`OVERHEAD`] bytes) per service of the
//! receiving port that took packets, about one per packet when packets come one at a time;
//! retransmissions are the loss rate's fraction of the packets, plus the window behind a
//! lost one (go-back-N). Storage: [`GlobalReliable::buffer_len`].
//!
//! Time comes in through [`Clock`] (never read globally). Storage is the caller's: one
//! buffer of [`GlobalReliable::buffer_len`] bytes. No allocation, no panics.

pub mod flow;

use core::ops::Range;

use super::envelope::{diff, HEADER_LEN, OVERHEAD, WINDOW_MAX};
use super::stats::GlobalRecovery;
use crate::error::Error;
use crate::link::{Clock, Face, Links, RecvError, SendError};
use crate::packet::{self, ADDR_BROADCAST};

pub use flow::{
    code, control, data_packet, destination, emit_data, envelope_type, parse, Envelope, FlowRx,
    Verdict,
};

/// Most peers (addresses with a flow) a board can keep.
pub const PEERS_MAX: usize = crate::limits::BOARD_COUNT + 2;
/// Most send slots (shared by the peers).
pub const TX_SLOTS_MAX: usize = 128;
/// Most packets received and not yet taken by the caller.
pub const RX_SLOTS_MAX: usize = 128;

/// Settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GlobalConfig {
    /// Packets kept per destination for retransmission (at most [`WINDOW_MAX`]).
    pub window: usize,
    /// Addresses with a flow (at most [`PEERS_MAX`]).
    pub peers_max: usize,
    /// Send slots, shared by the peers (at most [`TX_SLOTS_MAX`]): packets sent and not yet
    /// acknowledged, to any destination. A send with every slot taken is
    /// [`SendError::WouldBlock`].
    pub tx_slots: usize,
    /// Packets received and not yet taken (at most [`RX_SLOTS_MAX`]).
    pub rx_slots: usize,
    /// Largest packet carried (bytes, before the envelope).
    pub packet_len_max: usize,
    /// Retransmissions of one packet without an ack before the flow is given up.
    pub retries: u8,
    /// Wait for an ack before the first retransmission (ns).
    pub retransmit_after_ns: u64,
    /// Longest wait between retransmissions (ns).
    pub retransmit_backoff_max_ns: u64,
}

impl Default for GlobalConfig {
    fn default() -> Self {
        GlobalConfig {
            window: 4,
            peers_max: PEERS_MAX,
            tx_slots: 32,
            rx_slots: 64,
            packet_len_max: crate::limits::PACKET_LEN_MAX,
            retries: 8,
            retransmit_after_ns: 10_000_000,
            retransmit_backoff_max_ns: 160_000_000,
        }
    }
}

#[derive(Clone, Copy, Default)]
struct Peer {
    addr: u8,
    used: bool,
    next: u16,
    /// Oldest unacknowledged.
    base: u16,
    lens: [u16; WINDOW_MAX],
    /// Send slot of each unacknowledged packet (by `seq % window`).
    slots: [u8; WINDOW_MAX],
    /// Retransmit from here, if asked or timed out.
    resend: Option<u16>,
    /// When the oldest unacknowledged is retransmitted.
    timer_at: u64,
    /// Retransmissions since the window last moved.
    tries: u8,
    rx: FlowRx,
    ack_owed: bool,
    /// No nack before this (one per `retransmit_after_ns`).
    nack_at: u64,
    /// The number last retransmitted from on a nack: a nack for it again is ignored until
    /// the window moves or the timer fires (no retransmission storm from a burst of nacks).
    nacked: Option<u16>,
}

/// Global-network recovery over `L` (see the module doc); the faces pass through. `B` is
/// the caller's storage.
pub struct GlobalReliable<L, C, B> {
    inner: L,
    clock: C,
    config: GlobalConfig,
    address: u8,
    buf: B,
    peers: [Peer; PEERS_MAX],
    /// Peers in use: `peers[..peers_used]` (taken in order, never given back), so the
    /// timers and the flush walk only those.
    peers_used: usize,
    /// Free send slots (bit set: free).
    free: [u64; TX_SLOTS_MAX / 64],
    /// Received packets not yet taken: `count` from ring slot `head` on.
    head: usize,
    count: usize,
    lens: [u16; RX_SLOTS_MAX],
    failure: Option<(u8, u16, u8)>,
    stats: GlobalRecovery,
}

impl<L: Links, C: Clock, B: AsRef<[u8]> + AsMut<[u8]>> GlobalReliable<L, C, B> {
    /// Bytes of storage a configuration needs: `tx_slots` send slots, `rx_slots` receive
    /// slots and one slot to read into, each `packet_len_max + OVERHEAD` bytes.
    pub const fn buffer_len(config: &GlobalConfig) -> usize {
        (config.tx_slots + config.rx_slots + 1) * (config.packet_len_max + OVERHEAD)
    }

    /// Wraps `inner` for the board at global `address`. Fails with
    /// [`Error::BufferTooSmall`] if `buf` is shorter than [`Self::buffer_len`], or
    /// [`Error::Oversized`] for a window, peer count or receive slots beyond their maxima
    /// (or 0), or a packet length the u16 slot lengths cannot hold.
    pub fn new(
        inner: L,
        clock: C,
        address: u8,
        config: GlobalConfig,
        buf: B,
    ) -> Result<Self, Error> {
        if config.window == 0
            || config.window > WINDOW_MAX
            || config.peers_max == 0
            || config.peers_max > PEERS_MAX
            || config.tx_slots == 0
            || config.tx_slots > TX_SLOTS_MAX
            || config.rx_slots == 0
            || config.rx_slots > RX_SLOTS_MAX
            || config.packet_len_max + OVERHEAD > u16::MAX as usize
        {
            return Err(Error::Oversized);
        }
        if buf.as_ref().len() < Self::buffer_len(&config) {
            return Err(Error::BufferTooSmall);
        }
        Ok(GlobalReliable {
            inner,
            clock,
            config,
            address,
            buf,
            peers: [Peer::default(); PEERS_MAX],
            peers_used: 0,
            free: [u64::MAX; TX_SLOTS_MAX / 64],
            head: 0,
            count: 0,
            lens: [0; RX_SLOTS_MAX],
            failure: None,
            stats: GlobalRecovery::default(),
        })
    }

    /// The wrapped links.
    pub fn inner(&self) -> &L {
        &self.inner
    }

    /// The wrapped links, mutable.
    pub fn inner_mut(&mut self) -> &mut L {
        &mut self.inner
    }

    /// What recovery cost so far.
    pub fn stats(&self) -> &GlobalRecovery {
        &self.stats
    }

    /// The flow given up, if any: (peer address, the packet's number, retransmissions).
    pub fn failure(&self) -> Option<(u8, u16, u8)> {
        self.failure
    }

    /// Packets sent and not yet acknowledged, over every peer.
    pub fn unacknowledged(&self) -> usize {
        self.peers
            .iter()
            .filter(|p| p.used)
            .map(|p| diff(p.next, p.base).max(0) as usize)
            .sum()
    }

    fn slot_len(&self) -> usize {
        self.config.packet_len_max + OVERHEAD
    }

    fn slot(&self, i: usize) -> Range<usize> {
        let s = self.slot_len();
        i * s..(i + 1) * s
    }

    fn tx_slot(&self, peer: usize, seq: u16) -> Range<usize> {
        self.slot(usize::from(
            self.peers[peer].slots[seq as usize % self.config.window],
        ))
    }

    /// Takes a free send slot.
    fn take_slot(&mut self) -> Option<u8> {
        for (w, bits) in self.free.iter_mut().enumerate() {
            if *bits != 0 {
                let b = bits.trailing_zeros() as usize;
                let k = w * 64 + b;
                if k >= self.config.tx_slots {
                    return None;
                }
                *bits &= !(1u64 << b);
                return Some(k as u8);
            }
        }
        None
    }

    fn rx_slot(&self, k: usize) -> Range<usize> {
        let base = self.config.tx_slots;
        self.slot(base + (self.head + k) % self.config.rx_slots)
    }

    fn scratch(&self) -> Range<usize> {
        self.slot(self.config.tx_slots + self.config.rx_slots)
    }

    /// The slot of `addr`, taking a free one for a new address.
    fn peer(&mut self, addr: u8) -> Option<usize> {
        let used = self.peers_used;
        if let Some(i) = self.peers[..used]
            .iter()
            .position(|p| p.used && p.addr == addr)
        {
            return Some(i);
        }
        if used >= self.config.peers_max {
            return None;
        }
        self.peers[used] = Peer {
            addr,
            used: true,
            ..Peer::default()
        };
        self.peers_used = used + 1;
        self.stats.peers += 1;
        Some(used)
    }

    fn send_control(&mut self, dst: u8, kind: u8, seq: u16) -> bool {
        let e = control(dst, self.address, kind, seq);
        if self.inner.try_send_global(&e).is_err() {
            return false;
        }
        self.stats.control_bytes += OVERHEAD as u64;
        if kind == code::ACK {
            self.stats.acks_sent += 1;
        } else {
            self.stats.nacks_sent += 1;
        }
        true
    }

    /// `peer` acknowledged every packet before `ack`.
    fn acked(&mut self, i: usize, ack: u16, now: u64) {
        let after = self.config.retransmit_after_ns;
        let p = &mut self.peers[i];
        if diff(ack, p.base) > 0 && diff(ack, p.next) <= 0 {
            while p.base != ack {
                let k = usize::from(p.slots[p.base as usize % self.config.window]);
                if let Some(bits) = self.free.get_mut(k / 64) {
                    *bits |= 1u64 << (k % 64);
                }
                p.base = p.base.wrapping_add(1);
            }
            p.tries = 0;
            p.nacked = None;
            p.timer_at = now.saturating_add(after);
            if let Some(r) = p.resend {
                if diff(r, ack) < 0 {
                    p.resend = Some(ack);
                }
            }
        }
    }

    /// Handles the envelope of `n` bytes in the scratch slot.
    fn take(&mut self, n: usize, now: u64) {
        let range = self.scratch();
        let Some(e) = self.buf.as_ref()[range].get(..n) else {
            self.stats.damaged += 1;
            return;
        };
        let (src, seq, kind) = match parse(e) {
            Envelope::Damaged => {
                self.stats.damaged += 1;
                return;
            }
            Envelope::Ack { src, seq } => (src, seq, code::ACK),
            Envelope::Nack { src, seq } => (src, seq, code::NACK),
            Envelope::Data { src, seq, .. } => (src, seq, code::DATA),
        };
        let Some(i) = self.peer(src) else {
            self.stats.refused += 1;
            return;
        };
        match kind {
            code::ACK => self.acked(i, seq, now),
            code::NACK => {
                self.stats.nacks_received += 1;
                self.acked(i, seq, now);
                let p = &mut self.peers[i];
                if diff(seq, p.base) >= 0 && diff(seq, p.next) < 0 && p.nacked != Some(seq) {
                    p.nacked = Some(seq);
                    p.resend = Some(match p.resend {
                        Some(r) if diff(r, seq) < 0 => r,
                        _ => seq,
                    });
                }
            }
            _ => {
                let p = &mut self.peers[i];
                if seq == p.rx.expected() && self.count >= self.config.rx_slots {
                    // No room: not acknowledged, the sender's timer sends it again.
                    self.stats.refused += 1;
                    return;
                }
                match p.rx.take(seq) {
                    Verdict::Deliver => {
                        p.ack_owed = true;
                        let len = n - OVERHEAD;
                        let to = self.rx_slot(self.count);
                        let from = self.scratch();
                        let b = self.buf.as_mut();
                        b.copy_within(
                            from.start + HEADER_LEN..from.start + HEADER_LEN + len,
                            to.start,
                        );
                        let k = (self.head + self.count) % self.config.rx_slots;
                        self.lens[k] = len as u16;
                        self.count += 1;
                    }
                    Verdict::Duplicate => {
                        self.stats.duplicates += 1;
                        p.ack_owed = true;
                    }
                    Verdict::Gap { nack } => {
                        self.stats.gaps += 1;
                        if nack || now >= p.nack_at {
                            p.nack_at = now.saturating_add(self.config.retransmit_after_ns);
                            let want = p.rx.expected();
                            self.send_control(src, code::NACK, want);
                        }
                    }
                }
            }
        }
    }

    /// Reads what has arrived, runs the timers and sends what is owed (retransmissions,
    /// acks).
    fn service(&mut self) {
        let now = self.clock.now_ns();
        loop {
            let range = self.scratch();
            match self.inner.try_recv_global(&mut self.buf.as_mut()[range]) {
                Ok(None) => break,
                Ok(Some(n)) => self.take(n, now),
                Err(RecvError::Damaged(_)) | Err(RecvError::BufferTooSmall { .. }) => {
                    self.stats.damaged += 1;
                }
                Err(_) => break,
            }
        }
        let (after, max) = (
            self.config.retransmit_after_ns,
            self.config.retransmit_backoff_max_ns,
        );
        for i in 0..self.peers_used {
            let p = &mut self.peers[i];
            if !p.used || p.base == p.next || now < p.timer_at || p.resend.is_some() {
                continue;
            }
            if p.tries >= self.config.retries {
                if self.failure.is_none() {
                    self.failure = Some((p.addr, p.base, p.tries));
                }
                continue;
            }
            p.tries += 1;
            p.resend = Some(p.base);
            p.nacked = None;
            let wait = after
                .checked_shl(u32::from(p.tries.min(32)))
                .unwrap_or(u64::MAX)
                .min(max);
            p.timer_at = now.saturating_add(wait);
            self.stats.timeouts += 1;
        }
        for i in 0..self.peers_used {
            self.flush(i);
        }
    }

    /// Sends what is owed to peer `i`; whether every retransmission went out.
    fn flush(&mut self, i: usize) -> bool {
        if !self.peers[i].used {
            return true;
        }
        while let Some(s) = self.peers[i].resend {
            if s == self.peers[i].next {
                self.peers[i].resend = None;
                break;
            }
            let len = usize::from(self.peers[i].lens[s as usize % self.config.window]);
            let range = self.tx_slot(i, s);
            let bytes = &self.buf.as_ref()[range][..len];
            match self.inner.try_send_global(bytes) {
                Ok(()) => {}
                Err(SendError::WouldBlock) => return false,
                // Lost on the way (e.g. no route): the timer sends it again.
                Err(_) => {}
            }
            self.stats.retransmitted_packets += 1;
            self.stats.retransmitted_bytes += len as u64;
            self.peers[i].resend = Some(s.wrapping_add(1));
        }
        if self.peers[i].ack_owed {
            let (addr, e) = (self.peers[i].addr, self.peers[i].rx.expected());
            if self.send_control(addr, code::ACK, e) {
                self.peers[i].ack_owed = false;
            }
        }
        true
    }
}

impl<L: Links, C: Clock, B: AsRef<[u8]> + AsMut<[u8]>> Links for GlobalReliable<L, C, B> {
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        self.inner.try_send(face, frame)
    }

    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.inner.try_recv(face, buf)
    }

    fn try_send_global(&mut self, packet: &[u8]) -> Result<(), SendError> {
        if packet.len() > self.config.packet_len_max {
            return Err(SendError::TooLong);
        }
        // Shorter than its addresses: not a packet.
        let (Some(&dst), Some(_)) = (
            packet.get(packet::field::DST),
            packet.get(packet::field::SRC),
        ) else {
            return Err(SendError::TooLong);
        };
        if dst == ADDR_BROADCAST || self.failure.is_some() {
            return Err(SendError::NoLink);
        }
        self.service();
        let i = self.peer(dst).ok_or(SendError::NoLink)?;
        if !self.flush(i) {
            return Err(SendError::WouldBlock);
        }
        let p = self.peers[i];
        if diff(p.next, p.base) as usize >= self.config.window {
            return Err(SendError::WouldBlock);
        }
        let k = self.take_slot().ok_or(SendError::WouldBlock)?;
        let range = self.slot(usize::from(k));
        let sent = emit_data(packet, p.next, &mut self.buf.as_mut()[range.clone()])
            .ok_or(SendError::TooLong)
            .and_then(|len| {
                self.inner
                    .try_send_global(&self.buf.as_ref()[range][..len])
                    .map(|()| len)
            });
        let len = match sent {
            Ok(len) => len,
            Err(e) => {
                if let Some(bits) = self.free.get_mut(usize::from(k) / 64) {
                    *bits |= 1u64 << (k % 64);
                }
                return Err(e);
            }
        };
        self.peers[i].slots[p.next as usize % self.config.window] = k;
        let now = self.clock.now_ns();
        let p = &mut self.peers[i];
        if p.base == p.next {
            p.timer_at = now.saturating_add(self.config.retransmit_after_ns);
            p.tries = 0;
        }
        p.lens[p.next as usize % self.config.window] = len as u16;
        p.next = p.next.wrapping_add(1);
        self.stats.data_packets += 1;
        self.stats.data_bytes += len as u64;
        Ok(())
    }

    fn try_recv_global(&mut self, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.service();
        if self.count > 0 {
            let n = usize::from(self.lens[self.head]);
            let range = self.rx_slot(0);
            let out = buf
                .get_mut(..n)
                .ok_or(RecvError::BufferTooSmall { needed: n })?;
            out.copy_from_slice(&self.buf.as_ref()[range][..n]);
            self.head = (self.head + 1) % self.config.rx_slots;
            self.count -= 1;
            return Ok(Some(n));
        }
        if let Some((peer, seq, requests)) = self.failure {
            return Err(RecvError::GlobalRetriesExhausted {
                peer,
                seq,
                requests,
            });
        }
        Ok(None)
    }

    fn poll(&mut self) {
        self.service();
        self.inner.poll();
    }

    fn peek(&mut self, face: Face) -> crate::link::Peek {
        self.inner.peek(face)
    }
}
