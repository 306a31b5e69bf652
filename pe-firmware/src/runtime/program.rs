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
    /// The step: batch x; send ±x; batch y; receive ±x (and further x rounds); send ±y;
    /// batch z; receive ±y...; send ±z; inner batch; receive ±z...; update. External forces
    /// of owned nodes go in just before their first exchange. `rounds` per axis (at most
    /// [`ROUNDS_PER_AXIS_MAX`] are taken); graphics and contact come first when present.
    pub fn new(rounds: &[u8; 3], contact: bool, graphics: bool) -> Program {
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
        p.push(Op::Batch(0));
        for axis in 0..3u8 {
            let r = rounds[axis as usize].min(ROUNDS_PER_AXIS_MAX as u8);
            p.push(Op::External(axis));
            if r > 0 {
                p.push(Op::Send(axis, 0, 0));
                p.push(Op::Send(axis, 0, 1));
            }
            p.push(Op::Batch(axis + 1));
            for round in 0..r {
                if round > 0 {
                    p.push(Op::Send(axis, round, 0));
                    p.push(Op::Send(axis, round, 1));
                }
                // The −axis face first: the summation trees put the lower board on the left.
                p.push(Op::Recv(axis, round, 1));
                p.push(Op::Recv(axis, round, 0));
            }
        }
        p.push(Op::External(3));
        p.push(Op::Update);
        p
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
