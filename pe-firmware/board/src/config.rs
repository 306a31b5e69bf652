//! Build-time configuration: scalar and element type (cargo features `f32`, `full`), the
//! memory profile (feature `qemu`: QEMU mps2-an500, otherwise the PE board) and the storage
//! capacities derived from the profile's RAM, the same figures the compiler's fit check uses.

use core::mem::size_of;

use pe_firmware::image::{LoadRecord, NodeRecord, PathPoint, RecvEntry};
use pe_firmware::physics::MaterialLaw;
use pe_firmware::profile::BoardProfile;

#[cfg(feature = "f32")]
pub type Scalar = f32;
#[cfg(not(feature = "f32"))]
pub type Scalar = f64;

#[cfg(feature = "full")]
pub type Element = pe_firmware::physics::HexFull<Scalar>;
#[cfg(not(feature = "full"))]
pub type Element = pe_firmware::physics::HexReduced<Scalar>;

#[cfg(feature = "qemu")]
pub const PROFILE: BoardProfile = pe_firmware::profile::QEMU_MPS2_AN500;
#[cfg(not(feature = "qemu"))]
pub const PROFILE: BoardProfile = pe_firmware::profile::PE_BOARD;

/// Variant name, for the boot banner.
pub const VARIANT: &str = if cfg!(feature = "full") {
    if cfg!(feature = "f32") {
        "f32 full"
    } else {
        "f64 full"
    }
} else if cfg!(feature = "f32") {
    "f32 reduced"
} else {
    "f64 reduced"
};

/// Nodes a board holds (own and replicas): the link format's limit.
pub const NODES: usize = link_proto::NODES_PER_BOARD_MAX;
/// Exchange send (and receive) entries over all rounds and faces.
pub const EXCHANGE: usize = 4096;
pub const PATH_POINTS: usize = 64;
pub const LOADS: usize = 256;
pub const MATERIALS: usize = 8;

/// Contact and graphics capacities.
pub const CONTACT_NODES: usize = PROFILE.contact_nodes_max as usize;
pub const CONTACT_FACES: usize = PROFILE.contact_faces_max as usize;
pub const CONTACT_CANDIDATES: usize = 2048;
pub const CONTACT_SENDS: usize = 1024;
pub type ContactStatic = pe_firmware::runtime::StaticContactStorage<
    CONTACT_NODES,
    { 2 * CONTACT_NODES },
    CONTACT_FACES,
    CONTACT_CANDIDATES,
    CONTACT_SENDS,
    NODES,
    NODES,
>;

/// Static RAM that is not elements: node state, exchange lists, paths, loads, links.
pub const FIXED_BYTES: usize = NODES
    * (size_of::<NodeRecord<Scalar>>() + 1 + 3 * size_of::<[Scalar; 3]>())
    + EXCHANGE * (size_of::<u16>() + size_of::<RecvEntry>())
    + PATH_POINTS * size_of::<PathPoint>()
    + LOADS * size_of::<LoadRecord>()
    + MATERIALS * size_of::<MaterialLaw<Scalar>>()
    + size_of::<crate::links::BoardLinks>()
    + size_of::<ContactStatic>();

/// Elements: whatever the profile's RAM leaves after the reserve (stack, the runtime's
/// frame buffers) and the fixed part. The linker checks that it fits (schedule.x).
pub const ELEMENTS: usize = ((PROFILE.ram_bytes - PROFILE.ram_reserved_bytes) as usize
    - FIXED_BYTES)
    / size_of::<Element>();
