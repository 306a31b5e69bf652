//! The step program: the fixed sequence of operations of one step, the seed's interleaved
//! schedule. The runtime walks it, and so does board-sim's link timing model, so the
//! schedule is written once.

use link_proto::Face;

/// Most exchange rounds per axis a runtime handles.
pub const ROUNDS_PER_AXIS_MAX: usize = 8;

/// One operation of a step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    /// Surface nodes to the graphics engine (on the steps of a graphics update).
    Graphics,
    /// Contact: bounding boxes (every check interval), node exchange with the partners,
    /// contact forces of owned nodes, tool forces to the host.
    Contact,
    /// Internal forces of element batch 0..=3 (x, y, z border, inner).
    Batch(u8),
    /// External forces of the owned nodes of stage 0..=3 (before the x/y/z exchange, before
    /// the update).
    External(u8),
    /// Send (axis, round, face 0 = +axis / 1 = −axis).
    Send(u8, u8, u8),
    /// Receive and combine (axis, round, face).
    Recv(u8, u8, u8),
    /// Central-difference update of every held node; leaves the nodal forces zero for the
    /// next step (the loader zeroes them for the first).
    Update,
}

/// Most operations in a step: graphics, contact, 4 batches, 4 external stages,
/// 3 axes × rounds × 2 faces × (send + receive), update.
pub const OPS_MAX: usize = 12 + 3 * ROUNDS_PER_AXIS_MAX * 4;

/// A step's operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Program {
    ops: [Op; OPS_MAX],
    len: usize,
}

impl Program {
    /// The step, each axis's rounds in two parts: its first rounds, then the last
    /// `late[a]` (the broadcasts of the totals reduced along x and y, after the z exchange;
    /// none along z). Of the first ones, round 0 waits for no other board (the nodes first
    /// exchanged along the axis), so it goes as soon as the axis's batch is done; round 1
    /// waits for the earlier axes (nodes already summed along them):
    ///
    /// batch x; send x0, x1; batch y; send y0; receive x0, x1 (and further x rounds); send
    /// y1; batch z; send z0; receive y0, y1...; send z1; inner batch; receive z0, z1...;
    /// the late rounds, y then x (send, receive); update.
    ///
    /// Each face's frames are received −axis first (the summation trees put the lower
    /// board on the left). External forces of owned nodes go in just before their first
    /// exchange. `rounds` per axis (at most [`ROUNDS_PER_AXIS_MAX`] are taken); graphics
    /// and contact come first when present.
    pub fn new(rounds: &[u8; 3], late: &[u8; 3], contact: bool, graphics: bool) -> Program {
        let mut p = Program {
            ops: [Op::Update; OPS_MAX],
            len: 0,
        };
        if graphics {
            p.push(Op::Graphics);
        }
        if contact {
            p.push(Op::Contact);
        }
        let total = |a: u8| rounds[a as usize].min(ROUNDS_PER_AXIS_MAX as u8);
        let early = |a: u8| total(a).saturating_sub(late[a as usize]);
        p.push(Op::Batch(0));
        for axis in 0..3u8 {
            p.push(Op::External(axis));
            if early(axis) > 0 {
                p.send(axis, 0);
            }
            if axis > 0 {
                p.finish(axis - 1, early(axis - 1));
            }
            if early(axis) > 1 {
                p.send(axis, 1);
            }
            p.push(Op::Batch(axis + 1));
        }
        p.finish(2, early(2));
        for axis in [1u8, 0] {
            p.round_trips(axis, early(axis)..total(axis));
        }
        p.push(Op::External(3));
        p.push(Op::Update);
        p
    }

    /// The receives of an axis's rounds 0 and 1, then its further first rounds (send,
    /// receive).
    fn finish(&mut self, axis: u8, early: u8) {
        for round in 0..early.min(2) {
            self.recv(axis, round);
        }
        self.round_trips(axis, 2..early);
    }

    /// Rounds sent and received back to back (each waits for the one before).
    fn round_trips(&mut self, axis: u8, rounds: core::ops::Range<u8>) {
        for round in rounds {
            self.send(axis, round);
            self.recv(axis, round);
        }
    }

    fn send(&mut self, axis: u8, round: u8) {
        self.push(Op::Send(axis, round, 0));
        self.push(Op::Send(axis, round, 1));
    }

    fn recv(&mut self, axis: u8, round: u8) {
        self.push(Op::Recv(axis, round, 1));
        self.push(Op::Recv(axis, round, 0));
    }

    fn push(&mut self, op: Op) {
        if let Some(slot) = self.ops.get_mut(self.len) {
            *slot = op;
            self.len += 1;
        }
    }

    /// Operation `pc`, if the step has one.
    pub fn get(&self, pc: usize) -> Option<Op> {
        self.ops[..self.len].get(pc).copied()
    }

    pub fn ops(&self) -> &[Op] {
        &self.ops[..self.len]
    }
}

/// The link of `axis` and face `f` (0 = +axis, 1 = −axis).
pub fn face_of(axis: usize, f: usize) -> Face {
    Face::from_index(2 * axis + f).unwrap_or(Face::PosX)
}
