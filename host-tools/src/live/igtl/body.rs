//! A message body: in header version 1 the content alone; in version 2 an extended header,
//! the content, then the metadata (OpenIGTLink `Documents/Protocol/header.md`, "Extended
//! Header Fields" and "Metadata Fields"; `MessageBase::UnpackExtendedHeader` and
//! `PackMetaData` in `Source/igtlMessageBase.cxx`; pyigtl `MessageBase.unpack`). Big-endian:
//!
//! Extended header (12 bytes at the start of the body):
//!
//! | offset | size | field                                                  |
//! |--------|------|--------------------------------------------------------|
//! | 0      | 2    | extended header size (u16, 12 today; more is skipped)  |
//! | 2      | 2    | metadata header size (u16): 2 + 8 × entries            |
//! | 4      | 4    | metadata size (u32): the keys' and values' bytes       |
//! | 8      | 4    | message id (u32)                                       |
//!
//! The content runs from the extended header's end to `body − metadata header −
//! metadata`. The metadata header is a u16 entry count then per entry u16 key size, u16
//! value encoding (IANA MIBenum), u32 value size; the metadata is every key then its value,
//! in entry order. A version-2 body's metadata is read and checked (sizes consistent) and
//! otherwise ignored: the messages this server takes carry nothing in it.
//!
//! # Panics
//! [`split`] and [`emit`] never panic. The accessors of an [`ExtHeader`] made with
//! [`ExtHeader::new_unchecked`] panic on fewer than [`EXT_HEADER_LEN`] bytes.

use core::ops::Range;

use super::error::{Error, Result};

mod field {
    use core::ops::Range;
    pub const EXT_LEN: Range<usize> = 0..2;
    pub const META_HEADER_LEN: Range<usize> = 2..4;
    pub const META_LEN: Range<usize> = 4..8;
    pub const MESSAGE_ID: Range<usize> = 8..12;
    /// Metadata header: the entry count, then 8-byte entries.
    pub const META_COUNT: Range<usize> = 0..2;
    pub const META_ENTRY_LEN: usize = 8;
}

/// Bytes of the version-2 extended header as this protocol version defines it.
pub const EXT_HEADER_LEN: usize = field::MESSAGE_ID.end;

/// A zero-copy view of a version-2 extended header.
#[derive(Debug, Clone)]
pub struct ExtHeader<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> ExtHeader<T> {
    pub const fn new_unchecked(buffer: T) -> ExtHeader<T> {
        ExtHeader { buffer }
    }

    pub fn new_checked(buffer: T) -> Result<ExtHeader<T>> {
        let have = buffer.as_ref().len();
        if have < EXT_HEADER_LEN {
            return Err(Error::Truncated {
                what: "version-2 extended header",
                need: EXT_HEADER_LEN,
                have,
            });
        }
        Ok(ExtHeader { buffer })
    }

    fn u16_at(&self, r: Range<usize>) -> u16 {
        let b = &self.buffer.as_ref()[r];
        u16::from_be_bytes([b[0], b[1]])
    }

    fn u32_at(&self, r: Range<usize>) -> u32 {
        let b = &self.buffer.as_ref()[r];
        u32::from_be_bytes([b[0], b[1], b[2], b[3]])
    }

    pub fn ext_len(&self) -> u16 {
        self.u16_at(field::EXT_LEN)
    }

    pub fn meta_header_len(&self) -> u16 {
        self.u16_at(field::META_HEADER_LEN)
    }

    pub fn meta_len(&self) -> u32 {
        self.u32_at(field::META_LEN)
    }

    pub fn message_id(&self) -> u32 {
        self.u32_at(field::MESSAGE_ID)
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> ExtHeader<T> {
    pub fn set(&mut self, ext_len: u16, meta_header_len: u16, meta_len: u32, message_id: u32) {
        let b = self.buffer.as_mut();
        b[field::EXT_LEN].copy_from_slice(&ext_len.to_be_bytes());
        b[field::META_HEADER_LEN].copy_from_slice(&meta_header_len.to_be_bytes());
        b[field::META_LEN].copy_from_slice(&meta_len.to_be_bytes());
        b[field::MESSAGE_ID].copy_from_slice(&message_id.to_be_bytes());
    }
}

/// One metadata entry.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MetaEntry {
    pub key: String,
    /// IANA MIBenum of the value (3: US-ASCII, 106: UTF-8).
    pub encoding: u16,
    pub value: Vec<u8>,
}

/// What a body holds besides its content.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BodyParts<'a> {
    pub content: &'a [u8],
    /// Version 2's message id (0 in version 1).
    pub message_id: u32,
    /// Version 2's metadata (empty in version 1).
    pub metadata: Vec<MetaEntry>,
}

