//! The schedule image: everything one board needs to run its part of a scene, written by
//! the schedule compiler (`pe compile`) and read by the board runtime. The Rust types here
//! are the schema: both sides serialise them with postcard, so they cannot disagree.
//!
//! Layout: `MAGIC` (4 bytes), one [`ImageHeader`] (postcard; its version first, then the
//! [`CompilationId`] as 8 raw bytes), then the sections, each a run
//! of records whose count the header's [`Counts`] gives, in the order of
//! [`codec::transcode`], the one place that order is written: the compiler's writer, the
//! runtime's loader and `pe inspect`'s decoder all go through it. Last, a CRC-32
//! (little-endian) of everything before it. [`blob`] holds the flash region's framing of an
//! image and the board's identity record.
//!
//! Rooms: `mod.rs` the record types and errors, [`codec`] the section order, writer and
//! reader, [`blob`] the flash blob and identity record, [`path`] piecewise-linear paths.
//!
//! Reading never panics: a short, corrupted or foreign image is an [`ImageError`].

pub mod blob;
pub mod codec;
pub mod path;

pub use codec::{
    read_image, stamp_compilation, transcode, validate, write_image, zero_record, Codec,
    ElementRecord, ImageParts, ImageReader, ImageReal, ImageWriter,
};
pub use path::{path_value, piecewise, piecewise_linear, Segment};

use serde::{Deserialize, Serialize};

pub use crate::physics::contact::{ContactFace, ContactNode, ContactPair, ContactParams, Tool};
pub use crate::physics::element::Integration;

/// First four bytes of every schedule image.
pub const MAGIC: [u8; 4] = *b"PESI";
/// Format version; bumped whenever a record type changes.
pub const FORMAT_VERSION: u16 = 10;

/// The id of the compilation an image belongs to: a 64-bit hash the compiler computes over
/// every image of the set (with this field zero) and the scene's mesh (see `pe compile`).
/// A board only compares it: with its neighbours' before step 0 (the Hello frames) and the
/// host with the manifest's. Stored as 8 raw bytes (little-endian), so the header's length
/// does not depend on its value and [`codec::stamp_compilation`] can write it in place.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct CompilationId(pub [u8; 8]);

impl CompilationId {
    /// The id before the compiler stamps it (what the hash is computed over).
    pub const UNSET: CompilationId = CompilationId([0; 8]);

    pub const fn from_u64(v: u64) -> Self {
        CompilationId(v.to_le_bytes())
    }

    pub const fn as_u64(self) -> u64 {
        u64::from_le_bytes(self.0)
    }
}

/// 16 hex digits, as the manifest and the reports write it.
impl core::fmt::Display for CompilationId {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:016x}", self.as_u64())
    }
}

/// Scalar type of the image's element and node records.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Precision {
    F32,
    F64,
}

impl Precision {
    /// The name scenes, manifests and reports use: "f32" | "f64".
    pub const fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }

    /// The width a board of this precision puts its values on the wire with (force frames,
    /// contact-node packets).
    pub const fn wire(self) -> link_proto::Precision {
        match self {
            Precision::F32 => link_proto::Precision::F32,
            Precision::F64 => link_proto::Precision::F64,
        }
    }
}

impl core::fmt::Display for Precision {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Record counts (and the capacities they must fit).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    pub materials: u16,
    /// Elements of the general kernel (the image's integration's record).
    pub elements: u32,
    /// End (exclusive) of batches x, y, z, inner in the element list.
    pub batch_ends: [u32; 4],
    /// Parallelepipeds ([`crate::physics::HexBox`], reduced integration only): the cheap
    /// kernel's elements, chosen at compile time, and their batch ends. A batch runs its
    /// general elements, then its parallelepipeds.
    pub boxes: u32,
    pub box_batch_ends: [u32; 4],
    /// Axis-aligned cuboids ([`crate::physics::HexCuboid`], reduced integration only): the
    /// cheapest kernel's elements and their batch ends. A batch runs its general elements,
    /// then its parallelepipeds, then its cuboids.
    pub cuboids: u32,
    pub cuboid_batch_ends: [u32; 4],
    pub nodes: u32,
    /// Distinct nodes exchanged across each face (+x, −x, +y, −y, +z, −z).
    pub exchange: [u16; 6],
    /// Exchange rounds per axis (the same on every board of the machine).
    pub rounds: [u8; 3],
    /// Of each axis's `rounds`, how many run last, after the z exchange: the broadcasts of
    /// the totals back along x and y (none along z). See
    /// [`crate::runtime::program::Program::new`].
    pub late_rounds: [u8; 3],
    /// Send and receive entries over all rounds and faces.
    pub sends: u32,
    pub recvs: u32,
    pub path_points: u16,
    pub loads: u16,
    /// External-force records ([`ExternalRecord`]) per stage: 0/1/2 before the x/y/z
    /// exchange, 3 before the update.
    pub external: [u16; 4],
    pub contact_nodes: u32,
    pub contact_faces: u32,
    pub pairs: u8,
    pub tools: u8,
    pub contact_boards: u8,
    pub graphics_nodes: u16,
}

