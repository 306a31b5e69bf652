//! Tool poses on a board: the host sends each pose ([`link_proto::tool_pose`]) to every
//! board whose contact tables hold the tool, [`POSE_DELAY_STEPS`] steps before the step it
//! takes effect at. The board keeps them in a fixed queue ([`PoseQueue`]) and, at each
//! step, before the contact evaluation, applies those whose step has come, in the order
//! they arrived: from then on the tool's capsule is [`Capsule::posed`] of where the scene
//! places it (the pose replaces the tool's path), as in the host's solver
//! (`host_tools::solver::Stepper`), so a replayed session computes the same bits.
//!
//! A pose for a step whose contact this board already evaluated, for a tool it does not
//! hold, or one more than the queue holds is a [`FaultKind::Pose`] naming the board, the
//! step, the tool and the pose's step: never applied at another step, never a panic.
//!
//! With the host's step gate on ([`RuntimeConfig::host_gate`](super::RuntimeConfig), for a
//! replay on boards that run faster than the host sends: [`link_proto::gate`]), a board
//! holding a tool starts no step's contact at or past the host's permit: it tells the host
//! the step it waits at once, and files the permits that come with the poses.

use link_proto::gate::StepMarkRepr;
use link_proto::tool_pose::{ToolPoseRepr, POSE_DELAY_STEPS};
use link_proto::{Control, Links, PacketKind, PACKET_HEADER_LEN};

use super::contact::TOOLS_MAX;
use super::{Fault, FaultKind, Runtime, WireReal};
use crate::image::{path_value, ElementRecord};
use crate::physics::contact::Capsule;
use crate::physics::pose::Pose;

/// Poses a board holds before their step: one per tool and step over the
/// [`POSE_DELAY_STEPS`] steps the host sends them ahead (the host sends one per tool and
/// step at most). 64 entries of 64 bytes.
pub const POSE_QUEUE_MAX: usize = POSE_DELAY_STEPS as usize * TOOLS_MAX;

/// Why a pose was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseProblem {
    /// Its step's contact was already evaluated on this board: it came later than
    /// [`POSE_DELAY_STEPS`] ahead allows.
    Late,
    /// The queue holds [`POSE_QUEUE_MAX`] poses not yet due.
    QueueFull,
    /// This board's contact tables hold `tools` tools.
    UnknownTool { tools: u8 },
}

impl core::fmt::Display for PoseProblem {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PoseProblem::Late => write!(
                f,
                "arrived after that step's contact (the host sends a pose {POSE_DELAY_STEPS} steps ahead)"
            ),
            PoseProblem::QueueFull => write!(
                f,
                "the queue of {POSE_QUEUE_MAX} pending poses is full (more than one pose per tool and step)"
            ),
            PoseProblem::UnknownTool { tools } => {
                write!(f, "this board's contact tables hold {tools} tool(s)")
            }
        }
    }
}

/// One pose not yet due: its step and tool.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Pending {
    step: u32,
    tool: u8,
    pose: Pose,
}

/// The poses a board holds: those not yet due, in arrival order, and each tool's pose now
/// (`None`: its path).
#[derive(Clone, Copy, Debug)]
pub struct PoseQueue {
    pending: [Pending; POSE_QUEUE_MAX],
    len: usize,
    current: [Option<Pose>; TOOLS_MAX],
    /// The first step whose poses are not applied yet.
    next_step: u64,
    /// The host's gate: the first step not permitted yet (without the gate, unused).
    permit: u64,
    /// The step whose wait the host was told of.
    reported: Option<u64>,
}

impl PoseQueue {
    pub(super) const fn new() -> PoseQueue {
        PoseQueue {
            pending: [Pending {
                step: 0,
                tool: 0,
                pose: Pose::IDENTITY,
            }; POSE_QUEUE_MAX],
            len: 0,
            current: [None; TOOLS_MAX],
            next_step: 0,
            permit: 0,
            reported: None,
        }
    }

    /// Files a host's permit: steps below `until` may run (a permit never lowers the gate).
    fn permit(&mut self, until: u32) {
        self.permit = self.permit.max(u64::from(until));
    }

    /// Files `p` (for a board holding `tools` tools); the problem if it is refused.
    fn push(&mut self, p: &ToolPoseRepr, tools: u8) -> Result<(), PoseProblem> {
        if p.tool >= tools {
            return Err(PoseProblem::UnknownTool { tools });
        }
        if u64::from(p.step) < self.next_step {
            return Err(PoseProblem::Late);
        }
        let slot = self
            .pending
            .get_mut(self.len)
            .ok_or(PoseProblem::QueueFull)?;
        *slot = Pending {
            step: p.step,
            tool: p.tool,
            pose: Pose { q: p.q, p_m: p.p_m },
        };
        self.len += 1;
        Ok(())
    }

    /// Applies the poses due at `step` (in arrival order: a later one for the same tool
    /// wins, as on the host) and keeps the others in order.
    fn apply(&mut self, step: u64) {
        let mut kept = 0;
        for k in 0..self.len.min(POSE_QUEUE_MAX) {
            let p = self.pending[k];
            if u64::from(p.step) <= step {
                if let Some(c) = self.current.get_mut(p.tool as usize) {
                    *c = Some(p.pose);
                }
            } else {
                self.pending[kept] = p;
                kept += 1;
            }
        }
        self.len = kept;
        self.next_step = self.next_step.max(step + 1);
    }

