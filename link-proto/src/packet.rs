//! Global-network packets: addressed messages between any two boards, the
//! graphics engine and the host.
//!
//! Layout (all multi-byte fields little-endian):
//!
//! | offset  | size | field                                                  |
//! |---------|------|--------------------------------------------------------|
//! | 0       | 1    | destination address ([`BoardId`])                      |
//! | 1       | 1    | source address ([`BoardId`])                           |
//! | 2       | 2    | message id (u16, sender's counter)                     |
//! | 4       | 1    | kind ([`PacketKind`])                                  |
//! | 5       | 1    | version, always [`PACKET_VERSION`]                     |
//! | 6       | 2    | payload length `n` (u16, at most [`PACKET_PAYLOAD_LEN_MAX`]) |
//! | 8       | `n`  | payload (opaque bytes, meaning set by the kind)        |
//! | 8 + `n` | 4    | CRC-32/ISO-HDLC over bytes `0 .. 8 + n`                |
//!
//! Kind codes: 0x01 collision exchange, 0x02 graphics surface, 0x03 bounding box,
//! 0x04 tool force, 0x05 hello (a board's compilation id, to the host), 0x06 tool pose
//! (the host to the boards holding a tool: [`crate::tool_pose`]), 0x10 control
//! start, 0x11 control stop, 0x12 control step-done, 0x20 fault report; any
//! other code parses as [`PacketKind::Unknown`].
//!
//! # Panics
//!
//! [`Packet::new_checked`], [`PacketRepr::parse`] and [`PacketRepr::emit`]
//! never panic, whatever the input. The field accessors of a [`Packet`] built
//! with [`Packet::new_unchecked`] panic if the buffer is shorter than the
//! header and payload it describes: call them on untrusted bytes only after
//! [`Packet::new_checked`] (or [`Packet::check_len`]) succeeded.

use crate::error::{Error, Result};
use crate::frame::crc32;
use crate::limits::{
    enveloped_len, BOARD_COUNT, CRC_LEN, PACKET_HEADER_LEN, PACKET_LEN_MAX, PACKET_LEN_MIN,
    PACKET_PAYLOAD_LEN_MAX,
};

pub(crate) mod field {
    use core::ops::Range;
    pub const DST: usize = 0;
    pub const SRC: usize = 1;
    pub const MSG_ID: Range<usize> = 2..4;
    pub const KIND: usize = 4;
    pub const VERSION: usize = 5;
    pub const LEN: Range<usize> = 6..8;
    pub const PAYLOAD: usize = 8;
}

const _: () = assert!(field::PAYLOAD == PACKET_HEADER_LEN);
const _: () = assert!(packet_len(0) == PACKET_LEN_MIN);
const _: () = assert!(packet_len(PACKET_PAYLOAD_LEN_MAX) == PACKET_LEN_MAX);

/// Length of a global packet whose payload is `payload_len` bytes: header, payload and CRC
/// (without recovery's envelope: [`crate::limits::enveloped_len`] of this; on a byte stream
/// at most [`crate::limits::wire_len_max`] of either). The payloads' lengths are in
/// [`crate::payload`].
pub const fn packet_len(payload_len: usize) -> usize {
    PACKET_HEADER_LEN + payload_len + CRC_LEN
}

/// Version byte of the packet format described here.
pub const PACKET_VERSION: u8 = 1;

/// An address on the global network: a board (`0 .. BOARD_COUNT`, numbered
/// `x + 4y + 16z`) or one of the special addresses below.
pub type BoardId = u8;
/// Address of the graphics engine.
pub const ADDR_GRAPHICS: BoardId = BOARD_COUNT as u8;
/// Address of the host (control console).
pub const ADDR_HOST: BoardId = BOARD_COUNT as u8 + 1;
/// Broadcast to every board.
pub const ADDR_BROADCAST: BoardId = 0xFF;

/// Control commands and reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Control {
    /// Start stepping.
    Start,
    /// Stop stepping.
    Stop,
    /// A board finished a step (step number in the payload, by convention).
    StepDone,
}

/// What a global packet carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PacketKind {
    /// Collision data between distant boards.
    CollisionExchange,
    /// Surface nodes for the graphics engine.
    GraphicsSurface,
    /// A board's bounding box of its contact nodes (every check interval).
    BoundingBox,
    /// A board's share of a tool's contact force (to the host / haptic device).
    ToolForce,
    /// A board's compilation id, to the host before step 0 (the host checks the board
    /// runs the set it loaded).
    Hello,
    /// A tool's pose from a step on, from the host to each board whose contact tables
    /// hold the tool ([`crate::tool_pose`]).
    ToolPose,
    /// Control: start, stop, step done.
    Control(Control),
    /// A board reports a fault.
    FaultReport,
    /// A kind this firmware does not know. Parsed, never rejected.
    Unknown(u8),
}

