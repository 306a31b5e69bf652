//! The host's step gate: how a host holds the boards that take its tool poses to the
//! steps it has sent the poses for, when they run faster than it sends them (a recorded
//! session replayed on an emulated array, whose boards are not paced by a wall clock as a
//! live array is).
//!
//! A gated board (one whose firmware's run options switch the gate on, and whose contact
//! tables hold a tool) starts no step's contact at or past the host's last permit (there
//! is none before the first: it waits at step 0). At the first such step it sends the
//! host one [`Control::StepDone`](crate::Control) packet naming the step it waits at, and
//! goes on when a [`Control::Start`](crate::Control) packet permits steps past it. Both
//! carry one [`StepMarkRepr`]:
//!
//! | packet              | direction     | `step` means                          |
//! |---------------------|---------------|---------------------------------------|
//! | `Control::Start`    | host -> board | run the steps below `step`            |
//! | `Control::StepDone` | board -> host | waiting at `step`'s contact           |
//!
//! The host sends a window's poses before its permit on the same port, so they arrive
//! first: every pose is filed before its step (the run is deterministic), and a board
//! holds no more than one window of poses.
//!
//! Payload layout (little-endian, [`StepMarkRepr::LEN`] = 4 bytes): `step` (u32).
//!
//! # Panics
//!
//! Never: [`StepMark::new_checked`], [`StepMarkRepr::parse`] and [`StepMarkRepr::emit`]
//! check every length. The accessor of a view made with [`StepMark::new_unchecked`] panics
//! on a buffer shorter than [`StepMarkRepr::LEN`].

use crate::error::{Error, Result};

/// Field offsets (the layout above).
mod field {
    use core::ops::Range;
    pub const STEP: Range<usize> = 0..4;
}

/// A zero-copy view of a step mark payload.
#[derive(Debug, Clone)]
pub struct StepMark<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> StepMark<T> {
    /// Wraps a buffer without any check (see the module doc for when the accessor panics).
    pub const fn new_unchecked(buffer: T) -> StepMark<T> {
        StepMark { buffer }
    }

    /// Wraps a buffer holding exactly one payload: [`Error::TruncatedField`] if it ends
    /// inside `step`, [`Error::BadLength`] with trailing bytes.
    pub fn new_checked(buffer: T) -> Result<StepMark<T>> {
        let n = buffer.as_ref().len();
        if n < field::STEP.end {
            return Err(Error::TruncatedField("step"));
        }
        if n > field::STEP.end {
            return Err(Error::BadLength);
        }
        Ok(StepMark { buffer })
    }

    /// The step (see the module doc for what it means in each packet).
    pub fn step(&self) -> u32 {
        let b = &self.buffer.as_ref()[field::STEP];
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }
}

/// A step mark: a permit (host -> board) or the step a board waits at (board -> host).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepMarkRepr {
    /// The first step not permitted (a permit) or the step the board waits at.
    pub step: u32,
}

impl StepMarkRepr {
    /// Bytes of the payload.
    pub const LEN: usize = field::STEP.end;

    /// Reads a checked view.
    pub fn parse<T: AsRef<[u8]>>(v: &StepMark<T>) -> StepMarkRepr {
        StepMarkRepr { step: v.step() }
    }

    /// Checks and reads a payload.
    pub fn parse_bytes(b: &[u8]) -> Result<StepMarkRepr> {
        Ok(Self::parse(&StepMark::new_checked(b)?))
    }

    /// Writes the payload into `out`; the bytes written, or [`Error::BufferTooSmall`].
    pub fn emit(&self, out: &mut [u8]) -> Result<usize> {
        let dst = out.get_mut(field::STEP).ok_or(Error::BufferTooSmall)?;
        dst.copy_from_slice(&self.step.to_le_bytes());
        Ok(Self::LEN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mark_round_trips_and_wrong_lengths_are_named() {
        let mut buf = [0u8; 8];
        let n = StepMarkRepr { step: 0x0102_0304 }.emit(&mut buf).unwrap();
        assert_eq!(n, StepMarkRepr::LEN);
        assert_eq!(&buf[..4], &[4, 3, 2, 1], "little-endian");
        assert_eq!(
            StepMarkRepr::parse_bytes(&buf[..n]),
            Ok(StepMarkRepr { step: 0x0102_0304 })
        );
        assert_eq!(
            StepMarkRepr::parse_bytes(&buf[..3]),
            Err(Error::TruncatedField("step"))
        );
        assert_eq!(StepMarkRepr::parse_bytes(&buf[..5]), Err(Error::BadLength));
        assert_eq!(
            StepMarkRepr { step: 1 }.emit(&mut buf[..3]),
            Err(Error::BufferTooSmall)
        );
    }
}
