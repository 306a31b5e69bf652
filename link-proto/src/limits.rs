//! Board limits and every capacity derived from them, in one place.
//!
//! Change a board limit here and every buffer size, header field check and
//! COBS bound in the crate follows. Nothing else in the crate spells a size.
//!
//! # Wire lengths
//!
//! The lengths of one frame, packet or envelope, as `const fn`s usable without building
//! one (host reports and timing models, buffer sizes):
//!
//! | length | function |
//! |---|---|
//! | a link frame of `n` values of a precision | [`crate::frame::frame_len`] (and [`crate::frame::FrameRepr::buffer_len`]) |
//! | a global packet of `n` payload bytes | [`crate::packet::packet_len`] (and [`crate::packet::PacketRepr::buffer_len`]) |
//! | a payload: surface chunk, contact nodes, bounding box, tool force, hello, tool pose | [`crate::payload`]: `SurfaceHeader::payload_len`, `NodesHeader::payload_len`, `BoxPayload::LEN`, `ToolForcePayload::LEN`, `HelloPayload::LEN`; [`crate::tool_pose::ToolPoseRepr::LEN`] |
//! | a frame or packet inside its recovery envelope | [`enveloped_len`] (also `crate::recovery::enveloped_len`; `FrameRepr::enveloped_len`, `PacketRepr::enveloped_len`) |
//! | any of these on a byte stream (COBS and delimiters), at most | [`wire_len_max`] |
//!
//! So a graphics chunk of `n` nodes is `packet_len(SurfaceHeader::payload_len(n))` bytes,
//! `enveloped_len(..)` of that with global recovery, and at most `wire_len_max(..)` of
//! either on a stream.

/// Boards along each axis of the array (the array is `GRID_DIM`³ boards).
pub const GRID_DIM: usize = 4;
/// Number of boards in the array.
pub const BOARD_COUNT: usize = GRID_DIM * GRID_DIM * GRID_DIM;

/// Most mesh nodes one board holds (its partition of the tissue mesh).
pub const NODES_PER_BOARD_MAX: usize = 1024;
/// Most nodes one board shares with the neighbour across one face
/// (a face can border at most half of a board's nodes).
pub const BORDER_NODES_PER_FACE_MAX: usize = NODES_PER_BOARD_MAX / 2;
/// Most surface nodes one board reports to the graphics engine per step.
pub const SURFACE_NODES_PER_BOARD_MAX: usize = NODES_PER_BOARD_MAX;
/// Values per node in an exchange (a 3-D vector: displacement or force).
pub const DOFS_PER_NODE: usize = 3;

/// Most values in one link frame: one vector per border node of a face.
pub const VALUES_PER_FRAME_MAX: usize = DOFS_PER_NODE * BORDER_NODES_PER_FACE_MAX;
/// Width of the widest value (f64), in bytes.
pub const VALUE_LEN_MAX: usize = 8;

/// Length of the CRC-32 trailer of frames and packets.
pub const CRC_LEN: usize = 4;

/// Length of the link frame header.
pub const FRAME_HEADER_LEN: usize = 8;
/// Largest link frame payload, in bytes.
pub const FRAME_PAYLOAD_LEN_MAX: usize = VALUES_PER_FRAME_MAX * VALUE_LEN_MAX;
/// Smallest link frame (no values).
pub const FRAME_LEN_MIN: usize = FRAME_HEADER_LEN + CRC_LEN;
/// Largest link frame, header and CRC included.
pub const FRAME_LEN_MAX: usize = FRAME_HEADER_LEN + FRAME_PAYLOAD_LEN_MAX + CRC_LEN;
/// Length of the recovery envelope's header ([`crate::recovery`]): the same six bytes on
/// the faces and on the global network.
pub const ENVELOPE_HEADER_LEN: usize = 6;
/// Bytes the recovery envelope adds to the frame or packet it carries (header and CRC-32);
/// also the whole length of an envelope without one (an ack, nack or status).
pub const ENVELOPE_OVERHEAD: usize = ENVELOPE_HEADER_LEN + CRC_LEN;

/// Length of the recovery envelope around a frame or packet of `len` bytes.
pub const fn enveloped_len(len: usize) -> usize {
    len + ENVELOPE_OVERHEAD
}

/// A link receive buffer: any frame, also inside its recovery envelope, which
/// [`crate::recovery::face`] then checks and unwraps in place (one copy per frame, not two).
pub const FRAME_RX_LEN: usize = enveloped_len(FRAME_LEN_MAX);

/// Length of the global packet header.
pub const PACKET_HEADER_LEN: usize = 8;
/// Largest global packet payload, in bytes: every surface node of a board as
/// three f32 values (the largest message, a graphics surface update).
pub const PACKET_PAYLOAD_LEN_MAX: usize = SURFACE_NODES_PER_BOARD_MAX * DOFS_PER_NODE * 4;
/// Smallest global packet (empty payload).
pub const PACKET_LEN_MIN: usize = PACKET_HEADER_LEN + CRC_LEN;
/// Largest global packet, header and CRC included.
pub const PACKET_LEN_MAX: usize = PACKET_HEADER_LEN + PACKET_PAYLOAD_LEN_MAX + CRC_LEN;

/// Upper bound of the COBS encoding of `n` bytes (without delimiters):
/// one code byte per started run of 254 bytes plus one.
pub const fn cobs_len_max(n: usize) -> usize {
    n + n / 254 + 1
}

/// Number of `0x00` delimiters around each frame on a byte stream (one before,
/// one after; see [`crate::framing`]).
pub const WIRE_DELIMITERS: usize = 2;

/// Upper bound of `n` bytes on a byte stream: their COBS encoding and the delimiters
/// around it ([`crate::framing::encode_wire`] writes at most this many).
pub const fn wire_len_max(n: usize) -> usize {
    cobs_len_max(n) + WIRE_DELIMITERS
}

/// Largest COBS-encoded link frame (decoder buffer size for a face).
pub const FRAME_COBS_LEN_MAX: usize = cobs_len_max(FRAME_LEN_MAX);
/// Largest link frame on the byte stream, delimiters included.
pub const FRAME_WIRE_LEN_MAX: usize = wire_len_max(FRAME_LEN_MAX);
/// Largest COBS-encoded global packet (decoder buffer size for the global port).
pub const PACKET_COBS_LEN_MAX: usize = cobs_len_max(PACKET_LEN_MAX);
/// Largest global packet on the byte stream, delimiters included.
pub const PACKET_WIRE_LEN_MAX: usize = wire_len_max(PACKET_LEN_MAX);

// The header fields that carry these counts are u16.
const _: () = assert!(VALUES_PER_FRAME_MAX <= u16::MAX as usize);
const _: () = assert!(PACKET_PAYLOAD_LEN_MAX <= u16::MAX as usize);
// Board ids must fit the u8 address fields, leaving room for special addresses.
const _: () = assert!(BOARD_COUNT < 0xF0);
