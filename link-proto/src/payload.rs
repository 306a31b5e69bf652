//! Payloads of the global packets the board runtime sends: bounding boxes and contact-node
//! displacements (collision exchange between distant boards), tool forces (to the host,
//! which drives the haptic device) and surface chunks (to the graphics engine).
//!
//! Fixed little-endian layouts:
//!
//! | payload | layout |
//! |---|---|
//! | [`BoxPayload`] ([`PacketKind::BoundingBox`](crate::PacketKind)) | step u32, min 3×f64, max 3×f64 (52 bytes) |
//! | nodes ([`PacketKind::CollisionExchange`](crate::PacketKind)) | step u32, last u8 (1: the sender's last packet of the step), precision u8 (the value width, 4 or 8), count u16, then count × (contact-node index u32, displacement 3×f32 or 3×f64) |
//! | [`ToolForcePayload`] ([`PacketKind::ToolForce`](crate::PacketKind)) | step u32, tool u8, force 3×f64 (29 bytes) |
//! | [`HelloPayload`] ([`PacketKind::Hello`](crate::PacketKind)) | compilation id, 8 bytes as in the image header |
//! | [`ToolPoseRepr`](crate::tool_pose::ToolPoseRepr) ([`PacketKind::ToolPose`](crate::PacketKind), host to boards) | tool u8, step u32, q 4×f64, p_m 3×f64 (61 bytes; [`crate::tool_pose`]) |
//! | surface ([`PacketKind::GraphicsSurface`](crate::PacketKind)) | frame u32, step u32, chunk u8, chunks u8, count u16, then count × (mesh node u32, displacement 3×f32) |
//!
//! # Lengths
//!
//! Each payload says its length, for given counts, without being built:
//! [`SurfaceHeader::payload_len`]`(count)`, [`NodesHeader::payload_len`]`(count, precision)`,
//! [`BoxPayload::LEN`], [`ToolForcePayload::LEN`], [`HelloPayload::LEN`]; and, built, each
//! one's `encoded_len()` (what `emit` returns). The packet around a payload of `n` bytes is
//! [`crate::packet::packet_len`]`(n)` bytes (see [`crate::limits`] for the envelope and the
//! byte stream).
//!
//! # Panics
//!
//! Never: parsing checks every length first, emitting checks the buffer.

// Index loops mirror the byte offsets of the layout.
#![allow(clippy::needless_range_loop)]

use crate::error::{Error, Result};
use crate::frame::Precision;
use crate::limits::PACKET_PAYLOAD_LEN_MAX;
use crate::packet::PacketKind;

/// Field offsets of the payloads (the layouts above); an entry's fields are counted from
/// the entry's start.
mod field {
    /// A u32.
    pub const U32: usize = 4;
    /// An f64.
    pub const F64: usize = 8;
    /// An f32.
    pub const F32: usize = 4;

    /// [`super::BoxPayload`].
    pub mod bbox {
        pub const STEP: usize = 0;
        pub const MIN: usize = 4;
        pub const MAX: usize = MIN + 3 * super::F64;
        pub const END: usize = MAX + 3 * super::F64;
    }

    /// [`super::NodesHeader`] and its entries.
    pub mod nodes {
        pub const STEP: usize = 0;
        pub const LAST: usize = 4;
        pub const PRECISION: usize = 5;
        pub const COUNT: core::ops::Range<usize> = 6..8;
        pub const END: usize = COUNT.end;
        /// Within an entry: the contact-node index, then three values.
        pub const INDEX: usize = 0;
        pub const VALUES: usize = INDEX + super::U32;
    }

    /// [`super::ToolForcePayload`].
    pub mod tool {
        pub const STEP: usize = 0;
        pub const TOOL: usize = 4;
        pub const FORCE: usize = 5;
        pub const END: usize = FORCE + 3 * super::F64;
    }

    /// [`super::HelloPayload`].
    pub mod hello {
        pub const ID: usize = 0;
        pub const END: usize = ID + 8;
    }

