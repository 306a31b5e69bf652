//! Build-time configuration: scalar and element type (cargo features `f32`, `full`), the
//! board profile (feature `qemu`: QEMU mps2-an500; `stm32h743`: the prototype array of
//! STM32H743 boards over USARTs; otherwise the PE board, no link drivers yet) and the storage
//! capacities: the profile's capacity table ([`Capacities::for_board`]), the same figures
//! the compiler's fit check and board-sim's board-sized storage use.

use pe_firmware::profile::BoardProfile;
use pe_firmware::runtime::{Capacities, Heapless, StorageBuf};

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
#[cfg(feature = "stm32h743")]
pub const PROFILE: BoardProfile = pe_firmware::profile::STM32H743_UART;
#[cfg(not(any(feature = "qemu", feature = "stm32h743")))]
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

/// What this firmware holds: the profile's table, without the tables of a feature the
/// build leaves out (its images are refused before they are read).
pub const CAPACITIES: Capacities =
    without_absent_features(Capacities::for_board::<Scalar, Element>(&PROFILE));

const fn without_absent_features(c: Capacities) -> Capacities {
    let contact = cfg!(feature = "contact");
    Capacities {
        contact_nodes: if contact { c.contact_nodes } else { 0 },
        contact_faces: if contact { c.contact_faces } else { 0 },
        contact_candidates: if contact { c.contact_candidates } else { 0 },
        contact_sends: if contact { c.contact_sends } else { 0 },
        loads: if cfg!(feature = "loads") { c.loads } else { 0 },
        ..c
    }
}

/// The firmware's storage: fixed-capacity vectors of exactly [`CAPACITIES`].
pub type BoardStorage = StorageBuf<
    Heapless,
    Scalar,
    Element,
    { CAPACITIES.materials },
    { CAPACITIES.elements },
    { CAPACITIES.boxes },
    { CAPACITIES.cuboids },
    { CAPACITIES.nodes },
    { CAPACITIES.exchange },
    { CAPACITIES.path_points },
    { CAPACITIES.loads },
    { CAPACITIES.contact_nodes },
    { CAPACITIES.contact_faces },
    { CAPACITIES.contact_candidates },
    { CAPACITIES.contact_sends },
>;

// The table's per-node arrays (external forces, graphics nodes) take the node capacity.
const _: () = assert!(CAPACITIES.external == CAPACITIES.nodes);
const _: () = assert!(CAPACITIES.graphics_nodes == CAPACITIES.nodes);

// The link buffers' region holds them (when the profile gives them one).
const _: () = assert!(
    PROFILE.link_ram_bytes == 0
        || core::mem::size_of::<crate::links::BoardLinks>() as u64 <= PROFILE.link_ram_bytes
);

// The link buffers are what `Capacities::for_board` counts for them (the streams add a few
// words).
const _: () = assert!(
    core::mem::size_of::<crate::links::BoardLinks>()
        <= core::mem::size_of::<pe_firmware::runtime::storage::LinkBuffers>() + 256
);