/// A part of the firmware a board's image may need, each a cargo feature of `pe-firmware`
/// and of the board crate (all on by default). A build without one holds none of its code
/// and refuses an image that needs it ([`ImageError::Unsupported`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Feature {
    /// Tools and contact pairs: the contact tables and the contact protocol on the global
    /// network (a board that owns a contact node).
    Contact,
    /// The surface-node stream to the graphics engine (a board that owns a surface node).
    Graphics,
    /// External loads (a board that owns a loaded node).
    Loads,
}

impl Feature {
    pub const ALL: [Feature; 3] = [Feature::Contact, Feature::Graphics, Feature::Loads];

    /// Its cargo feature's name.
    pub const fn name(self) -> &'static str {
        match self {
            Feature::Contact => "contact",
            Feature::Graphics => "graphics",
            Feature::Loads => "loads",
        }
    }

    /// What [`ImageHeader::uses`] counts of it.
    pub const fn counted(self) -> &'static str {
        match self {
            Feature::Contact => "contact nodes",
            Feature::Graphics => "graphics nodes",
            Feature::Loads => "loads",
        }
    }

    /// Whether this build of the crate has it.
    pub const fn built(self) -> bool {
        match self {
            Feature::Contact => cfg!(feature = "contact"),
            Feature::Graphics => cfg!(feature = "graphics"),
            Feature::Loads => cfg!(feature = "loads"),
        }
    }
}

impl ImageHeader {
    /// How much of feature `f` this image holds ([`Feature::counted`]; `None`: it needs
    /// none of the feature's code): the one rule of the loader's refusal, of the step
    /// program's graphics operation and of the firmware build `pe image` makes.
    pub const fn uses(&self, f: Feature) -> Option<u32> {
        let c = &self.counts;
        match f {
            Feature::Contact if c.tools > 0 || c.pairs > 0 || c.contact_nodes > 0 => {
                Some(c.contact_nodes)
            }
            Feature::Graphics if c.graphics_nodes > 0 && self.graphics.interval_steps > 0 => {
                Some(c.graphics_nodes as u32)
            }
            Feature::Loads if c.loads > 0 => Some(c.loads as u32),
            _ => None,
        }
    }
}

impl Counts {
    /// Send/receive lists ([`ExchangeList`]): two faces per round of every axis.
    pub fn exchange_lists(&self) -> usize {
        2 * self.rounds.iter().map(|&r| r as usize).sum::<usize>()
    }

    /// External-force records over all stages.
    pub fn external_records(&self) -> usize {
        self.external.iter().map(|&n| n as usize).sum()
    }

    /// Records the image holds after its header, over every section (the contact nodes'
    /// two sections each count). Every record takes at least one byte (postcard writes at
    /// least a byte per field), so an image whose counts exceed the bytes after its header
    /// is malformed: [`ImageReader::new`](codec::ImageReader::new) refuses it before anyone
    /// sizes storage from the counts.
    pub fn records(&self) -> u64 {
        [
            u64::from(self.materials),
            u64::from(self.elements),
            u64::from(self.boxes),
            u64::from(self.cuboids),
            u64::from(self.nodes),
            self.exchange_lists() as u64,
            u64::from(self.sends),
            u64::from(self.recvs),
            u64::from(self.path_points),
            u64::from(self.loads),
            self.external_records() as u64,
            2 * u64::from(self.contact_nodes),
            u64::from(self.contact_faces),
            u64::from(self.pairs),
            u64::from(self.tools),
            u64::from(self.contact_boards),
            u64::from(self.graphics_nodes),
        ]
        .iter()
        .sum()
    }
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
    /// The path (a ramp: its first component) gravity is scaled by in time, `g · s(t)`
    /// ([`ExternalRecord::gravity`] times the ramp's factor at the stage's time, in the
    /// node's precision); None: gravity constant.
    pub gravity_ramp: Option<u16>,
    /// For the record (already folded into the node gains and the element records):
    /// inertia scaling, the hourglass control.
    pub mass_scaling: f64,
    pub hourglass: crate::physics::HourglassControl,
}

