//! The 58-byte message header, the same in header versions 1 and 2 (OpenIGTLink
//! `Documents/Protocol/header.md`; `igtl_header` in `Source/igtlutil/igtl_header.h`),
//! big-endian:
//!
//! | offset | size | field                                                         |
//! |--------|------|---------------------------------------------------------------|
//! | 0      | 2    | header version (u16): 1 (protocol 1 and 2) or 2 (protocol 3)  |
//! | 2      | 12   | message type, ASCII, NUL-padded (e.g. `TRANSFORM`)            |
//! | 14     | 20   | device name, NUL-padded                                       |
//! | 34     | 8    | timestamp (u64): seconds since 1970 in the high 32 bits, the fraction of a second (in 2⁻³² s) in the low 32 (`Documents/Protocol/timestamp.md`) |
//! | 42     | 8    | body size in bytes (u64); in version 2 the body is extended header + content + metadata |
//! | 50     | 8    | CRC-64 of the body ([`super::crc64`])                         |
//!
//! A name is read up to its first NUL (the spec pads with NUL; a name that fills its field
//! has none). pyigtl reads and writes the same layout (`MessageBase.parse_header`,
//! `pack`: `struct '> H 12s 20s II Q Q'`).
//!
//! # Panics
//! [`Header::new_checked`], [`HeaderRepr::parse`] and [`HeaderRepr::emit`] never panic.
//! The accessors of a [`Header`] made with [`Header::new_unchecked`] panic on a buffer
//! shorter than [`HEADER_LEN`]: use them on received bytes only after `new_checked`.

use std::time::{SystemTime, UNIX_EPOCH};

use super::error::{Error, Result};

mod field {
    use core::ops::Range;
    pub const VERSION: Range<usize> = 0..2;
    pub const TYPE: Range<usize> = 2..14;
    pub const DEVICE: Range<usize> = 14..34;
    pub const TIMESTAMP: Range<usize> = 34..42;
    pub const BODY_LEN: Range<usize> = 42..50;
    pub const CRC: Range<usize> = 50..58;
}

/// Bytes in a header.
pub const HEADER_LEN: usize = field::CRC.end;
/// Longest message type name (bytes).
pub const TYPE_LEN_MAX: usize = field::TYPE.end - field::TYPE.start;
/// Longest device name (bytes).
pub const DEVICE_LEN_MAX: usize = field::DEVICE.end - field::DEVICE.start;
/// Largest body this server reads (16 MiB): a header announcing more is refused and the
/// connection closed (a real TRANSFORM is 48 bytes; such a size means the stream is not
/// at a header).
pub const BODY_LEN_MAX: u64 = 16 << 20;

/// A zero-copy view of a header.
#[derive(Debug, Clone)]
pub struct Header<T: AsRef<[u8]>> {
    buffer: T,
}

fn be_u16(b: &[u8]) -> u16 {
    u16::from_be_bytes([b[0], b[1]])
}

fn be_u64(b: &[u8]) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[..8]);
    u64::from_be_bytes(a)
}

impl<T: AsRef<[u8]>> Header<T> {
    pub const fn new_unchecked(buffer: T) -> Header<T> {
        Header { buffer }
    }

    /// A view of the first [`HEADER_LEN`] bytes; refuses a shorter buffer.
    pub fn new_checked(buffer: T) -> Result<Header<T>> {
        let have = buffer.as_ref().len();
        if have < HEADER_LEN {
            return Err(Error::Truncated {
                what: "header",
                need: HEADER_LEN,
                have,
            });
        }
        Ok(Header { buffer })
    }

    pub fn into_inner(self) -> T {
        self.buffer
    }

    pub fn version(&self) -> u16 {
        be_u16(&self.buffer.as_ref()[field::VERSION])
    }

    /// The type field's bytes up to its first NUL.
    pub fn type_name(&self) -> &[u8] {
        until_nul(&self.buffer.as_ref()[field::TYPE])
    }

    /// The device field's bytes up to its first NUL.
    pub fn device_name(&self) -> &[u8] {
        until_nul(&self.buffer.as_ref()[field::DEVICE])
    }

    pub fn timestamp(&self) -> u64 {
        be_u64(&self.buffer.as_ref()[field::TIMESTAMP])
    }

    pub fn body_len(&self) -> u64 {
        be_u64(&self.buffer.as_ref()[field::BODY_LEN])
    }

