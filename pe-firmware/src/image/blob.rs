//! How an image sits in a board's flash, and how a board knows where it is: the one
//! definition of both, used by `pe image` (writing) and the board firmware (reading).
//!
//! - The schedule region at `ORIGIN(IMAGE)` holds a blob: a `u32` length (little-endian),
//!   then that many bytes of schedule image. Blank flash (`0xFFFF_FFFF`) or zeroed memory
//!   reads as "no image".
//! - The identity record is 16 bytes in the firmware: [`IDENTITY_MARKER`] (`PE-BOARD-ID`
//!   and a NUL), then x, y, z and a check byte `x ^ y ^ z ^ 0xA5`. The firmware ships with
//!   (0,0,0); `pe image` writes each board's position into its copy of the ELF.
//! - The run options record is 16 bytes in the firmware: [`RUN_OPTIONS_MARKER`]
//!   (`PE-RUN-OPTS` and a NUL), a flags byte ([`RUN_HOST_GATE`]), two zero bytes and a
//!   check byte `flags ^ 0x5A`. The firmware ships with no flag set; a host that needs one
//!   (`board-sim qemu --replay`: the host's step gate, `link_proto::gate`) writes it into
//!   its copy of the ELF, as `pe image` writes the identity.
//! - The build record is 16 bytes in the firmware: [`BUILD_MARKER`] (`PE-FW-BUILD` and a
//!   NUL), the board profile's index in [`crate::profile::PROFILES`], a flags byte
//!   ([`BUILD_F32`], [`BUILD_FULL`], [`BUILD_CONTACT`], [`BUILD_GRAPHICS`], [`BUILD_LOADS`]:
//!   what the build holds), a zero byte and a check byte `profile ^ flags ^ 0xC3`. Written
//!   by the build, never patched: `pe image --firmware` reads it to refuse an ELF built for
//!   another profile or without what the images need.
//!
//! Nothing here panics.

/// Bytes of the blob's length word.
pub const BLOB_HEADER_LEN: usize = 4;

/// Why a region holds no image to hand to the loader.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlobError {
    /// The length word is 0 or blank flash: nothing was flashed or loaded.
    Empty,
    /// The length word claims more bytes than the region holds.
    TooLong { len: u32, region: u32 },
    /// Writing: the output is too small for the blob.
    BufferFull,
}

impl core::fmt::Display for BlobError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            BlobError::Empty => write!(
                f,
                "no schedule image in the IMAGE region (flash a board-X-Y-Z.sched at its origin)"
            ),
            BlobError::TooLong { len, region } => write!(
                f,
                "schedule region claims {len} bytes but holds at most {region}: not a schedule blob"
            ),
            BlobError::BufferFull => write!(f, "output buffer too small for the schedule blob"),
        }
    }
}

/// Bytes of the blob of an image of `image_len` bytes.
pub const fn blob_len(image_len: usize) -> usize {
    BLOB_HEADER_LEN + image_len
}

/// Writes the blob of `image` into `out`; returns its length.
pub fn write_blob(image: &[u8], out: &mut [u8]) -> Result<usize, BlobError> {
    let len = blob_len(image.len());
    let dst = out.get_mut(..len).ok_or(BlobError::BufferFull)?;
    let (head, body) = dst.split_at_mut(BLOB_HEADER_LEN);
    head.copy_from_slice(&(image.len() as u32).to_le_bytes());
    body.copy_from_slice(image);
    Ok(len)
}

/// The schedule image stored in a region's bytes (without the length word).
pub fn read_blob(region: &[u8]) -> Result<&[u8], BlobError> {
    let (head, rest) = region.split_at(region.len().min(BLOB_HEADER_LEN));
    let len = match head {
        [a, b, c, d] => u32::from_le_bytes([*a, *b, *c, *d]),
        _ => 0,
    };
    if len == 0 || len == u32::MAX {
        return Err(BlobError::Empty);
    }
    rest.get(..len as usize).ok_or(BlobError::TooLong {
        len,
        region: rest.len() as u32,
    })
}

/// Bytes of a record the host finds in the firmware file by its marker (the identity, the
/// run options): a 12-byte marker, then 4 bytes.
const RECORD_LEN: usize = 16;

/// The record of `marker` and `tail`.
const fn marked_record(marker: [u8; 12], tail: [u8; 4]) -> [u8; RECORD_LEN] {
    let mut r = [0u8; RECORD_LEN];
    let mut k = 0;
    while k < RECORD_LEN {
        r[k] = if k < 12 { marker[k] } else { tail[k - 12] };
        k += 1;
    }
    r
}

/// Offsets in a firmware file of the records that start with `marker` and that `valid`
/// accepts.
fn find_marked(
    elf: &[u8],
    marker: [u8; 12],
    valid: fn(&[u8; RECORD_LEN]) -> bool,
) -> impl Iterator<Item = usize> + '_ {
    elf.windows(RECORD_LEN)
        .enumerate()
        .filter_map(move |(k, w)| {
            let r: &[u8; RECORD_LEN] = w.try_into().ok()?;
            (r[..12] == marker && valid(r)).then_some(k)
        })
}

