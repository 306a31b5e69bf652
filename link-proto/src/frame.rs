//! Local link frames: address-free, schedule-ordered values between neighbours.
//!
//! Layout (all multi-byte fields little-endian):
//!
//! | offset     | size    | field                                              |
//! |------------|---------|----------------------------------------------------|
//! | 0          | 1       | kind ([`FrameKind`])                               |
//! | 1          | 1       | precision: value width in bytes, 4 = f32, 8 = f64  |
//! | 2          | 2       | value count `n` (u16, at most [`VALUES_PER_FRAME_MAX`]) |
//! | 4          | 4       | step number (u32)                                  |
//! | 8          | `n * w` | values, IEEE-754 little-endian, in schedule order  |
//! | 8 + `n*w`  | 4       | CRC-32/ISO-HDLC over bytes `0 .. 8 + n*w`          |
//!
//! # Panics
//!
//! [`Frame::new_checked`], [`FrameRepr::parse`], [`FrameRepr::emit`] and
//! [`emit_values`] never panic, whatever the input. The field accessors of a
//! [`Frame`] built with [`Frame::new_unchecked`] panic if the buffer is shorter
//! than the header and payload it describes: call them on untrusted bytes only
//! after [`Frame::new_checked`] (or [`Frame::check_len`]) succeeded.

use crate::error::{Error, Result};
use crate::limits::{
    enveloped_len, CRC_LEN, FRAME_HEADER_LEN, FRAME_LEN_MAX, FRAME_LEN_MIN, VALUES_PER_FRAME_MAX,
};

mod field {
    use core::ops::Range;
    pub const KIND: usize = 0;
    pub const PRECISION: usize = 1;
    pub const COUNT: Range<usize> = 2..4;
    pub const STEP: Range<usize> = 4..8;
    pub const PAYLOAD: usize = 8;
}

const _: () = assert!(field::PAYLOAD == FRAME_HEADER_LEN);
const _: () = assert!(frame_len(0, Precision::F32) == FRAME_LEN_MIN);
const _: () = assert!(frame_len(VALUES_PER_FRAME_MAX, Precision::F64) == FRAME_LEN_MAX);

/// Length of a link frame of `values` values of `precision`: header, values and CRC (without
/// recovery's envelope: [`crate::limits::enveloped_len`] of this; on a byte stream at most
/// [`crate::limits::wire_len_max`] of either).
pub const fn frame_len(values: usize, precision: Precision) -> usize {
    FRAME_HEADER_LEN + values * precision.width() + CRC_LEN
}

/// What a link frame carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FrameKind {
    /// Displacements of the border nodes the neighbour needs for its next step.
    Displacements,
    /// Partial internal forces on shared border nodes, for the neighbour to add up.
    Forces,
    /// Step barrier: "I finished step N"; usually no values.
    Barrier,
    /// First exchange before step 0: the sender's compilation id (one f64 value whose
    /// 8 bytes are the id), which the receiver compares with its own.
    Hello,
    /// A kind this firmware does not know. Parsed, never rejected.
    Unknown(u8),
}

impl FrameKind {
    /// The wire code of this kind.
    pub const fn code(self) -> u8 {
        match self {
            FrameKind::Displacements => 0x01,
            FrameKind::Forces => 0x02,
            FrameKind::Barrier => 0x03,
            FrameKind::Hello => 0x04,
            FrameKind::Unknown(c) => c,
        }
    }

    /// The kind of a wire code; unknown codes give [`FrameKind::Unknown`].
    pub const fn from_code(code: u8) -> Self {
        match code {
            0x01 => FrameKind::Displacements,
            0x02 => FrameKind::Forces,
            0x03 => FrameKind::Barrier,
            0x04 => FrameKind::Hello,
            c => FrameKind::Unknown(c),
        }
    }
}

/// Width of the values of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Precision {
    /// IEEE-754 binary32, 4 bytes.
    F32,
    /// IEEE-754 binary64, 8 bytes.
    F64,
}

impl Precision {
    /// Width of one value in bytes; also the wire code.
    pub const fn width(self) -> usize {
        match self {
            Precision::F32 => 4,
            Precision::F64 => 8,
        }
    }

    /// The wire code (the width in bytes).
    pub const fn code(self) -> u8 {
        self.width() as u8
    }

    /// The precision of a wire code.
    pub const fn from_code(code: u8) -> Result<Self> {
        match code {
            4 => Ok(Precision::F32),
            8 => Ok(Precision::F64),
            c => Err(Error::UnknownPrecision(c)),
        }
    }
}

/// The board's CRC table: a byte at a time (1 KiB in flash).
pub type CrcTable = crc::Table<1>;

