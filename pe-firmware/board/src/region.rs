//! The schedule image region (linker symbols `__pe_image_start`/`__pe_image_end`, see
//! `schedule.x`), the board's identity (its position in the machine), its run options and
//! the firmware's build record.
//!
//! The region holds a schedule blob and the firmware its records, all defined in
//! [`pe_firmware::image::blob`]. The image itself (magic, version, CRC, board position,
//! every record) is checked by the runtime's loader.

use crate::config::PROFILE;
use pe_firmware::image::blob::{
    build_flag, build_of, build_record, identity_position, identity_record, read_blob,
    run_options_flags, run_options_record, BlobError, BUILD_F32, BUILD_FULL, BUILD_LEN,
    IDENTITY_LEN, RUN_HOST_GATE, RUN_OPTIONS_LEN,
};
use pe_firmware::image::Feature;
use pe_firmware::profile::profile_index;

/// The image linked into the region when built with `PE_SCHEDULE_IMAGE=FILE` (otherwise
/// empty, and the region is flashed or loaded separately).
#[used]
#[link_section = ".schedule"]
static LINKED_SCHEDULE: [u8; include_bytes!(concat!(env!("OUT_DIR"), "/schedule.bin")).len()] =
    *include_bytes!(concat!(env!("OUT_DIR"), "/schedule.bin"));

extern "C" {
    static __pe_image_start: u8;
    static __pe_image_end: u8;
}

/// The whole IMAGE region as bytes.
fn region() -> &'static [u8] {
    let start = core::ptr::addr_of!(__pe_image_start);
    let end = core::ptr::addr_of!(__pe_image_end);
    let len = (end as usize).saturating_sub(start as usize);
    // SAFETY: the linker script defines [__pe_image_start, __pe_image_end) as the IMAGE
    // memory region: flash (or QEMU RAM) that is mapped, readable, never written while the
    // firmware runs, and not aliased by any Rust object except LINKED_SCHEDULE (immutable).
    unsafe { core::slice::from_raw_parts(start, len) }
}

/// The schedule image stored in the region (without the length word).
pub fn schedule_image() -> Result<&'static [u8], BlobError> {
    // Keep the linked image even if nothing else names it.
    core::hint::black_box(&LINKED_SCHEDULE);
    read_blob(region())
}

/// The board's identity record ([`pe_firmware::image::blob`]): the firmware ships with
/// (0,0,0); `pe image` writes each board's position into its copy of the ELF. On a board with
/// position straps, read them here instead.
#[used]
#[no_mangle]
pub static PE_BOARD_IDENTITY: [u8; IDENTITY_LEN] = identity_record([0, 0, 0]);

/// This board's position, or `None` if the identity record is damaged.
pub fn board_position() -> Option<[u8; 3]> {
    // SAFETY: reading a valid, aligned, initialised static. Volatile so the compiler cannot
    // fold the shipped value: the host tool patches the bytes in the ELF after linking.
    let id = unsafe { core::ptr::read_volatile(core::ptr::addr_of!(PE_BOARD_IDENTITY)) };
    identity_position(&id)
}

/// The board's run options record ([`pe_firmware::image::blob`]): none set as shipped; a
/// host that needs its step gate (`board-sim qemu --replay`) writes it into its copy of
/// the ELF.
#[used]
#[no_mangle]
pub static PE_RUN_OPTIONS: [u8; RUN_OPTIONS_LEN] = run_options_record(0);

/// Whether the run options switch the host's step gate on (`None`: the record is damaged).
pub fn host_gate() -> Option<bool> {
    // SAFETY: as for PE_BOARD_IDENTITY: a valid static the host tool may patch in the ELF.
    let r = unsafe { core::ptr::read_volatile(core::ptr::addr_of!(PE_RUN_OPTIONS)) };
    run_options_flags(&r).map(|f| f & RUN_HOST_GATE != 0)
}

/// What this build holds ([`pe_firmware::image::blob`]'s build record): its profile, its
/// scalar and element, the parts it carries. Written by the build, never patched; `pe image
/// --firmware` reads it to refuse an ELF built for another board or without what the images
/// need.
#[used]
#[no_mangle]
pub static PE_FIRMWARE_BUILD: [u8; BUILD_LEN] = build_record(PROFILE_INDEX, BUILD_FLAGS);

const PROFILE_INDEX: u8 = match profile_index(PROFILE.name) {
    Some(i) => i,
    None => panic!("the firmware's profile is not registered in pe_firmware::profile::PROFILES"),
};

const BUILD_FLAGS: u8 = {
    let mut f = 0;
    if cfg!(feature = "f32") {
        f |= BUILD_F32;
    }
    if cfg!(feature = "full") {
        f |= BUILD_FULL;
    }
    let mut k = 0;
    while k < Feature::ALL.len() {
        if Feature::ALL[k].built() {
            f |= build_flag(Feature::ALL[k]);
        }
        k += 1;
    }
    f
};

/// Whether the build record reads as this build wrote it (read, so the linker keeps it).
pub fn build_record_intact() -> bool {
    // SAFETY: as for PE_BOARD_IDENTITY: a valid, aligned, initialised static.
    let r = unsafe { core::ptr::read_volatile(core::ptr::addr_of!(PE_FIRMWARE_BUILD)) };
    build_of(&r) == Some((PROFILE_INDEX, BUILD_FLAGS))
}
