//! Faults: what went wrong on a board, where (link, element, node) and at which step.
//! Every failure of the runtime is one of these; nothing panics.

use link_proto::machine::across;
use link_proto::Face;

use crate::image::{CompilationId, ImageError};
use crate::physics::PhysicsError;

/// What went wrong, where.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FaultKind {
    /// No frame arrived on `face` within the link timeout.
    LinkTimeout {
        face: Face,
    },
    /// The link reported an error (damaged frame, I/O).
    LinkError {
        face: Face,
        error: link_proto::RecvError,
    },
    /// A frame could not be sent.
    SendFailed {
        face: Face,
        error: link_proto::SendError,
    },
    /// A frame arrived intact but is not the one the schedule expects.
    UnexpectedFrame {
        face: Face,
        expected_step: u32,
        step: u32,
        expected_values: u16,
        values: u16,
    },
    /// The frame failed to parse (CRC, length).
    BadFrame {
        face: Face,
        error: link_proto::Error,
    },
    Physics(PhysicsError),
    /// The schedule image was refused.
    Image(ImageError),
    /// The global port refused a packet to `dst`.
    GlobalSendFailed {
        dst: u8,
        error: link_proto::SendError,
    },
    /// The global port reported an error.
    GlobalError {
        error: link_proto::RecvError,
    },
    /// A global packet failed to parse (CRC, length, payload layout).
    BadPacket {
        error: link_proto::Error,
    },
    /// A global packet arrived intact but is not one the schedule expects now.
    UnexpectedPacket {
        src: u8,
        kind: u8,
        step: u32,
    },
    /// No packet from board `src` (global address) within the link timeout.
    GlobalTimeout {
        src: u8,
    },
    /// The neighbour across `face` runs an image of another compilation (its Hello before
    /// step 0 carried `theirs`): the image set is mixed.
    CompilationMismatch {
        face: Face,
        ours: CompilationId,
        theirs: CompilationId,
    },
    /// The link on `face` goes to another board or connector than the schedule's: the
    /// neighbour's Hello says it is board `theirs_board` (of a `theirs_machine` machine)
    /// and sent on its face `theirs_face`, where the schedule expects the board across
    /// `face` sending on the opposite face. Cables are crossed or plugged into the wrong
    /// connector.
    Miscabled {
        face: Face,
        theirs_board: [u8; 3],
        theirs_machine: [u8; 3],
        theirs_face: Face,
    },
    /// The contact search needs more room than this firmware has.
    ContactCapacity {
        what: &'static str,
        needed: u32,
        max: u32,
    },
    /// The host's pose of `tool` for step `at_step` was refused ([`super::pose`]).
    Pose {
        tool: u8,
        at_step: u32,
        problem: super::pose::PoseProblem,
    },
}

/// A fault with its board and step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fault {
    pub board: [u8; 3],
    pub step: u64,
    pub kind: FaultKind,
}

impl core::fmt::Display for Fault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let [x, y, z] = self.board;
        write!(f, "board ({x},{y},{z}) step {}: ", self.step)?;
        match self.kind {
            FaultKind::LinkTimeout { face } => write!(f, "link {face:?}: no frame within the timeout"),
            FaultKind::LinkError { face, error } => write!(f, "link {face:?}: {error}"),
            FaultKind::SendFailed { face, error } => write!(f, "link {face:?}: send failed: {error:?}"),
            FaultKind::UnexpectedFrame { face, expected_step, step, expected_values, values } => write!(
                f,
                "link {face:?}: frame for step {step} with {values} values, expected step {expected_step} with {expected_values}"
            ),
            FaultKind::BadFrame { face, error } => write!(f, "link {face:?}: bad frame: {error}"),
            FaultKind::Physics(e) => write!(f, "{e}"),
            FaultKind::Image(e) => write!(f, "schedule image: {e}"),
            FaultKind::GlobalSendFailed { dst, error } => {
                write!(f, "global network: send to {dst} failed: {error:?}")
            }
            FaultKind::GlobalError { error } => write!(f, "global network: {error:?}"),
            FaultKind::BadPacket { error } => write!(f, "global network: bad packet: {error}"),
            FaultKind::UnexpectedPacket { src, kind, step } => write!(
                f,
                "global network: unexpected packet of kind {kind:#04x} for step {step} from {src}"
            ),
            FaultKind::GlobalTimeout { src } => {
                write!(f, "global network: nothing from board {src} within the timeout")
            }
            FaultKind::CompilationMismatch { face, ours, theirs } => {
                write!(f, "link {face:?}")?;
                if let Some([nx, ny, nz]) = across(self.board.map(usize::from), face) {
                    write!(f, " (to board ({nx},{ny},{nz}))")?;
                }
                write!(
                    f,
                    ": the neighbour's image is from compilation {theirs}, this board's from {ours}: the image set is mixed; recompile or load the whole set"
                )
            }
            FaultKind::Miscabled { face, theirs_board: [tx, ty, tz], theirs_machine: [mx, my, mz], theirs_face } => {
                write!(
                    f,
                    "link {face:?}: the cable goes to board ({tx},{ty},{tz})'s {theirs_face:?} connector ({mx}x{my}x{mz} machine)"
                )?;
                match across(self.board.map(usize::from), face) {
                    Some([nx, ny, nz]) => write!(
                        f,
                        "; the schedule expects board ({nx},{ny},{nz})'s {:?}: cables crossed",
                        face.opposite()
                    ),
                    None => write!(f, "; the schedule has no neighbour there"),
                }
            }
            FaultKind::ContactCapacity { what, needed, max } => write!(
                f,
                "contact: {needed} {what} needed, this firmware holds {max}"
            ),
            FaultKind::Pose { tool, at_step, problem } => {
                write!(f, "tool {tool}: the host's pose for step {at_step} refused: {problem}")
            }
        }
    }
}
