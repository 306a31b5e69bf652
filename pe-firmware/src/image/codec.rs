//! The image's one codec: [`transcode`] walks the sections in their fixed order, and the
//! writer ([`ImageWriter`], the compiler), the reader ([`ImageReader`], the runtime's loader
//! and `pe inspect`) both go through it, so the order and the record type of every section
//! are written once. [`validate`] checks every index a loaded image holds.
//!
//! Sections (counts from the header's [`Counts`]): materials × [`MaterialLaw<T>`], elements
//! × `E` (batch order x, y, z, inner), parallelepipeds × [`HexBox<T>`] (batch order), cuboids × [`HexCuboid<T>`] (batch order), nodes × [`NodeRecord<T>`], exchange lists ×
//! [`ExchangeList`] (axis, round, face), sends × `u16` (local nodes), receives ×
//! [`RecvEntry`], path points × [`PathPoint`], loads × [`LoadRecord`] (in external-record
//! order), external forces × [`ExternalRecord<T>`] (stage order), contact nodes ×
//! [`ContactNode`], contact-node places × [`ContactNodePlace`], contact faces ×
//! [`ContactFace`], pairs × [`ContactPair`], tools × [`Tool`], contact boards × `u8`
//! (global-network addresses of the boards that own a pair-surface node), graphics nodes ×
//! `u16` (this board's owned surface nodes, local indices).
//!
//! Nothing here panics or allocates: a record that does not fit its slots is
//! [`ImageError::Capacity`], a record that does not decode [`ImageError::Malformed`].

use serde::{de::DeserializeOwned, Serialize};

use super::*;
use crate::physics::{Element, ElementKind, HexBox, HexCuboid, HexElement, MaterialLaw, Real};

/// A scalar an image can hold.
pub trait ImageReal: Real + Serialize + DeserializeOwned {
    const PRECISION: Precision;
}

impl ImageReal for f32 {
    const PRECISION: Precision = Precision::F32;
}

impl ImageReal for f64 {
    const PRECISION: Precision = Precision::F64;
}

/// An element record an image can hold: an element kind ([`Element`]) in an image scalar,
/// serialised as postcard. The image's general table holds the kind
/// [`ElementKind::in_table`] gives for its header's integration, table 0; the runtime, the
/// compiler and the decoder are generic over it (one [`crate::with_element_types`] picks it
/// from a header).
pub trait ElementRecord<T: Real>: Element<T> + Serialize + DeserializeOwned + Copy {
    /// The element choice the kind belongs to.
    const INTEGRATION: Integration = Self::KIND.integration();
}

impl<T: ImageReal, E: Element<T> + Serialize + DeserializeOwned + Copy> ElementRecord<T> for E {}

/// `$body` with `$t` the scalar type and `$e` the element record type of the general table
/// of an image of `$precision` and `$integration` (an [`crate::image::Precision`] and an
/// [`crate::image::Integration`], e.g. a header's): the one place that maps those settings
/// to the generic types the image codec, the runtime and the compiler are instantiated
/// with. Each arm declares the two types and evaluates `$body` with them:
///
/// ```ignore
/// let caps = with_element_types!(h.precision, h.integration, |T, E| {
///     Capacities::for_board::<T, E>(profile)
/// });
/// ```
#[macro_export]
macro_rules! with_element_types {
    ($precision:expr, $integration:expr, |$t:ident, $e:ident| $body:expr) => {
        match ($precision, $integration) {
            ($crate::image::Precision::F32, $crate::image::Integration::Reduced) => {
                type $t = f32;
                type $e = $crate::physics::HexReduced<f32>;
                $body
            }
            ($crate::image::Precision::F32, $crate::image::Integration::Full) => {
                type $t = f32;
                type $e = $crate::physics::HexFull<f32>;
                $body
            }
            ($crate::image::Precision::F64, $crate::image::Integration::Reduced) => {
                type $t = f64;
                type $e = $crate::physics::HexReduced<f64>;
                $body
            }
            ($crate::image::Precision::F64, $crate::image::Integration::Full) => {
                type $t = f64;
                type $e = $crate::physics::HexFull<f64>;
                $body
            }
        }
    };
}

/// Whether `E` is the record of the general table of an image of `integration`.
fn is_general_record<T: Real, E: ElementRecord<T>>(integration: Integration) -> bool {
    matches!(ElementKind::in_table(integration, 0), Some(k) if k == E::KIND)
}