    /// [`super::SurfaceHeader`] and its entries.
    pub mod surface {
        pub const FRAME: usize = 0;
        pub const STEP: usize = 4;
        pub const CHUNK: usize = 8;
        pub const CHUNKS: usize = 9;
        pub const COUNT: core::ops::Range<usize> = 10..12;
        pub const END: usize = COUNT.end;
        /// Within an entry: the mesh node, then three f32 values.
        pub const NODE: usize = 0;
        pub const VALUES: usize = NODE + super::U32;
        pub const ENTRY_END: usize = VALUES + 3 * super::F32;
    }
}

const _: () = assert!(field::bbox::STEP + field::U32 == field::bbox::MIN);
const _: () = assert!(field::nodes::STEP + field::U32 == field::nodes::LAST);
const _: () = assert!(field::tool::STEP + field::U32 == field::tool::TOOL);
const _: () = assert!(field::surface::FRAME + field::U32 == field::surface::STEP);
const _: () = assert!(field::surface::STEP + field::U32 == field::surface::CHUNK);

/// The step a payload of `kind` belongs to, read from its step field alone (boxes, contact
/// nodes and tool forces carry it first, surface chunks after their frame number); `None`
/// for other kinds or too short a payload. No other check: for observers of a packet that
/// may be damaged.
pub fn step_of(kind: PacketKind, payload: &[u8]) -> Option<u32> {
    let at = match kind {
        PacketKind::BoundingBox => field::bbox::STEP,
        PacketKind::CollisionExchange => field::nodes::STEP,
        PacketKind::ToolForce => field::tool::STEP,
        PacketKind::GraphicsSurface => field::surface::STEP,
        _ => return None,
    };
    u32_at(payload, at).ok()
}

/// Offset of entry `k`, `None` if the entry would end past `usize::MAX` (found by
/// fuzzing: `k * len` overflowed for a huge `k`).
fn entry_offset(header: usize, k: usize, len: usize) -> Option<usize> {
    let at = k.checked_mul(len)?.checked_add(header)?;
    at.checked_add(len).map(|_| at)
}

fn u16_at(b: &[u8], range: core::ops::Range<usize>) -> Result<u16> {
    match b.get(range) {
        Some(&[x, y]) => Ok(u16::from_le_bytes([x, y])),
        _ => Err(Error::Truncated),
    }
}
fn u32_at(b: &[u8], at: usize) -> Result<u32> {
    match b.get(at..at + field::U32) {
        Some(&[a, c, d, e]) => Ok(u32::from_le_bytes([a, c, d, e])),
        _ => Err(Error::Truncated),
    }
}
fn f64_at(b: &[u8], at: usize) -> Result<f64> {
    let s = b.get(at..at + field::F64).ok_or(Error::Truncated)?;
    let mut a = [0u8; 8];
    a.copy_from_slice(s);
    Ok(f64::from_le_bytes(a))
}
fn f32_at(b: &[u8], at: usize) -> Result<f32> {
    u32_at(b, at).map(f32::from_bits)
}
fn put(buf: &mut [u8], at: usize, bytes: &[u8]) -> Result<()> {
    buf.get_mut(at..at + bytes.len())
        .ok_or(Error::BufferTooSmall)?
        .copy_from_slice(bytes);
    Ok(())
}

/// [`Error::Truncated`] or [`Error::BadLength`] unless `b` is exactly `len` bytes.
fn exact(b: &[u8], len: usize) -> Result<()> {
    match b.len() {
        n if n < len => Err(Error::Truncated),
        n if n > len => Err(Error::BadLength),
        _ => Ok(()),
    }
}

/// A board's bounding box of its contact nodes at a check step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxPayload {
    /// Step of the check.
    pub step: u32,
    /// Lower corner (m).
    pub min: [f64; 3],
    /// Upper corner (m).
    pub max: [f64; 3],
}

