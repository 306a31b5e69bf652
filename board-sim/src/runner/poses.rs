//! The host's tool poses to the boards (`board-sim run --replay FILE`): each pose goes as a
//! ToolPose packet ([`link_proto::tool_pose`]) from the host to every board whose contact
//! tables hold its tool, [`POSE_DELAY_STEPS`] steps ahead of the step it takes effect at.
//!
//! The emulated boards run as fast as the host's cores allow, not paced by a wall clock as
//! a live array is; so the host paces them instead: a board starts step `s` only once the
//! host has sent every pose for the steps before [`PoseFeed::gate`], which it raises to the
//! slowest board's step + [`POSE_DELAY_STEPS`] after sending the poses below it. Every pose
//! is then in its boards' inboxes before their step (the run is deterministic, whatever
//! the threads' timing), and a board holds at most [`POSE_DELAY_STEPS`] steps of poses,
//! within its queue (`pe_firmware::runtime::pose::POSE_QUEUE_MAX`; the host sends one
//! pose per tool and step: of several for one tool at one step, the last, the one the
//! host's solver keeps).

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{anyhow, bail, Result};
use host_tools::solver::PoseSchedule;
use link_proto::packet::ADDR_HOST;
use link_proto::recovery::global::emit_data;
use link_proto::tool_pose::{ToolPoseRepr, POSE_DELAY_STEPS};
use link_proto::{PacketKind, PacketRepr};
use pe_firmware::physics::pose::Pose;

use crate::clock::{Retire, SweepClock};
use crate::fabric::{Doorbell, GlobalNet};

/// What the workers and the pose sender share: each board's steps done and the gate.
#[derive(Clone)]
pub(crate) struct PoseFeed {
    /// Boards start no step at or past this (u64::MAX: no poses, no gate).
    pub gate: Arc<AtomicU64>,
    /// Steps done per board (index order).
    pub board_steps: Arc<Vec<AtomicU64>>,
}

impl PoseFeed {
    pub(crate) fn new(boards: usize, poses: bool) -> PoseFeed {
        PoseFeed {
            gate: Arc::new(AtomicU64::new(if poses { 0 } else { u64::MAX })),
            board_steps: Arc::new((0..boards).map(|_| AtomicU64::new(0)).collect()),
        }
    }

    /// Whether board at `step` (at the start of it) may go on.
    pub(crate) fn open(&self, step: u64) -> bool {
        step < self.gate.load(Ordering::Acquire)
    }

    /// Board `b` has done `steps` steps.
    pub(crate) fn done(&self, b: usize, steps: u64) {
        if let Some(s) = self.board_steps.get(b) {
            s.store(steps, Ordering::Release);
        }
    }

    fn slowest(&self) -> u64 {
        self.board_steps
            .iter()
            .map(|s| s.load(Ordering::Acquire))
            .min()
            .unwrap_or(0)
    }
}

/// The schedule as sent: one pose per (step, tool), the last given, in step order.
pub(crate) fn one_per_tool_and_step(poses: &PoseSchedule) -> Vec<(u64, usize, Pose)> {
    let last: HashMap<(u64, usize), usize> = poses
        .poses
        .iter()
        .enumerate()
        .map(|(k, &(s, t, _))| ((s, t), k))
        .collect();
    (poses.poses.iter().enumerate())
        .filter(|(k, (s, t, _))| last.get(&(*s, *t)) == Some(k))
        .map(|(_, p)| *p)
        .collect()
}

/// The host's pose sender: the schedule, the boards holding each tool, the network.
pub(crate) struct PoseSender {
    pub poses: Vec<(u64, usize, Pose)>,
    /// Global addresses of the boards whose contact tables hold tool `t`: `holders[t]`.
    pub holders: Vec<Vec<u8>>,
    pub net: Arc<GlobalNet>,
    /// The boards' global ports take envelopes (global recovery): the host numbers its
    /// flow to each board.
    pub envelopes: bool,
    pub feed: PoseFeed,
    pub bells: Vec<Arc<Doorbell>>,
    pub stop: Arc<AtomicBool>,
    pub steps: u64,
    /// The sender's clock: with simulated time, a participant (boards held at the gate
    /// wait for the sender, so time stands still while it has poses to send).
    pub clock: Arc<SweepClock>,
}

/// Checks a schedule against the boards (every tool held somewhere, every pose a unit
/// rotation the boards accept, its step and tool on the wire) before any board runs:
/// `holders[t]`, the boards holding tool `t`.
pub(crate) fn check_schedule(poses: &[(u64, usize, Pose)], holders: &[Vec<u8>]) -> Result<()> {
    for &(step, tool, pose) in poses {
        if holders.get(tool).is_none_or(|h| h.is_empty()) {
            bail!("pose for tool {tool} at step {step}: no board's contact tables hold that tool");
        }
        let repr = pose_repr(step, tool, &pose)?;
        let mut buf = [0u8; ToolPoseRepr::LEN];
        repr.emit(&mut buf)?;
        ToolPoseRepr::parse_bytes(&buf)
            .map_err(|e| anyhow!("pose for tool {tool} at step {step}: {e}"))?;
    }
    Ok(())
}