/// Where an image's records live: one slice per section, at least as long as its count (the
/// slice lengths are the capacities). The compiler lends its tables, the runtime its
/// storage, the decoder vectors sized from the header.
pub struct ImageParts<'a, T, E> {
    pub laws: &'a mut [MaterialLaw<T>],
    pub elements: &'a mut [E],
    pub boxes: &'a mut [HexBox<T>],
    pub cuboids: &'a mut [HexCuboid<T>],
    pub nodes: &'a mut [NodeRecord<T>],
    pub lists: &'a mut [ExchangeList],
    pub sends: &'a mut [u16],
    pub recvs: &'a mut [RecvEntry],
    pub path_points: &'a mut [PathPoint],
    pub loads: &'a mut [LoadRecord],
    pub external: &'a mut [ExternalRecord<T>],
    pub contact_nodes: &'a mut [ContactNode],
    pub contact_places: &'a mut [ContactNodePlace],
    pub contact_faces: &'a mut [ContactFace],
    pub pairs: &'a mut [ContactPair],
    pub tools: &'a mut [Tool],
    pub contact_boards: &'a mut [u8],
    pub graphics_nodes: &'a mut [u16],
}

/// One direction of the codec: the writer emits `*record`, the reader decodes into it.
pub trait Codec {
    fn record<R: Serialize + DeserializeOwned>(
        &mut self,
        what: &'static str,
        record: &mut R,
    ) -> Result<(), ImageError>;
}

/// Transcodes the first `count` records of one section.
fn section<C: Codec, R: Serialize + DeserializeOwned>(
    codec: &mut C,
    what: &'static str,
    count: usize,
    slots: &mut [R],
) -> Result<(), ImageError> {
    let max = slots.len();
    let slots = slots.get_mut(..count).ok_or(ImageError::Capacity {
        what,
        count: count as u32,
        max: max as u32,
    })?;
    for r in slots {
        codec.record(what, r)?;
    }
    Ok(())
}

/// The image's sections after the header, in order: the one definition of the layout.
pub fn transcode<T: ImageReal, E: ElementRecord<T>, C: Codec>(
    codec: &mut C,
    c: &Counts,
    p: &mut ImageParts<'_, T, E>,
) -> Result<(), ImageError> {
    section(codec, "materials", c.materials as usize, p.laws)?;
    section(codec, "elements", c.elements as usize, p.elements)?;
    section(codec, "parallelepipeds", c.boxes as usize, p.boxes)?;
    section(codec, "cuboids", c.cuboids as usize, p.cuboids)?;
    section(codec, "nodes", c.nodes as usize, p.nodes)?;
    section(codec, "exchange lists", c.exchange_lists(), p.lists)?;
    section(codec, "exchange sends", c.sends as usize, p.sends)?;
    section(codec, "exchange receives", c.recvs as usize, p.recvs)?;
    section(codec, "path points", c.path_points as usize, p.path_points)?;
    section(codec, "loads", c.loads as usize, p.loads)?;
    section(codec, "external forces", c.external_records(), p.external)?;
    let nc = c.contact_nodes as usize;
    section(codec, "contact nodes", nc, p.contact_nodes)?;
    section(codec, "contact nodes", nc, p.contact_places)?;
    section(
        codec,
        "contact faces",
        c.contact_faces as usize,
        p.contact_faces,
    )?;
    section(codec, "contact pairs", c.pairs as usize, p.pairs)?;
    section(codec, "tools", c.tools as usize, p.tools)?;
    section(
        codec,
        "contact boards",
        c.contact_boards as usize,
        p.contact_boards,
    )?;
    section(
        codec,
        "graphics nodes",
        c.graphics_nodes as usize,
        p.graphics_nodes,
    )
}

fn index_ok(what: &'static str, index: usize, ok: bool) -> Result<(), ImageError> {
    if ok {
        Ok(())
    } else {
        Err(ImageError::BadIndex {
            what,
            index: index as u32,
        })
    }
}

/// Checks what a loaded image refers to: batch ends, element nodes and materials, list
/// lengths, local node indices, contact surfaces. `p` holds the records `c` counts. The
/// checks run in this order, each a function of its own; the first failure is the error.
pub fn validate<T: ImageReal, E: ElementRecord<T>>(
    c: &Counts,
    p: &ImageParts<'_, T, E>,
) -> Result<(), ImageError> {
    check_batch_ends(c)?;
    check_elements(c, p)?;
    check_exchange(c, p)?;
    check_external(c, p)?;
    check_contact(c, p)?;
    check_graphics(c, p)
}

