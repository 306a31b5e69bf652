//! A tool's pose, from the host to every board whose contact tables hold that tool
//! ([`PacketKind::ToolPose`](crate::PacketKind)): a live session's instrument moved, or a
//! recorded session replayed. From step `step` on, the board places the tool's capsule at
//! the rigid motion `x' = R(q) x + p` of where the scene places it (the host solver's
//! semantics: `pe_firmware::physics::pose::Pose`).
//!
//! Payload layout (little-endian, [`ToolPoseRepr::LEN`] = 61 bytes):
//!
//! | offset | size | field                                              |
//! |--------|------|----------------------------------------------------|
//! | 0      | 1    | tool (u8, the scene's tool index)                  |
//! | 1      | 4    | step (u32): the step the pose takes effect at      |
//! | 5      | 32   | q: unit quaternion w, x, y, z (4 × f64)            |
//! | 37     | 24   | p_m: translation (m, 3 × f64)                      |
//!
//! A payload that ends inside a field is [`Error::TruncatedField`] naming it; a
//! non-finite value or a quaternion whose squared norm is not within
//! [`Q_NORM2_TOLERANCE`] of 1 is [`Error::BadField`] naming it; bytes after the last field
//! are [`Error::BadLength`].
//!
//! # Timing
//!
//! The host sends a pose [`POSE_DELAY_STEPS`] steps before the step it takes effect at, so
//! that every board holding the tool has it before that step's contact evaluation: the run
//! stays deterministic (a recorded session replays bit for bit). A pose that arrives
//! later is a fault on the board (never applied at another step).
//!
//! # Panics
//!
//! Never: [`ToolPose::new_checked`], [`ToolPoseRepr::parse`] and [`ToolPoseRepr::emit`]
//! check every length. The accessors of a view made with [`ToolPose::new_unchecked`] panic
//! on a buffer shorter than [`ToolPoseRepr::LEN`].

use crate::error::{Error, Result};

/// Steps between the host sending a pose and the step it takes effect at: the global
/// network's latency in steps, with the array's skew. The host knows the array's step
/// from the tool-force packets, which report a step the boards finished (1 step); the
/// boards of a 4×4×4 array run up to its diameter, 9 hops, steps apart (a board cannot
/// finish a step before its neighbours' frames of that step arrive), so some board may
/// be 9 steps past the one the host heard from; the pose packet itself (73 bytes, 83 in
/// recovery's envelope: 6.6 µs at the PE board's 12.5 MB/s global port) and what is
/// queued ahead of it in the board's port take the remaining 6 steps (≥ 126 µs at the
/// built-in medium scene's 21 µs step). 1 + 9 + 6 = 16.
pub const POSE_DELAY_STEPS: u64 = 16;

/// How far `|q|²` may be from 1 in a pose on the wire (the host normalises `q` before it
/// sends it; a larger error is a damaged or foreign payload).
pub const Q_NORM2_TOLERANCE: f64 = 1e-6;

/// Field offsets (the layout above).
mod field {
    use core::ops::Range;
    pub const TOOL: usize = 0;
    pub const STEP: Range<usize> = 1..5;
    pub const Q: Range<usize> = 5..37;
    pub const P: Range<usize> = 37..61;
    pub const END: usize = P.end;
}

/// A zero-copy view of a tool-pose payload.
#[derive(Debug, Clone)]
pub struct ToolPose<T: AsRef<[u8]>> {
    buffer: T,
}

fn f64s<const N: usize>(b: &[u8], at: usize) -> [f64; N] {
    core::array::from_fn(|i| {
        let mut a = [0u8; 8];
        a.copy_from_slice(&b[at + 8 * i..at + 8 * i + 8]);
        f64::from_le_bytes(a)
    })
}

impl<T: AsRef<[u8]>> ToolPose<T> {
    /// Wraps a buffer without any check (see the module doc for when accessors panic).
    pub const fn new_unchecked(buffer: T) -> ToolPose<T> {
        ToolPose { buffer }
    }

