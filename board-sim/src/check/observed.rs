//! What a board (or a sink) reported when a run stopped, and where in its step.

use link_proto::Face;
use pe_firmware::runtime::{Fault, FaultKind, Op};

use crate::fabric::address_name;

/// What a board reported when the run stopped: a fault, or (`waiting`) the link it was
/// still waiting on.
#[derive(Clone, Debug, PartialEq)]
pub struct Observed {
    /// For a waiting board: the timeout its wait would have become.
    pub fault: Fault,
    /// Where in the step ([`phase`]), comparable across boards.
    pub phase: u32,
    /// The board was still waiting, not yet timed out, when the run was stopped.
    pub waiting: bool,
    /// Observed by a sink (the graphics engine or the host, by address), not a board: the
    /// fault's board is then the board whose packets arrived damaged or are missing.
    pub sink: Option<u8>,
}

impl Observed {
    /// A wait (a timeout, or a board stopped while waiting): a consequence of a fault
    /// elsewhere when there is one.
    pub fn is_wait(&self) -> bool {
        self.waiting
            || matches!(
                self.fault.kind,
                FaultKind::LinkTimeout { .. } | FaultKind::GlobalTimeout { .. }
            )
    }

    /// The link the observation names, if any.
    pub fn face(&self) -> Option<Face> {
        use FaultKind as K;
        match self.fault.kind {
            K::LinkTimeout { face }
            | K::LinkError { face, .. }
            | K::SendFailed { face, .. }
            | K::UnexpectedFrame { face, .. }
            | K::BadFrame { face, .. } => Some(face),
            _ => None,
        }
    }

    /// Ordering across boards and workers: by step; in a step faults before waits (a
    /// timeout is a consequence of a fault elsewhere when there is one), then by phase and
    /// board.
    pub(crate) fn key(&self) -> (u64, bool, u32, [u8; 3]) {
        (
            self.fault.step,
            self.is_wait(),
            self.phase,
            self.fault.board,
        )
    }
}

impl std::fmt::Display for Observed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.fault.board;
        if let Some(sink) = self.sink {
            let what = match self.fault.kind {
                FaultKind::BadPacket { error } => format!("a damaged packet ({error})"),
                _ => "fewer packets than the board sent: some were lost".to_string(),
            };
            return write!(
                f,
                "{} received from board ({x},{y},{z}) (step {}) {what}",
                address_name(sink),
                self.fault.step
            );
        }
        if !self.waiting {
            return write!(f, "{}", self.fault);
        }
        match self.face() {
            Some(face) => write!(
                f,
                "board ({x},{y},{z}) step {}: link {face:?}: still waiting when the run stopped",
                self.fault.step
            ),
            None => write!(f, "{} (still waiting when the run stopped)", self.fault),
        }
    }
}

/// Where in a step an operation lies, in the order every board's step program runs them
/// (graphics, contact, batch 0, then per axis: external, send round 0, batch, and per round
/// its sends and receives; last the update): comparable across boards whose programs
/// differ in length.
pub fn phase(op: Option<Op>) -> u32 {
    let axis = |a: u8, k: u32| 3 + 100 * a as u32 + k;
    match op {
        Some(Op::Graphics) => 0,
        Some(Op::Contact) => 1,
        Some(Op::Batch(0)) => 2,
        Some(Op::External(a)) => axis(a, 0),
        Some(Op::Batch(b)) => axis(b - 1, 2),
        Some(Op::Send(a, 0, _)) => axis(a, 1),
        Some(Op::Send(a, r, _)) => axis(a, 3 + 3 * r as u32),
        Some(Op::Recv(a, r, f)) => axis(a, 4 + 3 * r as u32 + (1 - f.min(1)) as u32),
        Some(Op::Update) => axis(3, 1),
        None => u32::MAX,
    }
}