/// Each element table's batch ends ascend and end at the table's count.
fn check_batch_ends(c: &Counts) -> Result<(), ImageError> {
    let ordered = |b: [u32; 4], n: u32| b[0] <= b[1] && b[1] <= b[2] && b[2] <= b[3] && b[3] == n;
    if !ordered(c.batch_ends, c.elements)
        || !ordered(c.box_batch_ends, c.boxes)
        || !ordered(c.cuboid_batch_ends, c.cuboids)
    {
        return Err(ImageError::Malformed {
            record: "batch ends",
        });
    }
    Ok(())
}

/// The element tables the image's integration holds ([`ElementKind::in_table`]), and every
/// element's nodes and material in range.
fn check_elements<T: ImageReal, E: ElementRecord<T>>(
    c: &Counts,
    p: &ImageParts<'_, T, E>,
) -> Result<(), ImageError> {
    let (ne, nb, nq) = (c.elements as usize, c.boxes as usize, c.cuboids as usize);
    let held = |table, n| n == 0 || ElementKind::in_table(E::INTEGRATION, table).is_some();
    if !held(1, nb) || !held(2, nq) {
        return Err(ImageError::Malformed {
            record: "parallelepipeds or cuboids in a fully integrated image",
        });
    }
    // Elements are numbered general first, then parallelepipeds, then cuboids.
    let all = p.elements[..ne]
        .iter()
        .map(|e| e.connectivity())
        .chain(p.boxes[..nb].iter().map(|e| e.connectivity()))
        .chain(p.cuboids[..nq].iter().map(|e| e.connectivity()));
    let nn = c.nodes as usize;
    for (k, e) in all.enumerate() {
        index_ok(
            "node of element",
            k,
            e.nodes.iter().all(|&n| (n as usize) < nn),
        )?;
        index_ok(
            "material of element",
            k,
            (e.material as usize) < c.materials as usize,
        )?;
    }
    Ok(())
}

/// The exchange rounds: late rounds within the rounds (none along z), the lists' lengths
/// summing to the send and receive sections, every entry a local node.
fn check_exchange<T, E>(c: &Counts, p: &ImageParts<'_, T, E>) -> Result<(), ImageError> {
    if c.late_rounds[2] > 0 || (0..3).any(|a| c.late_rounds[a] > c.rounds[a]) {
        return Err(ImageError::Malformed {
            record: "late exchange rounds",
        });
    }
    let lists = &p.lists[..c.exchange_lists()];
    let sends: usize = lists.iter().map(|l| l.sends as usize).sum();
    let recvs: usize = lists.iter().map(|l| l.recvs as usize).sum();
    if sends != c.sends as usize || recvs != c.recvs as usize {
        return Err(ImageError::Malformed {
            record: "exchange list lengths",
        });
    }
    let nn = c.nodes as usize;
    for &v in &p.sends[..c.sends as usize] {
        index_ok("node of send list", v as usize, (v as usize) < nn)?;
    }
    for r in &p.recvs[..c.recvs as usize] {
        index_ok(
            "node of receive list",
            r.node as usize,
            (r.node as usize) < nn,
        )?;
    }
    Ok(())
}

/// Loads and external records: every load's node local; the external records on owned
/// nodes, their loads one run each, in order, covering the loads section; their contact
/// node held here, by them, and owned; and every owned contact node with a record.
fn check_external<T, E>(c: &Counts, p: &ImageParts<'_, T, E>) -> Result<(), ImageError> {
    let (nn, nc) = (c.nodes as usize, c.contact_nodes as usize);
    for (k, l) in p.loads[..c.loads as usize].iter().enumerate() {
        index_ok("node of load", k, (l.node as usize) < nn)?;
    }
    let mut next_load = 0usize;
    for (k, x) in p.external[..c.external_records()].iter().enumerate() {
        let node = x.node as usize;
        index_ok(
            "node of external force",
            k,
            p.nodes[..nn].get(node).is_some_and(|n| n.owner),
        )?;
        let (first, end) = (
            x.first_load as usize,
            x.first_load as usize + x.loads as usize,
        );
        index_ok(
            "loads of external force",
            k,
            first == next_load
                && p.loads[..c.loads as usize]
                    .get(first..end)
                    .is_some_and(|ls| ls.iter().all(|l| l.node == x.node)),
        )?;
        next_load = end;
        index_ok(
            "contact node of external force",
            k,
            x.contact.is_none_or(|cn| {
                p.contact_places[..nc]
                    .get(cn as usize)
                    .is_some_and(|pl| pl.owned && pl.local == Some(x.node))
            }),
        )?;
    }
    if next_load != c.loads as usize {
        return Err(ImageError::Malformed {
            record: "loads outside the external forces",
        });
    }
    let with_contact = p.external[..c.external_records()]
        .iter()
        .filter(|x| x.contact.is_some())
        .count();
    if with_contact != p.contact_places[..nc].iter().filter(|pl| pl.owned).count() {
        return Err(ImageError::Malformed {
            record: "owned contact nodes without an external force",
        });
    }
    Ok(())
}