    /// Poses received and not yet due.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Tool `t`'s pose now (`None`: it follows its path).
    pub fn current(&self, t: usize) -> Option<Pose> {
        self.current.get(t).copied().flatten()
    }
}

impl<T: WireReal, E: ElementRecord<T>> Runtime<'_, T, E> {
    /// A pose from the host: filed until its step, or the fault naming it.
    pub(super) fn file_pose(&mut self, p: &ToolPoseRepr) -> Result<(), Fault> {
        let tools = self.header.counts.tools;
        self.contact.poses.push(p, tools).map_err(|problem| {
            self.fault(FaultKind::Pose {
                tool: p.tool,
                at_step: p.step,
                problem,
            })
        })
    }

    /// A permit from the host (`link_proto::gate`): steps below `until` may run (without
    /// the gate it changes nothing).
    pub(super) fn file_permit(&mut self, until: u32) {
        self.contact.poses.permit(until);
    }

    /// Whether this step's contact may start: always without the host's gate; with it,
    /// once the host permits the step. While it waits, the host is told the step once
    /// (`Ok(false)` also while the port is busy).
    pub(super) fn gate_open(&mut self, links: &mut impl Links) -> Result<bool, Fault> {
        if !self.waits_for_permit() {
            return Ok(true);
        }
        if self.contact.poses.reported == Some(self.step) {
            return Ok(false);
        }
        let step = u32::try_from(self.step).unwrap_or(u32::MAX);
        let len = StepMarkRepr { step }
            .emit(&mut self.st.tx[PACKET_HEADER_LEN..])
            .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
        let host = link_proto::packet::ADDR_HOST;
        let kind = PacketKind::Control(Control::StepDone);
        if self.send_global(links, host, kind, len)? {
            self.contact.poses.reported = Some(self.step);
        }
        Ok(false)
    }

    /// Whether this step's contact waits for the host's permit.
    pub(super) fn waits_for_permit(&self) -> bool {
        self.config.host_gate
            && self.header.counts.tools > 0
            && self.step >= self.contact.poses.permit
    }

    /// The poses due at this step, before its contact evaluation.
    pub(super) fn apply_poses(&mut self) {
        self.contact.poses.apply(self.step);
    }

    /// Each tool's capsule at this step: posed where a pose is set (the host solver's
    /// `Capsule::posed` of the scene's placement), else moved along its path to this
    /// step's time.
    pub(super) fn tool_capsules(&self) -> [Capsule; TOOLS_MAX] {
        let c = self.header.counts;
        let np = c.path_points as usize;
        let t = self.step as f64 * self.header.params.dt_s;
        let mut capsules = [Capsule {
            a: [0.0; 3],
            b: [0.0; 3],
            radius_m: 0.0,
        }; TOOLS_MAX];
        for (k, tool) in self.contact.tools.iter().enumerate().take(c.tools as usize) {
            capsules[k] = match self.contact.poses.current(k) {
                Some(pose) => tool.capsule.posed(&pose),
                None => {
                    tool.capsule
                        .translated(path_value(&self.st.path_points[..np], tool.path, t))
                }
            };
        }
        capsules
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(tool: u8, step: u32, dz: f64) -> ToolPoseRepr {
        ToolPoseRepr {
            tool,
            step,
            q: [1.0, 0.0, 0.0, 0.0],
            p_m: [0.0, 0.0, dz],
        }
    }

    #[test]
    fn poses_apply_at_their_step_in_arrival_order() {
        let mut q = PoseQueue::new();
        q.push(&pose(0, 3, -1e-3), 2).unwrap();
        q.push(&pose(1, 2, 5e-3), 2).unwrap();
        q.push(&pose(0, 3, -2e-3), 2).unwrap();
        q.apply(1);
        assert_eq!((q.current(0), q.current(1), q.pending()), (None, None, 3));
        q.apply(2);
        assert_eq!(q.current(1).map(|p| p.p_m[2]), Some(5e-3));
        assert_eq!((q.current(0), q.pending()), (None, 2));
        q.apply(3);
        // Two poses for tool 0 at step 3: the later one holds.
        assert_eq!(q.current(0).map(|p| p.p_m[2]), Some(-2e-3));
        assert_eq!(q.pending(), 0);
    }

    #[test]
    fn a_late_unknown_or_overflowing_pose_is_refused() {
        let mut q = PoseQueue::new();
        q.apply(4);
        assert_eq!(q.push(&pose(0, 4, 0.0), 1), Err(PoseProblem::Late));
        assert_eq!(
            q.push(&pose(1, 9, 0.0), 1),
            Err(PoseProblem::UnknownTool { tools: 1 })
        );
        for k in 0..POSE_QUEUE_MAX {
            q.push(&pose(0, 5 + k as u32, 0.0), 1).unwrap();
        }
        assert_eq!(q.push(&pose(0, 200, 0.0), 1), Err(PoseProblem::QueueFull));
        assert_eq!(q.pending(), POSE_QUEUE_MAX);
    }

    #[test]
    fn a_permit_only_raises_the_gate() {
        let mut q = PoseQueue::new();
        assert_eq!(
            q.permit, 0,
            "a gated board waits at step 0 for the first permit"
        );
        q.permit(32);
        q.permit(16);
        assert_eq!(
            q.permit, 32,
            "a late, lower permit does not close steps again"
        );
        q.permit(u32::MAX);
        assert_eq!(q.permit, u64::from(u32::MAX));
    }
}
