//! What face and global recovery share: the envelope's length, its CRC rule, the window
//! bound and the arithmetic of the u16 sequence numbers.
//!
//! Every envelope is a six-byte header ([`HEADER_LEN`]; its fields differ: see
//! [`super::face`] and [`super::global`]), then (data) the frame or packet carried, which
//! ends with the CRC-32 of its other bytes, then the envelope's CRC-32 over the header
//! followed by the carried CRC (`envelope_crc`). [`OVERHEAD`] = 10 bytes per frame or
//! packet, and the whole length of an envelope that carries none (ack, nack, status).

use crate::frame::{crc32, CRC32};
use crate::limits::CRC_LEN;

pub use crate::limits::enveloped_len;
/// Envelope header length (its home: [`crate::limits::ENVELOPE_HEADER_LEN`]).
pub use crate::limits::ENVELOPE_HEADER_LEN as HEADER_LEN;
/// Bytes an envelope adds to a frame or packet, and the length of an envelope without one
/// (its home: [`crate::limits::ENVELOPE_OVERHEAD`]).
pub use crate::limits::ENVELOPE_OVERHEAD as OVERHEAD;

/// Largest window: frames kept per face (packets per destination) for retransmission, and
/// (faces) received ahead of delivery.
pub const WINDOW_MAX: usize = 16;

// Go-back-N over u16 numbers: a window must stay far below half the number space, or
// `diff` could not order the numbers in it.
const _: () = assert!(WINDOW_MAX < 1 << 14);

/// `a - b` on the u16 sequence-number circle: positive if `a` comes after `b`.
pub(crate) fn diff(a: u16, b: u16) -> i16 {
    a.wrapping_sub(b) as i16
}

/// The CRC an envelope ends with: over its header, then (data) the carried frame's or
/// packet's own CRC, its last four bytes. Ten bytes at most: the byte-wise table, on the
/// host too (no set-up per call).
pub(crate) fn envelope_crc(header: &[u8], carried_crc: &[u8]) -> u32 {
    let mut d = CRC32.digest();
    d.update(header);
    d.update(carried_crc);
    d.finalize()
}

/// Checks envelope `e`: a header of [`HEADER_LEN`] bytes, then (`data`) a frame or packet
/// that ends with the CRC-32 of its other bytes, or nothing, then the envelope's CRC
/// ([`envelope_crc`]). The carried bytes, or `None` if too short or a CRC fails.
pub(crate) fn check_envelope(e: &[u8], data: bool) -> Option<&[u8]> {
    let body_len = e.len().checked_sub(CRC_LEN)?;
    let (body, crc) = e.split_at(body_len);
    let (header, carried) = body.split_at_checked(HEADER_LEN)?;
    let carried_crc = if data {
        let (rest, own) = carried.split_at(carried.len().checked_sub(CRC_LEN)?);
        if crc32(rest).to_le_bytes() != own {
            return None;
        }
        own
    } else if carried.is_empty() {
        carried
    } else {
        return None;
    };
    (envelope_crc(header, carried_crc).to_le_bytes() == crc).then_some(carried)
}

/// Seals envelope `e` (header filled in, then the carried frame or packet, if any, then
/// [`CRC_LEN`] bytes for the envelope's CRC): writes that CRC. `None` if `e` is shorter
/// than an envelope without a frame.
pub(crate) fn seal(e: &mut [u8], carried: bool) -> Option<()> {
    let body_len = e.len().checked_sub(CRC_LEN)?;
    let (body, crc) = e.split_at_mut(body_len);
    let (header, frame) = body.split_at_checked(HEADER_LEN)?;
    let carried_crc = if carried {
        frame.get(frame.len().checked_sub(CRC_LEN)?..)?
    } else {
        &[]
    };
    crc.copy_from_slice(&envelope_crc(header, carried_crc).to_le_bytes());
    Some(())
}

/// The bytes an envelope carries (unchecked: for observers such as fault injectors), or
/// `None` if it is shorter than an envelope.
pub(crate) fn carried(envelope: &[u8]) -> Option<&[u8]> {
    envelope.get(HEADER_LEN..envelope.len().checked_sub(CRC_LEN)?)
}

/// The u16 field at `range` of an envelope (little-endian), or `None` if it is too short.
pub(crate) fn u16_at(e: &[u8], range: core::ops::Range<usize>) -> Option<u16> {
    let b: [u8; 2] = e.get(range)?.try_into().ok()?;
    Some(u16::from_le_bytes(b))
}
