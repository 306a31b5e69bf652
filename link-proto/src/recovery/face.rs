//! Face recovery, on the point-to-point links: a [`Links`] wrapper that numbers the frames
//! of every face, acknowledges them, asks again for a frame lost or damaged (negative
//! acknowledgement) and retransmits it, within bounded retries.
//!
//! Every frame on a face goes out in an envelope (little-endian):
//!
//! | offset  | size | field                                                                |
//! |---------|------|----------------------------------------------------------------------|
//! | 0       | 1    | type: `0xA1` data, `0xA2` ack, `0xA3` nack, `0xA4` status            |
//! | 1       | 1    | reserved (0)                                                         |
//! | 2       | 2    | seq (u16): data: its number; ack: the next expected (all before it arrived); nack: the number wanted (all before it arrived); status: the sender's next number |
//! | 4       | 2    | (data) the next number this side expects on the reverse direction: a piggybacked ack; else 0 |
//! | 6       | `n`  | (data) the frame, whose last four bytes are the CRC-32 of the rest   |
//! | 6 + `n` | 4    | CRC-32 of bytes `0 .. 6` followed by (data) the frame's last four    |
//!
//! [`OVERHEAD`] = 10 bytes per frame ([`super::envelope`]: shared with global recovery,
//! as is the CRC rule below). The type codes lie outside the frame kinds (a link
//! carries envelopes only, or frames only; [`data_frame`] finds the frame in an envelope).
//!
//! A data envelope carries a link frame, which ends with the CRC-32 of its other bytes
//! ([`crate::frame`]). That CRC protects the frame; the envelope's protects the header and
//! binds the frame's CRC to it. So the sender computes a CRC over ten bytes, not over the
//! frame again, and the receiver checks both: any change to the envelope fails one of
//! them. Bytes that do not end with their own CRC-32 are refused by every receiver as
//! damaged (sent again until the receiver's requests run out): recovery carries frames,
//! not arbitrary bytes.
//!
//! The protocol, per face and direction (go-back-N with a window of `window` frames):
//! - The sender keeps every frame until it is acknowledged, at most `window`; a send
//!   beyond that is [`SendError::WouldBlock`] (flow control).
//! - The receiver takes frames in order only. A frame that fails its CRC, a frame beyond
//!   the next expected (one was lost) or a wait for the next frame longer than
//!   `nack_after_ns` (doubling with each request, up to `nack_backoff_max_ns`) sends a nack
//!   of the next expected number; the sender answers it with that frame and every later
//!   one, or with a status "not sent yet" (which tells the receiver the sender is alive:
//!   its count of requests starts again). A duplicate is dropped and acknowledged again.
//! - Acks ride on data frames of the reverse direction; a receiver that has taken half a
//!   window without sending data acknowledges explicitly.
//! - A receiver that has asked `retries` times for a frame without getting it stops with
//!   [`RecvError::RetriesExhausted`] (the caller names its board, link and step).
//! - A face's data is read when its frames are asked for, when its send window is full
//!   (for acks), and by a wait for a frame that has lasted half `nack_after_ns` (every
//!   face then: a board waiting on one link still answers the nacks of the others, before
//!   their first request is repeated). Its control envelopes are read sooner: at each send
//!   on it and each poll, from the head of a link that can look ahead ([`Links::peek`];
//!   one that cannot is read to the end). A receive buffer that holds an envelope
//!   ([`crate::FRAME_RX_LEN`]) takes the next frame straight from the link, checked and
//!   unwrapped in place; frames read ahead wait in receive slots and are copied out.
//!
//! Time comes in through [`Clock`] (never read globally). Storage is the caller's: one
//! buffer of [`Reliable::buffer_len`] bytes. No allocation, no panics.

use core::ops::Range;

use super::envelope::{check_envelope, diff, seal, u16_at, HEADER_LEN, OVERHEAD, WINDOW_MAX};
use super::stats::FaceRecovery;
use crate::error::Error;
use crate::limits::CRC_LEN;
use crate::link::{Clock, Face, Links, Peek, RecvError, SendError};

