//! POINT: a list of 136-byte point records (OpenIGTLink `Documents/Protocol/point.md`;
//! `igtl_point_element` in `Source/igtlutil/igtl_point.h`; pyigtl `PointMessage`, struct
//! `'> 64s 32s B B B B f f f f 20s'`), big-endian:
//!
//! | offset | size | field                                      |
//! |--------|------|--------------------------------------------|
//! | 0      | 64   | name, NUL-padded                           |
//! | 64     | 32   | group, NUL-padded                          |
//! | 96     | 4    | colour R, G, B, A (u8)                     |
//! | 100    | 12   | X, Y, Z (f32; millimetres in the spec)     |
//! | 112    | 4    | diameter (f32, mm)                         |
//! | 116    | 20   | owner, NUL-padded                          |
//!
//! This server sends a tool's force as one such point ([`super::outbound`]): name = tool,
//! group [`FORCE_GROUP`], X Y Z = the force in newtons (not a position), diameter 0.
//!
//! # Panics
//! [`Point::new_checked`], [`PointRepr::parse`] and [`PointRepr::emit`] never panic. The
//! accessors of a [`Point`] made with [`Point::new_unchecked`] panic on a record index past
//! the buffer.

use super::error::{Error, Result};
use super::header::{set_padded, until_nul};

mod field {
    use core::ops::Range;
    pub const NAME: Range<usize> = 0..64;
    pub const GROUP: Range<usize> = 64..96;
    pub const RGBA: Range<usize> = 96..100;
    pub const XYZ: usize = 100;
    pub const DIAMETER: Range<usize> = 112..116;
    pub const OWNER: Range<usize> = 116..136;
}

/// Bytes of one point record.
pub const POINT_LEN: usize = field::OWNER.end;
/// The group of the force points this server sends.
pub const FORCE_GROUP: &str = "force_n";

/// A zero-copy view of a POINT content: `len / 136` records.
#[derive(Debug, Clone)]
pub struct Point<T: AsRef<[u8]>> {
    buffer: T,
}

fn be_f32(b: &[u8]) -> f32 {
    f32::from_be_bytes([b[0], b[1], b[2], b[3]])
}

impl<T: AsRef<[u8]>> Point<T> {
    pub const fn new_unchecked(buffer: T) -> Point<T> {
        Point { buffer }
    }

    /// A view of whole records only.
    pub fn new_checked(buffer: T) -> Result<Point<T>> {
        let len = buffer.as_ref().len();
        if len % POINT_LEN != 0 {
            return Err(Error::BadLength {
                what: "POINT content",
                len,
                expected: "a multiple of 136",
            });
        }
        Ok(Point { buffer })
    }

    pub fn count(&self) -> usize {
        self.buffer.as_ref().len() / POINT_LEN
    }

    fn record(&self, i: usize) -> &[u8] {
        &self.buffer.as_ref()[i * POINT_LEN..(i + 1) * POINT_LEN]
    }

    pub fn name(&self, i: usize) -> &[u8] {
        until_nul(&self.record(i)[field::NAME])
    }

    pub fn group(&self, i: usize) -> &[u8] {
        until_nul(&self.record(i)[field::GROUP])
    }

    pub fn rgba(&self, i: usize) -> [u8; 4] {
        let r = &self.record(i)[field::RGBA];
        [r[0], r[1], r[2], r[3]]
    }

    pub fn xyz(&self, i: usize) -> [f32; 3] {
        let r = self.record(i);
        core::array::from_fn(|k| be_f32(&r[field::XYZ + 4 * k..]))
    }

    pub fn diameter(&self, i: usize) -> f32 {
        be_f32(&self.record(i)[field::DIAMETER])
    }