impl PoseSender {
    /// [`check_schedule`] of this sender's poses.
    pub(crate) fn check(&self) -> Result<()> {
        check_schedule(&self.poses, &self.holders)
    }

    /// The sender's thread, when there are poses to send ([`PoseSender::run`]); without
    /// any, none runs, and its clock holds no simulated time back.
    pub(crate) fn start(self) -> Option<std::thread::JoinHandle<Result<u64>>> {
        if self.poses.is_empty() {
            self.clock.retire();
            return None;
        }
        Some(std::thread::spawn(move || self.run()))
    }

    /// Sends the poses as the boards go, raising the gate; returns the packets sent.
    pub(crate) fn run(self) -> Result<u64> {
        let mut seq = vec![0u16; link_proto::BOARD_COUNT];
        let (mut next, mut sent, mut idle) = (0, 0u64, 0u32);
        let mut buf = vec![0u8; link_proto::PACKET_LEN_MAX + 16];
        let _retire = Retire(&self.clock);
        loop {
            if self.stop.load(Ordering::Relaxed) {
                return Ok(sent);
            }
            // What the sender sends or raises is activity (the boards' doorbells count it).
            let sweep = self.clock.tick();
            let slowest = self.feed.slowest();
            let target = slowest.saturating_add(POSE_DELAY_STEPS).min(self.steps);
            while let Some(&(step, tool, pose)) = self.poses.get(next) {
                if step >= target {
                    break;
                }
                sent += self.send_to_holders(step, tool, &pose, &mut seq, &mut buf)?;
                next += 1;
            }
            if target > self.feed.gate.load(Ordering::Acquire) {
                self.feed.gate.store(target, Ordering::Release);
                self.bells.iter().for_each(|b| b.ring());
                idle = 0;
            }
            if slowest >= self.steps {
                return Ok(sent);
            }
            if self.clock.swept(sweep, false) {
                idle = 0;
            }
            idle += 1;
            if idle < 64 {
                std::thread::yield_now();
            } else {
                std::thread::sleep(Duration::from_micros(50));
            }
        }
    }

    /// `tool`'s pose for `step` to every board holding the tool (`seq`: the host's flow
    /// numbers, per board address; `buf`: scratch of `PACKET_LEN_MAX + 16`); the packets
    /// sent.
    pub(crate) fn send_to_holders(
        &self,
        step: u64,
        tool: usize,
        pose: &Pose,
        seq: &mut [u16],
        buf: &mut [u8],
    ) -> Result<u64> {
        let mut sent = 0;
        for &dst in self.holders.get(tool).map_or(&[][..], |h| h) {
            self.send(dst, &pose_repr(step, tool, pose)?, seq, buf)?;
            sent += 1;
        }
        Ok(sent)
    }

    /// One ToolPose packet from the host to board `dst` (in its envelope with recovery).
    fn send(&self, dst: u8, p: &ToolPoseRepr, seq: &mut [u16], buf: &mut [u8]) -> Result<()> {
        let mut payload = [0u8; ToolPoseRepr::LEN];
        p.emit(&mut payload)?;
        let s = seq
            .get_mut(dst as usize)
            .ok_or_else(|| anyhow!("board {dst}"))?;
        let packet = PacketRepr {
            dst,
            src: ADDR_HOST,
            msg_id: *s,
            kind: PacketKind::ToolPose,
            payload: &payload,
        };
        let (head, tail) = buf.split_at_mut(link_proto::PACKET_LEN_MAX / 2);
        let n = packet.emit(head)?;
        let bytes = if self.envelopes {
            let m = emit_data(&head[..n], *s, tail)
                .ok_or_else(|| anyhow!("tool pose to board {dst}: envelope"))?;
            &tail[..m]
        } else {
            &head[..n]
        };
        *s = s.wrapping_add(1);
        self.net
            .deliver(dst, ADDR_HOST, bytes)
            .map_err(|e| anyhow!("tool pose for step {} to board {dst}: {e:?}", p.step))
    }
}

/// The payload of `tool`'s pose at `step`.
pub(crate) fn pose_repr(step: u64, tool: usize, pose: &Pose) -> Result<ToolPoseRepr> {
    Ok(ToolPoseRepr {
        tool: u8::try_from(tool).map_err(|_| anyhow!("tool {tool}: past the wire's u8"))?,
        step: u32::try_from(step)
            .map_err(|_| anyhow!("pose at step {step}: past the wire's u32"))?,
        q: pose.q,
        p_m: pose.p_m,
    })
}
