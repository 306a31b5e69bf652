//! Link frames (point-to-point, address-free), global-network packets, their
//! byte-stream framing and the link interface firmware talks to.
//!
//! `no_std`, allocation-free; builds for `thumbv7em-none-eabihf`.
//!
//! # Formats
//!
//! All multi-byte fields are little-endian. Both formats end in a CRC-32 of
//! everything before it: CRC-32/ISO-HDLC (polynomial `0x04C11DB7`, reflected,
//! init and xor-out `0xFFFFFFFF`; the zlib/Ethernet CRC, also computed by the
//! STM32 CRC unit), see [`frame::crc32`]. It detects every single-bit and
//! every odd-weight error and every burst of up to 32 bits.
//!
//! ## Local link frame ([`frame`])
//!
//! Between neighbours the schedule fixes which value comes when, so a frame
//! carries no address.
//!
//! | offset    | size    | field                                                   |
//! |-----------|---------|---------------------------------------------------------|
//! | 0         | 1       | kind: 1 displacements, 2 forces, 3 barrier, else unknown |
//! | 1         | 1       | precision: value width in bytes, 4 = f32, 8 = f64       |
//! | 2         | 2       | value count `n` (u16, ≤ [`VALUES_PER_FRAME_MAX`])       |
//! | 4         | 4       | step number (u32)                                       |
//! | 8         | `n * w` | values in schedule order                                |
//! | 8 + `n*w` | 4       | CRC-32                                                  |
//!
//! ## Global packet ([`packet`])
//!
//! | offset  | size | field                                                        |
//! |---------|------|--------------------------------------------------------------|
//! | 0       | 1    | destination (board `0..64`, graphics 64, host 65, broadcast 255) |
//! | 1       | 1    | source                                                       |
//! | 2       | 2    | message id (u16)                                             |
//! | 4       | 1    | kind: 0x01 collision, 0x02 graphics surface, 0x03 bounding box, 0x04 tool force, 0x06 tool pose, 0x10/0x11/0x12 control start/stop/step-done, 0x20 fault report, else unknown |
//! | 5       | 1    | version (1)                                                  |
//! | 6       | 2    | payload length `n` (u16, ≤ [`PACKET_PAYLOAD_LEN_MAX`])       |
//! | 8       | `n`  | payload                                                      |
//! | 8 + `n` | 4    | CRC-32                                                       |
//!
//! ## Recovery envelope ([`recovery`])
//!
//! With link recovery, every frame on a face travels in a 10-byte envelope: type, sequence
//! number, piggybacked acknowledgement, the frame, and a CRC-32 of the header and the
//! frame's own CRC; acks, nacks and statuses are envelopes without a frame
//! ([`recovery::face`]). Global packets travel in the same way ([`recovery::global`]).
//!
//! ## Byte stream ([`framing`])
//!
//! `0x00`, COBS(frame or packet), `0x00`. Every `0x00` is a
//! resynchronisation point; damage costs only the frame it hits.
//!
//! # Capacities
//!
//! All sizes derive from the board limits in [`limits`]: 1024 nodes per
//! board, 512 border nodes per face, 3 values per node, so a frame holds at
//! most 1536 values and is at most [`FRAME_LEN_MAX`] = 12 300 bytes
//! ([`FRAME_WIRE_LEN_MAX`] on the stream); a packet carries at most
//! [`PACKET_PAYLOAD_LEN_MAX`] = 12 288 bytes (1024 surface nodes × 3 f32).
//!
//! # Wire lengths
//!
//! One home each, as `const fn`s usable without building a frame (the table is in
//! [`limits`]): [`frame::frame_len`], [`packet::packet_len`], the payloads' `payload_len`
//! and `LEN` in [`payload`], [`enveloped_len`] for recovery's envelope and
//! [`wire_len_max`] for the byte stream.
//!
//! # Panics
//!
//! Parsing, emitting and decoding never panic on any input. Only the field
//! accessors of views made with `new_unchecked` over too-short buffers panic;
//! see each module.
#![no_std]
#![deny(missing_docs)]

pub mod error;
pub mod frame;
pub mod framing;
pub mod gate;
pub mod limits;
pub mod link;
pub mod machine;
pub mod packet;
pub mod payload;
pub mod recovery;
pub mod stream;
pub mod tool_pose;

pub use error::{Error, Result};
pub use frame::{emit_values, Frame, FrameKind, FrameRepr, Payload, Precision, Values};
pub use framing::{encode_wire, StreamDecoder};
pub use limits::*;
pub use link::{Axis, Clock, Face, Links, Peek, RecvError, SendError};
pub use machine::Machine;
pub use packet::{Control, Packet, PacketKind, PacketRepr};
pub use stream::{FacePort, GlobalPort, StreamLinks, StreamPort};