impl BoxPayload {
    /// Payload length.
    pub const LEN: usize = field::bbox::END;

    /// The payload's length: [`BoxPayload::LEN`].
    pub const fn encoded_len(&self) -> usize {
        Self::LEN
    }

    /// Writes the payload; returns its length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        use field::bbox;
        put(buf, bbox::STEP, &self.step.to_le_bytes())?;
        for i in 0..3 {
            put(buf, bbox::MIN + field::F64 * i, &self.min[i].to_le_bytes())?;
            put(buf, bbox::MAX + field::F64 * i, &self.max[i].to_le_bytes())?;
        }
        Ok(self.encoded_len())
    }

    /// Reads a payload of exactly [`BoxPayload::LEN`] bytes.
    pub fn parse(b: &[u8]) -> Result<Self> {
        use field::bbox;
        exact(b, Self::LEN)?;
        let mut p = BoxPayload {
            step: u32_at(b, bbox::STEP)?,
            min: [0.0; 3],
            max: [0.0; 3],
        };
        for i in 0..3 {
            p.min[i] = f64_at(b, bbox::MIN + field::F64 * i)?;
            p.max[i] = f64_at(b, bbox::MAX + field::F64 * i)?;
        }
        Ok(p)
    }
}

/// Header of a contact-node displacement payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NodesHeader {
    /// Step whose displacements these are.
    pub step: u32,
    /// The sender's last packet for this step.
    pub last: bool,
    /// Width of the displacements: the sender's arithmetic (a board computing in f32 sends
    /// its f32 values, exactly, in half the bytes).
    pub precision: Precision,
    /// Entries that follow.
    pub count: u16,
}

/// Header length of a node payload.
pub const NODES_HEADER_LEN: usize = field::nodes::END;

/// Length of one node entry whose displacement has `precision`: index u32, 3 values.
pub const fn node_entry_len(precision: Precision) -> usize {
    field::nodes::VALUES + 3 * precision.width()
}

/// Most node entries of `precision` in one packet.
pub const fn nodes_per_packet_max(precision: Precision) -> usize {
    (PACKET_PAYLOAD_LEN_MAX - NODES_HEADER_LEN) / node_entry_len(precision)
}

impl NodesHeader {
    /// Length of a node payload of `count` entries of `precision`: the header and the
    /// entries.
    pub const fn payload_len(count: usize, precision: Precision) -> usize {
        NODES_HEADER_LEN + count * node_entry_len(precision)
    }

    /// Length of the payload this header heads ([`NodesHeader::payload_len`]).
    pub const fn encoded_len(&self) -> usize {
        Self::payload_len(self.count as usize, self.precision)
    }

    /// Writes the header; the entries go after it with [`emit_node_entry`]. Returns the
    /// payload's length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        use field::nodes;
        put(buf, nodes::STEP, &self.step.to_le_bytes())?;
        put(buf, nodes::LAST, &[self.last as u8])?;
        put(buf, nodes::PRECISION, &[self.precision.code()])?;
        put(buf, nodes::COUNT.start, &self.count.to_le_bytes())?;
        Ok(self.encoded_len())
    }

    /// Reads the header and checks that exactly `count` entries follow.
    pub fn parse(b: &[u8]) -> Result<Self> {
        use field::nodes;
        let step = u32_at(b, nodes::STEP)?;
        let last = match b.get(nodes::LAST) {
            Some(0) => false,
            Some(1) => true,
            Some(_) => return Err(Error::BadLength),
            None => return Err(Error::Truncated),
        };
        let precision = Precision::from_code(*b.get(nodes::PRECISION).ok_or(Error::Truncated)?)?;
        let count = u16_at(b, nodes::COUNT)?;
        exact(b, Self::payload_len(usize::from(count), precision))?;
        Ok(NodesHeader {
            step,
            last,
            precision,
            count,
        })
    }
}