/// The contact tables: contact nodes' local nodes, faces' contact nodes, the surfaces of
/// pairs and tools.
fn check_contact<T, E>(c: &Counts, p: &ImageParts<'_, T, E>) -> Result<(), ImageError> {
    let (nn, nc) = (c.nodes as usize, c.contact_nodes as usize);
    for (k, pl) in p.contact_places[..nc].iter().enumerate() {
        index_ok(
            "local node of contact node",
            k,
            pl.local.is_none_or(|l| (l as usize) < nn),
        )?;
    }
    for (k, f) in p.contact_faces[..c.contact_faces as usize]
        .iter()
        .enumerate()
    {
        index_ok(
            "node of contact face",
            k,
            f.nodes.iter().all(|&n| (n as usize) < nc),
        )?;
    }
    let surfaces = crate::physics::contact::SURFACES_MAX;
    for (k, q) in p.pairs[..c.pairs as usize].iter().enumerate() {
        index_ok(
            "surface of contact pair",
            k,
            (q.a as usize) < surfaces && (q.b as usize) < surfaces,
        )?;
    }
    for (k, t) in p.tools[..c.tools as usize].iter().enumerate() {
        index_ok("surface of tool", k, (t.surface as usize) < surfaces)?;
    }
    Ok(())
}

/// The graphics nodes are local nodes.
fn check_graphics<T, E>(c: &Counts, p: &ImageParts<'_, T, E>) -> Result<(), ImageError> {
    for (k, &g) in p.graphics_nodes[..c.graphics_nodes as usize]
        .iter()
        .enumerate()
    {
        index_ok("graphics node", k, (g as usize) < c.nodes as usize)?;
    }
    Ok(())
}

/// Writes `header` and the records `parts` holds into `buf`; returns the image length.
pub fn write_image<T: ImageReal, E: ElementRecord<T>>(
    buf: &mut [u8],
    header: &ImageHeader,
    parts: &mut ImageParts<'_, T, E>,
) -> Result<usize, ImageError> {
    if header.precision != T::PRECISION || !is_general_record::<T, E>(header.integration) {
        return Err(ImageError::Malformed {
            record: "header's precision or integration differs from its records",
        });
    }
    let mut w = ImageWriter::new(buf, header)?;
    transcode(&mut w, &header.counts, parts)?;
    w.finish()
}

/// Checks `image` (for board `expected_board`, if given), loads its records into `parts`
/// and validates them; returns the header.
pub fn read_image<T: ImageReal, E: ElementRecord<T>>(
    image: &[u8],
    expected_board: Option<[u8; 3]>,
    parts: &mut ImageParts<'_, T, E>,
) -> Result<ImageHeader, ImageError> {
    let mut r = ImageReader::new(image, expected_board)?;
    let h = r.header;
    if h.precision != T::PRECISION {
        return Err(ImageError::Malformed {
            record: "precision differs from this runtime's",
        });
    }
    if !is_general_record::<T, E>(h.integration) {
        return Err(ImageError::Malformed {
            record: "integration differs from this runtime's",
        });
    }
    transcode(&mut r, &h.counts, parts)?;
    if !r.is_done() {
        return Err(ImageError::Malformed {
            record: "trailing bytes",
        });
    }
    validate(&h.counts, parts)?;
    Ok(h)
}

/// A record decoded from zero bytes: all numbers zero, every enum its first variant, every
/// option `None`. Storage is filled with it before an image is loaded over it.
pub fn zero_record<R: DeserializeOwned>() -> Option<R> {
    const ZEROS: [u8; 2048] = [0; 2048];
    postcard::take_from_bytes::<R>(&ZEROS).ok().map(|(r, _)| r)
}

/// Writes an image into a caller's buffer: the header here, the sections through [`transcode`].
pub struct ImageWriter<'a> {
    buf: &'a mut [u8],
    len: usize,
}

impl<'a> ImageWriter<'a> {
    pub fn new(buf: &'a mut [u8], header: &ImageHeader) -> Result<Self, ImageError> {
        if buf.len() < MAGIC.len() {
            return Err(ImageError::BufferFull);
        }
        buf[..4].copy_from_slice(&MAGIC);
        let mut w = ImageWriter { buf, len: 4 };
        w.push(header)?;
        Ok(w)
    }