impl PacketKind {
    /// The wire code.
    pub const fn code(self) -> u8 {
        match self {
            PacketKind::CollisionExchange => 0x01,
            PacketKind::GraphicsSurface => 0x02,
            PacketKind::BoundingBox => 0x03,
            PacketKind::ToolForce => 0x04,
            PacketKind::Hello => 0x05,
            PacketKind::ToolPose => 0x06,
            PacketKind::Control(Control::Start) => 0x10,
            PacketKind::Control(Control::Stop) => 0x11,
            PacketKind::Control(Control::StepDone) => 0x12,
            PacketKind::FaultReport => 0x20,
            PacketKind::Unknown(c) => c,
        }
    }

    /// The kind of a wire code; unknown codes give [`PacketKind::Unknown`].
    pub const fn from_code(code: u8) -> Self {
        match code {
            0x01 => PacketKind::CollisionExchange,
            0x02 => PacketKind::GraphicsSurface,
            0x03 => PacketKind::BoundingBox,
            0x04 => PacketKind::ToolForce,
            0x05 => PacketKind::Hello,
            0x06 => PacketKind::ToolPose,
            0x10 => PacketKind::Control(Control::Start),
            0x11 => PacketKind::Control(Control::Stop),
            0x12 => PacketKind::Control(Control::StepDone),
            0x20 => PacketKind::FaultReport,
            c => PacketKind::Unknown(c),
        }
    }
}

/// A zero-copy view of a global packet in a byte buffer.
#[derive(Debug, Clone)]
pub struct Packet<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Packet<T> {
    /// Wraps a buffer without any check. See the module doc for when accessors panic.
    pub const fn new_unchecked(buffer: T) -> Packet<T> {
        Packet { buffer }
    }

    /// Wraps a buffer after [`Packet::check_len`]. Version and CRC are checked
    /// by [`PacketRepr::parse`].
    pub fn new_checked(buffer: T) -> Result<Packet<T>> {
        let p = Self::new_unchecked(buffer);
        p.check_len()?;
        Ok(p)
    }

    /// Checks that the buffer holds exactly one packet: header, payload of the
    /// announced length (at most [`PACKET_PAYLOAD_LEN_MAX`]) and CRC, nothing
    /// after. Never panics.
    pub fn check_len(&self) -> Result<()> {
        let data = self.buffer.as_ref();
        if data.len() > PACKET_LEN_MAX {
            return Err(Error::Oversized);
        }
        if data.len() < PACKET_LEN_MIN {
            return Err(Error::Truncated);
        }
        let len = match data.get(field::LEN) {
            Some(&[a, b]) => usize::from(u16::from_le_bytes([a, b])),
            _ => return Err(Error::Truncated),
        };
        if len > PACKET_PAYLOAD_LEN_MAX {
            return Err(Error::Oversized);
        }
        let total = packet_len(len);
        match data.len() {
            n if n < total => Err(Error::Truncated),
            n if n > total => Err(Error::BadLength),
            _ => Ok(()),
        }
    }

    /// Returns the underlying buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    /// Destination address.
    pub fn dst(&self) -> BoardId {
        self.buffer.as_ref()[field::DST]
    }

    /// Source address.
    pub fn src(&self) -> BoardId {
        self.buffer.as_ref()[field::SRC]
    }

    /// Message id.
    pub fn msg_id(&self) -> u16 {
        let d = self.buffer.as_ref();
        u16::from_le_bytes([d[field::MSG_ID.start], d[field::MSG_ID.start + 1]])
    }

    /// Kind.
    pub fn kind(&self) -> PacketKind {
        PacketKind::from_code(self.buffer.as_ref()[field::KIND])
    }

    /// Version byte.
    pub fn version(&self) -> u8 {
        self.buffer.as_ref()[field::VERSION]
    }

    /// Announced payload length.
    pub fn payload_len(&self) -> u16 {
        let d = self.buffer.as_ref();
        u16::from_le_bytes([d[field::LEN.start], d[field::LEN.start + 1]])
    }

    /// Payload bytes.
    pub fn payload(&self) -> &[u8] {
        let end = field::PAYLOAD + usize::from(self.payload_len());
        &self.buffer.as_ref()[field::PAYLOAD..end]
    }

    /// What follows the header, whatever the length field says (payload, CRC and any bytes
    /// after; empty if the buffer is no longer than a header). Never panics: for observers
    /// of a packet that may be damaged, its length field included.
    pub fn after_header(&self) -> &[u8] {
        self.buffer.as_ref().get(field::PAYLOAD..).unwrap_or(&[])
    }

    /// The CRC stored in the trailer.
    pub fn crc(&self) -> u32 {
        let d = self.buffer.as_ref();
        let s = field::PAYLOAD + usize::from(self.payload_len());
        u32::from_le_bytes([d[s], d[s + 1], d[s + 2], d[s + 3]])
    }

