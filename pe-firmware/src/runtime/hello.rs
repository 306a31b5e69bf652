//! The first exchange: before step 0 every board sends a [`HelloFrame`] to each neighbour it
//! exchanges with (one [`FrameKind::Hello`] frame per linked face, step 0) and reads one
//! from each. The frame carries the image's [`CompilationId`] and where the sender is: its
//! position, the machine's size and the face it sent on. A neighbour whose id differs is
//! [`FaultKind::CompilationMismatch`]: the boards run images of different compilations (a
//! board flashed from another compile, a set mixed by hand), whose schedules would agree
//! frame by frame and compute a wrong answer. A neighbour that is not the board the
//! schedule expects across that face, or that sent on another face than the opposite one,
//! is [`FaultKind::Miscabled`]: a cable goes to the wrong board or connector (frames carry
//! no address, so crossed cables would otherwise mix two boards' forces silently). Each
//! board also sends its id to the host in a [`PacketKind::Hello`] packet on the global
//! network, so the host checks what every board runs (a board with no neighbour too). Once
//! per run, never on a step's path.

use link_proto::payload::HelloPayload;
use link_proto::{Face, FrameKind, FrameRepr, Links, PacketKind, Payload, Precision};

use super::{Fault, FaultKind, Runtime, WireReal};
use crate::image::{CompilationId, ElementRecord};

/// What a Hello frame says: two 8-byte values (the frame's precision is f64), the
/// compilation id, then `[x, y, z, X, Y, Z, face, 0]`: the sender's position, the machine's
/// size (boards per axis) and the index ([`Face::index`]) of the face it was sent on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HelloFrame {
    pub compilation: CompilationId,
    pub board: [u8; 3],
    pub machine: [u8; 3],
    pub face: Face,
}

impl HelloFrame {
    /// Bytes of the payload.
    pub const LEN: usize = 16;

    pub fn to_bytes(&self) -> [u8; Self::LEN] {
        let mut b = [0u8; Self::LEN];
        b[..8].copy_from_slice(&self.compilation.0);
        let [x, y, z] = self.board;
        let [mx, my, mz] = self.machine;
        b[8..].copy_from_slice(&[x, y, z, mx, my, mz, self.face.index() as u8, 0]);
        b
    }

    /// `None` unless `b` is exactly a Hello payload with a valid face.
    pub fn parse(b: &[u8]) -> Option<Self> {
        let b: &[u8; Self::LEN] = b.try_into().ok()?;
        let mut id = [0u8; 8];
        id.copy_from_slice(&b[..8]);
        if b[15] != 0 {
            return None;
        }
        Some(HelloFrame {
            compilation: CompilationId(id),
            board: [b[8], b[9], b[10]],
            machine: [b[11], b[12], b[13]],
            face: Face::from_index(b[14] as usize)?,
        })
    }
}

/// Which faces still owe a Hello (bit `face.index()`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct Hello {
    to_send: u8,
    to_recv: u8,
    /// The host's Hello packet is still to be sent.
    to_host: bool,
}

impl Hello {
    /// The faces the schedule exchanges over ([`crate::image::linked_faces`]): both ends
    /// of every link agree on which faces say Hello.
    pub fn new(board: [u8; 3], machine: [u8; 3], rounds: [u8; 3]) -> Self {
        let linked = crate::image::linked_faces(board, machine, rounds);
        let mut faces = 0u8;
        for face in Face::ALL {
            if linked[face.index()] {
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
            let hello = HelloFrame {
                compilation: id,
                board: self.header.board,
                machine: self.header.machine,
                face,
            }
            .to_bytes();
            let repr = FrameRepr {
                kind: FrameKind::Hello,
                step: 0,
                payload: Payload::new(Precision::F64, &hello)
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
            let theirs = match HelloFrame::parse(repr.payload.as_bytes()) {
                Some(h) if repr.kind == FrameKind::Hello && repr.step == 0 => h,
                _ => {
                    return Err(self.fault(FaultKind::UnexpectedFrame {
                        face,
                        expected_step: 0,
                        step: repr.step,
                        expected_values: (HelloFrame::LEN / 8) as u16,
                        values: repr.payload.len() as u16,
                    }))
                }
            };
            if theirs.compilation != id {
                return Err(self.fault(FaultKind::CompilationMismatch {
                    face,
                    ours: id,
                    theirs: theirs.compilation,
                }));
            }
            let expected = link_proto::machine::across(self.header.board.map(usize::from), face);
            if expected != Some(theirs.board.map(usize::from))
                || theirs.machine != self.header.machine
                || theirs.face != face.opposite()
            {
                return Err(self.fault(FaultKind::Miscabled {
                    face,
                    theirs_board: theirs.board,
                    theirs_machine: theirs.machine,
                    theirs_face: theirs.face,
                }));
            }
            self.hello.to_recv &= !bit;
        }
        Ok(self.hello.is_done())
    }
}
