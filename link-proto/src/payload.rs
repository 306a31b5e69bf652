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
//! | surface ([`PacketKind::GraphicsSurface`](crate::PacketKind)) | frame u32, step u32, chunk u8, chunks u8, count u16, then count × (mesh node u32, displacement 3×f32) |
//!
//! # Panics
//!
//! Never: parsing checks every length first, emitting checks the buffer.

// Index loops mirror the byte offsets of the layout.
#![allow(clippy::needless_range_loop)]

use crate::error::{Error, Result};
use crate::frame::Precision;
use crate::limits::PACKET_PAYLOAD_LEN_MAX;

/// Offset of entry `k`, `None` if the entry would end past `usize::MAX` (found by
/// fuzzing: `k * len` overflowed for a huge `k`).
fn entry_offset(header: usize, k: usize, len: usize) -> Option<usize> {
    let at = k.checked_mul(len)?.checked_add(header)?;
    at.checked_add(len).map(|_| at)
}

fn u32_at(b: &[u8], at: usize) -> Result<u32> {
    match b.get(at..at + 4) {
        Some(&[a, c, d, e]) => Ok(u32::from_le_bytes([a, c, d, e])),
        _ => Err(Error::Truncated),
    }
}
fn f64_at(b: &[u8], at: usize) -> Result<f64> {
    let s = b.get(at..at + 8).ok_or(Error::Truncated)?;
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
    pub const LEN: usize = 52;

    /// Writes the payload; returns its length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        put(buf, 0, &self.step.to_le_bytes())?;
        for i in 0..3 {
            put(buf, 4 + 8 * i, &self.min[i].to_le_bytes())?;
            put(buf, 28 + 8 * i, &self.max[i].to_le_bytes())?;
        }
        Ok(Self::LEN)
    }

    /// Reads a payload of exactly [`BoxPayload::LEN`] bytes.
    pub fn parse(b: &[u8]) -> Result<Self> {
        if b.len() != Self::LEN {
            return Err(if b.len() < Self::LEN {
                Error::Truncated
            } else {
                Error::BadLength
            });
        }
        let mut p = BoxPayload {
            step: u32_at(b, 0)?,
            min: [0.0; 3],
            max: [0.0; 3],
        };
        for i in 0..3 {
            p.min[i] = f64_at(b, 4 + 8 * i)?;
            p.max[i] = f64_at(b, 28 + 8 * i)?;
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
pub const NODES_HEADER_LEN: usize = 8;

/// Length of one node entry whose displacement has `precision`: index u32, 3 values.
pub const fn node_entry_len(precision: Precision) -> usize {
    4 + 3 * precision.width()
}

/// Most node entries of `precision` in one packet.
pub const fn nodes_per_packet_max(precision: Precision) -> usize {
    (PACKET_PAYLOAD_LEN_MAX - NODES_HEADER_LEN) / node_entry_len(precision)
}

impl NodesHeader {
    /// Writes the header; the entries go after it with [`emit_node_entry`].
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        put(buf, 0, &self.step.to_le_bytes())?;
        put(buf, 4, &[self.last as u8, self.precision.code()])?;
        put(buf, 6, &self.count.to_le_bytes())?;
        Ok(NODES_HEADER_LEN + usize::from(self.count) * node_entry_len(self.precision))
    }

    /// Reads the header and checks that exactly `count` entries follow.
    pub fn parse(b: &[u8]) -> Result<Self> {
        let step = u32_at(b, 0)?;
        let last = match b.get(4) {
            Some(0) => false,
            Some(1) => true,
            Some(_) => return Err(Error::BadLength),
            None => return Err(Error::Truncated),
        };
        let precision = Precision::from_code(*b.get(5).ok_or(Error::Truncated)?)?;
        let count = match b.get(6..8) {
            Some(&[x, y]) => u16::from_le_bytes([x, y]),
            _ => return Err(Error::Truncated),
        };
        let need = NODES_HEADER_LEN + usize::from(count) * node_entry_len(precision);
        match b.len() {
            n if n < need => Err(Error::Truncated),
            n if n > need => Err(Error::BadLength),
            _ => Ok(NodesHeader {
                step,
                last,
                precision,
                count,
            }),
        }
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
    put(buf, at, &index.to_le_bytes())?;
    let w = precision.width();
    for i in 0..3 {
        match precision {
            Precision::F32 => put(buf, at + 4 + w * i, &(u[i] as f32).to_le_bytes())?,
            Precision::F64 => put(buf, at + 4 + w * i, &u[i].to_le_bytes())?,
        }
    }
    Ok(())
}

/// Reads node entry `k` of a payload whose header (of `precision`) parsed.
pub fn node_entry(b: &[u8], precision: Precision, k: usize) -> Result<(u32, [f64; 3])> {
    let len = node_entry_len(precision);
    let at = entry_offset(NODES_HEADER_LEN, k, len).ok_or(Error::Truncated)?;
    let w = precision.width();
    let value = |i: usize| match precision {
        Precision::F32 => f32_at(b, at + 4 + w * i).map(f64::from),
        Precision::F64 => f64_at(b, at + 4 + w * i),
    };
    Ok((u32_at(b, at)?, [value(0)?, value(1)?, value(2)?]))
}

/// The compilation id of the image a board runs (to the host, before step 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HelloPayload {
    /// The id's bytes, as the image header holds them.
    pub compilation: [u8; 8],
}

impl HelloPayload {
    /// Payload length.
    pub const LEN: usize = 8;

    /// Writes the payload; returns its length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        put(buf, 0, &self.compilation)?;
        Ok(Self::LEN)
    }

    /// Reads a payload of exactly [`HelloPayload::LEN`] bytes.
    pub fn parse(b: &[u8]) -> Result<Self> {
        match <[u8; 8]>::try_from(b) {
            Ok(compilation) => Ok(HelloPayload { compilation }),
            Err(_) if b.len() < Self::LEN => Err(Error::Truncated),
            Err(_) => Err(Error::BadLength),
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
    pub const LEN: usize = 29;

    /// Writes the payload; returns its length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        put(buf, 0, &self.step.to_le_bytes())?;
        put(buf, 4, &[self.tool])?;
        for i in 0..3 {
            put(buf, 5 + 8 * i, &self.force[i].to_le_bytes())?;
        }
        Ok(Self::LEN)
    }

    /// Reads a payload of exactly [`ToolForcePayload::LEN`] bytes.
    pub fn parse(b: &[u8]) -> Result<Self> {
        if b.len() != Self::LEN {
            return Err(if b.len() < Self::LEN {
                Error::Truncated
            } else {
                Error::BadLength
            });
        }
        Ok(ToolForcePayload {
            step: u32_at(b, 0)?,
            tool: b[4],
            force: [f64_at(b, 5)?, f64_at(b, 13)?, f64_at(b, 21)?],
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
pub const SURFACE_HEADER_LEN: usize = 12;
/// Length of one surface entry.
pub const SURFACE_ENTRY_LEN: usize = 16;
/// Most surface entries in one packet.
pub const SURFACE_NODES_PER_PACKET_MAX: usize =
    (PACKET_PAYLOAD_LEN_MAX - SURFACE_HEADER_LEN) / SURFACE_ENTRY_LEN;

impl SurfaceHeader {
    /// Writes the header; entries follow with [`emit_surface_entry`]. Returns the payload length.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        put(buf, 0, &self.frame.to_le_bytes())?;
        put(buf, 4, &self.step.to_le_bytes())?;
        put(buf, 8, &[self.chunk, self.chunks])?;
        put(buf, 10, &self.count.to_le_bytes())?;
        Ok(SURFACE_HEADER_LEN + usize::from(self.count) * SURFACE_ENTRY_LEN)
    }

    /// Reads the header and checks that exactly `count` entries follow.
    pub fn parse(b: &[u8]) -> Result<Self> {
        let (chunk, chunks, count) = match b.get(8..12) {
            Some(&[c, n, x, y]) => (c, n, u16::from_le_bytes([x, y])),
            _ => return Err(Error::Truncated),
        };
        let need = SURFACE_HEADER_LEN + usize::from(count) * SURFACE_ENTRY_LEN;
        match b.len() {
            n if n < need => Err(Error::Truncated),
            n if n > need => Err(Error::BadLength),
            _ => Ok(SurfaceHeader {
                frame: u32_at(b, 0)?,
                step: u32_at(b, 4)?,
                chunk,
                chunks,
                count,
            }),
        }
    }
}

/// Writes surface entry `k` (mesh node, displacement as f32).
pub fn emit_surface_entry(buf: &mut [u8], k: usize, node: u32, u: [f32; 3]) -> Result<()> {
    let at = entry_offset(SURFACE_HEADER_LEN, k, SURFACE_ENTRY_LEN).ok_or(Error::BufferTooSmall)?;
    put(buf, at, &node.to_le_bytes())?;
    for i in 0..3 {
        put(buf, at + 4 + 4 * i, &u[i].to_bits().to_le_bytes())?;
    }
    Ok(())
}

/// Reads surface entry `k` of a payload whose header parsed.
pub fn surface_entry(b: &[u8], k: usize) -> Result<(u32, [f32; 3])> {
    let at = entry_offset(SURFACE_HEADER_LEN, k, SURFACE_ENTRY_LEN).ok_or(Error::Truncated)?;
    Ok((
        u32_at(b, at)?,
        [f32_at(b, at + 4)?, f32_at(b, at + 8)?, f32_at(b, at + 12)?],
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
