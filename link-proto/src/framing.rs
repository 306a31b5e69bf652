//! COBS byte-stream framing with resynchronisation.
//!
//! On a byte stream (UART, SPI) each frame or packet travels as
//!
//! | bytes              | meaning                                     |
//! |--------------------|---------------------------------------------|
//! | `0x00`             | leading delimiter                           |
//! | COBS(frame)        | the frame, Consistent Overhead Byte Stuffed: no `0x00` inside |
//! | `0x00`             | trailing delimiter                          |
//!
//! The receiver ([`StreamDecoder`]) collects the bytes between two `0x00`
//! and decodes them; empty runs (`0x00 0x00`, idle line) are skipped. Since
//! no `0x00` occurs inside an encoded frame, every delimiter is a
//! resynchronisation point: a lost, corrupted or inserted byte damages only
//! the frame it falls in, and a lost delimiter costs nothing because each
//! frame carries two. The decoder reports a damaged run as an error
//! ([`Error::BadEncoding`], [`Error::Oversized`]) and carries on; damage that
//! still decodes as COBS is caught by the CRC of the frame or packet.
//!
//! # Panics
//!
//! Nothing here panics, whatever the input.

use crate::error::{Error, Result};

/// Writes `0x00`, COBS(`frame`), `0x00` at the start of `out`; returns the
/// number of bytes written (at most [`crate::limits::cobs_len_max`]`(frame.len()) + 2`).
pub fn encode_wire(frame: &[u8], out: &mut [u8]) -> Result<usize> {
    let (first, rest) = out.split_first_mut().ok_or(Error::BufferTooSmall)?;
    *first = 0;
    // Keep one byte for the trailing delimiter.
    let body_cap = rest.len().checked_sub(1).ok_or(Error::BufferTooSmall)?;
    let body = rest.get_mut(..body_cap).ok_or(Error::BufferTooSmall)?;
    let n = if frame.is_empty() {
        // COBS of nothing is one code byte 0x01; the `cobs` crate writes
        // nothing, which the receiver could not tell from an idle line.
        *body.first_mut().ok_or(Error::BufferTooSmall)? = 0x01;
        1
    } else {
        cobs::try_encode(frame, body).map_err(|_| Error::BufferTooSmall)?
    };
    *rest.get_mut(n).ok_or(Error::BufferTooSmall)? = 0;
    Ok(n + 2)
}

/// Streaming COBS decoder with a fixed buffer of `N` encoded bytes.
///
/// Feed it bytes as they arrive; it yields each whole frame (decoded in place,
/// valid until the next byte is fed) or reports a damaged one, then carries on
/// with the next delimiter. `N` must hold the largest encoded frame
/// ([`crate::limits::FRAME_COBS_LEN_MAX`] or
/// [`crate::limits::PACKET_COBS_LEN_MAX`]).
#[derive(Debug, Clone)]
pub struct StreamDecoder<const N: usize> {
    buf: [u8; N],
    len: usize,
    overflowed: bool,
}

impl<const N: usize> Default for StreamDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> StreamDecoder<N> {
    /// An empty decoder.
    pub const fn new() -> Self {
        StreamDecoder {
            buf: [0; N],
            len: 0,
            overflowed: false,
        }
    }

    /// Drops any partial frame.
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }

    /// Number of bytes of the current partial frame.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Feeds one byte; at a delimiter returns the decoded length of the frame
    /// now at `buf[..len]`, or the damage.
    fn feed_inner(&mut self, byte: u8) -> Option<Result<usize>> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => self.overflowed = true,
            }
            return None;
        }
        let len = self.len;
        let overflowed = self.overflowed;
        self.reset();
        if overflowed {
            return Some(Err(Error::Oversized));
        }
        if len == 0 {
            return None; // idle / double delimiter
        }
        let encoded = self.buf.get_mut(..len)?;
        Some(cobs::decode_in_place(encoded).map_err(|_| Error::BadEncoding))
    }

    /// Feeds one byte. At the end of a frame returns `Some(Ok(frame))` or
    /// `Some(Err(damage))`; otherwise `None`.
    pub fn feed(&mut self, byte: u8) -> Option<Result<&[u8]>> {
        match self.feed_inner(byte)? {
            Ok(n) => Some(Ok(self.buf.get(..n).unwrap_or(&[]))),
            Err(e) => Some(Err(e)),
        }
    }

    /// Feeds bytes until the first frame ends or the input runs out. Returns
    /// how many bytes were consumed and the event, if any; call again with the
    /// rest of the input.
    pub fn push(&mut self, bytes: &[u8]) -> (usize, Option<Result<&[u8]>>) {
        for (i, &b) in bytes.iter().enumerate() {
            if let Some(r) = self.feed_inner(b) {
                return match r {
                    Ok(n) => (i + 1, Some(Ok(self.buf.get(..n).unwrap_or(&[])))),
                    Err(e) => (i + 1, Some(Err(e))),
                };
            }
        }
        (bytes.len(), None)
    }
}