/// Splits a body of header version `version` into content, message id and metadata.
pub fn split(version: u16, body: &[u8]) -> Result<BodyParts<'_>> {
    if version < 2 {
        return Ok(BodyParts {
            content: body,
            ..BodyParts::default()
        });
    }
    let x = ExtHeader::new_checked(body)?;
    let ext = usize::from(x.ext_len());
    let meta_header = usize::from(x.meta_header_len());
    let meta = x.meta_len() as usize;
    if ext < EXT_HEADER_LEN {
        return Err(Error::BadExtendedHeader(format!(
            "its size field says {ext} bytes, less than the {EXT_HEADER_LEN} it holds"
        )));
    }
    let tail = meta_header
        .checked_add(meta)
        .filter(|&t| t.checked_add(ext).is_some_and(|n| n <= body.len()));
    let Some(tail) = tail else {
        return Err(Error::BadExtendedHeader(format!(
            "{ext} bytes of extended header, {meta_header} of metadata header and {meta} of \
             metadata do not fit a body of {} bytes",
            body.len()
        )));
    };
    let content_end = body.len() - tail;
    let metadata = parse_metadata(
        &body[content_end..content_end + meta_header],
        &body[content_end + meta_header..],
    )?;
    Ok(BodyParts {
        content: &body[ext..content_end],
        message_id: x.message_id(),
        metadata,
    })
}

/// Reads the metadata header `head` (count, then entries) and the keys and values `data`.
fn parse_metadata(head: &[u8], data: &[u8]) -> Result<Vec<MetaEntry>> {
    let bad = |why: String| Err(Error::BadExtendedHeader(why));
    if head.is_empty() {
        return if data.is_empty() {
            Ok(Vec::new())
        } else {
            bad(format!(
                "{} bytes of metadata without a metadata header",
                data.len()
            ))
        };
    }
    let Some(&[c0, c1]) = head.get(field::META_COUNT) else {
        return bad(format!("a metadata header of {} byte", head.len()));
    };
    let count = usize::from(u16::from_be_bytes([c0, c1]));
    let want = field::META_COUNT.end + count * field::META_ENTRY_LEN;
    if head.len() != want {
        return bad(format!(
            "{count} metadata entries need a {want}-byte metadata header, not {}",
            head.len()
        ));
    }
    let mut out = Vec::with_capacity(count);
    let mut at = 0usize;
    for e in head[field::META_COUNT.end..].chunks_exact(field::META_ENTRY_LEN) {
        let key_len = usize::from(u16::from_be_bytes([e[0], e[1]]));
        let encoding = u16::from_be_bytes([e[2], e[3]]);
        let value_len = u32::from_be_bytes([e[4], e[5], e[6], e[7]]) as usize;
        let end = at
            .checked_add(key_len)
            .and_then(|k| k.checked_add(value_len))
            .filter(|&end| end <= data.len());
        let Some(end) = end else {
            return bad(format!(
                "metadata entry {} runs past the {} bytes of metadata",
                out.len(),
                data.len()
            ));
        };
        let key = String::from_utf8_lossy(&data[at..at + key_len]).into_owned();
        out.push(MetaEntry {
            key,
            encoding,
            value: data[at + key_len..end].to_vec(),
        });
        at = end;
    }
    if at != data.len() {
        return bad(format!(
            "the entries hold {at} bytes of the {} bytes of metadata",
            data.len()
        ));
    }
    Ok(out)
}

/// How a body is framed on output.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Framing<'m> {
    /// Header version 1: the content alone.
    V1,
    /// Header version 2: extended header, content, metadata header and metadata.
    V2 {
        message_id: u32,
        metadata: &'m [MetaEntry],
    },
}

impl Framing<'_> {
    pub fn version(&self) -> u16 {
        match self {
            Framing::V1 => 1,
            Framing::V2 { .. } => 2,
        }
    }

    /// Bytes around a content (extended header and metadata).
    pub fn overhead(&self) -> usize {
        match self {
            Framing::V1 => 0,
            Framing::V2 { metadata, .. } => {
                EXT_HEADER_LEN
                    + field::META_COUNT.end
                    + metadata
                        .iter()
                        .map(|m| field::META_ENTRY_LEN + m.key.len() + m.value.len())
                        .sum::<usize>()
            }
        }
    }
}

