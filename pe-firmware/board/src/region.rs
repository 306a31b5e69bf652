//! The schedule image region (linker symbols `__pe_image_start`/`__pe_image_end`, see
//! `schedule.x`) and the board's identity (its position in the machine).
//!
//! Region layout at `ORIGIN(IMAGE)`: a `u32` length (little-endian), then that many bytes of
//! schedule image. Blank flash (`0xFFFF_FFFF`) or zeroed memory reads as "no image". The
//! image itself (magic, version, CRC, board position, every record) is checked by the
//! runtime's loader.

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

/// Why there is no image to hand to the loader.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RegionError {
    /// The length word is 0 or blank flash: nothing was flashed or loaded.
    Empty,
    /// The length word claims more bytes than the region holds.
    TooLong { len: u32, region: u32 },
}

impl core::fmt::Display for RegionError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            RegionError::Empty => write!(
                f,
                "no schedule image in the IMAGE region (flash a board-X-Y-Z.sched at its origin)"
            ),
            RegionError::TooLong { len, region } => write!(
                f,
                "schedule region claims {len} bytes but holds at most {region}: not a schedule blob"
            ),
        }
    }
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
pub fn schedule_image() -> Result<&'static [u8], RegionError> {
    // Keep the linked image even if nothing else names it.
    core::hint::black_box(&LINKED_SCHEDULE);
    let r = region();
    let (head, rest) = r.split_at(r.len().min(4));
    let len = match head {
        [a, b, c, d] => u32::from_le_bytes([*a, *b, *c, *d]),
        _ => 0,
    };
    if len == 0 || len == u32::MAX {
        return Err(RegionError::Empty);
    }
    rest.get(..len as usize).ok_or(RegionError::TooLong {
        len,
        region: rest.len() as u32,
    })
}

/// Where the board's position comes from: a 16-byte identity record in flash, `PE-BOARD-ID`
/// plus a NUL, then x, y, z and a check byte (`x ^ y ^ z ^ 0xA5`). The firmware ships with
/// (0,0,0); `pe image` writes each board's position into its copy of the ELF. On a board with
/// position straps, read them here instead.
#[used]
#[no_mangle]
pub static PE_BOARD_IDENTITY: [u8; 16] = *b"PE-BOARD-ID\0\0\0\0\xA5";

/// This board's position, or `None` if the identity record is damaged.
pub fn board_position() -> Option<[u8; 3]> {
    // SAFETY: reading a valid, aligned, initialised static. Volatile so the compiler cannot
    // fold the shipped value: the host tool patches the bytes in the ELF after linking.
    let id = unsafe { core::ptr::read_volatile(core::ptr::addr_of!(PE_BOARD_IDENTITY)) };
    let [x, y, z, check] = [id[12], id[13], id[14], id[15]];
    // Only the check byte is compared: a copy of the marker in the code would be a second
    // match for the host tool's search.
    (x ^ y ^ z ^ 0xA5 == check).then_some([x, y, z])
}
