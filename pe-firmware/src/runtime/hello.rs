//! The first exchange: before step 0 every board sends its image's [`CompilationId`] to each
//! neighbour it exchanges with (one [`FrameKind::Hello`] frame per linked face: step 0, one f64
//! value whose 8 bytes are the id) and reads one from each. A neighbour whose id differs is
//! [`FaultKind::CompilationMismatch`]: the boards run images of different compilations (a
//! board flashed from another compile, a set mixed by hand), whose schedules would agree
//! frame by frame and compute a wrong answer. Each board also sends its id to the host in
//! a [`PacketKind::Hello`] packet on the global network, so the host checks what every
//! board runs (a board with no neighbour too). Once per run, never on a step's path.

use link_proto::payload::HelloPayload;
use link_proto::{Face, FrameKind, FrameRepr, Links, PacketKind, Payload, Precision};

use super::{Fault, FaultKind, Runtime, WireReal};
use crate::image::{CompilationId, ElementRecord};

/// Which faces still owe a Hello (bit `face.index()`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Hello {
    to_send: u8,
    to_recv: u8,
    /// The host's Hello packet is still to be sent.
    to_host: bool,
}

impl Hello {
    /// The faces of board `board` that have a neighbour in a `machine` (boards per axis)
    /// on an axis the schedule exchanges over (`rounds` per axis, the same on every board):
    /// the links the step needs, so both ends agree on which faces say Hello.
    pub fn new(board: [u8; 3], machine: [u8; 3], rounds: [u8; 3]) -> Self {
        let mut faces = 0u8;
        for face in Face::ALL {
            let a = face.index() / 2;
            let linked = rounds[a] > 0
                && if face.sign() > 0 {
                    board[a].saturating_add(1) < machine[a]
                } else {
                    board[a] > 0
                };
            if linked {
                faces |= 1 << face.index();
            }
        }
        Hello {
            to_send: faces,
            to_recv: faces,
            to_host: true,
        }
    }

    pub fn is_done(&self) -> bool {
        self.to_send == 0 && self.to_recv == 0 && !self.to_host
    }

    /// The first face whose Hello has not arrived (for a timeout).
    pub fn missing(&self) -> Face {
        Face::ALL
            .into_iter()
            .find(|f| self.to_recv & (1 << f.index()) != 0)
            .unwrap_or(Face::PosX)
    }
}

impl<T: WireReal, E: ElementRecord<T>> Runtime<'_, T, E> {
    /// Sends and receives what Hellos the links allow; `Ok(true)` when every linked face
    /// has sent its own and delivered the neighbour's (which matched).
    pub(super) fn hello_poll(&mut self, links: &mut impl Links) -> Result<bool, Fault> {
        let id = self.header.compilation;
        for face in Face::ALL {
            let bit = 1u8 << face.index();
            if self.hello.to_send & bit == 0 {
                continue;
            }
            let repr = FrameRepr {
                kind: FrameKind::Hello,
                step: 0,
                payload: Payload::new(Precision::F64, &id.0)
                    .map_err(|error| self.fault(FaultKind::BadFrame { face, error }))?,
            };
            let len = repr.emit(self.st.tx).map_err(|_| {
                self.fault(FaultKind::SendFailed {
                    face,
                    error: link_proto::SendError::TooLong,
                })
            })?;
            if self.send_frame(links, face, len)? {
                self.hello.to_send &= !bit;
            }
        }
        if self.hello.to_host {
            let host = link_proto::packet::ADDR_HOST;
            let len = HelloPayload { compilation: id.0 }
                .emit(
                    self.st
                        .tx
                        .get_mut(link_proto::PACKET_HEADER_LEN..)
                        .unwrap_or_default(),
                )
                .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
            if self.send_global(links, host, PacketKind::Hello, len)? {
                self.hello.to_host = false;
            }
        }
        for face in Face::ALL {
            let bit = 1u8 << face.index();
            if self.hello.to_recv & bit == 0 {
                continue;
            }
            let len = match links.try_recv(face, self.st.rx) {
                Ok(Some(len)) => len,
                Ok(None) => continue,
                Err(error) => return Err(self.fault(FaultKind::LinkError { face, error })),
            };
            self.stats.frames_received[face.index()] += 1;
            let repr = FrameRepr::parse_bytes(&self.st.rx[..len.min(self.st.rx.len())])
                .map_err(|error| self.fault(FaultKind::BadFrame { face, error }))?;
            let theirs = match <[u8; 8]>::try_from(repr.payload.as_bytes()) {
                Ok(b) if repr.kind == FrameKind::Hello && repr.step == 0 => CompilationId(b),
                _ => {
                    return Err(self.fault(FaultKind::UnexpectedFrame {
                        face,
                        expected_step: 0,
                        step: repr.step,
                        expected_values: 1,
                        values: repr.payload.len() as u16,
                    }))
                }
            };
            if theirs != id {
                return Err(self.fault(FaultKind::CompilationMismatch {
                    face,
                    ours: id,
                    theirs,
                }));
            }
            self.hello.to_recv &= !bit;
        }
        Ok(self.hello.is_done())
    }
}