/// Writes the framing around a content of `content_len` bytes into `body` (exactly
/// `content_len + framing.overhead()` bytes) and returns the content's range in it.
pub fn emit(framing: &Framing<'_>, content_len: usize, body: &mut [u8]) -> Result<Range<usize>> {
    let need = content_len + framing.overhead();
    if body.len() != need {
        return Err(Error::BufferTooSmall {
            need,
            have: body.len(),
        });
    }
    let Framing::V2 {
        message_id,
        metadata,
    } = framing
    else {
        return Ok(0..content_len);
    };
    let too_long = |what: &'static str| Error::TooLong {
        field: what,
        text: format!("{} entries", metadata.len()),
        max: usize::from(u16::MAX),
    };
    let count = u16::try_from(metadata.len()).map_err(|_| too_long("metadata"))?;
    let head_len = field::META_COUNT.end + metadata.len() * field::META_ENTRY_LEN;
    let head_len16 = u16::try_from(head_len).map_err(|_| too_long("metadata header"))?;
    let data_len: usize = metadata.iter().map(|m| m.key.len() + m.value.len()).sum();
    let data_len32 = u32::try_from(data_len).map_err(|_| too_long("metadata"))?;
    ExtHeader::new_unchecked(&mut body[..EXT_HEADER_LEN]).set(
        EXT_HEADER_LEN as u16,
        head_len16,
        data_len32,
        *message_id,
    );
    let content = EXT_HEADER_LEN..EXT_HEADER_LEN + content_len;
    let (head, data) = body[content.end..].split_at_mut(head_len);
    head[field::META_COUNT].copy_from_slice(&count.to_be_bytes());
    let mut at = 0;
    for (m, e) in metadata
        .iter()
        .zip(head[field::META_COUNT.end..].chunks_exact_mut(field::META_ENTRY_LEN))
    {
        let key_len = u16::try_from(m.key.len()).map_err(|_| too_long("metadata key"))?;
        let value_len = u32::try_from(m.value.len()).map_err(|_| too_long("metadata value"))?;
        e[0..2].copy_from_slice(&key_len.to_be_bytes());
        e[2..4].copy_from_slice(&m.encoding.to_be_bytes());
        e[4..8].copy_from_slice(&value_len.to_be_bytes());
        data[at..at + m.key.len()].copy_from_slice(m.key.as_bytes());
        at += m.key.len();
        data[at..at + m.value.len()].copy_from_slice(&m.value);
        at += m.value.len();
    }
    Ok(content)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta() -> Vec<MetaEntry> {
        vec![
            MetaEntry {
                key: "Status".into(),
                encoding: 3,
                value: b"OK".to_vec(),
            },
            MetaEntry {
                key: "TransformStatus".into(),
                encoding: 106,
                value: "gültig".as_bytes().to_vec(),
            },
        ]
    }

    #[test]
    fn a_version_2_body_round_trips_with_its_metadata() {
        let m = meta();
        let f = Framing::V2 {
            message_id: 77,
            metadata: &m,
        };
        let content = [1u8, 2, 3, 4, 5];
        // 12 + 5 + (2 + 2·8) + (6 + 2 + 15 + 7).
        assert_eq!(f.overhead() + content.len(), 12 + 5 + 18 + 30);
        let mut body = vec![0u8; f.overhead() + content.len()];
        let r = emit(&f, content.len(), &mut body).unwrap();
        body[r].copy_from_slice(&content);
        // The extended header's fields, big-endian, as the spec lays them out.
        assert_eq!(&body[..12], &[0, 12, 0, 18, 0, 0, 0, 30, 0, 0, 0, 77]);
        let p = split(2, &body).unwrap();
        assert_eq!(p.content, &content);
        assert_eq!(p.message_id, 77);
        assert_eq!(p.metadata, m);
        // Version 1 reads the same bytes as content.
        assert_eq!(split(1, &body).unwrap().content.len(), body.len());
    }

    #[test]
    fn a_longer_extended_header_and_an_empty_metadata_header_are_skipped() {
        // ext size 16 (4 unknown bytes), metadata header of just a zero count.
        let mut body = vec![0, 16, 0, 2, 0, 0, 0, 0, 0, 0, 0, 9, 0xEE, 0xEE, 0xEE, 0xEE];
        body.extend_from_slice(&[7, 7, 7]);
        body.extend_from_slice(&[0, 0]);
        let p = split(2, &body).unwrap();
        assert_eq!(p.content, &[7, 7, 7]);
        assert_eq!(p.message_id, 9);
        assert!(p.metadata.is_empty());
        // No metadata header at all (sizes 0): the rest is content.
        let body = [0, 12, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 5, 6];
        assert_eq!(split(2, &body).unwrap().content, &[5, 6]);
    }

    #[test]
    fn inconsistent_sizes_are_refused_without_breaking_the_framing() {
        let cases: [(&[u8], &str); 5] = [
            (&[0, 12, 0, 0], "bytes, 12 needed"),
            (&[0, 8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0], "less than the 12"),
            (&[0, 12, 0, 2, 0, 0, 0, 9, 0, 0, 0, 0, 0, 0], "do not fit"),
            // one entry announced, a 2-byte metadata header
            (
                &[0, 12, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1],
                "need a 10-byte",
            ),
            // an entry whose key runs past the metadata
            (
                &[
                    0, 12, 0, 10, 0, 0, 0, 1, 0, 0, 0, 0, 0, 1, 0, 5, 0, 3, 0, 0, 0, 0, b'k',
                ],
                "runs past",
            ),
        ];
        for (body, why) in cases {
            let e = split(2, body).unwrap_err();
            assert!(e.to_string().contains(why), "{e} for {body:?}");
            assert!(!e.breaks_framing());
        }
    }
}