    /// Wraps a buffer after [`ToolPose::check_len`].
    pub fn new_checked(buffer: T) -> Result<ToolPose<T>> {
        let v = Self::new_unchecked(buffer);
        v.check_len()?;
        Ok(v)
    }

    /// Checks that the buffer is exactly one payload: [`Error::TruncatedField`] naming the
    /// field it ends in, or [`Error::BadLength`] with trailing bytes.
    pub fn check_len(&self) -> Result<()> {
        let n = self.buffer.as_ref().len();
        let fields = [
            ("tool", field::TOOL + 1),
            ("step", field::STEP.end),
            ("q", field::Q.end),
            ("p_m", field::P.end),
        ];
        if let Some((name, _)) = fields.iter().find(|(_, end)| n < *end) {
            return Err(Error::TruncatedField(name));
        }
        if n > field::END {
            return Err(Error::BadLength);
        }
        Ok(())
    }

    /// The scene's tool index.
    pub fn tool(&self) -> u8 {
        self.buffer.as_ref()[field::TOOL]
    }

    /// The step the pose takes effect at.
    pub fn step(&self) -> u32 {
        let b = &self.buffer.as_ref()[field::STEP];
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }

    /// The rotation's unit quaternion `[w, x, y, z]`.
    pub fn q(&self) -> [f64; 4] {
        f64s(self.buffer.as_ref(), field::Q.start)
    }

    /// The translation (m).
    pub fn p_m(&self) -> [f64; 3] {
        f64s(self.buffer.as_ref(), field::P.start)
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> ToolPose<T> {
    /// Sets the tool index.
    pub fn set_tool(&mut self, v: u8) {
        self.buffer.as_mut()[field::TOOL] = v;
    }

    /// Sets the step.
    pub fn set_step(&mut self, v: u32) {
        self.buffer.as_mut()[field::STEP].copy_from_slice(&v.to_le_bytes());
    }

    /// Sets the quaternion.
    pub fn set_q(&mut self, q: [f64; 4]) {
        let b = &mut self.buffer.as_mut()[field::Q];
        for (i, v) in q.iter().enumerate() {
            b[8 * i..8 * i + 8].copy_from_slice(&v.to_le_bytes());
        }
    }

    /// Sets the translation (m).
    pub fn set_p_m(&mut self, p: [f64; 3]) {
        let b = &mut self.buffer.as_mut()[field::P];
        for (i, v) in p.iter().enumerate() {
            b[8 * i..8 * i + 8].copy_from_slice(&v.to_le_bytes());
        }
    }
}

/// The checked content of a tool-pose payload.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolPoseRepr {
    /// The scene's tool index.
    pub tool: u8,
    /// The step the pose takes effect at.
    pub step: u32,
    /// Unit quaternion `[w, x, y, z]`.
    pub q: [f64; 4],
    /// Translation (m).
    pub p_m: [f64; 3],
}

impl ToolPoseRepr {
    /// Payload length.
    pub const LEN: usize = field::END;

    /// The payload's length: [`ToolPoseRepr::LEN`].
    pub const fn encoded_len(&self) -> usize {
        Self::LEN
    }

    /// Parses and checks a payload view: finite values, `q` of unit length (within
    /// [`Q_NORM2_TOLERANCE`] on `|q|²`), each refusal naming its field.
    pub fn parse<T: AsRef<[u8]>>(view: &ToolPose<T>) -> Result<ToolPoseRepr> {
        view.check_len()?;
        let (q, p_m) = (view.q(), view.p_m());
        let norm2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
        // Finite components give a finite or infinite norm: never NaN here.
        if !q.iter().all(|v| v.is_finite()) || (norm2 - 1.0).abs() > Q_NORM2_TOLERANCE {
            return Err(Error::BadField("q"));
        }
        if !p_m.iter().all(|v| v.is_finite()) {
            return Err(Error::BadField("p_m"));
        }
        Ok(ToolPoseRepr {
            tool: view.tool(),
            step: view.step(),
            q,
            p_m,
        })
    }

