//! Why the codec refused a message. Every variant says what was wrong in words a client's
//! author can act on; [`Error::breaks_framing`] says whether the stream can go on.

/// A refusal of the OpenIGTLink codec.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Error {
    #[error("{what}: {have} bytes, {need} needed")]
    Truncated {
        what: &'static str,
        need: usize,
        have: usize,
    },
    #[error("{what}: {len} bytes, expected {expected}")]
    BadLength {
        what: &'static str,
        len: usize,
        expected: &'static str,
    },
    #[error("header version {0}: this server reads versions 1 and 2")]
    BadVersion(u16),
    #[error("{field} is not NUL-padded text: {bytes:02x?}")]
    BadName { field: &'static str, bytes: Vec<u8> },
    #[error("body of {len} bytes: more than the {max} this server takes")]
    Oversized { len: u64, max: u64 },
    #[error("body CRC-64 {computed:#018x} differs from the header's {header:#018x}")]
    BadCrc { header: u64, computed: u64 },
    #[error("extended header: {0}")]
    BadExtendedHeader(String),
    #[error("message type {0:?} is not taken here (TRANSFORM and POSITION are)")]
    UnknownType(String),
    #[error("{what} holds a non-finite number: {values:?}")]
    NonFinite {
        what: &'static str,
        values: Vec<f32>,
    },
    #[error(
        "the rotation is not rigid: |RᵀR − I| reaches {deviation:.2e} (at most {tolerance:.0e}), \
         det R = {det:.6}"
    )]
    NotRigid {
        deviation: f64,
        det: f64,
        tolerance: f64,
    },
    #[error("the quaternion has length {norm:.6}, not within {tolerance:.0e} of 1")]
    NotUnit { norm: f64, tolerance: f64 },
    #[error("{field} {text:?} is longer than its {max} bytes")]
    TooLong {
        field: &'static str,
        text: String,
        max: usize,
    },
    #[error("POLYDATA {kind}: {why}")]
    BadCells { kind: &'static str, why: String },
    #[error("{what}: index {index} is past the {count} points")]
    BadIndex {
        what: &'static str,
        index: u32,
        count: usize,
    },
    #[error("string encoding {0} (MIBenum): this server reads US-ASCII (3) and UTF-8 (106)")]
    BadEncoding(u16),
    #[error("string is not valid UTF-8")]
    BadText,
    #[error("output buffer of {have} bytes, {need} needed")]
    BufferTooSmall { need: usize, have: usize },
}

impl Error {
    /// Whether the error leaves the stream without a trustworthy next message boundary
    /// (a header that is not a header): the connection must close. Every other refusal
    /// concerns one message whose body was read whole, and the stream goes on.
    pub fn breaks_framing(&self) -> bool {
        matches!(
            self,
            Error::BadVersion(_) | Error::BadName { .. } | Error::Oversized { .. }
        )
    }
}

pub type Result<T> = core::result::Result<T, Error>;
