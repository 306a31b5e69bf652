//! POSITION: a position (mm) and an orientation quaternion, big-endian f32 (OpenIGTLink
//! `Documents/Protocol/position.md`; `igtl_position` in `Source/igtlutil/igtl_position.h`,
//! which also admits the shorter forms):
//!
//! | size | content                                                              |
//! |------|----------------------------------------------------------------------|
//! | 28   | X Y Z (mm), then the quaternion OX OY OZ W                          |
//! | 24   | X Y Z, OX OY OZ: W = √(1 − OX² − OY² − OZ²)                          |
//! | 12   | X Y Z only: no rotation                                              |
//!
//! Note the quaternion's order on the wire, `(x, y, z, w)`, against the session's
//! `(w, x, y, z)`. pyigtl's `PositionMessage` packs a different, POINT-like layout (name,
//! group, colour, ...) that no OpenIGTLink implementation reads; this server reads the
//! specification's.
//!
//! # Panics
//! [`Position::new_checked`], [`PositionRepr::parse`], [`PositionRepr::emit`] and
//! [`PositionRepr::pose`] never panic. The accessors of a [`Position`] made with
//! [`Position::new_unchecked`] panic on fewer than 12 bytes (quaternion accessors: on
//! fewer than the form they read).

use super::error::{Error, Result};
use super::transform::MM_PER_M;
use crate::live::engine::Pose;

/// Bytes of the full POSITION content.
pub const POSITION_LEN: usize = 28;
/// A quaternion's length may differ from 1 by this much (as the session's JSON poses).
pub const UNIT_TOLERANCE: f64 = 1e-3;

/// A zero-copy view of a POSITION content (12, 24 or 28 bytes).
#[derive(Debug, Clone)]
pub struct Position<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Position<T> {
    pub const fn new_unchecked(buffer: T) -> Position<T> {
        Position { buffer }
    }

    pub fn new_checked(buffer: T) -> Result<Position<T>> {
        let len = buffer.as_ref().len();
        if !matches!(len, 12 | 24 | 28) {
            return Err(Error::BadLength {
                what: "POSITION content",
                len,
                expected: "12, 24 or 28",
            });
        }
        Ok(Position { buffer })
    }

    /// Number of f32 values (3, 6 or 7).
    pub fn values(&self) -> usize {
        self.buffer.as_ref().len() / 4
    }

    /// The `i`-th f32 in wire order.
    pub fn value(&self, i: usize) -> f32 {
        let b = &self.buffer.as_ref()[4 * i..4 * i + 4];
        f32::from_be_bytes([b[0], b[1], b[2], b[3]])
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Position<T> {
    pub fn set_value(&mut self, i: usize, v: f32) {
        self.buffer.as_mut()[4 * i..4 * i + 4].copy_from_slice(&v.to_be_bytes());
    }
}

/// A POSITION's values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionRepr {
    pub position_mm: [f32; 3],
    /// `(x, y, z, w)` as on the wire; `None` for the 12-byte form.
    pub quaternion_xyzw: Option<[f32; 4]>,
}

impl PositionRepr {
    /// Reads any of the three forms (the 24-byte form's `w` from the unit length).
    pub fn parse<T: AsRef<[u8]>>(v: &Position<T>) -> PositionRepr {
        let position_mm = core::array::from_fn(|i| v.value(i));
        let quaternion_xyzw = match v.values() {
            7 => Some(core::array::from_fn(|i| v.value(3 + i))),
            6 => {
                let [x, y, z] = [v.value(3), v.value(4), v.value(5)];
                Some([x, y, z, (1.0 - x * x - y * y - z * z).max(0.0).sqrt()])
            }
            _ => None,
        };
        PositionRepr {
            position_mm,
            quaternion_xyzw,
        }
    }

    pub fn parse_bytes(content: &[u8]) -> Result<PositionRepr> {
        Ok(Self::parse(&Position::new_checked(content)?))
    }