    /// Whether the trailer matches the CRC of header and payload.
    pub fn verify_crc(&self) -> bool {
        let end = field::PAYLOAD + usize::from(self.payload_len());
        crc32(&self.buffer.as_ref()[..end]) == self.crc()
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Packet<T> {
    /// Sets the destination.
    pub fn set_dst(&mut self, v: BoardId) {
        self.buffer.as_mut()[field::DST] = v;
    }

    /// Sets the source.
    pub fn set_src(&mut self, v: BoardId) {
        self.buffer.as_mut()[field::SRC] = v;
    }

    /// Sets the message id.
    pub fn set_msg_id(&mut self, v: u16) {
        self.buffer.as_mut()[field::MSG_ID].copy_from_slice(&v.to_le_bytes());
    }

    /// Sets the kind.
    pub fn set_kind(&mut self, v: PacketKind) {
        self.buffer.as_mut()[field::KIND] = v.code();
    }

    /// Sets the version byte.
    pub fn set_version(&mut self, v: u8) {
        self.buffer.as_mut()[field::VERSION] = v;
    }

    /// Sets the payload length.
    pub fn set_payload_len(&mut self, v: u16) {
        self.buffer.as_mut()[field::LEN].copy_from_slice(&v.to_le_bytes());
    }

    /// Payload bytes, mutable (set the length first).
    pub fn payload_mut(&mut self) -> &mut [u8] {
        let end = field::PAYLOAD + usize::from(self.payload_len());
        &mut self.buffer.as_mut()[field::PAYLOAD..end]
    }

    /// Computes the CRC of header and payload and stores it in the trailer.
    pub fn fill_crc(&mut self) {
        let end = field::PAYLOAD + usize::from(self.payload_len());
        let crc = crc32(&self.buffer.as_ref()[..end]);
        self.buffer.as_mut()[end..end + CRC_LEN].copy_from_slice(&crc.to_le_bytes());
    }
}

/// The checked, high-level content of a global packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PacketRepr<'a> {
    /// Destination address.
    pub dst: BoardId,
    /// Source address.
    pub src: BoardId,
    /// Message id.
    pub msg_id: u16,
    /// Kind.
    pub kind: PacketKind,
    /// Payload (borrowed from the parsed buffer).
    pub payload: &'a [u8],
}

impl<'a> PacketRepr<'a> {
    /// Parses and fully validates a packet: length, version and CRC. Never panics.
    pub fn parse<T: AsRef<[u8]> + ?Sized>(packet: &Packet<&'a T>) -> Result<PacketRepr<'a>> {
        Self::parse_bytes(packet.buffer.as_ref())
    }

    /// [`PacketRepr::parse`] directly on a byte slice.
    pub fn parse_bytes(bytes: &'a [u8]) -> Result<PacketRepr<'a>> {
        let p = Packet::new_checked(bytes)?;
        if !p.verify_crc() {
            return Err(Error::BadCrc);
        }
        if p.version() != PACKET_VERSION {
            return Err(Error::UnsupportedVersion(p.version()));
        }
        let len = usize::from(p.payload_len());
        Ok(PacketRepr {
            dst: p.dst(),
            src: p.src(),
            msg_id: p.msg_id(),
            kind: p.kind(),
            payload: bytes
                .get(field::PAYLOAD..field::PAYLOAD + len)
                .unwrap_or(&[]),
        })
    }

    /// Length of the emitted packet ([`packet_len`]).
    pub fn buffer_len(&self) -> usize {
        packet_len(self.payload.len())
    }

    /// Length of the emitted packet inside recovery's envelope ([`enveloped_len`]).
    pub fn enveloped_len(&self) -> usize {
        enveloped_len(self.buffer_len())
    }

    /// Emits the packet at the start of `buf`; returns its length. Fails with
    /// [`Error::Oversized`] past [`PACKET_PAYLOAD_LEN_MAX`] payload bytes and
    /// [`Error::BufferTooSmall`]; never panics.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        let plen = u16::try_from(self.payload.len())
            .ok()
            .filter(|&l| usize::from(l) <= PACKET_PAYLOAD_LEN_MAX)
            .ok_or(Error::Oversized)?;
        let len = self.buffer_len();
        let out = buf.get_mut(..len).ok_or(Error::BufferTooSmall)?;
        let mut p = Packet::new_unchecked(out);
        p.set_dst(self.dst);
        p.set_src(self.src);
        p.set_msg_id(self.msg_id);
        p.set_kind(self.kind);
        p.set_version(PACKET_VERSION);
        p.set_payload_len(plen);
        p.payload_mut().copy_from_slice(self.payload);
        p.fill_crc();
        Ok(len)
    }
}
