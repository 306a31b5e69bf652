//! Whole messages: header + body ([`super::header`], [`super::body`]) around one of the
//! contents this codec knows, the body's CRC-64 checked on reading and computed on writing.
//!
//! # Panics
//! [`decode`], [`open_body`], [`Content::parse`], [`encode`] and [`encode_with`] never
//! panic.

use super::body::{self, BodyParts, Framing};
use super::crc64::crc64;
use super::error::{Error, Result};
use super::header::{HeaderRepr, HEADER_LEN};
use super::point::PointRepr;
use super::polydata::PolyDataRepr;
use super::position::PositionRepr;
use super::string::StringRepr;
use super::transform::TransformRepr;

/// A message content of a type this codec reads and writes.
#[derive(Clone, Debug, PartialEq)]
pub enum Content {
    Transform(TransformRepr),
    Position(PositionRepr),
    Point(Vec<PointRepr>),
    String(StringRepr),
    PolyData(PolyDataRepr),
}

impl Content {
    /// The header's type name.
    pub fn type_name(&self) -> &'static str {
        match self {
            Content::Transform(_) => "TRANSFORM",
            Content::Position(_) => "POSITION",
            Content::Point(_) => "POINT",
            Content::String(_) => "STRING",
            Content::PolyData(_) => "POLYDATA",
        }
    }

    /// Reads a content of type `type_name`; refuses a type it does not know.
    pub fn parse(type_name: &str, content: &[u8]) -> Result<Content> {
        Ok(match type_name {
            "TRANSFORM" => Content::Transform(TransformRepr::parse_bytes(content)?),
            "POSITION" => Content::Position(PositionRepr::parse_bytes(content)?),
            "POINT" => Content::Point(PointRepr::parse_bytes(content)?),
            "STRING" => Content::String(StringRepr::parse_bytes(content)?),
            "POLYDATA" => Content::PolyData(PolyDataRepr::parse_bytes(content)?),
            other => return Err(Error::UnknownType(other.to_string())),
        })
    }

    pub fn buffer_len(&self) -> usize {
        match self {
            Content::Transform(t) => t.buffer_len(),
            Content::Position(p) => p.buffer_len(),
            Content::Point(p) => PointRepr::buffer_len(p),
            Content::String(s) => s.buffer_len(),
            Content::PolyData(p) => p.buffer_len(),
        }
    }

    pub fn emit(&self, buf: &mut [u8]) -> Result<()> {
        match self {
            Content::Transform(t) => t.emit(buf),
            Content::Position(p) => p.emit(buf),
            Content::Point(p) => PointRepr::emit(p, buf),
            Content::String(s) => s.emit(buf),
            Content::PolyData(p) => p.emit(buf),
        }
    }
}

/// Checks a received body against its header (length and CRC-64) and splits it.
pub fn open_body<'a>(header: &HeaderRepr, body: &'a [u8]) -> Result<BodyParts<'a>> {
    if body.len() as u64 != header.body_len {
        return Err(Error::Truncated {
            what: "body",
            need: usize::try_from(header.body_len).unwrap_or(usize::MAX),
            have: body.len(),
        });
    }
    let computed = crc64(body);
    if computed != header.crc {
        return Err(Error::BadCrc {
            header: header.crc,
            computed,
        });
    }
    body::split(header.version, body)
}

/// A decoded message.
#[derive(Clone, Debug, PartialEq)]
pub struct Decoded {
    pub header: HeaderRepr,
    pub message_id: u32,
    pub metadata: Vec<body::MetaEntry>,
    pub content: Content,
}

/// Decodes a whole message (header then body) of a known type.
pub fn decode(bytes: &[u8]) -> Result<Decoded> {
    let header = HeaderRepr::parse_bytes(bytes)?;
    let parts = open_body(&header, &bytes[HEADER_LEN..])?;
    let content = Content::parse(&header.type_name, parts.content)?;
    Ok(Decoded {
        message_id: parts.message_id,
        metadata: parts.metadata,
        header,
        content,
    })
}