    /// Bytes of the emitted content: the full 28-byte form, or 12 without a quaternion.
    pub fn buffer_len(&self) -> usize {
        if self.quaternion_xyzw.is_some() {
            POSITION_LEN
        } else {
            12
        }
    }

    pub fn emit(&self, buf: &mut [u8]) -> Result<()> {
        let need = self.buffer_len();
        if buf.len() != need {
            return Err(Error::BufferTooSmall {
                need,
                have: buf.len(),
            });
        }
        let mut v = Position::new_unchecked(buf);
        let q = self.quaternion_xyzw.iter().flatten();
        for (i, x) in self.position_mm.iter().chain(q).enumerate() {
            v.set_value(i, *x);
        }
        Ok(())
    }

    /// The pose (mm → m; quaternion to `(w, x, y, z)`, normalised): refused if a value is
    /// not finite or the quaternion's length is not within [`UNIT_TOLERANCE`] of 1.
    pub fn pose(&self) -> Result<Pose> {
        let [x, y, z, w] = self.quaternion_xyzw.unwrap_or([0.0, 0.0, 0.0, 1.0]);
        let values = vec![
            self.position_mm[0],
            self.position_mm[1],
            self.position_mm[2],
            x,
            y,
            z,
            w,
        ];
        if values.iter().any(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "POSITION",
                values,
            });
        }
        let q = [w, x, y, z].map(f64::from);
        let norm = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > UNIT_TOLERANCE {
            return Err(Error::NotUnit {
                norm,
                tolerance: UNIT_TOLERANCE,
            });
        }
        Ok(Pose {
            q: q.map(|c| c / norm),
            p_m: self.position_mm.map(|c| f64::from(c) / MM_PER_M),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes(values: &[f32]) -> Vec<u8> {
        values.iter().flat_map(|v| v.to_be_bytes()).collect()
    }

    #[test]
    fn the_three_forms_read_as_the_spec_lays_them_out() {
        let h = 0.5f32.sqrt();
        let full = PositionRepr::parse_bytes(&bytes(&[1.0, 2.0, 3.0, 0.0, 0.0, h, h])).unwrap();
        assert_eq!(full.quaternion_xyzw, Some([0.0, 0.0, h, h]));
        let p = full.pose().unwrap();
        assert!((p.q[0] - f64::from(h)).abs() < 1e-7 && (p.q[3] - f64::from(h)).abs() < 1e-7);
        assert_eq!(p.p_m, [0.001, 0.002, 0.003]);
        let mut out = vec![0u8; full.buffer_len()];
        full.emit(&mut out).unwrap();
        assert_eq!(out, bytes(&[1.0, 2.0, 3.0, 0.0, 0.0, h, h]));

        let three = PositionRepr::parse_bytes(&bytes(&[1.0, 2.0, 3.0, 0.0, 0.6, 0.0])).unwrap();
        assert_eq!(three.quaternion_xyzw, Some([0.0, 0.6, 0.0, 0.8]));

        let only = PositionRepr::parse_bytes(&bytes(&[4.0, 5.0, 6.0])).unwrap();
        assert_eq!(only.pose().unwrap().q, [1.0, 0.0, 0.0, 0.0]);
        let mut out = vec![0u8; only.buffer_len()];
        only.emit(&mut out).unwrap();
        assert_eq!(out.len(), 12);
    }

    #[test]
    fn bad_lengths_values_and_quaternions_are_refused() {
        let e = PositionRepr::parse_bytes(&[0u8; 16]).unwrap_err();
        assert!(matches!(e, Error::BadLength { len: 16, .. }));
        let inf = PositionRepr::parse_bytes(&bytes(&[f32::INFINITY, 0.0, 0.0])).unwrap();
        assert!(matches!(inf.pose(), Err(Error::NonFinite { .. })));
        let long =
            PositionRepr::parse_bytes(&bytes(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.01])).unwrap();
        let e = long.pose().unwrap_err();
        assert!(matches!(e, Error::NotUnit { .. }), "{e}");
        assert!(e.to_string().contains("1.010000"), "{e}");
    }
}