/// CRC-32/ISO-HDLC (polynomial 0x04C11DB7, reflected, init and xor-out
/// 0xFFFFFFFF: the zlib/Ethernet CRC, which the STM32 CRC unit also computes).
pub const CRC32: crc::Crc<u32, CrcTable> = crc::Crc::<u32, CrcTable>::new(&crc::CRC_32_ISO_HDLC);

/// CRC-32/ISO-HDLC of `bytes`: on the board by [`CRC32`]'s byte-wise table; on the host by
/// `crc32fast` (carry-less multiplication where the CPU has it, chosen at run time; board-sim
/// checks every frame and packet of 64 boards, and the table CRC, even sixteen bytes at a
/// time, was a fifth of its profile). The same CRC either way.
#[cfg(target_os = "none")]
pub fn crc32(bytes: &[u8]) -> u32 {
    CRC32.checksum(bytes)
}

/// See the board's definition.
#[cfg(not(target_os = "none"))]
pub fn crc32(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

/// A zero-copy view of a link frame in a byte buffer.
#[derive(Debug, Clone)]
pub struct Frame<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Frame<T> {
    /// Wraps a buffer without any check. See the module doc for when accessors panic.
    pub const fn new_unchecked(buffer: T) -> Frame<T> {
        Frame { buffer }
    }

    /// Wraps a buffer after [`Frame::check_len`]. The CRC is not checked here
    /// (see [`Frame::verify_crc`] and [`FrameRepr::parse`]).
    pub fn new_checked(buffer: T) -> Result<Frame<T>> {
        let frame = Self::new_unchecked(buffer);
        frame.check_len()?;
        Ok(frame)
    }

    /// Checks that the buffer holds exactly one frame: a header with a known
    /// precision and a value count within [`VALUES_PER_FRAME_MAX`], the payload
    /// and the CRC, and nothing after it. Never panics.
    pub fn check_len(&self) -> Result<()> {
        let data = self.buffer.as_ref();
        if data.len() > FRAME_LEN_MAX {
            return Err(Error::Oversized);
        }
        let (Some(&precision), Some(&[c0, c1])) = (
            data.get(field::PRECISION),
            data.get(field::COUNT)
                .and_then(|s| <&[u8; 2]>::try_from(s).ok()),
        ) else {
            return Err(Error::Truncated);
        };
        if data.len() < FRAME_LEN_MIN {
            return Err(Error::Truncated);
        }
        let precision = Precision::from_code(precision)?;
        let count = usize::from(u16::from_le_bytes([c0, c1]));
        if count > VALUES_PER_FRAME_MAX {
            return Err(Error::Oversized);
        }
        let total = frame_len(count, precision);
        match data.len() {
            n if n < total => Err(Error::Truncated),
            n if n > total => Err(Error::BadLength),
            _ => Ok(()),
        }
    }

    /// Returns the underlying buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    /// The frame kind.
    pub fn kind(&self) -> FrameKind {
        FrameKind::from_code(self.buffer.as_ref()[field::KIND])
    }

    /// The raw precision code.
    pub fn precision_code(&self) -> u8 {
        self.buffer.as_ref()[field::PRECISION]
    }

    /// The precision, or [`Error::UnknownPrecision`].
    pub fn precision(&self) -> Result<Precision> {
        Precision::from_code(self.precision_code())
    }

    /// The number of values.
    pub fn value_count(&self) -> u16 {
        let d = self.buffer.as_ref();
        u16::from_le_bytes([d[field::COUNT.start], d[field::COUNT.start + 1]])
    }

    /// The step number.
    pub fn step(&self) -> u32 {
        let d = self.buffer.as_ref();
        let s = field::STEP.start;
        u32::from_le_bytes([d[s], d[s + 1], d[s + 2], d[s + 3]])
    }

    fn payload_len(&self) -> usize {
        let width = self.precision().map(Precision::width).unwrap_or(0);
        usize::from(self.value_count()) * width
    }

    /// The payload bytes (values, little-endian).
    pub fn payload(&self) -> &[u8] {
        let end = field::PAYLOAD + self.payload_len();
        &self.buffer.as_ref()[field::PAYLOAD..end]
    }

    /// The CRC stored in the trailer.
    pub fn crc(&self) -> u32 {
        let d = self.buffer.as_ref();
        let s = field::PAYLOAD + self.payload_len();
        u32::from_le_bytes([d[s], d[s + 1], d[s + 2], d[s + 3]])
    }

    /// Whether the trailer matches the CRC of header and payload.
    pub fn verify_crc(&self) -> bool {
        let end = field::PAYLOAD + self.payload_len();
        crc32(&self.buffer.as_ref()[..end]) == self.crc()
    }

    /// The values as a typed view.
    pub fn values(&self) -> Result<Payload<'_>> {
        Payload::new(self.precision()?, self.payload())
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Frame<T> {
    /// Sets the kind.
    pub fn set_kind(&mut self, kind: FrameKind) {
        self.buffer.as_mut()[field::KIND] = kind.code();
    }

    /// Sets the precision.
    pub fn set_precision(&mut self, precision: Precision) {
        self.buffer.as_mut()[field::PRECISION] = precision.code();
    }

    /// Sets the value count.
    pub fn set_value_count(&mut self, count: u16) {
        self.buffer.as_mut()[field::COUNT].copy_from_slice(&count.to_le_bytes());
    }

    /// Sets the step number.
    pub fn set_step(&mut self, step: u32) {
        self.buffer.as_mut()[field::STEP].copy_from_slice(&step.to_le_bytes());
    }

    /// The payload bytes, mutable (header fields must be set first).
    pub fn payload_mut(&mut self) -> &mut [u8] {
        let end = field::PAYLOAD + self.payload_len();
        &mut self.buffer.as_mut()[field::PAYLOAD..end]
    }

    /// Computes the CRC of header and payload and stores it in the trailer.
    pub fn fill_crc(&mut self) {
        let end = field::PAYLOAD + self.payload_len();
        let crc = crc32(&self.buffer.as_ref()[..end]);
        self.buffer.as_mut()[end..end + CRC_LEN].copy_from_slice(&crc.to_le_bytes());
    }
}

/// A validated, borrowed run of little-endian values of one precision.
///
/// Equality is bitwise (same precision, same bytes), so NaNs compare equal to
/// themselves and `0.0 != -0.0`: what a round trip must preserve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Payload<'a> {
    precision: Precision,
    bytes: &'a [u8],
}

impl<'a> Payload<'a> {
    /// Wraps little-endian value bytes. Fails with [`Error::BadLength`] if the
    /// length is not a multiple of the width, [`Error::Oversized`] if there are
    /// more than [`VALUES_PER_FRAME_MAX`] values.
    pub fn new(precision: Precision, bytes: &'a [u8]) -> Result<Self> {
        if !bytes.chunks_exact(precision.width()).remainder().is_empty() {
            return Err(Error::BadLength);
        }
        if bytes.len() / precision.width() > VALUES_PER_FRAME_MAX {
            return Err(Error::Oversized);
        }
        Ok(Payload { precision, bytes })
    }

    /// An empty payload.
    pub const fn empty(precision: Precision) -> Self {
        Payload {
            precision,
            bytes: &[],
        }
    }

    /// The precision.
    pub fn precision(&self) -> Precision {
        self.precision
    }

    /// The raw little-endian bytes.
    pub fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        self.bytes.len() / self.precision.width()
    }

    /// Whether there are no values.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// Value `i` widened to f64 (exact for f32), or `None` past the end.
    pub fn get(&self, i: usize) -> Option<f64> {
        let w = self.precision.width();
        let chunk = self
            .bytes
            .get(i.checked_mul(w)?..i.checked_mul(w)?.checked_add(w)?)?;
        Some(decode_value(self.precision, chunk))
    }

    /// All values widened to f64 (exact for f32).
    pub fn iter(&self) -> impl Iterator<Item = f64> + 'a {
        let p = self.precision;
        self.bytes
            .chunks_exact(p.width())
            .map(move |c| decode_value(p, c))
    }

    /// Copies f32 values into `out` (f64 values are rounded to f32); returns
    /// the number copied, `min(self.len(), out.len())`.
    pub fn copy_to_f32(&self, out: &mut [f32]) -> usize {
        let mut n = 0;
        for (o, v) in out.iter_mut().zip(self.iter()) {
            *o = v as f32;
            n += 1;
        }
        n
    }

    /// Copies values into `out` as f64; returns the number copied.
    pub fn copy_to_f64(&self, out: &mut [f64]) -> usize {
        let mut n = 0;
        for (o, v) in out.iter_mut().zip(self.iter()) {
            *o = v;
            n += 1;
        }
        n
    }
}

