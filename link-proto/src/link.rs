//! The link interface firmware uses: six faces and the global port, and the clock passed
//! in beside them.
//!
//! Sending and receiving never block. A send that finds the outgoing queue
//! full returns [`SendError::WouldBlock`] and leaves the frame with the caller
//! (it is a borrowed slice: nothing was consumed), who retries later. A
//! receive returns `Ok(None)` when no whole frame has arrived yet. Errors are
//! per frame: after any `Err` the link stays usable.
//!
//! [`crate::stream::StreamLinks`] implements [`Links`] over `embedded-io`
//! byte streams; board-sim provides an emulated implementation.

use core::fmt;

use crate::error::Error;

/// A spatial axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    /// x
    X,
    /// y
    Y,
    /// z
    Z,
}

/// One of a board's six faces, each linked to at most one neighbour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Face {
    /// +x
    PosX,
    /// -x
    NegX,
    /// +y
    PosY,
    /// -y
    NegY,
    /// +z
    PosZ,
    /// -z
    NegZ,
}

impl Face {
    /// Number of faces.
    pub const COUNT: usize = 6;
    /// All faces, in [`Face::index`] order.
    pub const ALL: [Face; Face::COUNT] = [
        Face::PosX,
        Face::NegX,
        Face::PosY,
        Face::NegY,
        Face::PosZ,
        Face::NegZ,
    ];

    /// The face's name in reports: `+x`, `-x`, `+y`, `-y`, `+z`, `-z`.
    pub const fn name(self) -> &'static str {
        FACE_NAMES[self as usize]
    }

    /// Index `0 .. 6` (for arrays of per-face state).
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The face of an index, or `None` past 5.
    pub const fn from_index(i: usize) -> Option<Face> {
        if i < Face::COUNT {
            Some(Face::ALL[i])
        } else {
            None
        }
    }

    /// The face on the other side of the link (the neighbour's face).
    pub const fn opposite(self) -> Face {
        match self {
            Face::PosX => Face::NegX,
            Face::NegX => Face::PosX,
            Face::PosY => Face::NegY,
            Face::NegY => Face::PosY,
            Face::PosZ => Face::NegZ,
            Face::NegZ => Face::PosZ,
        }
    }

    /// The axis the face is normal to.
    pub const fn axis(self) -> Axis {
        match self {
            Face::PosX | Face::NegX => Axis::X,
            Face::PosY | Face::NegY => Axis::Y,
            Face::PosZ | Face::NegZ => Axis::Z,
        }
    }

    /// +1 for the positive faces, -1 for the negative ones.
    pub const fn sign(self) -> i8 {
        match self {
            Face::PosX | Face::PosY | Face::PosZ => 1,
            Face::NegX | Face::NegY | Face::NegZ => -1,
        }
    }
}

/// The faces' names in [`Face::index`] order (reports, command lines).
pub const FACE_NAMES: [&str; Face::COUNT] = ["+x", "-x", "+y", "-y", "+z", "-z"];

/// Why a send did not happen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SendError {
    /// The outgoing queue is full; nothing was sent. Retry with the same frame later.
    WouldBlock,
    /// The frame is longer than the largest frame the port carries.
    TooLong,
    /// No link on this face (edge of the array).
    NoLink,
    /// Shorter than the CRC a link frame ends with: link recovery ([`crate::recovery::face`])
    /// carries frames only.
    NotAFrame,
    /// The underlying stream failed.
    Io(embedded_io::ErrorKind),
}

/// Why a receive did not yield a frame. After any of these the link stays usable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecvError {
    /// A damaged frame arrived and was dropped (lost bytes, bad COBS, oversize).
    Damaged(Error),
    /// A whole frame arrived but did not fit the caller's buffer; it was dropped.
    BufferTooSmall {
        /// The frame's length.
        needed: usize,
    },
    /// No link on this face (edge of the array).
    NoLink,
    /// The underlying stream failed.
    Io(embedded_io::ErrorKind),
    /// Link recovery ([`crate::recovery::face`]) asked the neighbour for frame `seq` `requests`
    /// times without getting it: the link is given up.
    RetriesExhausted {
        /// The frame's sequence number on this link.
        seq: u16,
        /// Requests (negative acknowledgements) sent for it.
        requests: u8,
    },
    /// Global-network recovery ([`crate::recovery::global`]) sent packet `seq` to `peer`
    /// `requests` times again without an acknowledgement: the flow is given up.
    GlobalRetriesExhausted {
        /// The peer's global address.
        peer: u8,
        /// The packet's number in the flow to `peer`.
        seq: u16,
        /// Retransmissions sent for it.
        requests: u8,
    },
}