    fn push<R: Serialize>(&mut self, record: &R) -> Result<(), ImageError> {
        let rest = self.buf.get_mut(self.len..).ok_or(ImageError::BufferFull)?;
        let used = postcard::to_slice(record, rest)
            .map_err(|_| ImageError::BufferFull)?
            .len();
        self.len += used;
        Ok(())
    }

    /// Appends the CRC; returns the image length.
    pub fn finish(self) -> Result<usize, ImageError> {
        let crc = link_proto::frame::crc32(&self.buf[..self.len]);
        let end = self.len + 4;
        let dst = self
            .buf
            .get_mut(self.len..end)
            .ok_or(ImageError::BufferFull)?;
        dst.copy_from_slice(&crc.to_le_bytes());
        Ok(end)
    }
}

/// Writes `id` into a finished image's header and renews its CRC: how the compiler stamps
/// every image of a set once the set's id (a hash over the set with the field unset) is
/// known. The header is re-encoded through its own type; the id is 8 raw bytes, so its
/// length cannot change (checked: a different length is [`ImageError::Malformed`]).
pub fn stamp_compilation(image: &mut [u8], id: CompilationId) -> Result<(), ImageError> {
    let (mut header, header_end) = {
        let r = ImageReader::new(image, None)?;
        (r.header, image.len() - CRC_BYTES - r.rest.len())
    };
    header.compilation = id;
    let slot = image
        .get_mut(MAGIC.len()..header_end)
        .ok_or(ImageError::TooShort)?;
    let written = postcard::to_slice(&header, slot)
        .map_err(|_| ImageError::Malformed { record: "header" })?
        .len();
    if written != header_end - MAGIC.len() {
        return Err(ImageError::Malformed { record: "header" });
    }
    let body_end = image.len() - CRC_BYTES;
    let crc = link_proto::frame::crc32(&image[..body_end]);
    image[body_end..].copy_from_slice(&crc.to_le_bytes());
    Ok(())
}

/// Bytes of the CRC that ends an image.
const CRC_BYTES: usize = 4;

/// Reads an image: checks magic, CRC and version up front; the sections go through
/// [`transcode`].
pub struct ImageReader<'a> {
    pub header: ImageHeader,
    rest: &'a [u8],
}

impl<'a> ImageReader<'a> {
    /// Checks the image; `expected_board` (if given) must match the header's position.
    pub fn new(image: &'a [u8], expected_board: Option<[u8; 3]>) -> Result<Self, ImageError> {
        if image.len() < MAGIC.len() + 4 {
            return Err(ImageError::TooShort);
        }
        if image[..4] != MAGIC {
            return Err(ImageError::BadMagic);
        }
        let (body, tail) = image.split_at(image.len() - 4);
        let stored = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
        let computed = link_proto::frame::crc32(body);
        if stored != computed {
            return Err(ImageError::BadCrc { stored, computed });
        }
        let (header, rest): (ImageHeader, _) = postcard::take_from_bytes(&body[4..])
            .map_err(|_| ImageError::Malformed { record: "header" })?;
        if header.version != FORMAT_VERSION {
            return Err(ImageError::WrongVersion {
                found: header.version,
                expected: FORMAT_VERSION,
            });
        }
        if let Some(b) = expected_board {
            if b != header.board {
                return Err(ImageError::WrongBoard {
                    image: header.board,
                    expected: b,
                });
            }
        }
        // Storage is sized from the counts: counts the bytes cannot hold (a damaged or
        // forged header) are refused here, before anything is allocated or filled.
        if header.counts.records() > rest.len() as u64 {
            return Err(ImageError::Malformed {
                record: "header counts (more records than the image has bytes)",
            });
        }
        Ok(ImageReader { header, rest })
    }

    /// The next record.
    fn next<R: DeserializeOwned>(&mut self, record: &'static str) -> Result<R, ImageError> {
        let (r, rest) =
            postcard::take_from_bytes(self.rest).map_err(|_| ImageError::Malformed { record })?;
        self.rest = rest;
        Ok(r)
    }

    /// True when every record has been read.
    pub fn is_done(&self) -> bool {
        self.rest.is_empty()
    }
}

impl Codec for ImageWriter<'_> {
    fn record<R: Serialize + DeserializeOwned>(
        &mut self,
        _what: &'static str,
        record: &mut R,
    ) -> Result<(), ImageError> {
        self.push(record)
    }
}

impl Codec for ImageReader<'_> {
    fn record<R: Serialize + DeserializeOwned>(
        &mut self,
        what: &'static str,
        record: &mut R,
    ) -> Result<(), ImageError> {
        *record = self.next(what)?;
        Ok(())
    }
}