fn decode_value(p: Precision, c: &[u8]) -> f64 {
    match (p, c) {
        (Precision::F32, &[a, b, c, d]) => f64::from(f32::from_le_bytes([a, b, c, d])),
        (Precision::F64, &[a, b, c, d, e, f, g, h]) => f64::from_le_bytes([a, b, c, d, e, f, g, h]),
        // Unreachable: chunks are cut at the precision's width.
        _ => f64::NAN,
    }
}

/// Native values to send, in schedule order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Values<'a> {
    /// Single precision.
    F32(&'a [f32]),
    /// Double precision.
    F64(&'a [f64]),
}

impl Values<'_> {
    /// The precision.
    pub fn precision(&self) -> Precision {
        match self {
            Values::F32(_) => Precision::F32,
            Values::F64(_) => Precision::F64,
        }
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            Values::F32(v) => v.len(),
            Values::F64(v) => v.len(),
        }
    }

    /// Whether there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The checked, high-level content of a link frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRepr<'a> {
    /// Frame kind.
    pub kind: FrameKind,
    /// Step number the values belong to.
    pub step: u32,
    /// The values (borrowed from the parsed buffer).
    pub payload: Payload<'a>,
}

impl<'a> FrameRepr<'a> {
    /// Parses and fully validates a frame: length, precision, count and CRC.
    /// Never panics.
    pub fn parse<T: AsRef<[u8]> + ?Sized>(frame: &Frame<&'a T>) -> Result<FrameRepr<'a>> {
        let bytes: &'a [u8] = frame.buffer.as_ref();
        Self::parse_bytes(bytes)
    }

    /// [`FrameRepr::parse`] directly on a byte slice.
    pub fn parse_bytes(bytes: &'a [u8]) -> Result<FrameRepr<'a>> {
        let view = Frame::new_checked(bytes)?;
        if !view.verify_crc() {
            return Err(Error::BadCrc);
        }
        let payload = Payload::new(view.precision()?, payload_of(bytes, view.payload_len()))?;
        Ok(FrameRepr {
            kind: view.kind(),
            step: view.step(),
            payload,
        })
    }

    /// Length of the emitted frame ([`frame_len`]).
    pub fn buffer_len(&self) -> usize {
        frame_len(self.payload.len(), self.payload.precision)
    }

    /// Length of the emitted frame inside recovery's envelope ([`enveloped_len`]).
    pub fn enveloped_len(&self) -> usize {
        enveloped_len(self.buffer_len())
    }

    /// Emits the frame at the start of `buf`; returns its length.
    /// Fails with [`Error::BufferTooSmall`]; never panics.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize> {
        let len = self.buffer_len();
        let out = buf.get_mut(..len).ok_or(Error::BufferTooSmall)?;
        write_header(
            out,
            self.kind,
            self.step,
            self.payload.precision,
            self.payload.len(),
        )?;
        out.get_mut(field::PAYLOAD..len - CRC_LEN)
            .ok_or(Error::BufferTooSmall)?
            .copy_from_slice(self.payload.bytes);
        Frame::new_unchecked(out).fill_crc();
        Ok(len)
    }
}

fn payload_of(bytes: &[u8], len: usize) -> &[u8] {
    bytes
        .get(field::PAYLOAD..field::PAYLOAD + len)
        .unwrap_or(&[])
}

fn write_header(
    out: &mut [u8],
    kind: FrameKind,
    step: u32,
    precision: Precision,
    count: usize,
) -> Result<()> {
    let count = u16::try_from(count)
        .ok()
        .filter(|&c| usize::from(c) <= VALUES_PER_FRAME_MAX)
        .ok_or(Error::Oversized)?;
    if out.len() < frame_len(usize::from(count), precision) {
        return Err(Error::BufferTooSmall);
    }
    let mut f = Frame::new_unchecked(out);
    f.set_kind(kind);
    f.set_precision(precision);
    f.set_value_count(count);
    f.set_step(step);
    Ok(())
}

/// Emits a frame of native values at the start of `buf`; returns its length.
/// Fails with [`Error::Oversized`] past [`VALUES_PER_FRAME_MAX`] values and
/// [`Error::BufferTooSmall`]; never panics.
pub fn emit_values(
    kind: FrameKind,
    step: u32,
    values: Values<'_>,
    buf: &mut [u8],
) -> Result<usize> {
    let precision = values.precision();
    let len = frame_len(values.len(), precision);
    if values.len() > VALUES_PER_FRAME_MAX {
        return Err(Error::Oversized);
    }
    let out = buf.get_mut(..len).ok_or(Error::BufferTooSmall)?;
    write_header(out, kind, step, precision, values.len())?;
    let payload = out
        .get_mut(field::PAYLOAD..len - CRC_LEN)
        .ok_or(Error::BufferTooSmall)?;
    match values {
        Values::F32(v) => {
            for (c, x) in payload.chunks_exact_mut(4).zip(v) {
                c.copy_from_slice(&x.to_le_bytes());
            }
        }
        Values::F64(v) => {
            for (c, x) in payload.chunks_exact_mut(8).zip(v) {
                c.copy_from_slice(&x.to_le_bytes());
            }
        }
    }
    Frame::new_unchecked(out).fill_crc();
    Ok(len)
}