impl fmt::Display for SendError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SendError::WouldBlock => f.write_str("send queue full"),
            SendError::TooLong => f.write_str("frame too long for the port"),
            SendError::NoLink => f.write_str("no link on this face"),
            SendError::NotAFrame => f.write_str("not a link frame: shorter than its CRC"),
            SendError::Io(k) => write!(f, "stream error: {k:?}"),
        }
    }
}

impl core::error::Error for SendError {}
impl core::error::Error for RecvError {}

impl fmt::Display for RecvError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RecvError::Damaged(e) => write!(f, "damaged frame dropped: {e}"),
            RecvError::BufferTooSmall { needed } => {
                write!(f, "frame of {needed} bytes dropped: buffer too small")
            }
            RecvError::NoLink => f.write_str("no link on this face"),
            RecvError::Io(k) => write!(f, "stream error: {k:?}"),
            RecvError::RetriesExhausted { seq, requests } => write!(
                f,
                "frame {seq} lost: not received after {requests} retransmission requests"
            ),
            RecvError::GlobalRetriesExhausted {
                peer,
                seq,
                requests,
            } => write!(
                f,
                "global packet {seq} to address {peer} not acknowledged after {requests} retransmissions"
            ),
        }
    }
}

/// Monotonic time, passed in (never read globally): what link recovery
/// ([`crate::recovery`]) times its requests by, and what the board runtime's environment
/// extends.
pub trait Clock {
    /// Now, in ns.
    fn now_ns(&mut self) -> u64;
}

/// Non-blocking access to the six face links and the global port.
///
/// Frames are opaque bytes here (one [`crate::frame::Frame`] or
/// [`crate::packet::Packet`] each, by convention); validation is the caller's,
/// through [`crate::frame::FrameRepr::parse`] and
/// [`crate::packet::PacketRepr::parse`].
pub trait Links {
    /// Queues one frame on a face. `Err(WouldBlock)` if the queue is full.
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError>;

    /// Receives one whole frame from a face into `buf`: `Ok(Some(len))`, or
    /// `Ok(None)` if none has arrived yet.
    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError>;

    /// Queues one packet on the global port. `Err(WouldBlock)` if the queue is full.
    fn try_send_global(&mut self, packet: &[u8]) -> Result<(), SendError>;

    /// Receives one whole packet from the global port into `buf`.
    fn try_recv_global(&mut self, buf: &mut [u8]) -> Result<Option<usize>, RecvError>;

    /// Moves queued bytes along without sending or receiving a new frame, for
    /// firmware that computes between sends. Default: nothing to do.
    fn poll(&mut self) {}

    /// The first byte of the next whole frame on a face, without taking it, for a link
    /// that can tell (a wrapper reads control frames ahead of data this way:
    /// [`crate::recovery::face`]). Default: [`Peek::Unknown`].
    fn peek(&mut self, face: Face) -> Peek {
        let _ = face;
        Peek::Unknown
    }
}

/// What [`Links::peek`] saw on a face.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Peek {
    /// No whole frame has arrived.
    Nothing,
    /// A whole frame has arrived; this is its first byte.
    First(u8),
    /// The link cannot tell without taking the frame.
    Unknown,
}

impl<L: Links + ?Sized> Links for &mut L {
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        (**self).try_send(face, frame)
    }

    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        (**self).try_recv(face, buf)
    }

    fn try_send_global(&mut self, packet: &[u8]) -> Result<(), SendError> {
        (**self).try_send_global(packet)
    }

    fn try_recv_global(&mut self, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        (**self).try_recv_global(buf)
    }

    fn poll(&mut self) {
        (**self).poll()
    }

    fn peek(&mut self, face: Face) -> Peek {
        (**self).peek(face)
    }
}