/// The image header: what the image is, for which board of which machine.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageHeader {
    pub version: u16,
    /// The compilation this image belongs to (the same in every image of a set).
    pub compilation: CompilationId,
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

impl ImageHeader {
    /// The faces this board exchanges over: see [`linked_faces`].
    pub fn linked_faces(&self) -> [bool; 6] {
        linked_faces(self.board, self.machine, self.counts.rounds)
    }
}

/// The faces (indexed by [`link_proto::Face::index`]) of board `board` in a `machine`
/// (boards per axis) that the schedule exchanges over: those with a neighbour, on an axis
/// with exchange rounds (`rounds` per axis, the same on every board). Both ends of a link
/// agree on it; the links a board needs drivers (and cables) for. One rule for the runtime's
/// Hello, the firmware's driver check and the compiler's port check.
pub const fn linked_faces(board: [u8; 3], machine: [u8; 3], rounds: [u8; 3]) -> [bool; 6] {
    let mut linked = [false; 6];
    let mut i = 0;
    while i < 6 {
        let a = i / 2;
        let positive = i % 2 == 0; // Face::ALL: +x, -x, +y, -y, +z, -z
        let neighbour = if positive {
            (board[a] as u16) + 1 < machine[a] as u16
        } else {
            board[a] > 0
        };
        linked[i] = rounds[a] > 0 && neighbour;
        i += 1;
    }
    linked
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
    /// Half the inertial mass, `(0.5 m) · mass_scaling` (kg), for the kinetic energy (the
    /// serial solver's factor, so each node's term is the same bits); zero on replicas,
    /// whose energy their owner counts.
    pub half_mass_kg: f64,
    pub motion: NodeMotion,
    /// The owner applies gravity and external loads (once for the whole machine) and
    /// counts the node's reaction and kinetic energy.
    pub owner: bool,
}

/// The external force of one owned node, subtracted from its force at its stage: gravity,
/// then its loads in the scene's order, then its contact force (the serial solver's order
/// of additions). Only owned nodes whose external force is not identically zero have one
/// (non-zero gravity, a load, or a contact surface); for the others `f − 0 = f`, so
/// skipping them changes no bit. The records come grouped by stage ([`Counts::external`]);
/// the loads section is in record order, each record's loads one run of it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExternalRecord<T> {
    /// Local node index.
    pub node: u16,
    /// Gravity force (true mass), N.
    pub gravity: [T; 3],
    /// The node's loads: `loads[first_load..first_load + loads]`.
    pub first_load: u16,
    pub loads: u16,
    /// The node's contact-node index, if it is on a contact surface.
    pub contact: Option<u32>,
}

/// The stage of an owned node's external force: 0/1/2 before the x/y/z exchange, 3 before
/// the update.
pub const STAGES: usize = 4;

/// The compiler's stage of a replica: its external force is added by its owner (replicas
/// have no [`ExternalRecord`]).
pub const STAGE_NOT_OWNED: u8 = 255;

/// One send/receive list of an exchange round: how many entries of the flat `sends` and
/// `recvs` sections it takes. Lists come in the order axis, round, face (+axis, −axis).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ExchangeList {
    pub sends: u16,
    pub recvs: u16,
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
    /// How the path goes to this point from the one before ([`path::Segment`]).
    pub segment: Segment,
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
    /// The image needs a part of the firmware ([`Feature`]) this build was made without:
    /// `count` of what [`ImageHeader::uses`] counts. (No larger than the other variants:
    /// every step's `Result` carries a `Fault`, which can carry an `ImageError`.)
    Unsupported {
        feature: Feature,
        count: u32,
    },
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
            ImageError::Unsupported { feature, count } => write!(
                f,
                "image has {count} {}, but this firmware was built without `{}` (build it with the cargo feature `{}`)",
                feature.counted(),
                feature.name(),
                feature.name()
            ),
        }
    }
}