/// The marker that starts the identity record.
pub const IDENTITY_MARKER: [u8; 12] = *b"PE-BOARD-ID\0";
/// Bytes of the identity record.
pub const IDENTITY_LEN: usize = RECORD_LEN;

/// The identity record of the board at `board`.
pub const fn identity_record(board: [u8; 3]) -> [u8; IDENTITY_LEN] {
    let tail = [board[0], board[1], board[2], identity_check(board)];
    marked_record(IDENTITY_MARKER, tail)
}

/// The check byte of a position.
pub const fn identity_check(board: [u8; 3]) -> u8 {
    board[0] ^ board[1] ^ board[2] ^ 0xA5
}

/// The position in an identity record, or `None` if its check byte is wrong. Only the
/// check byte is compared, not the marker: a copy of the marker in the firmware's code would
/// be a second match for the host's search.
pub fn identity_position(record: &[u8; IDENTITY_LEN]) -> Option<[u8; 3]> {
    let board = [record[12], record[13], record[14]];
    (identity_check(board) == record[15]).then_some(board)
}

/// Offsets of the identity records in a firmware file: the marker followed by a valid
/// position and check byte.
pub fn find_identity(elf: &[u8]) -> impl Iterator<Item = usize> + '_ {
    find_marked(elf, IDENTITY_MARKER, |r| identity_position(r).is_some())
}

/// The marker that starts the run options record.
pub const RUN_OPTIONS_MARKER: [u8; 12] = *b"PE-RUN-OPTS\0";
/// Bytes of the run options record.
pub const RUN_OPTIONS_LEN: usize = RECORD_LEN;
/// Run option: a board whose contact tables hold a tool waits for the host's permits
/// (`link_proto::gate`).
pub const RUN_HOST_GATE: u8 = 1;

/// The run options record with `flags`.
pub const fn run_options_record(flags: u8) -> [u8; RUN_OPTIONS_LEN] {
    marked_record(RUN_OPTIONS_MARKER, [flags, 0, 0, flags ^ 0x5A])
}

/// The flags of a run options record, or `None` if it is damaged (its check byte or
/// reserved bytes wrong).
pub fn run_options_flags(record: &[u8; RUN_OPTIONS_LEN]) -> Option<u8> {
    let flags = record[12];
    (record[13] == 0 && record[14] == 0 && record[15] == flags ^ 0x5A).then_some(flags)
}

/// Offsets of the run options records in a firmware file.
pub fn find_run_options(elf: &[u8]) -> impl Iterator<Item = usize> + '_ {
    find_marked(elf, RUN_OPTIONS_MARKER, |r| run_options_flags(r).is_some())
}

/// The marker that starts the build record.
pub const BUILD_MARKER: [u8; 12] = *b"PE-FW-BUILD\0";
/// Bytes of the build record.
pub const BUILD_LEN: usize = RECORD_LEN;
/// Build flag: the schedule's scalar is `f32` (else `f64`).
pub const BUILD_F32: u8 = 1;
/// Build flag: full integration (else reduced).
pub const BUILD_FULL: u8 = 2;
/// Build flag: the contact code and tables.
pub const BUILD_CONTACT: u8 = 4;
/// Build flag: the graphics stream.
pub const BUILD_GRAPHICS: u8 = 8;
/// Build flag: loads (`[[load]]`).
pub const BUILD_LOADS: u8 = 16;

/// The build flag of a part ([`BUILD_CONTACT`], [`BUILD_GRAPHICS`], [`BUILD_LOADS`]).
pub const fn build_flag(part: super::Feature) -> u8 {
    match part {
        super::Feature::Contact => BUILD_CONTACT,
        super::Feature::Graphics => BUILD_GRAPHICS,
        super::Feature::Loads => BUILD_LOADS,
    }
}

/// The build record of a firmware for the profile at `profile` in
/// [`crate::profile::PROFILES`] holding `flags`.
pub const fn build_record(profile: u8, flags: u8) -> [u8; BUILD_LEN] {
    marked_record(BUILD_MARKER, [profile, flags, 0, profile ^ flags ^ 0xC3])
}

/// The profile index and flags of a build record, or `None` if it is damaged.
pub fn build_of(record: &[u8; BUILD_LEN]) -> Option<(u8, u8)> {
    let (profile, flags) = (record[12], record[13]);
    (record[14] == 0 && record[15] == profile ^ flags ^ 0xC3).then_some((profile, flags))
}

/// Offsets of the build records in a firmware file.
pub fn find_build(elf: &[u8]) -> impl Iterator<Item = usize> + '_ {
    find_marked(elf, BUILD_MARKER, |r| build_of(r).is_some())
}