/// Writes node entry `k` (contact-node index, displacement) of a payload whose values have
/// `precision` (an f32 entry holds `u` rounded to f32: exact for a board computing in f32).
pub fn emit_node_entry(
    buf: &mut [u8],
    precision: Precision,
    k: usize,
    index: u32,
    u: [f64; 3],
) -> Result<()> {
    let len = node_entry_len(precision);
    let at = entry_offset(NODES_HEADER_LEN, k, len).ok_or(Error::BufferTooSmall)?;
    put(buf, at + field::nodes::INDEX, &index.to_le_bytes())?;
    let (w, values) = (precision.width(), at + field::nodes::VALUES);
    for i in 0..3 {
        match precision {
            Precision::F32 => put(buf, values + w * i, &(u[i] as f32).to_le_bytes())?,
            Precision::F64 => put(buf, values + w * i, &u[i].to_le_bytes())?,
        }
    }
    Ok(())
}

/// Reads node entry `k` of a payload whose header (of `precision`) parsed.
pub fn node_entry(b: &[u8], precision: Precision, k: usize) -> Result<(u32, [f64; 3])> {
    let len = node_entry_len(precision);
    let at = entry_offset(NODES_HEADER_LEN, k, len).ok_or(Error::Truncated)?;
    let (w, values) = (precision.width(), at + field::nodes::VALUES);
    let value = |i: usize| match precision {
        Precision::F32 => f32_at(b, values + w * i).map(f64::from),
        Precision::F64 => f64_at(b, values + w * i),
    };
    Ok((
        u32_at(b, at + field::nodes::INDEX)?,
        [value(0)?, value(1)?, value(2)?],
    ))
}

/// The compilation id of the image a board runs (to the host, before step 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HelloPayload {
    /// The id's bytes, as the image header holds them.
    pub compilation: [u8; 8],
}

impl HelloPayload {
    /// Payload length.
    pub const LEN: usize = field::hello::END;

    /// The payload's length: [`HelloPayload::LEN`].
    pub const fn encoded_len(&self) -> usize {
        Self::LEN
    }

    /// Writes the payload; returns its length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        put(buf, field::hello::ID, &self.compilation)?;
        Ok(self.encoded_len())
    }

    /// Reads a payload of exactly [`HelloPayload::LEN`] bytes.
    pub fn parse(b: &[u8]) -> Result<Self> {
        exact(b, Self::LEN)?;
        let id = b.get(field::hello::ID..field::hello::END);
        match id.and_then(|id| <[u8; 8]>::try_from(id).ok()) {
            Some(compilation) => Ok(HelloPayload { compilation }),
            None => Err(Error::Truncated),
        }
    }
}

/// A board's share of a tool's contact force at a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolForcePayload {
    /// Step.
    pub step: u32,
    /// Tool index in the scene.
    pub tool: u8,
    /// Force of the tissue on the tool (N).
    pub force: [f64; 3],
}

impl ToolForcePayload {
    /// Payload length.
    pub const LEN: usize = field::tool::END;

    /// The payload's length: [`ToolForcePayload::LEN`].
    pub const fn encoded_len(&self) -> usize {
        Self::LEN
    }

    /// Writes the payload; returns its length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        use field::tool;
        put(buf, tool::STEP, &self.step.to_le_bytes())?;
        put(buf, tool::TOOL, &[self.tool])?;
        for i in 0..3 {
            put(
                buf,
                tool::FORCE + field::F64 * i,
                &self.force[i].to_le_bytes(),
            )?;
        }
        Ok(self.encoded_len())
    }

    /// Reads a payload of exactly [`ToolForcePayload::LEN`] bytes.
    pub fn parse(b: &[u8]) -> Result<Self> {
        use field::tool;
        exact(b, Self::LEN)?;
        let force = |i: usize| f64_at(b, tool::FORCE + field::F64 * i);
        Ok(ToolForcePayload {
            step: u32_at(b, tool::STEP)?,
            tool: *b.get(tool::TOOL).ok_or(Error::Truncated)?,
            force: [force(0)?, force(1)?, force(2)?],
        })
    }
}

