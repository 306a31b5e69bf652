//! The global network's envelope on the wire and the receiving end of one flow: all a
//! sink that only receives (a graphics engine, the host) needs, [`FlowRx`] with [`parse`]
//! and [`control`]. Its layout is in [`super`]'s doc; the length, the CRC rule and the
//! sequence numbers are [`crate::recovery::envelope`]'s.

use crate::limits::CRC_LEN;
use crate::packet;
use crate::recovery::envelope::{
    carried, check_envelope, diff, enveloped_len, seal, u16_at, HEADER_LEN, OVERHEAD,
};

/// The fields of a global envelope's header.
mod field {
    use core::ops::Range;
    pub const DST: usize = 0;
    pub const SRC: usize = 1;
    pub const TYPE: usize = 2;
    pub const RESERVED: usize = 3;
    pub const SEQ: Range<usize> = 4..6;
}

// The network routes an envelope as it routes a packet: on its first byte, the destination.
const _: () = assert!(field::DST == packet::field::DST && field::SRC == packet::field::SRC);
const _: () = assert!(field::SEQ.end == HEADER_LEN);

/// Envelope type codes.
pub mod code {
    /// A data packet.
    pub const DATA: u8 = 0xB1;
    /// Acknowledgement: every packet before `seq` arrived.
    pub const ACK: u8 = 0xB2;
    /// Negative acknowledgement: send `seq` (and later ones) again.
    pub const NACK: u8 = 0xB3;
}

/// The destination of a packet or of an envelope (both carry it first, where a network
/// routes on it), or `None` for no bytes.
pub fn destination(bytes: &[u8]) -> Option<u8> {
    bytes.get(field::DST).copied()
}

/// The type of an envelope ([`code`]; unchecked: for observers), or `None` if it is too
/// short to have one.
pub fn envelope_type(envelope: &[u8]) -> Option<u8> {
    envelope.get(field::TYPE).copied()
}

/// The packet inside a data envelope (unchecked: for observers such as fault injectors),
/// or `None` for anything else.
pub fn data_packet(envelope: &[u8]) -> Option<&[u8]> {
    if envelope.get(field::TYPE) != Some(&code::DATA) {
        return None;
    }
    carried(envelope)
}

/// What an envelope carries, once its CRC and length are checked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Envelope<'a> {
    /// A data packet number `seq` of the flow from `src`.
    Data {
        /// Source address.
        src: u8,
        /// Number in the flow.
        seq: u16,
        /// The packet.
        packet: &'a [u8],
    },
    /// `src` received every packet before `seq`.
    Ack {
        /// Source address (the receiver of the acknowledged flow).
        src: u8,
        /// Next expected.
        seq: u16,
    },
    /// `src` asks for `seq` and later ones again.
    Nack {
        /// Source address.
        src: u8,
        /// The number wanted.
        seq: u16,
    },
    /// Failed its CRC or length, or an unknown type: dropped.
    Damaged,
}

/// Checks and reads an envelope: its CRC and (data) its packet's.
pub fn parse(envelope: &[u8]) -> Envelope<'_> {
    let data = envelope.get(field::TYPE) == Some(&code::DATA);
    let Some(carried) = check_envelope(envelope, data) else {
        return Envelope::Damaged;
    };
    // A checked envelope holds its header.
    let (Some(&src), Some(&kind), Some(seq)) = (
        envelope.get(field::SRC),
        envelope.get(field::TYPE),
        u16_at(envelope, field::SEQ),
    ) else {
        return Envelope::Damaged;
    };
    match kind {
        code::DATA => Envelope::Data {
            src,
            seq,
            packet: carried,
        },
        // An envelope without a packet is exactly OVERHEAD bytes (checked above).
        code::ACK => Envelope::Ack { src, seq },
        code::NACK => Envelope::Nack { src, seq },
        _ => Envelope::Damaged,
    }
}

/// An ack or nack envelope (`kind` [`code::ACK`] or [`code::NACK`]) from `src` to `dst`.
pub fn control(dst: u8, src: u8, kind: u8, seq: u16) -> [u8; OVERHEAD] {
    let mut e = [0u8; OVERHEAD];
    e[field::DST] = dst;
    e[field::SRC] = src;
    e[field::TYPE] = kind;
    e[field::SEQ].copy_from_slice(&seq.to_le_bytes());
    // An envelope of OVERHEAD bytes always seals.
    let _ = seal(&mut e, false);
    e
}

/// Wraps `packet` (its byte 0 the destination, byte 1 the source, its last four bytes the
/// CRC-32 of the rest) as data number `seq` into `out`; returns the envelope's length, or
/// `None` if `out` is too short or the packet is shorter than its addresses and CRC. The
/// envelope's CRC binds the packet's own (ten bytes, not the packet again).
pub fn emit_data(packet: &[u8], seq: u16, out: &mut [u8]) -> Option<usize> {
    let len = enveloped_len(packet.len());
    let (dst, src) = (
        *packet.get(packet::field::DST)?,
        *packet.get(packet::field::SRC)?,
    );
    if packet.len() < CRC_LEN {
        return None;
    }
    let e = out.get_mut(..len)?;
    e[field::DST] = dst;
    e[field::SRC] = src;
    e[field::TYPE] = code::DATA;
    e[field::RESERVED] = 0;
    e[field::SEQ].copy_from_slice(&seq.to_le_bytes());
    e[HEADER_LEN..HEADER_LEN + packet.len()].copy_from_slice(packet);
    seal(e, true)?;
    Some(len)
}

/// The receiving end of one flow: in order only.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FlowRx {
    expected: u16,
    /// The number last nacked (one nack per gap: a lost nack is recovered by the sender's
    /// timer).
    nacked: Option<u16>,
}

/// What to do with a data packet of a flow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// The next expected: deliver it, then acknowledge [`FlowRx::expected`].
    Deliver,
    /// Already delivered: drop it, acknowledge again.
    Duplicate,
    /// Beyond the next expected (one was lost): drop it, and nack [`FlowRx::expected`] if
    /// `nack` (the first packet beyond this gap).
    Gap {
        /// Whether to nack.
        nack: bool,
    },
}

impl FlowRx {
    /// The verdict on data number `seq`; a delivered one moves the flow on.
    pub fn take(&mut self, seq: u16) -> Verdict {
        match diff(seq, self.expected) {
            0 => {
                self.expected = self.expected.wrapping_add(1);
                Verdict::Deliver
            }
            d if d < 0 => Verdict::Duplicate,
            _ => {
                let nack = self.nacked != Some(self.expected);
                self.nacked = Some(self.expected);
                Verdict::Gap { nack }
            }
        }
    }

    /// The next number expected (every one before it was delivered).
    pub fn expected(&self) -> u16 {
        self.expected
    }
}
