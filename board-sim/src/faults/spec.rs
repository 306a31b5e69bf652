//! What to inject: `--faults seed=S,drop=P,corrupt=P,delay=MS,stall=X.Y.Z@STEP,on=all`.

use anyhow::{anyhow, bail, Result};
use link_proto::Machine;

/// Which traffic drop and corrupt apply to (`on=all|links|global`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FaultScope {
    /// Point-to-point frames and global packets (the default).
    #[default]
    All,
    /// Point-to-point frames only.
    Links,
    /// Global packets only.
    Global,
}

/// What to inject (`--faults seed=S,drop=P,corrupt=P,delay=MS,stall=X.Y.Z@STEP,on=all`).
///
/// `drop` and `corrupt` apply to every point-to-point frame and every global packet a board
/// sends (`on=links` or `on=global` for one kind only; global packets draw from their own
/// random stream, so adding them leaves the frames' faults of a seed as they were); `delay`
/// to the point-to-point frames; a stalled board sends nothing more, frames or packets.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FaultSpec {
    pub seed: u64,
    /// Probability that a frame is lost.
    pub drop: f64,
    /// Probability that one bit of a frame is flipped.
    pub corrupt: f64,
    /// Every frame is held this long before delivery (ms; the link holds it, the sender
    /// goes on).
    pub delay_ms: u64,
    /// This board stops sending at this step.
    pub stall: Option<([usize; 3], u64)>,
    /// Which traffic `drop` and `corrupt` apply to.
    pub on: FaultScope,
}

impl FaultSpec {
    pub fn parse(s: &str) -> Result<FaultSpec> {
        let mut f = FaultSpec {
            seed: 1,
            ..Default::default()
        };
        for part in s.split(',').filter(|p| !p.is_empty()) {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| anyhow!("--faults: {part:?} is not key=value"))?;
            f.set(k, v)?;
        }
        if !(0.0..=1.0).contains(&f.drop) || !(0.0..=1.0).contains(&f.corrupt) {
            bail!("--faults: probabilities must lie in [0, 1]");
        }
        Ok(f)
    }

    /// One `key=value` of the spec.
    fn set(&mut self, k: &str, v: &str) -> Result<()> {
        let num = |v: &str| {
            v.parse::<f64>()
                .map_err(|_| anyhow!("--faults {k}: {v:?} is not a number"))
        };
        match k {
            "seed" => self.seed = v.parse().map_err(|_| anyhow!("--faults seed: {v:?}"))?,
            "drop" => self.drop = num(v)?,
            "corrupt" => self.corrupt = num(v)?,
            "delay" => {
                self.delay_ms = v
                    .parse()
                    .map_err(|_| anyhow!("--faults delay: {v:?} (ms)"))?
            }
            "on" => {
                self.on = match v {
                    "all" => FaultScope::All,
                    "links" => FaultScope::Links,
                    "global" => FaultScope::Global,
                    _ => bail!("--faults on: {v:?} (all, links, global)"),
                }
            }
            "stall" => {
                let (b, st) = v
                    .split_once('@')
                    .ok_or_else(|| anyhow!("--faults stall=X.Y.Z@STEP"))?;
                let c: Vec<usize> = b.split(['.', ':']).filter_map(|x| x.parse().ok()).collect();
                let step = st
                    .parse()
                    .map_err(|_| anyhow!("--faults stall step: {st:?}"))?;
                if c.len() != 3 {
                    bail!("--faults stall=X.Y.Z@STEP: board {b:?}");
                }
                self.stall = Some(([c[0], c[1], c[2]], step));
            }
            _ => bail!("--faults: unknown key {k:?} (seed, drop, corrupt, delay, stall, on)"),
        }
        Ok(())
    }

    /// Refuses a spec that names a board `machine` does not have (before the run).
    pub fn check(&self, machine: Machine) -> Result<()> {
        if let Some((b, step)) = self.stall {
            if !machine.contains(b) {
                let d = machine.dims();
                bail!(
                    "--faults stall={}.{}.{}@{step}: no board ({},{},{}) on this {}x{}x{} machine (boards 0..{} x 0..{} x 0..{})",
                    b[0], b[1], b[2], b[0], b[1], b[2], d[0], d[1], d[2],
                    d[0], d[1], d[2]
                );
            }
        }
        Ok(())
    }
}