/// Header of a graphics surface chunk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SurfaceHeader {
    /// Graphics frame number (0, 1, ... every graphics interval).
    pub frame: u32,
    /// Step whose displacements the chunk carries.
    pub step: u32,
    /// Chunk number and chunk count of this board's frame.
    pub chunk: u8,
    /// Chunks of this board's frame.
    pub chunks: u8,
    /// Entries that follow.
    pub count: u16,
}

/// Header length of a surface payload.
pub const SURFACE_HEADER_LEN: usize = field::surface::END;
/// Length of one surface entry.
pub const SURFACE_ENTRY_LEN: usize = field::surface::ENTRY_END;
/// Most surface entries in one packet.
pub const SURFACE_NODES_PER_PACKET_MAX: usize =
    (PACKET_PAYLOAD_LEN_MAX - SURFACE_HEADER_LEN) / SURFACE_ENTRY_LEN;

impl SurfaceHeader {
    /// Length of a surface payload of `count` entries: the header and the entries.
    pub const fn payload_len(count: usize) -> usize {
        SURFACE_HEADER_LEN + count * SURFACE_ENTRY_LEN
    }

    /// Length of the payload this header heads ([`SurfaceHeader::payload_len`]).
    pub const fn encoded_len(&self) -> usize {
        Self::payload_len(self.count as usize)
    }

    /// Writes the header; entries follow with [`emit_surface_entry`]. Returns the payload length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        use field::surface;
        put(buf, surface::FRAME, &self.frame.to_le_bytes())?;
        put(buf, surface::STEP, &self.step.to_le_bytes())?;
        put(buf, surface::CHUNK, &[self.chunk])?;
        put(buf, surface::CHUNKS, &[self.chunks])?;
        put(buf, surface::COUNT.start, &self.count.to_le_bytes())?;
        Ok(self.encoded_len())
    }

    /// Reads the header and checks that exactly `count` entries follow.
    pub fn parse(b: &[u8]) -> Result<Self> {
        use field::surface;
        let (Some(&chunk), Some(&chunks), Ok(count)) = (
            b.get(surface::CHUNK),
            b.get(surface::CHUNKS),
            u16_at(b, surface::COUNT),
        ) else {
            return Err(Error::Truncated);
        };
        exact(b, Self::payload_len(usize::from(count)))?;
        Ok(SurfaceHeader {
            frame: u32_at(b, surface::FRAME)?,
            step: u32_at(b, surface::STEP)?,
            chunk,
            chunks,
            count,
        })
    }
}

/// Writes surface entry `k` (mesh node, displacement as f32).
pub fn emit_surface_entry(buf: &mut [u8], k: usize, node: u32, u: [f32; 3]) -> Result<()> {
    use field::surface;
    let at = entry_offset(SURFACE_HEADER_LEN, k, SURFACE_ENTRY_LEN).ok_or(Error::BufferTooSmall)?;
    put(buf, at + surface::NODE, &node.to_le_bytes())?;
    for i in 0..3 {
        let v = at + surface::VALUES + field::F32 * i;
        put(buf, v, &u[i].to_bits().to_le_bytes())?;
    }
    Ok(())
}

