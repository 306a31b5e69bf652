//! The schedule image: everything one board needs to run its part of a scene, written by
//! the schedule compiler (`pe compile`) and read by the board runtime. The Rust types here
//! are the schema: both sides serialise them with postcard, so they cannot disagree.
//!
//! Layout: `MAGIC` (4 bytes), then postcard records: one [`ImageHeader`], then
//! `materials` × [`MaterialLaw<f64>`], `elements` × element (`HexReduced<T>` or
//! `HexFull<T>` by `integration`, `T` by `precision`, local node indices, batch order),
//! `nodes` × ([`NodeRecord<T>`], `u8` stage at which an owned node's external force is
//! added: 0/1/2 before the x/y/z exchange, 3 before the update, 255 not owned), then the
//! exchange rounds: for each axis x, y, z, `rounds[axis]` rounds, each with, for the faces
//! (+axis, −axis) in turn, a `u16` count and that many `u16` local node indices to send,
//! then a `u16` count and that many [`RecvEntry`]; then `path_points` × [`PathPoint`],
//! `loads` × [`LoadRecord`]; then the contact tables (the same on every board):
//! `contact_nodes` × ([`ContactNode`], [`ContactNodePlace`]), `contact_faces` ×
//! [`ContactFace`], `pairs` × [`ContactPair`], `tools` × [`Tool`], `contact_boards` × `u8`
//! (global-network addresses of every board that owns a node of a contact pair's
//! surface), `graphics_nodes` × `u16` (this board's owned surface nodes, local indices,
//! sent to the graphics engine); last, a CRC-32 (little-endian) of everything before it.
//!
//! Reading never panics: a short, corrupted or foreign image is an [`ImageError`].

use serde::{de::DeserializeOwned, Deserialize, Serialize};

pub use crate::physics::contact::{ContactFace, ContactNode, ContactPair, Tool};

/// First four bytes of every schedule image.
pub const MAGIC: [u8; 4] = *b"PESI";
/// Format version; bumped whenever a record type changes.
pub const FORMAT_VERSION: u16 = 2;

/// Scalar type of the image's element and node records.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Precision {
    F32,
    F64,
}

/// Element kind of the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Integration {
    Reduced,
    Full,
}

impl Precision {
    /// The name scenes, manifests and reports use: "f32" | "f64".
    pub const fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }
}

impl Integration {
    /// The name scenes, manifests and reports use: "reduced" | "full".
    pub const fn name(self) -> &'static str {
        match self {
            Integration::Reduced => "reduced",
            Integration::Full => "full",
        }
    }
}

impl core::fmt::Display for Precision {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

impl core::fmt::Display for Integration {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Record counts (and the capacities they must fit).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    pub materials: u16,
    pub elements: u32,
    /// End (exclusive) of batches x, y, z, inner in the element list.
    pub batch_ends: [u32; 4],
    pub nodes: u32,
    /// Distinct nodes exchanged across each face (+x, −x, +y, −y, +z, −z).
    pub exchange: [u16; 6],
    /// Exchange rounds per axis (the same on every board of the machine).
    pub rounds: [u8; 3],
    /// Send and receive entries over all rounds and faces.
    pub sends: u32,
    pub recvs: u32,
    pub path_points: u16,
    pub loads: u16,
    pub contact_nodes: u32,
    pub contact_faces: u32,
    pub pairs: u8,
    pub tools: u8,
    pub contact_boards: u8,
    pub graphics_nodes: u16,
}

/// Contact search parameters (all zero without contact).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ContactParams {
    /// Bounding boxes are exchanged (and the candidates rebuilt) every this many steps.
    pub check_interval_steps: u32,
    /// Farthest a pair-surface node may move between two checks (m): `speed_bound ·
    /// check_interval · Δt`, at most half the scene's gap.
    pub travel_max_m: f64,
    /// A slave node is a candidate of a face whose bounding box, grown by this, holds it.
    pub candidate_margin_m: f64,
    /// Boards whose boxes, grown by this, overlap exchange nodes until the next check:
    /// twice (face diameter + contact depth) plus twice the travel.
    pub box_margin_m: f64,
    /// Deepest penetration tolerated (m).
    pub tolerance_m: f64,
    /// Bit mask of the surfaces that take part in a pair.
    pub pair_surfaces: u8,
}

/// The graphics stream: every `interval_steps` steps the owned surface nodes go to the
/// graphics engine, spread over `spread_steps` steps (0: no stream).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GraphicsParams {
    pub interval_steps: u32,
    pub spread_steps: u16,
}

/// Where a contact node lives on this board.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ContactNodePlace {
    /// Local node index, if the board holds the node (owner or replica).
    pub local: Option<u16>,
    /// The board owns it (applies its contact force).
    pub owned: bool,
}

/// Scene parameters the board needs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneParams {
    pub dt_s: f64,
    pub damping_per_s: f64,
    pub steps: u64,
    /// A node faster than this (m/s) is reported as an instability.
    pub speed_limit_m_per_s: f64,
    /// For the record (already folded into the node gains): inertia scaling, hourglass κ.
    pub mass_scaling: f64,
    pub hourglass: f64,
}

/// The image header: what the image is, for which board of which machine.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageHeader {
    pub version: u16,
    /// This board's logical coordinates.
    pub board: [u8; 3],
    /// Machine size (boards per axis).
    pub machine: [u8; 3],
    pub precision: Precision,
    pub integration: Integration,
    pub counts: Counts,
    pub params: SceneParams,
    /// Scene totals, for reports.
    pub scene_elements: u32,
    pub scene_nodes: u32,
    pub contact: ContactParams,
    pub graphics: GraphicsParams,
}