/// The fields of a face envelope's header.
mod field {
    use core::ops::Range;
    pub const TYPE: usize = 0;
    pub const RESERVED: usize = 1;
    pub const SEQ: Range<usize> = 2..4;
    pub const ACK: Range<usize> = 4..6;
}

const _: () = assert!(field::ACK.end == HEADER_LEN);

/// Envelope type codes.
pub mod code {
    /// A data frame.
    pub const DATA: u8 = 0xA1;
    /// Acknowledgement: every frame before `seq` arrived.
    pub const ACK: u8 = 0xA2;
    /// Negative acknowledgement: send `seq` (and later ones) again; every frame before it arrived.
    pub const NACK: u8 = 0xA3;
    /// The sender's next sequence number (answer to a nack for a frame not sent yet).
    pub const STATUS: u8 = 0xA4;
}

/// The frame inside a data envelope (unchecked: for observers such as fault injectors),
/// or `None` for anything else.
pub fn data_frame(envelope: &[u8]) -> Option<&[u8]> {
    if envelope.get(field::TYPE) != Some(&code::DATA) {
        return None;
    }
    super::envelope::carried(envelope)
}

/// The frame that bytes sent on a face carry: a bare frame (recovery off) itself, a data
/// envelope's frame (unchecked, as [`data_frame`]); `None` for a control envelope (ack,
/// nack, status). For observers such as fault injectors.
pub fn carried_frame(bytes: &[u8]) -> Option<&[u8]> {
    match bytes.get(field::TYPE) {
        Some(&code::DATA) => data_frame(bytes),
        Some(c) if *c >= code::ACK => None,
        _ => Some(bytes),
    }
}

/// Writes the header of a face envelope at the start of `e`.
fn write_header(e: &mut [u8], kind: u8, seq: u16, ack: u16) {
    e[field::TYPE] = kind;
    e[field::RESERVED] = 0;
    e[field::SEQ].copy_from_slice(&seq.to_le_bytes());
    e[field::ACK].copy_from_slice(&ack.to_le_bytes());
}

/// Settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReliableConfig {
    /// Frames kept per face for retransmission (at most [`WINDOW_MAX`]).
    pub window: usize,
    /// Largest frame carried (bytes, before the envelope).
    pub frame_len_max: usize,
    /// Requests for one frame before the receiver gives up.
    pub retries: u8,
    /// Wait before the first request for a frame that has not arrived (ns).
    pub nack_after_ns: u64,
    /// Longest wait between requests (ns).
    pub nack_backoff_max_ns: u64,
}

impl Default for ReliableConfig {
    fn default() -> Self {
        ReliableConfig {
            window: 8,
            frame_len_max: crate::limits::FRAME_LEN_MAX,
            retries: 10,
            nack_after_ns: 1_000_000,
            nack_backoff_max_ns: 64_000_000,
        }
    }
}

#[derive(Clone, Copy, Default)]
struct TxState {
    next: u16,
    /// Oldest unacknowledged.
    base: u16,
    lens: [u16; WINDOW_MAX],
    /// Retransmit from here (go-back-N), if asked.
    resend: Option<u16>,
    /// A status answer owed.
    status_owed: bool,
}

#[derive(Clone, Copy, Default)]
struct RxState {
    expected: u16,
    /// Envelopes taken in order and not yet delivered: `count` from slot `head` on.
    head: usize,
    count: usize,
    lens: [u16; WINDOW_MAX],
    /// Requests sent for `expected` since it was last heard of.
    nacks: u8,
    waiting_since: Option<u64>,
    next_nack_at: u64,
    /// Frames taken since this side last acknowledged (explicitly or on data).
    unacked: u16,
    ack_owed: bool,
}

/// The type, sequence number and piggybacked ack of the envelope `bytes[..n]`, or `None` if
/// it is too short, longer than `bytes`, or fails a CRC: its own, or (data) its frame's.
fn envelope_header(bytes: &[u8], n: usize) -> Option<(u8, u16, u16)> {
    let e = bytes.get(..n)?;
    let kind = *e.get(field::TYPE)?;
    check_envelope(e, kind == code::DATA)?;
    Some((kind, u16_at(e, field::SEQ)?, u16_at(e, field::ACK)?))
}

