//! The force exchange over the point-to-point links: one frame per face and round, its
//! values in the order of the image's send list, combined on arrival by the receive list's
//! rule (the summation tree the compiler fixed).

use link_proto::{emit_values, Face, FrameKind, FrameRepr, Links};

use super::program::{face_of, ROUNDS_PER_AXIS_MAX};
use super::{Fault, FaultKind, Runtime, WireReal};
use crate::image::{Combine, ElementRecord, ExchangeList};

/// One list of the step program: (axis, round, face 0 = +axis / 1 = −axis).
pub(super) type ListId = (u8, u8, u8);

/// Most send/receive lists: two faces per round of every axis.
pub const LISTS_MAX: usize = 3 * ROUNDS_PER_AXIS_MAX * 2;

/// Ranges of one round's lists in the flat `sends` / `recvs` arrays, per face (+, −).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct RoundRanges {
    send: [(u32, u32); 2],
    recv: [(u32, u32); 2],
}

/// The exchange's tables and its scratch frame.
pub(super) struct Exchange<T> {
    /// The image's lists (axis, round, face), kept for the ranges below.
    pub lists: [ExchangeList; LISTS_MAX],
    rounds: [[RoundRanges; ROUNDS_PER_AXIS_MAX]; 3],
    _scalar: core::marker::PhantomData<T>,
}

impl<T: WireReal> Exchange<T> {
    pub fn new() -> Self {
        Exchange {
            lists: [ExchangeList::default(); LISTS_MAX],
            rounds: [[RoundRanges::default(); ROUNDS_PER_AXIS_MAX]; 3],
            _scalar: core::marker::PhantomData,
        }
    }

    /// The ranges of every list in the flat arrays, from the loaded lists (whose lengths
    /// [`crate::image::validate`] checked against the counts).
    pub fn index(&mut self, rounds: &[u8; 3]) {
        let (mut s, mut r, mut k) = (0u32, 0u32, 0usize);
        for (a, &n) in rounds.iter().enumerate() {
            for round in self.rounds[a].iter_mut().take(n as usize) {
                for f in 0..2 {
                    let l = self.lists[k];
                    round.send[f] = (s, s + l.sends as u32);
                    round.recv[f] = (r, r + l.recvs as u32);
                    s += l.sends as u32;
                    r += l.recvs as u32;
                    k += 1;
                }
            }
        }
    }
}

impl<T: WireReal, E: ElementRecord<T>> Runtime<'_, T, E> {
    /// Sends one face's frame of a round; `Ok(false)` if the link's queue is full.
    pub(super) fn send_face(
        &mut self,
        links: &mut impl Links,
        list: ListId,
    ) -> Result<bool, Fault> {
        let (axis, round, f) = (list.0 as usize, list.1 as usize, list.2 as usize);
        let (s, e) = self.exchange.rounds[axis][round].send[f];
        if s == e {
            return Ok(true);
        }
        let face = face_of(axis, f);
        let mut m = 0;
        for &k in &self.st.sends[s as usize..e as usize] {
            let v = self.st.force[k as usize];
            self.st.scratch[m..m + 3].copy_from_slice(&v);
            m += 3;
        }
        let len = emit_values(
            FrameKind::Forces,
            self.step as u32,
            T::wire(&self.st.scratch[..m]),
            self.st.tx,
        )
        .map_err(|_| {
            self.fault(FaultKind::SendFailed {
                face,
                error: link_proto::SendError::TooLong,
            })
        })?;
        self.send_frame(links, face, len)
    }

    /// Sends the frame of `len` bytes already in `tx` on `face` and counts it; `Ok(false)`
    /// if the link's queue is full (nothing sent: send it again later), a fault for any
    /// other refusal. The one path every frame a board sends goes out by.
    pub(super) fn send_frame(
        &mut self,
        links: &mut impl Links,
        face: Face,
        len: usize,
    ) -> Result<bool, Fault> {
        match links.try_send(face, &self.st.tx[..len.min(self.st.tx.len())]) {
            Ok(()) => {
                self.stats.frames_sent[face.index()] += 1;
                self.stats.bytes_sent[face.index()] += len as u64;
                Ok(true)
            }
            Err(link_proto::SendError::WouldBlock) => Ok(false),
            Err(error) => Err(self.fault(FaultKind::SendFailed { face, error })),
        }
    }

    /// Receives and combines one face's frame of a round; `Ok(false)` if it has not arrived.
    pub(super) fn recv_face(
        &mut self,
        links: &mut impl Links,
        list: ListId,
    ) -> Result<bool, Fault> {
        let (axis, round, f) = (list.0 as usize, list.1 as usize, list.2 as usize);
        let (s, e) = self.exchange.rounds[axis][round].recv[f];
        if s == e {
            return Ok(true);
        }
        let face = face_of(axis, f);
        let len = match links.try_recv(face, self.st.rx) {
            Ok(Some(len)) => len,
            Ok(None) => return Ok(false),
            Err(error) => return Err(self.fault(FaultKind::LinkError { face, error })),
        };
        self.stats.frames_received[face.index()] += 1;
        let repr = FrameRepr::parse_bytes(&self.st.rx[..len.min(self.st.rx.len())])
            .map_err(|error| self.fault(FaultKind::BadFrame { face, error }))?;
        let expected = 3 * (e - s) as usize;
        if repr.kind != FrameKind::Forces
            || repr.step != self.step as u32
            || repr.payload.len() != expected
            || repr.payload.precision() != T::wire(&[]).precision()
        {
            return Err(self.fault(FaultKind::UnexpectedFrame {
                face,
                expected_step: self.step as u32,
                step: repr.step,
                expected_values: expected as u16,
                values: repr.payload.len() as u16,
            }));
        }
        // The payload holds exactly three values per entry (checked above): walked once,
        // in order, instead of indexed value by value.
        let mut values = repr.payload.iter();
        for entry in &self.st.recvs[s as usize..e as usize] {
            // The loader checked every node index (`image::codec`): never skipped.
            let Some(force) = self.st.force.get_mut(entry.node as usize) else {
                continue;
            };
            let v = [(); 3].map(|()| T::from_f64(values.next().unwrap_or(f64::NAN)));
            match entry.combine {
                Combine::Before => {
                    for (f, v) in force.iter_mut().zip(v) {
                        *f = v + *f;
                    }
                }
                Combine::After => {
                    for (f, v) in force.iter_mut().zip(v) {
                        *f += v;
                    }
                }
                Combine::Replace => *force = v,
            }
        }
        Ok(true)
    }
}