    /// [`ToolPoseRepr::parse`] directly on a payload's bytes.
    pub fn parse_bytes(b: &[u8]) -> Result<ToolPoseRepr> {
        Self::parse(&ToolPose::new_unchecked(b))
    }

    /// Writes the payload at the start of `buf`; returns its length
    /// ([`Error::BufferTooSmall`] if it does not fit).
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        let out = buf.get_mut(..Self::LEN).ok_or(Error::BufferTooSmall)?;
        let mut v = ToolPose::new_unchecked(out);
        v.set_tool(self.tool);
        v.set_step(self.step);
        v.set_q(self.q);
        v.set_p_m(self.p_m);
        Ok(Self::LEN)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::ToString;

    fn pose() -> ToolPoseRepr {
        // A quarter turn about z (|q| = 1 to round-off) and a translation far from zero.
        let h = core::f64::consts::FRAC_1_SQRT_2;
        ToolPoseRepr {
            tool: 2,
            step: 0x0102_0304,
            q: [h, 0.0, 0.0, h],
            p_m: [1.5e-3, -2.25e-2, 7.0e-5],
        }
    }

    #[test]
    fn a_pose_round_trips_at_its_documented_offsets() {
        let mut buf = [0u8; 80];
        let p = pose();
        let n = p.emit(&mut buf).unwrap();
        assert_eq!(n, 61);
        assert_eq!(n, p.encoded_len());
        assert_eq!(ToolPoseRepr::parse_bytes(&buf[..n]).unwrap(), p);
        // The layout: tool at 0, step (LE) at 1, q's w at 5, p's x at 37.
        assert_eq!(buf[0], 2);
        assert_eq!(&buf[1..5], &[4, 3, 2, 1]);
        assert_eq!(&buf[5..13], &p.q[0].to_le_bytes());
        assert_eq!(&buf[37..45], &p.p_m[0].to_le_bytes());
        let v = ToolPose::new_checked(&buf[..n]).unwrap();
        assert_eq!(
            (v.tool(), v.step(), v.q(), v.p_m()),
            (2, p.step, p.q, p.p_m)
        );
    }

    #[test]
    fn a_short_or_long_payload_is_refused_naming_the_field() {
        let mut buf = [0u8; 80];
        let n = pose().emit(&mut buf).unwrap();
        for (len, field) in [(0, "tool"), (1, "step"), (4, "step"), (5, "q"), (36, "q")] {
            assert_eq!(
                ToolPoseRepr::parse_bytes(&buf[..len]),
                Err(Error::TruncatedField(field)),
                "{len} bytes"
            );
        }
        assert_eq!(
            ToolPoseRepr::parse_bytes(&buf[..n - 1]),
            Err(Error::TruncatedField("p_m"))
        );
        assert_eq!(
            ToolPoseRepr::parse_bytes(&buf[..n + 1]),
            Err(Error::BadLength)
        );
        assert_eq!(pose().emit(&mut buf[..60]), Err(Error::BufferTooSmall));
    }

    #[test]
    fn a_corrupt_value_is_refused_naming_the_field() {
        let mut buf = [0u8; 61];
        let mut p = pose();
        p.q[1] = f64::NAN;
        p.emit(&mut buf).unwrap();
        assert_eq!(ToolPoseRepr::parse_bytes(&buf), Err(Error::BadField("q")));
        // Not a rotation: |q|² = 1.010025.
        p.q = [1.005, 0.0, 0.0, 0.0];
        p.emit(&mut buf).unwrap();
        assert_eq!(ToolPoseRepr::parse_bytes(&buf), Err(Error::BadField("q")));
        let mut p = pose();
        p.p_m[2] = f64::INFINITY;
        p.emit(&mut buf).unwrap();
        assert_eq!(ToolPoseRepr::parse_bytes(&buf), Err(Error::BadField("p_m")));
        // The error names the field in words.
        assert!(Error::BadField("p_m").to_string().contains("p_m"));
        assert!(Error::TruncatedField("q").to_string().contains("`q`"));
    }
}