/// A whole message of `content` from `device` at `timestamp`.
pub fn encode(
    framing: &Framing<'_>,
    device: &str,
    timestamp: u64,
    content: &Content,
) -> Result<Vec<u8>> {
    encode_with(
        framing,
        content.type_name(),
        device,
        timestamp,
        content.buffer_len(),
        |buf| content.emit(buf),
    )
}

/// A whole message whose `content_len`-byte content `fill` writes (for contents written
/// straight into the message, such as the surface's POLYDATA).
pub fn encode_with(
    framing: &Framing<'_>,
    type_name: &str,
    device: &str,
    timestamp: u64,
    content_len: usize,
    fill: impl FnOnce(&mut [u8]) -> Result<()>,
) -> Result<Vec<u8>> {
    let body_len = framing.overhead() + content_len;
    let mut out = vec![0u8; HEADER_LEN + body_len];
    let (head, body) = out.split_at_mut(HEADER_LEN);
    let content = body::emit(framing, content_len, body)?;
    fill(&mut body[content])?;
    HeaderRepr {
        version: framing.version(),
        type_name: type_name.to_string(),
        device: device.to_string(),
        timestamp,
        body_len: body_len as u64,
        crc: crc64(body),
    }
    .emit(head)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::live::engine::Pose;
    use crate::live::igtl::body::MetaEntry;

    fn transform() -> Content {
        Content::Transform(TransformRepr::of_pose(&Pose {
            q: [0.5, 0.5, -0.5, 0.5],
            p_m: [0.01, 0.02, -0.03],
        }))
    }

    #[test]
    fn every_content_round_trips_in_both_header_versions() {
        let meta = [MetaEntry {
            key: "k".into(),
            encoding: 3,
            value: b"v".to_vec(),
        }];
        let contents = [
            transform(),
            Content::Position(PositionRepr {
                position_mm: [1.0, 2.0, 3.0],
                quaternion_xyzw: Some([0.0, 0.0, 0.0, 1.0]),
            }),
            Content::Point(vec![PointRepr {
                name: "probe".into(),
                group: "force_n".into(),
                rgba: [1, 2, 3, 4],
                xyz: [0.5, 0.25, -2.0],
                diameter: 0.0,
                owner: String::new(),
            }]),
            Content::String(StringRepr::new("hello")),
            Content::PolyData(PolyDataRepr {
                points: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                cells: [vec![], vec![], vec![vec![0, 1, 2]], vec![]],
            }),
        ];
        for framing in [
            Framing::V1,
            Framing::V2 {
                message_id: 5,
                metadata: &meta,
            },
        ] {
            for c in &contents {
                let bytes = encode(&framing, "dev", 42 << 32, c).unwrap();
                let d = decode(&bytes).unwrap();
                assert_eq!(&d.content, c);
                assert_eq!(d.header.type_name, c.type_name());
                assert_eq!(d.header.device, "dev");
                assert_eq!(d.header.version, framing.version());
                assert_eq!(d.header.timestamp, 42 << 32);
                assert_eq!(d.header.body_len as usize, bytes.len() - HEADER_LEN);
                assert_eq!(d.header.crc, crc64(&bytes[HEADER_LEN..]));
                if framing.version() == 2 {
                    assert_eq!((d.message_id, d.metadata.as_slice()), (5, &meta[..]));
                }
            }
        }
    }

    #[test]
    fn a_flipped_bit_is_a_crc_error_and_an_unknown_type_is_named() {
        let mut bytes = encode(&Framing::V1, "probe", 0, &transform()).unwrap();
        bytes[HEADER_LEN + 7] ^= 0x10;
        let e = decode(&bytes).unwrap_err();
        assert!(matches!(e, Error::BadCrc { .. }), "{e}");
        assert!(!e.breaks_framing());

        let odd = encode_with(&Framing::V1, "SENSOR", "s", 0, 4, |b| {
            b.copy_from_slice(&[1, 2, 3, 4]);
            Ok(())
        })
        .unwrap();
        let e = decode(&odd).unwrap_err();
        assert_eq!(e, Error::UnknownType("SENSOR".into()));
        assert!(e.to_string().contains("\"SENSOR\" is not taken"), "{e}");
    }
}
