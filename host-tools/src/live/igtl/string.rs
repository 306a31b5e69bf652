//! STRING: a character string of at most 65535 bytes (OpenIGTLink
//! `Documents/Protocol/string.md`; pyigtl `StringMessage`), big-endian:
//!
//! | offset | size     | field                                            |
//! |--------|----------|--------------------------------------------------|
//! | 0      | 2        | encoding, IANA MIBenum (3: US-ASCII, 106: UTF-8) |
//! | 2      | 2        | length in bytes (u16)                            |
//! | 4      | length   | the string                                       |
//!
//! This server writes US-ASCII when the text is ASCII and UTF-8 otherwise (pyigtl decodes
//! exactly these two), and reads the same two.
//!
//! # Panics
//! [`StringMessage::new_checked`], [`StringRepr::parse`] and [`StringRepr::emit`] never
//! panic. The accessors of a [`StringMessage`] made with
//! [`StringMessage::new_unchecked`] panic on fewer bytes than it announces.

use super::error::{Error, Result};
use super::header::cut_to;

mod field {
    use core::ops::Range;
    pub const ENCODING: Range<usize> = 0..2;
    pub const LEN: Range<usize> = 2..4;
    pub const TEXT: usize = 4;
}

/// IANA MIBenum of US-ASCII.
pub const US_ASCII: u16 = 3;
/// IANA MIBenum of UTF-8.
pub const UTF_8: u16 = 106;
/// Longest string a STRING carries.
pub const STRING_LEN_MAX: usize = u16::MAX as usize;

/// A zero-copy view of a STRING content.
#[derive(Debug, Clone)]
pub struct StringMessage<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> StringMessage<T> {
    pub const fn new_unchecked(buffer: T) -> StringMessage<T> {
        StringMessage { buffer }
    }

    /// A view of a content holding exactly the announced length.
    pub fn new_checked(buffer: T) -> Result<StringMessage<T>> {
        let b = buffer.as_ref();
        if b.len() < field::TEXT {
            return Err(Error::Truncated {
                what: "STRING content",
                need: field::TEXT,
                have: b.len(),
            });
        }
        let v = StringMessage { buffer };
        let len = v.buffer.as_ref().len();
        if len != field::TEXT + usize::from(v.text_len()) {
            return Err(Error::BadLength {
                what: "STRING content",
                len,
                expected: "4 + its length field",
            });
        }
        Ok(v)
    }

    pub fn encoding(&self) -> u16 {
        let b = &self.buffer.as_ref()[field::ENCODING];
        u16::from_be_bytes([b[0], b[1]])
    }

    pub fn text_len(&self) -> u16 {
        let b = &self.buffer.as_ref()[field::LEN];
        u16::from_be_bytes([b[0], b[1]])
    }

    pub fn text(&self) -> &[u8] {
        &self.buffer.as_ref()[field::TEXT..field::TEXT + usize::from(self.text_len())]
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> StringMessage<T> {
    pub fn set_encoding(&mut self, e: u16) {
        self.buffer.as_mut()[field::ENCODING].copy_from_slice(&e.to_be_bytes());
    }

    /// Writes the length and the text; the caller sized the buffer (`4 + text.len()`).
    pub fn set_text(&mut self, text: &[u8]) {
        let b = self.buffer.as_mut();
        b[field::LEN].copy_from_slice(&(text.len() as u16).to_be_bytes());
        b[field::TEXT..field::TEXT + text.len()].copy_from_slice(text);
    }
}

/// A STRING's text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StringRepr {
    pub text: String,
}

impl StringRepr {
    /// `text` cut to at most [`STRING_LEN_MAX`] bytes at a character boundary.
    pub fn new(text: &str) -> StringRepr {
        StringRepr {
            text: cut_to(text, STRING_LEN_MAX).to_string(),
        }
    }

    pub fn parse<T: AsRef<[u8]>>(v: &StringMessage<T>) -> Result<StringRepr> {
        let e = v.encoding();
        if e != US_ASCII && e != UTF_8 {
            return Err(Error::BadEncoding(e));
        }
        let text = std::str::from_utf8(v.text()).map_err(|_| Error::BadText)?;
        if e == US_ASCII && !text.is_ascii() {
            return Err(Error::BadText);
        }
        Ok(StringRepr {
            text: text.to_string(),
        })
    }

    pub fn parse_bytes(content: &[u8]) -> Result<StringRepr> {
        Self::parse(&StringMessage::new_checked(content)?)
    }

    /// The encoding written: US-ASCII for ASCII text, UTF-8 otherwise.
    pub fn encoding(&self) -> u16 {
        if self.text.is_ascii() {
            US_ASCII
        } else {
            UTF_8
        }
    }

    pub fn buffer_len(&self) -> usize {
        field::TEXT + self.text.len()
    }

    pub fn emit(&self, buf: &mut [u8]) -> Result<()> {
        if self.text.len() > STRING_LEN_MAX {
            return Err(Error::TooLong {
                field: "STRING",
                text: self.text.chars().take(40).collect(),
                max: STRING_LEN_MAX,
            });
        }
        let need = self.buffer_len();
        if buf.len() != need {
            return Err(Error::BufferTooSmall {
                need,
                have: buf.len(),
            });
        }
        let mut v = StringMessage::new_unchecked(buf);
        v.set_encoding(self.encoding());
        v.set_text(self.text.as_bytes());
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strings_round_trip_in_ascii_and_utf8() {
        for text in ["unknown tool \"forceps\"", "Kraft über 5 N", ""] {
            let s = StringRepr::new(text);
            let mut b = vec![0u8; s.buffer_len()];
            s.emit(&mut b).unwrap();
            let enc = u16::from_be_bytes([b[0], b[1]]);
            assert_eq!(enc, if text.is_ascii() { 3 } else { 106 });
            assert_eq!(usize::from(u16::from_be_bytes([b[2], b[3]])), text.len());
            assert_eq!(&b[4..], text.as_bytes());
            assert_eq!(StringRepr::parse_bytes(&b).unwrap(), s);
        }
    }

    #[test]
    fn bad_strings_are_refused_and_long_ones_cut() {
        assert!(matches!(
            StringRepr::parse_bytes(&[0, 3, 0]),
            Err(Error::Truncated { .. })
        ));
        assert!(matches!(
            StringRepr::parse_bytes(&[0, 3, 0, 5, b'a']),
            Err(Error::BadLength { len: 5, .. })
        ));
        assert_eq!(
            StringRepr::parse_bytes(&[0, 4, 0, 1, b'a']),
            Err(Error::BadEncoding(4))
        );
        assert_eq!(
            StringRepr::parse_bytes(&[0, 3, 0, 1, 0xE9]),
            Err(Error::BadText)
        );
        let long = "é".repeat(40_000); // 80 000 bytes
        let s = StringRepr::new(&long);
        assert_eq!(s.text.len(), 65_534);
        assert!(s.text.len() <= STRING_LEN_MAX);
    }
}
