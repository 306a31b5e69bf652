//! Link recovery: frames on the faces and packets on the global network travel in an
//! envelope that numbers them, so that a receiver can acknowledge them and ask again for
//! one lost or damaged.
//!
//! Rooms, from the bottom:
//! - [`envelope`]: what both share, once: the header length [`HEADER_LEN`], the bytes an
//!   envelope adds [`OVERHEAD`] (its home is [`crate::limits`], below the frames' buffer
//!   sizes), [`enveloped_len`], the CRC rule, [`WINDOW_MAX`] and the arithmetic of the
//!   u16 sequence numbers;
//! - [`stats`]: what recovery cost, [`FaceRecovery`] and [`GlobalRecovery`] (serialisable
//!   with the crate's `serde` feature);
//! - [`face`]: face recovery, [`face::Reliable`] over the point-to-point links (go-back-N
//!   per face and direction, nacks on a gap or a timeout);
//! - [`global`]: global recovery, [`global::GlobalReliable`] over the global network
//!   (go-back-N per flow, retransmission on a nack or a timeout); [`global::flow`] is
//!   the envelope on the wire and the receiving end of one flow, for a sink.
//!
//! Both take time through [`crate::Clock`] and storage from the caller; no allocation, no
//! panics.
//!
//! Lengths: a frame of `n` values is [`crate::frame::frame_len`]`(n, precision)` bytes,
//! `enveloped_len(frame_len(n, precision))` with face recovery; a packet is
//! [`crate::packet::packet_len`] of its payload, and again [`enveloped_len`] of that with
//! global recovery (see [`crate::limits`] for every wire length).

pub mod envelope;
pub mod face;
pub mod global;
pub mod stats;

pub use envelope::{enveloped_len, HEADER_LEN, OVERHEAD, WINDOW_MAX};
pub use stats::{FaceRecovery, GlobalRecovery};