/// How a node moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum NodeMotion {
    Free,
    Fixed,
    /// Follows prescribed path `k`.
    Prescribed(u16),
}

/// One node held by the board (an own node or a replica).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct NodeRecord<T> {
    /// Index of the node in the scene's mesh.
    pub global: u32,
    /// `C / m_inertial` of the central-difference update, from the node's full mass.
    pub gain: T,
    pub motion: NodeMotion,
    /// The owner applies gravity and external loads (once for the whole machine).
    pub owner: bool,
    /// Gravity force (true mass), N; zero on replicas.
    pub gravity: [T; 3],
}

/// How a received value combines with the node's current value `v`. Every replica of a node
/// ends the exchange with the same bits because the compiler fixes one summation tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Combine {
    /// `v = received + v` (the sender is on the left of the summation order).
    Before,
    /// `v = v + received`.
    After,
    /// `v = received` (the total, broadcast back).
    Replace,
}

/// One value received in an exchange round.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecvEntry {
    pub node: u16,
    pub combine: Combine,
}

/// A point of a prescribed path (or of a load ramp, factor in `value[0]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PathPoint {
    pub path: u16,
    pub t_s: f64,
    pub value: [f64; 3],
}

/// An external nodal force applied by the node's owner, scaled by an optional ramp path.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LoadRecord {
    pub node: u16,
    pub force: [f64; 3],
    pub ramp: Option<u16>,
}

/// Why an image is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageError {
    TooShort,
    BadMagic,
    /// The CRC at the end does not match the content (a flipped bit, a truncated copy).
    BadCrc {
        stored: u32,
        computed: u32,
    },
    WrongVersion {
        found: u16,
        expected: u16,
    },
    /// The image is for another board position (or another machine size).
    WrongBoard {
        image: [u8; 3],
        expected: [u8; 3],
    },
    /// A record does not decode, or the records run past the end.
    Malformed {
        record: &'static str,
    },
    /// A count exceeds this firmware's capacity.
    Capacity {
        what: &'static str,
        count: u32,
        max: u32,
    },
    /// A record refers to a node or material that does not exist.
    BadIndex {
        what: &'static str,
        index: u32,
    },
    /// Writing: the output buffer is too small.
    BufferFull,
}

impl core::fmt::Display for ImageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            ImageError::TooShort => write!(f, "image too short"),
            ImageError::BadMagic => write!(f, "not a schedule image (bad magic)"),
            ImageError::BadCrc { stored, computed } => {
                write!(f, "image CRC mismatch (stored {stored:#010x}, computed {computed:#010x}): corrupted")
            }
            ImageError::WrongVersion { found, expected } => {
                write!(
                    f,
                    "image format version {found}, this firmware reads {expected}"
                )
            }
            ImageError::WrongBoard { image, expected } => write!(
                f,
                "image is for board ({},{},{}) but this is board ({},{},{})",
                image[0], image[1], image[2], expected[0], expected[1], expected[2]
            ),
            ImageError::Malformed { record } => write!(f, "malformed image record: {record}"),
            ImageError::Capacity { what, count, max } => {
                write!(
                    f,
                    "image has {count} {what}, this firmware holds at most {max}"
                )
            }
            ImageError::BadIndex { what, index } => {
                write!(f, "image refers to {what} {index}, which does not exist")
            }
            ImageError::BufferFull => write!(f, "output buffer too small for the image"),
        }
    }
}

/// Writes an image record by record into a caller's buffer.
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

    pub fn push<R: Serialize>(&mut self, record: &R) -> Result<(), ImageError> {
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

/// Reads an image: checks magic, CRC and version up front, then hands out records in order.
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
        Ok(ImageReader { header, rest })
    }

    /// The next record.
    pub fn next<R: DeserializeOwned>(&mut self, record: &'static str) -> Result<R, ImageError> {
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

/// Value at time `t` of a piecewise-linear path through `(t_k, v_k)`, held constant before
/// the first and after the last point: `v = a + s (b − a)`, `s = (t − t0)/(t1 − t0)`.
/// The host solver and the board runtime both call this, so they compute the same bits.
pub fn piecewise_linear(t: f64, len: usize, point: impl Fn(usize) -> (f64, [f64; 3])) -> [f64; 3] {
    if len == 0 {
        return [0.0; 3];
    }
    let mut k = 0;
    while k < len && point(k).0 <= t {
        k += 1;
    }
    if k == len {
        return point(len - 1).1;
    }
    if k == 0 {
        return point(0).1;
    }
    let (t0, a) = point(k - 1);
    let (t1, b) = point(k);
    let s = (t - t0) / (t1 - t0);
    [
        a[0] + s * (b[0] - a[0]),
        a[1] + s * (b[1] - a[1]),
        a[2] + s * (b[2] - a[2]),
    ]
}

/// Value of path `path` in a table of [`PathPoint`]s (points of one path are contiguous).
pub fn path_value(points: &[PathPoint], path: u16, t: f64) -> [f64; 3] {
    let first = points
        .iter()
        .position(|p| p.path == path)
        .unwrap_or(points.len());
    let len = points[first..]
        .iter()
        .take_while(|p| p.path == path)
        .count();
    let run = &points[first..first + len];
    piecewise_linear(t, len, |k| (run[k].t_s, run[k].value))
}