    pub fn crc(&self) -> u64 {
        be_u64(&self.buffer.as_ref()[field::CRC])
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Header<T> {
    pub fn set_version(&mut self, v: u16) {
        self.buffer.as_mut()[field::VERSION].copy_from_slice(&v.to_be_bytes());
    }

    /// Writes `name` NUL-padded; the caller checked it fits ([`TYPE_LEN_MAX`]).
    pub fn set_type_name(&mut self, name: &[u8]) {
        set_padded(&mut self.buffer.as_mut()[field::TYPE], name);
    }

    /// Writes `name` NUL-padded; the caller checked it fits ([`DEVICE_LEN_MAX`]).
    pub fn set_device_name(&mut self, name: &[u8]) {
        set_padded(&mut self.buffer.as_mut()[field::DEVICE], name);
    }

    pub fn set_timestamp(&mut self, t: u64) {
        self.buffer.as_mut()[field::TIMESTAMP].copy_from_slice(&t.to_be_bytes());
    }

    pub fn set_body_len(&mut self, n: u64) {
        self.buffer.as_mut()[field::BODY_LEN].copy_from_slice(&n.to_be_bytes());
    }

    pub fn set_crc(&mut self, crc: u64) {
        self.buffer.as_mut()[field::CRC].copy_from_slice(&crc.to_be_bytes());
    }
}

/// `field` up to its first NUL (all of it when it has none).
pub(super) fn until_nul(field: &[u8]) -> &[u8] {
    let end = field.iter().position(|&b| b == 0).unwrap_or(field.len());
    &field[..end]
}

/// `text` then NULs to the end of `field` (`text` no longer than `field`: cut if it is).
pub(super) fn set_padded(field: &mut [u8], text: &[u8]) {
    let n = text.len().min(field.len());
    field[..n].copy_from_slice(&text[..n]);
    field[n..].fill(0);
}

/// A header's fields.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HeaderRepr {
    /// 1 or 2.
    pub version: u16,
    /// Message type (ASCII, at most [`TYPE_LEN_MAX`] bytes).
    pub type_name: String,
    /// Device name (at most [`DEVICE_LEN_MAX`] bytes).
    pub device: String,
    /// Seconds since 1970 in 32.32 fixed point (0: unused).
    pub timestamp: u64,
    pub body_len: u64,
    pub crc: u64,
}

impl HeaderRepr {
    /// Reads a header: version 1 or 2, a type of printable ASCII, a device name of UTF-8
    /// text without control characters, a body of at most [`BODY_LEN_MAX`] bytes. Every
    /// refusal here [breaks the framing](Error::breaks_framing). The CRC is checked
    /// against the body later ([`super::message::decode`]).
    pub fn parse<T: AsRef<[u8]>>(h: &Header<T>) -> Result<HeaderRepr> {
        let version = h.version();
        if version != 1 && version != 2 {
            return Err(Error::BadVersion(version));
        }
        let t = h.type_name();
        if t.is_empty() || !t.iter().all(|b| b.is_ascii_graphic()) {
            return Err(Error::BadName {
                field: "message type",
                bytes: t.to_vec(),
            });
        }
        let device = std::str::from_utf8(h.device_name())
            .ok()
            .filter(|d| !d.chars().any(char::is_control))
            .ok_or_else(|| Error::BadName {
                field: "device name",
                bytes: h.device_name().to_vec(),
            })?;
        let body_len = h.body_len();
        if body_len > BODY_LEN_MAX {
            return Err(Error::Oversized {
                len: body_len,
                max: BODY_LEN_MAX,
            });
        }
        Ok(HeaderRepr {
            version,
            type_name: String::from_utf8_lossy(t).into_owned(),
            device: device.to_string(),
            timestamp: h.timestamp(),
            body_len,
            crc: h.crc(),
        })
    }

    /// [`HeaderRepr::parse`] on bytes.
    pub fn parse_bytes(bytes: &[u8]) -> Result<HeaderRepr> {
        Self::parse(&Header::new_checked(bytes)?)
    }