/// One read of a link ([`Reliable::read`]).
enum Read {
    Nothing,
    Damaged,
    /// An envelope of this many bytes.
    Envelope(usize),
}

/// Links with recovery over `L` (see the module doc). `B` is the caller's storage.
pub struct Reliable<L, C, B> {
    inner: L,
    clock: C,
    config: ReliableConfig,
    buf: B,
    tx: [TxState; Face::COUNT],
    rx: [RxState; Face::COUNT],
    stats: [FaceRecovery; Face::COUNT],
}

impl<L: Links, C: Clock, B: AsRef<[u8]> + AsMut<[u8]>> Reliable<L, C, B> {
    /// Bytes of storage a configuration needs: per face, `window` send slots and `window`
    /// receive slots of `frame_len_max + OVERHEAD` bytes (a sender has at most a window
    /// unacknowledged, so the receiver can always read its link to the end, and no ack or
    /// nack waits behind data).
    pub const fn buffer_len(config: &ReliableConfig) -> usize {
        Face::COUNT * 2 * config.window * (config.frame_len_max + OVERHEAD)
    }

    /// Wraps `inner`. Fails with [`Error::BufferTooSmall`] if `buf` is shorter than
    /// [`Self::buffer_len`], [`Error::Oversized`] for a window beyond [`WINDOW_MAX`] (or 0),
    /// or a frame length the u16 slot lengths cannot hold.
    pub fn new(inner: L, clock: C, config: ReliableConfig, buf: B) -> Result<Self, Error> {
        if config.window == 0
            || config.window > WINDOW_MAX
            || config.frame_len_max + OVERHEAD > u16::MAX as usize
        {
            return Err(Error::Oversized);
        }
        if buf.as_ref().len() < Self::buffer_len(&config) {
            return Err(Error::BufferTooSmall);
        }
        Ok(Reliable {
            inner,
            clock,
            config,
            buf,
            tx: [TxState::default(); Face::COUNT],
            rx: [RxState::default(); Face::COUNT],
            stats: [FaceRecovery::default(); Face::COUNT],
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

    /// What recovery cost so far, per face ([`Face::index`] order).
    pub fn stats(&self) -> &[FaceRecovery; Face::COUNT] {
        &self.stats
    }

    fn slot_len(&self) -> usize {
        self.config.frame_len_max + OVERHEAD
    }

    fn slot_range(&self, face: Face, i: usize) -> Range<usize> {
        let s = self.slot_len();
        let start = (face.index() * 2 * self.config.window + i) * s;
        start..start + s
    }

    fn tx_slot(&self, face: Face, seq: u16) -> Range<usize> {
        self.slot_range(face, seq as usize % self.config.window)
    }

    /// The receive slot `k` places after the oldest held.
    fn rx_slot(&self, face: Face, k: usize) -> Range<usize> {
        let w = self.config.window;
        self.slot_range(face, w + (self.rx[face.index()].head + k) % w)
    }

    /// Sends a control envelope; `false` if the link's queue is full (nothing sent).
    fn control(&mut self, face: Face, kind: u8, seq: u16) -> bool {
        let mut e = [0u8; OVERHEAD];
        write_header(&mut e, kind, seq, 0);
        // An envelope of OVERHEAD bytes always seals.
        let _ = seal(&mut e, false);
        if self.inner.try_send(face, &e).is_err() {
            return false;
        }
        let st = &mut self.stats[face.index()];
        st.control_bytes += OVERHEAD as u64;
        match kind {
            code::ACK => st.acks_sent += 1,
            code::NACK => st.nacks_sent += 1,
            _ => st.statuses_sent += 1,
        }
        true
    }

    /// The neighbour acknowledged every frame before `ack`.
    fn acked(&mut self, face: Face, ack: u16) {
        let t = &mut self.tx[face.index()];
        if diff(ack, t.base) > 0 && diff(ack, t.next) <= 0 {
            t.base = ack;
            if let Some(r) = t.resend {
                if diff(r, ack) < 0 {
                    t.resend = Some(ack);
                }
            }
        }
    }

    /// Something was lost or damaged on the way in: ask for the next expected frame now,
    /// unless a request for it is already out (the timer asks again).
    fn lost(&mut self, face: Face) {
        let now = self.clock.now_ns();
        let r = &mut self.rx[face.index()];
        if r.nacks > 0 && now < r.next_nack_at {
            return;
        }
        let seq = r.expected;
        self.nack(face, seq, now);
    }

    fn nack(&mut self, face: Face, seq: u16, now: u64) {
        let r = &mut self.rx[face.index()];
        r.nacks = r.nacks.saturating_add(1);
        let shift = u32::from(r.nacks.min(32));
        r.next_nack_at = now.saturating_add(
            self.config
                .nack_after_ns
                .checked_shl(shift)
                .unwrap_or(u64::MAX)
                .min(self.config.nack_backoff_max_ns),
        );
        self.control(face, code::NACK, seq);
    }

    /// Handles the envelope of `n` bytes just read into the first free receive slot: a
    /// frame taken in order stays there for delivery.
    fn take(&mut self, face: Face, n: usize) {
        let range = self.rx_slot(face, self.rx[face.index()].count);
        let head = envelope_header(&self.buf.as_ref()[range], n);
        if self.take_header(face, head) {
            let r = &mut self.rx[face.index()];
            let k = (r.head + r.count) % self.config.window;
            r.lens[k] = n as u16;
            r.count += 1;
        }
    }

    /// Acts on a received envelope whose check gave `head` (see [`envelope_header`]); true
    /// for a data frame taken in order, which the caller keeps for delivery.
    fn take_header(&mut self, face: Face, head: Option<(u8, u16, u16)>) -> bool {
        let f = face.index();
        let Some((kind, seq, ack)) = head else {
            self.stats[f].damaged += 1;
            self.lost(face);
            return false;
        };
        match kind {
            code::ACK => self.acked(face, seq),
            code::NACK => {
                self.stats[f].nacks_received += 1;
                self.acked(face, seq);
                let t = &mut self.tx[f];
                if seq == t.next {
                    t.status_owed = true;
                } else if diff(seq, t.base) >= 0 && diff(seq, t.next) < 0 {
                    t.resend = Some(match t.resend {
                        Some(r) if diff(r, seq) < 0 => r,
                        _ => seq,
                    });
                }
            }
            code::STATUS => {
                let r = &mut self.rx[f];
                if seq == r.expected {
                    // Alive, and has sent nothing newer: the wait starts again.
                    r.nacks = 0;
                    r.waiting_since = None;
                } else if diff(seq, r.expected) > 0 {
                    self.lost(face);
                }
            }
            code::DATA => {
                self.acked(face, ack);
                let r = &mut self.rx[f];
                match diff(seq, r.expected) {
                    0 => {
                        r.expected = r.expected.wrapping_add(1);
                        r.nacks = 0;
                        r.waiting_since = None;
                        r.unacked += 1;
                        if usize::from(r.unacked) * 2 >= self.config.window {
                            r.ack_owed = true;
                        }
                        return true;
                    }
                    d if d < 0 => {
                        self.stats[f].duplicates += 1;
                        r.ack_owed = true;
                    }
                    _ => {
                        self.stats[f].gaps += 1;
                        self.lost(face);
                    }
                }
            }
            _ => {
                self.stats[f].damaged += 1;
                self.lost(face);
            }
        }
        false
    }

    /// Reads what has arrived on `face` while a receive slot is free, then sends what is
    /// owed (retransmissions, status, ack).
    fn service(&mut self, face: Face) -> Result<(), RecvError> {
        while self.read_one(face)? {}
        self.flush(face);
        Ok(())
    }

    /// Reads the control envelopes (acks, nacks, statuses) at the head of `face`'s link,
    /// up to its first data envelope, which stays on the link for the caller's buffer;
    /// then sends what is owed. A link that cannot look ahead ([`Peek::Unknown`]) is read
    /// to the end as by [`Self::service`].
    fn read_controls(&mut self, face: Face) -> Result<(), RecvError> {
        loop {
            match self.inner.peek(face) {
                Peek::Nothing | Peek::First(code::DATA) => break,
                Peek::First(_) => {
                    if !self.read_one(face)? {
                        break;
                    }
                }
                Peek::Unknown => return self.service(face),
            }
        }
        self.flush(face);
        Ok(())
    }

    /// Reads one envelope from `face` into the first free receive slot and acts on it;
    /// false if none was read (nothing arrived, no slot free, no link).
    fn read_one(&mut self, face: Face) -> Result<bool, RecvError> {
        let f = face.index();
        if self.rx[f].count >= self.config.window {
            return Ok(false);
        }
        let range = self.rx_slot(face, self.rx[f].count);
        let read = self.inner.try_recv(face, &mut self.buf.as_mut()[range]);
        Ok(match self.read(face, read)? {
            Read::Nothing => false,
            Read::Damaged => true,
            Read::Envelope(n) => {
                self.take(face, n);
                true
            }
        })
    }

    /// What a read of `face`'s link gave: a damaged or truncated envelope is counted and
    /// asked for again; a missing link reads as nothing; other errors are the caller's.
    fn read(&mut self, face: Face, r: Result<Option<usize>, RecvError>) -> Result<Read, RecvError> {
        match r {
            Ok(None) | Err(RecvError::NoLink) => Ok(Read::Nothing),
            Ok(Some(n)) => Ok(Read::Envelope(n)),
            Err(RecvError::Damaged(_)) | Err(RecvError::BufferTooSmall { .. }) => {
                self.stats[face.index()].damaged += 1;
                self.lost(face);
                Ok(Read::Damaged)
            }
            Err(e) => Err(e),
        }
    }

    /// Sends what is owed on `face`; returns whether every retransmission went out.
    fn flush(&mut self, face: Face) -> bool {
        let f = face.index();
        while let Some(s) = self.tx[f].resend {
            if s == self.tx[f].next {
                self.tx[f].resend = None;
                break;
            }
            let len = usize::from(self.tx[f].lens[s as usize % self.config.window]);
            let range = self.tx_slot(face, s);
            let bytes = &self.buf.as_ref()[range][..len];
            if self.inner.try_send(face, bytes).is_err() {
                return false;
            }
            self.stats[f].retransmitted_frames += 1;
            self.stats[f].retransmitted_bytes += len as u64;
            self.tx[f].resend = Some(s.wrapping_add(1));
        }
        if self.tx[f].status_owed {
            let next = self.tx[f].next;
            self.tx[f].status_owed = !self.control(face, code::STATUS, next);
        }
        if self.rx[f].ack_owed {
            let e = self.rx[f].expected;
            if self.control(face, code::ACK, e) {
                self.rx[f].ack_owed = false;
                self.rx[f].unacked = 0;
            }
        }
        true
    }

    /// Whether a wait for a frame began less than half `nack_after_ns` ago on some face.
    /// Such a board reads only the control envelopes at the head of its other faces, so
    /// that their frames go straight into the caller's buffer when asked for; once a wait
    /// is older, it reads every face to its end, to answer the nacks of neighbours waiting
    /// on it (behind data, or on a link that cannot look ahead) before their first request
    /// is repeated.
    fn waiting_briefly(&self, now: u64) -> bool {
        let brief = self.config.nack_after_ns / 2;
        self.rx.iter().any(|r| {
            r.waiting_since
                .is_some_and(|t| now.saturating_sub(t) < brief)
        })
    }

    /// Answers every face: its control envelopes while a wait is brief, everything it
    /// carries once a wait has lasted (see [`Self::waiting_briefly`]).
    fn answer_all(&mut self, now: u64) -> Result<(), RecvError> {
        if !self.waiting_briefly(now) {
            return self.service_all();
        }
        for face in Face::ALL {
            self.read_controls(face)?;
        }
        Ok(())
    }

    /// Services every face (a board waiting on one link still answers the others).
    fn service_all(&mut self) -> Result<(), RecvError> {
        for face in Face::ALL {
            self.service(face)?;
        }
        Ok(())
    }
}

impl<L: Links, C: Clock, B: AsRef<[u8]> + AsMut<[u8]>> Links for Reliable<L, C, B> {
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        let f = face.index();
        if frame.len() > self.config.frame_len_max {
            return Err(SendError::TooLong);
        }
        if frame.len() < CRC_LEN {
            return Err(SendError::NotAFrame);
        }
        // Nacks and acks at the head of the link are read now (a nack for a frame not sent
        // yet is answered "not yet", not with the frame sent in the meantime); data waits
        // for the caller's buffer.
        let _ = self.read_controls(face);
        if !self.flush(face) {
            return Err(SendError::WouldBlock);
        }
        if diff(self.tx[f].next, self.tx[f].base) as usize >= self.config.window {
            // The window is full: read the face to its end for acks, on data too.
            let _ = self.service(face);
            if !self.flush(face) {
                return Err(SendError::WouldBlock);
            }
        }
        let t = self.tx[f];
        if diff(t.next, t.base) as usize >= self.config.window {
            return Err(SendError::WouldBlock);
        }
        let len = frame.len() + OVERHEAD;
        let ack = self.rx[f].expected;
        let range = self.tx_slot(face, t.next);
        let e = &mut self.buf.as_mut()[range][..len];
        write_header(e, code::DATA, t.next, ack);
        e[HEADER_LEN..HEADER_LEN + frame.len()].copy_from_slice(frame);
        // The frame ends with its CRC (at least CRC_LEN bytes, checked above): it seals.
        let _ = seal(e, true);
        let range = self.tx_slot(face, t.next);
        self.inner
            .try_send(face, &self.buf.as_ref()[range][..len])?;
        let t = &mut self.tx[f];
        t.lens[t.next as usize % self.config.window] = len as u16;
        t.next = t.next.wrapping_add(1);
        self.rx[f].unacked = 0;
        self.rx[f].ack_owed = false;
        let st = &mut self.stats[f];
        st.data_frames += 1;
        st.data_bytes += len as u64;
        Ok(())
    }

    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        let f = face.index();
        if self.rx[f].count == 0 && buf.len() >= self.slot_len() {
            // Nothing held: the next frame in order goes from the link straight into the
            // caller's buffer, checked there and moved to its start (one copy of the frame,
            // not two: the slot is only for frames read ahead of their delivery).
            loop {
                let read = self.inner.try_recv(face, buf);
                let n = match self.read(face, read)? {
                    Read::Nothing => break,
                    Read::Damaged => continue,
                    Read::Envelope(n) => n,
                };
                if self.take_header(face, envelope_header(buf, n)) {
                    let len = n - OVERHEAD;
                    buf.copy_within(HEADER_LEN..HEADER_LEN + len, 0);
                    self.flush(face);
                    return Ok(Some(len));
                }
            }
        }
        self.service(face)?;
        let now = self.clock.now_ns();
        if self.rx[f].count == 0 {
            // Waiting: answer the other links (their nacks; all they carry once the wait has
            // lasted), and ask again for this one's frame in time.
            self.answer_all(now)?;
        }
        if self.rx[f].count > 0 {
            let r = self.rx[f];
            let n = usize::from(r.lens[r.head]) - OVERHEAD;
            let range = self.rx_slot(face, 0);
            let out = buf
                .get_mut(..n)
                .ok_or(RecvError::BufferTooSmall { needed: n })?;
            out.copy_from_slice(&self.buf.as_ref()[range][HEADER_LEN..HEADER_LEN + n]);
            let r = &mut self.rx[f];
            r.head = (r.head + 1) % self.config.window;
            r.count -= 1;
            return Ok(Some(n));
        }
        let r = &mut self.rx[f];
        match r.waiting_since {
            None => {
                r.waiting_since = Some(now);
                r.next_nack_at = now.saturating_add(self.config.nack_after_ns);
            }
            Some(_) if now >= r.next_nack_at => {
                if r.nacks >= self.config.retries {
                    return Err(RecvError::RetriesExhausted {
                        seq: r.expected,
                        requests: r.nacks,
                    });
                }
                let seq = r.expected;
                self.nack(face, seq, now);
            }
            Some(_) => {}
        }
        Ok(None)
    }

    fn try_send_global(&mut self, packet: &[u8]) -> Result<(), SendError> {
        self.inner.try_send_global(packet)
    }

    fn try_recv_global(&mut self, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.inner.try_recv_global(buf)
    }

    fn poll(&mut self) {
        let now = self.clock.now_ns();
        let _ = self.answer_all(now);
        self.inner.poll();
    }
}
