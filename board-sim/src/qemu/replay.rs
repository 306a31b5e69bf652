//! `board-sim qemu DIR --replay FILE`: a recorded session on the emulated array, bit for
//! bit as `board-sim run DIR --replay FILE` and `pe solve --replay FILE` compute it.
//!
//! The emulated boards run as fast as QEMU goes, not paced by a wall clock, so the host
//! holds them with its step gate ([`link_proto::gate`]): every board's ELF gets the run
//! option [`blob::RUN_HOST_GATE`], and a board holding a tool then waits at each step's
//! contact until the host permits it. The host ([`feed`]) waits until every such board
//! waits at the permit, sends the poses of the next [`POSE_DELAY_STEPS`] steps (one per
//! tool and step, as board-sim's host does) to the boards holding their tools, then the
//! next permit on the same port, so the poses arrive first. Each board holds at most one
//! window of poses, within its queue. After the last pose the permit opens to the end.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::Duration;

use anyhow::{anyhow, Context, Result};
use host_tools::firmware::{patch_run_options, ImageBoard};
use link_proto::gate::StepMarkRepr;
use link_proto::packet::ADDR_HOST;
use link_proto::tool_pose::{ToolPoseRepr, POSE_DELAY_STEPS};
use link_proto::{Control, PacketKind, PacketRepr};
use pe_firmware::image::blob;
use pe_firmware::physics::pose::Pose;

use super::relay::GlobalSwitch;
use crate::runner::{check_schedule, pose_repr};

/// The steps each gated board said it waits at (by global address).
#[derive(Default)]
pub(crate) struct GateWaits(Mutex<BTreeMap<u8, u32>>);

impl GateWaits {
    /// Board `src` waits at `step` (a `Control::StepDone` packet).
    pub fn report(&self, src: u8, payload: &[u8]) -> Result<(), link_proto::Error> {
        let mark = StepMarkRepr::parse_bytes(payload)?;
        if let Ok(mut w) = self.0.lock() {
            let s = w.entry(src).or_insert(0);
            *s = (*s).max(mark.step);
        }
        Ok(())
    }

    /// Whether every board of `boards` waits at `step` or later.
    fn all_at(&self, boards: &[u8], step: u32) -> bool {
        self.0
            .lock()
            .is_ok_and(|w| boards.iter().all(|b| w.get(b).is_some_and(|&s| s >= step)))
    }
}

/// What the host replays: the poses (one per tool and step, in step order), the boards
/// holding each tool, and the boards it gates (every board holding a tool).
pub(crate) struct Replay {
    pub poses: Vec<(u64, usize, Pose)>,
    pub holders: Vec<Vec<u8>>,
    pub gated: Vec<u8>,
}

impl Replay {
    pub fn new(poses: Vec<(u64, usize, Pose)>, holders: Vec<Vec<u8>>) -> Result<Replay> {
        check_schedule(&poses, &holders)?;
        let mut gated: Vec<u8> = holders.iter().flatten().copied().collect();
        gated.sort_unstable();
        gated.dedup();
        Ok(Replay {
            poses,
            holders,
            gated,
        })
    }
}

/// Copies of the boards' ELFs with the host's step gate on (`NAME.gated.elf` beside each
/// in `images`); the boards then name the copies.
pub(crate) fn gated_elfs(boards: &mut [ImageBoard], images: &Path) -> Result<()> {
    for b in boards {
        let from = images.join(&b.elf);
        let elf = std::fs::read(&from).with_context(|| format!("reading {}", from.display()))?;
        let gated = patch_run_options(&elf, blob::RUN_HOST_GATE)
            .with_context(|| format!("{}", from.display()))?;
        let name = format!("{}.gated.elf", b.elf.trim_end_matches(".elf"));
        let to = images.join(&name);
        host_tools::output::file::write_atomic(&to, gated)?;
        b.elf = name;
    }
    Ok(())
}

/// The host's side of the gate until the last pose is sent (or `stop`): returns the pose
/// packets sent.
pub(crate) fn feed(
    replay: &Replay,
    switch: &GlobalSwitch,
    waits: &GateWaits,
    stop: &AtomicBool,
) -> Result<u64> {
    let mut msg_id = 0u16;
    let (mut permit, mut next, mut sent) = (0u32, 0usize, 0u64);
    let mut send = |dst: u8, kind: PacketKind, payload: &[u8]| -> Result<()> {
        let mut buf = [0u8; link_proto::PACKET_LEN_MAX];
        let n = PacketRepr {
            dst,
            src: ADDR_HOST,
            msg_id,
            kind,
            payload,
        }
        .emit(&mut buf)?;
        msg_id = msg_id.wrapping_add(1);
        switch.forward(dst, &buf[..n]);
        Ok(())
    };
    loop {
        while !waits.all_at(&replay.gated, permit) {
            if stop.load(Ordering::Relaxed) {
                return Ok(sent);
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        let end = u64::from(permit) + POSE_DELAY_STEPS;
        while let Some(&(step, tool, pose)) = replay.poses.get(next).filter(|p| p.0 < end) {
            let mut payload = [0u8; ToolPoseRepr::LEN];
            pose_repr(step, tool, &pose)?.emit(&mut payload)?;
            for &dst in &replay.holders[tool] {
                send(dst, PacketKind::ToolPose, &payload)?;
                sent += 1;
            }
            next += 1;
        }
        // After the last pose, the boards run to the end.
        let until = if next < replay.poses.len() {
            u32::try_from(end).map_err(|_| anyhow!("step {end}: past the wire's u32"))?
        } else {
            u32::MAX
        };
        let mut payload = [0u8; StepMarkRepr::LEN];
        StepMarkRepr { step: until }.emit(&mut payload)?;
        for &dst in &replay.gated {
            send(dst, PacketKind::Control(Control::Start), &payload)?;
        }
        if until == u32::MAX {
            return Ok(sent);
        }
        permit = until;
    }
}