    /// Writes the header into the first [`HEADER_LEN`] bytes of `buf`. Refuses names longer
    /// than their fields and a short buffer.
    pub fn emit(&self, buf: &mut [u8]) -> Result<()> {
        check_name("message type", &self.type_name, TYPE_LEN_MAX)?;
        check_name("device name", &self.device, DEVICE_LEN_MAX)?;
        let have = buf.len();
        let out = buf.get_mut(..HEADER_LEN).ok_or(Error::BufferTooSmall {
            need: HEADER_LEN,
            have,
        })?;
        let mut h = Header::new_unchecked(out);
        h.set_version(self.version);
        h.set_type_name(self.type_name.as_bytes());
        h.set_device_name(self.device.as_bytes());
        h.set_timestamp(self.timestamp);
        h.set_body_len(self.body_len);
        h.set_crc(self.crc);
        Ok(())
    }
}

fn check_name(field: &'static str, text: &str, max: usize) -> Result<()> {
    if text.len() > max {
        return Err(Error::TooLong {
            field,
            text: text.to_string(),
            max,
        });
    }
    Ok(())
}

/// `name` cut to at most [`DEVICE_LEN_MAX`] bytes at a character boundary (a scene or tool
/// name longer than a device name can hold).
pub fn device_name_of(name: &str) -> &str {
    cut_to(name, DEVICE_LEN_MAX)
}

/// `text` cut to at most `max` bytes at a character boundary.
pub fn cut_to(text: &str, max: usize) -> &str {
    let mut end = text.len().min(max);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

/// `t` as an OpenIGTLink timestamp: seconds since 1970 in the high 32 bits, the fraction
/// in units of 2⁻³² s in the low 32 (`Documents/Protocol/timestamp.md`).
pub fn timestamp_of(t: SystemTime) -> u64 {
    let d = t.duration_since(UNIX_EPOCH).unwrap_or_default();
    let frac = (u64::from(d.subsec_nanos()) << 32) / 1_000_000_000;
    ((d.as_secs() & 0xFFFF_FFFF) << 32) | frac
}

/// The timestamp of now.
pub fn timestamp_now() -> u64 {
    timestamp_of(SystemTime::now())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header() -> HeaderRepr {
        HeaderRepr {
            version: 1,
            type_name: "TRANSFORM".into(),
            device: "probe".into(),
            timestamp: 0x1234_5678_8000_0000,
            body_len: 48,
            crc: 0xDEAD_BEEF_0123_4567,
        }
    }

    #[test]
    fn a_header_round_trips_and_lies_where_the_spec_says() {
        let h = header();
        let mut b = [0xAAu8; HEADER_LEN];
        h.emit(&mut b).unwrap();
        assert_eq!(HeaderRepr::parse_bytes(&b).unwrap(), h);
        // Offsets from the spec's table, big-endian.
        assert_eq!(&b[0..2], &[0, 1]);
        assert_eq!(&b[2..14], b"TRANSFORM\0\0\0");
        assert_eq!(&b[14..20], b"probe\0");
        assert!(b[20..34].iter().all(|&x| x == 0));
        assert_eq!(&b[34..42], &[0x12, 0x34, 0x56, 0x78, 0x80, 0, 0, 0]);
        assert_eq!(&b[42..50], &[0, 0, 0, 0, 0, 0, 0, 48]);
        assert_eq!(&b[50..58], &0xDEAD_BEEF_0123_4567u64.to_be_bytes());
    }

    #[test]
    fn names_that_fill_their_fields_have_no_nul() {
        let mut h = header();
        h.type_name = "ABCDEFGHIJKL".into();
        h.device = "abcdefghijklmnopqrst".into();
        let mut b = [0u8; HEADER_LEN];
        h.emit(&mut b).unwrap();
        assert_eq!(HeaderRepr::parse_bytes(&b).unwrap(), h);
        h.device.push('u');
        assert!(matches!(h.emit(&mut b), Err(Error::TooLong { .. })));
    }

    #[test]
    fn refusals_name_the_field_and_break_the_framing() {
        let mut b = [0u8; HEADER_LEN];
        header().emit(&mut b).unwrap();
        let short = HeaderRepr::parse_bytes(&b[..57]).unwrap_err();
        assert!(matches!(
            short,
            Error::Truncated {
                need: 58,
                have: 57,
                ..
            }
        ));

        let mut v = b;
        v[1] = 3;
        let e = HeaderRepr::parse_bytes(&v).unwrap_err();
        assert_eq!(e, Error::BadVersion(3));
        assert!(e.breaks_framing());

        let mut t = b;
        t[2] = 0x01;
        let e = HeaderRepr::parse_bytes(&t).unwrap_err();
        assert!(
            matches!(
                e,
                Error::BadName {
                    field: "message type",
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.breaks_framing());

        let mut d = b;
        d[14] = 0xFF;
        let e = HeaderRepr::parse_bytes(&d).unwrap_err();
        assert!(
            matches!(
                e,
                Error::BadName {
                    field: "device name",
                    ..
                }
            ),
            "{e}"
        );

        let mut big = b;
        big[42..50].copy_from_slice(&(BODY_LEN_MAX + 1).to_be_bytes());
        let e = HeaderRepr::parse_bytes(&big).unwrap_err();
        assert!(matches!(e, Error::Oversized { .. }));
        assert!(e.breaks_framing());
        assert!(e.to_string().contains("16777217"), "{e}");
        big[42..50].copy_from_slice(&BODY_LEN_MAX.to_be_bytes());
        assert!(HeaderRepr::parse_bytes(&big).is_ok());
    }

    #[test]
    fn timestamps_are_seconds_and_binary_fractions() {
        let t = UNIX_EPOCH + std::time::Duration::new(1_700_000_000, 500_000_000);
        assert_eq!(timestamp_of(t), (1_700_000_000u64 << 32) | 0x8000_0000);
        let quarter = UNIX_EPOCH + std::time::Duration::new(3, 250_000_000);
        assert_eq!(timestamp_of(quarter), (3u64 << 32) | 0x4000_0000);
    }

    #[test]
    fn long_names_are_cut_at_a_character_boundary() {
        assert_eq!(device_name_of("builtin:medium"), "builtin:medium");
        let long = "scenes/a-very-long-scene-name.toml";
        assert_eq!(device_name_of(long).len(), DEVICE_LEN_MAX);
        let accents = "ééééééééééé"; // 22 bytes: cut to 20 = 10 characters
        assert_eq!(device_name_of(accents), "éééééééééé");
    }
}