/// Reads surface entry `k` of a payload whose header parsed.
pub fn surface_entry(b: &[u8], k: usize) -> Result<(u32, [f32; 3])> {
    use field::surface;
    let at = entry_offset(SURFACE_HEADER_LEN, k, SURFACE_ENTRY_LEN).ok_or(Error::Truncated)?;
    let value = |i: usize| f32_at(b, at + surface::VALUES + field::F32 * i);
    Ok((
        u32_at(b, at + surface::NODE)?,
        [value(0)?, value(1)?, value(2)?],
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payloads_round_trip_and_refuse_bad_lengths() {
        let mut buf = [0u8; 256];
        let b = BoxPayload {
            step: 7,
            min: [-1.0, 0.5, 2.0],
            max: [3.0, 4.0, 5.5],
        };
        let n = b.emit(&mut buf).unwrap();
        assert_eq!(BoxPayload::parse(&buf[..n]).unwrap(), b);
        assert_eq!(BoxPayload::parse(&buf[..n - 1]), Err(Error::Truncated));
        // Both widths: the values (far from zero, with bits below f32's precision in f64)
        // come back exactly as emitted, f32 entries as the f32 rounding of what was given.
        let u = [[1.0, -2.5, 3.0e-3], [4.0 + 1e-12, 5.0, -6.25]];
        for precision in [Precision::F32, Precision::F64] {
            let h = NodesHeader {
                step: 9,
                last: true,
                precision,
                count: 2,
            };
            let n = h.emit(&mut buf).unwrap();
            assert_eq!(n, NODES_HEADER_LEN + 2 * node_entry_len(precision));
            emit_node_entry(&mut buf, precision, 0, 5, u[0]).unwrap();
            emit_node_entry(&mut buf, precision, 1, 6, u[1]).unwrap();
            assert_eq!(NodesHeader::parse(&buf[..n]).unwrap(), h);
            let want = match precision {
                Precision::F32 => u[1].map(|v| f64::from(v as f32)),
                Precision::F64 => u[1],
            };
            assert_eq!(node_entry(&buf[..n], precision, 1).unwrap(), (6, want));
            assert_eq!(NodesHeader::parse(&buf[..n + 1]), Err(Error::BadLength));
            assert_eq!(NodesHeader::parse(&buf[..n - 1]), Err(Error::Truncated));
        }
        assert_ne!(
            f64::from(u[1][0] as f32),
            u[1][0],
            "the f64 value has bits f32 drops"
        );
        // An f32 entry is 16 bytes against 28, and a packet holds more of them.
        assert_eq!(node_entry_len(Precision::F32), 16);
        assert_eq!(node_entry_len(Precision::F64), 28);
        assert!(nodes_per_packet_max(Precision::F32) > nodes_per_packet_max(Precision::F64));
        // An unknown width code is refused.
        buf[5] = 3;
        assert_eq!(
            NodesHeader::parse(&buf[..8]),
            Err(Error::UnknownPrecision(3))
        );
        let t = ToolForcePayload {
            step: 3,
            tool: 1,
            force: [0.1, -0.2, 0.3],
        };
        let n = t.emit(&mut buf).unwrap();
        assert_eq!(ToolForcePayload::parse(&buf[..n]).unwrap(), t);
        let hello = HelloPayload {
            compilation: [0x57, 0xdc, 1, 2, 3, 4, 5, 0xff],
        };
        let n = hello.emit(&mut buf).unwrap();
        assert_eq!(n, HelloPayload::LEN);
        assert_eq!(HelloPayload::parse(&buf[..n]).unwrap(), hello);
        assert_eq!(HelloPayload::parse(&buf[..n - 1]), Err(Error::Truncated));
        assert_eq!(HelloPayload::parse(&buf[..n + 1]), Err(Error::BadLength));
        assert_eq!(hello.emit(&mut buf[..7]), Err(Error::BufferTooSmall));
        let s = SurfaceHeader {
            frame: 2,
            step: 800,
            chunk: 3,
            chunks: 20,
            count: 1,
        };
        let n = s.emit(&mut buf).unwrap();
        emit_surface_entry(&mut buf, 0, 42, [1.5, -2.0, 0.25]).unwrap();
        assert_eq!(SurfaceHeader::parse(&buf[..n]).unwrap(), s);
        assert_eq!(
            surface_entry(&buf[..n], 0).unwrap(),
            (42, [1.5, -2.0, 0.25])
        );
        assert_eq!(SurfaceHeader::parse(&buf[..3]), Err(Error::Truncated));
    }
}
