//! The crate's error type.

use core::fmt;

/// Why a frame, packet or byte-stream chunk was rejected, or could not be emitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// The buffer ends before the header, payload or CRC it announces.
    Truncated,
    /// The buffer, or the length a header announces, exceeds the compile-time maximum
    /// (for a stream decoder: the frame did not fit the decoder's buffer).
    Oversized,
    /// The buffer is longer than the frame its header describes (trailing bytes).
    BadLength,
    /// The CRC-32 trailer does not match the contents.
    BadCrc,
    /// The precision code of a link frame is neither 4 (f32) nor 8 (f64).
    UnknownPrecision(u8),
    /// The version byte of a global packet is not [`crate::packet::PACKET_VERSION`].
    UnsupportedVersion(u8),
    /// The bytes between two stream delimiters are not valid COBS.
    BadEncoding,
    /// The caller's output buffer is too small for what is to be emitted or received.
    BufferTooSmall,
    /// A payload ends inside this field (a payload whose fields are named:
    /// [`crate::tool_pose`]).
    TruncatedField(&'static str),
    /// This field of a payload holds a value it cannot (non-finite, out of range).
    BadField(&'static str),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Truncated => f.write_str("truncated: buffer shorter than announced"),
            Error::Oversized => f.write_str("oversized: exceeds the compile-time maximum"),
            Error::BadLength => f.write_str("bad length: trailing bytes after the frame"),
            Error::BadCrc => f.write_str("CRC mismatch"),
            Error::UnknownPrecision(p) => write!(f, "unknown precision code {p}"),
            Error::UnsupportedVersion(v) => write!(f, "unsupported packet version {v}"),
            Error::BadEncoding => f.write_str("invalid COBS encoding"),
            Error::BufferTooSmall => f.write_str("output buffer too small"),
            Error::TruncatedField(name) => {
                write!(f, "truncated: the payload ends inside field `{name}`")
            }
            Error::BadField(name) => write!(f, "bad value in field `{name}`"),
        }
    }
}

/// Result with this crate's [`Error`].
pub type Result<T> = core::result::Result<T, Error>;

impl core::error::Error for Error {}
