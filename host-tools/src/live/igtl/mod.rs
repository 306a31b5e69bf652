//! OpenIGTLink (the protocol of 3D Slicer's OpenIGTLinkIF, PLUS and tracked instruments):
//! a trainer's tracker or Slicer drives the scene's tools with TRANSFORM messages and sees
//! the tool forces (POINT) and the tissue's surface (POLYDATA) while the session runs.
//!
//! - the codec, one module per wire structure in the style of smoltcp's wire modules (a
//!   zero-copy view with `new_checked`, a `Repr` with `parse`/`emit`): [`crc64`],
//!   [`header`], [`body`] (version 2's extended header and metadata), [`transform`],
//!   [`position`], [`point`], [`string`], [`polydata`], and [`message`] (a whole message);
//!   every layout is cited in its module from the OpenIGTLink specification
//!   (`Documents/Protocol/*.md` in <https://github.com/openigtlink/OpenIGTLink>), its C
//!   library (`Source/igtlutil/`) and pyigtl (<https://github.com/lassoan/pyigtl>,
//!   `pyigtl/messages.py`);
//! - the transport ([`server`]): a TCP server speaking to the session only through
//!   [`super::hub`]: [`inbound`] turns messages into [`super::hub::Inbound`], [`outbound`]
//!   turns [`super::hub::Outbound`] into messages.
//!
//! # Panics
//! No code here panics on input: every view's `new_checked`, every `Repr::parse` and
//! `emit`, and the transport refuse bad bytes with an [`Error`] naming what was wrong. The
//! views' accessors may panic on a view made with `new_unchecked` over a buffer too short
//! for it (each module says when); the transport makes none over received bytes.

pub mod body;
pub mod crc64;
pub mod error;
pub mod header;
pub mod inbound;
pub mod message;
pub mod outbound;
pub mod point;
pub mod polydata;
pub mod position;
pub mod server;
pub mod string;
pub mod transform;

pub use error::Error;
pub use server::{address_beside, start, IgtlServer, Scene, DEFAULT_PORT};