    pub fn owner(&self, i: usize) -> &[u8] {
        until_nul(&self.record(i)[field::OWNER])
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Point<T> {
    fn record_mut(&mut self, i: usize) -> &mut [u8] {
        &mut self.buffer.as_mut()[i * POINT_LEN..(i + 1) * POINT_LEN]
    }

    /// Writes record `i` (names cut to their fields; [`PointRepr::emit`] checks them).
    pub fn set(&mut self, i: usize, p: &PointRepr) {
        let r = self.record_mut(i);
        set_padded(&mut r[field::NAME], p.name.as_bytes());
        set_padded(&mut r[field::GROUP], p.group.as_bytes());
        r[field::RGBA].copy_from_slice(&p.rgba);
        for (k, v) in p.xyz.iter().enumerate() {
            r[field::XYZ + 4 * k..field::XYZ + 4 * k + 4].copy_from_slice(&v.to_be_bytes());
        }
        r[field::DIAMETER].copy_from_slice(&p.diameter.to_be_bytes());
        set_padded(&mut r[field::OWNER], p.owner.as_bytes());
    }
}

/// One point record.
#[derive(Clone, Debug, PartialEq)]
pub struct PointRepr {
    pub name: String,
    pub group: String,
    pub rgba: [u8; 4],
    pub xyz: [f32; 3],
    pub diameter: f32,
    pub owner: String,
}

fn text(field: &'static str, b: &[u8]) -> Result<String> {
    std::str::from_utf8(b)
        .map(str::to_string)
        .map_err(|_| Error::BadName {
            field,
            bytes: b.to_vec(),
        })
}

impl PointRepr {
    /// Every record of a POINT content.
    pub fn parse<T: AsRef<[u8]>>(v: &Point<T>) -> Result<Vec<PointRepr>> {
        (0..v.count())
            .map(|i| {
                Ok(PointRepr {
                    name: text("POINT name", v.name(i))?,
                    group: text("POINT group", v.group(i))?,
                    rgba: v.rgba(i),
                    xyz: v.xyz(i),
                    diameter: v.diameter(i),
                    owner: text("POINT owner", v.owner(i))?,
                })
            })
            .collect()
    }

    pub fn parse_bytes(content: &[u8]) -> Result<Vec<PointRepr>> {
        Self::parse(&Point::new_checked(content)?)
    }

    pub fn buffer_len(points: &[PointRepr]) -> usize {
        points.len() * POINT_LEN
    }

    /// Writes `points` into `buf` (exactly [`PointRepr::buffer_len`] bytes); refuses names
    /// longer than their fields.
    pub fn emit(points: &[PointRepr], buf: &mut [u8]) -> Result<()> {
        let need = Self::buffer_len(points);
        if buf.len() != need {
            return Err(Error::BufferTooSmall {
                need,
                have: buf.len(),
            });
        }
        for p in points {
            for (what, t, r) in [
                ("POINT name", &p.name, field::NAME),
                ("POINT group", &p.group, field::GROUP),
                ("POINT owner", &p.owner, field::OWNER),
            ] {
                if t.len() > r.len() {
                    return Err(Error::TooLong {
                        field: what,
                        text: t.clone(),
                        max: r.len(),
                    });
                }
            }
        }
        let mut v = Point::new_unchecked(buf);
        for (i, p) in points.iter().enumerate() {
            v.set(i, p);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn force() -> PointRepr {
        PointRepr {
            name: "probe".into(),
            group: FORCE_GROUP.into(),
            rgba: [255, 64, 0, 255],
            xyz: [0.25, -1.5, 3.0],
            diameter: 0.0,
            owner: String::new(),
        }
    }

    #[test]
    fn points_round_trip_at_the_spec_offsets() {
        let mut other = force();
        other.name = "n".repeat(64);
        other.owner = "o".repeat(20);
        let pts = vec![force(), other];
        let mut b = vec![0xAA; PointRepr::buffer_len(&pts)];
        PointRepr::emit(&pts, &mut b).unwrap();
        assert_eq!(b.len(), 272);
        assert_eq!(&b[0..6], b"probe\0");
        assert_eq!(&b[64..72], b"force_n\0");
        assert_eq!(&b[96..100], &[255, 64, 0, 255]);
        assert_eq!(&b[100..104], &0.25f32.to_be_bytes());
        assert_eq!(&b[108..112], &3.0f32.to_be_bytes());
        assert_eq!(&b[112..116], &0.0f32.to_be_bytes());
        assert!(b[116..136].iter().all(|&x| x == 0));
        assert_eq!(PointRepr::parse_bytes(&b).unwrap(), pts);
    }

    #[test]
    fn partial_records_and_long_names_are_refused() {
        let e = PointRepr::parse_bytes(&[0u8; 137]).unwrap_err();
        assert!(matches!(e, Error::BadLength { len: 137, .. }));
        let mut p = force();
        p.group = "g".repeat(33);
        let mut b = vec![0u8; POINT_LEN];
        let e = PointRepr::emit(&[p], &mut b).unwrap_err();
        assert!(matches!(
            e,
            Error::TooLong {
                field: "POINT group",
                max: 32,
                ..
            }
        ));
    }
}
