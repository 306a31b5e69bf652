//! Who drives which tool, and where each tool goes next. The first client to send a valid
//! pose for a tool drives it until it releases it or leaves; another client's pose for it
//! is refused, naming the driver. A pose the tool cannot reach in one step without a
//! capsule end outrunning the contact search's speed bound is reached at that bound over
//! several steps ([`crate::live::pose::step_toward`]), and the driver told so.

use std::time::{Duration, Instant};

use crate::live::engine::{Pose, ToolInfo};
use crate::live::hub::ClientId;
use crate::live::pose::{end_travel_m, step_toward};
use crate::live::EngineInfo;

/// The least time between two notices about one tool's clamped motion.
const NOTICE_EVERY: Duration = Duration::from_secs(1);

/// The tools of a session: drivers, applied poses and the poses they move toward.
#[derive(Clone, Debug)]
pub struct Tools {
    pub info: Vec<ToolInfo>,
    pub driver: Vec<Option<ClientId>>,
    /// The pose last given to the engine, per tool.
    pub applied: Vec<Pose>,
    target: Vec<Option<Target>>,
    last_notice: Vec<Option<Instant>>,
    pub poses_applied: u64,
    pub poses_clamped: u64,
    pub poses_refused: u64,
}

#[derive(Clone, Copy, Debug)]
struct Target {
    pose: Pose,
    /// When the pose was read, until its first step is given (latency).
    received: Option<Instant>,
    /// Whether the driver was told the motion is clamped.
    told: bool,
}

/// A pose to give the engine before the next step.
#[derive(Clone, Copy, Debug)]
pub struct Move {
    pub tool: usize,
    pub pose: Pose,
    /// When the client's pose this move starts was read (its first move only).
    pub received: Option<Instant>,
}

/// A notice for a tool's driver.
#[derive(Clone, Debug)]
pub struct Notice {
    pub client: ClientId,
    pub message: String,
}

impl Tools {
    pub fn new(info: &EngineInfo) -> Tools {
        let n = info.tools.len();
        Tools {
            info: info.tools.clone(),
            driver: vec![None; n],
            applied: vec![Pose::IDENTITY; n],
            target: vec![None; n],
            last_notice: vec![None; n],
            poses_applied: 0,
            poses_clamped: 0,
            poses_refused: 0,
        }
    }

    fn index(&self, name: &str) -> Result<usize, String> {
        self.info
            .iter()
            .position(|t| t.name == name)
            .ok_or_else(|| unknown_tool(name, self.info.iter().map(|t| t.name.as_str())))
    }

    /// Client `client` asks for `pose` on tool `name`: Ok(Some(tool)) when it now drives a
    /// tool it did not, Ok(None) when it already drove it, Err when refused (the reason).
    pub fn offer(
        &mut self,
        client: ClientId,
        name: &str,
        pose: Pose,
        received: Instant,
    ) -> Result<Option<usize>, String> {
        let tool = self.index(name).inspect_err(|_| self.poses_refused += 1)?;
        let newly = match self.driver[tool] {
            Some(d) if d != client => {
                self.poses_refused += 1;
                return Err(format!(
                    "tool {name:?} is driven by client {d}: it must release it (or leave) first"
                ));
            }
            Some(_) => None,
            None => {
                self.driver[tool] = Some(client);
                Some(tool)
            }
        };
        self.poses_applied += 1;
        self.target[tool] = Some(Target {
            pose,
            received: Some(received),
            told: false,
        });
        Ok(newly)
    }

    /// Client `client` stops driving `name`: Ok(tool) when it drove it.
    pub fn release(&mut self, client: ClientId, name: &str) -> Result<usize, String> {
        let tool = self.index(name)?;
        match self.driver[tool] {
            Some(d) if d == client => {
                self.driver[tool] = None;
                Ok(tool)
            }
            Some(d) => Err(format!("tool {name:?} is driven by client {d}, not by you")),
            None => Err(format!("tool {name:?} has no driver")),
        }
    }

    /// Client `client` left: the tools it drove (now free; they stay where they are).
    pub fn release_all(&mut self, client: ClientId) -> Vec<usize> {
        let mut freed = Vec::new();
        for (k, d) in self.driver.iter_mut().enumerate() {
            if *d == Some(client) {
                *d = None;
                freed.push(k);
            }
        }
        freed
    }

    /// The poses to give the engine before the next step, each tool's end moving at most
    /// `bound_m`; notices for drivers whose pose is reached over several steps.
    pub fn advance(&mut self, bound_m: f64, now: Instant) -> (Vec<Move>, Vec<Notice>) {
        let (mut moves, mut notices) = (Vec::new(), Vec::new());
        for tool in 0..self.info.len() {
            let Some(t) = self.target[tool].as_mut() else {
                continue;
            };
            let info = &self.info[tool];
            let from = self.applied[tool];
            let (pose, reached) = step_toward(info, &from, &t.pose, bound_m);
            if !reached && !t.told {
                t.told = true;
                self.poses_clamped += 1;
                let due = self.last_notice[tool].is_none_or(|l| now >= l + NOTICE_EVERY);
                if let (Some(client), true) = (self.driver[tool], due) {
                    self.last_notice[tool] = Some(now);
                    let travel = end_travel_m(info, &from, &t.pose);
                    notices.push(Notice {
                        client,
                        message: format!(
                            "tool {:?}: the pose moves a capsule end {:.3} mm, more than the {:.4} mm per step the contact search allows (its speed bound): the tool goes there at that bound, over about {} steps",
                            info.name,
                            travel * 1e3,
                            bound_m * 1e3,
                            (travel / bound_m).ceil()
                        ),
                    });
                }
            }
            moves.push(Move {
                tool,
                pose,
                received: t.received.take(),
            });
            self.applied[tool] = pose;
            if reached {
                self.target[tool] = None;
            }
        }
        (moves, notices)
    }
}

/// The refusal of an unknown tool name, naming the scene's tools.
pub fn unknown_tool<'a>(name: &str, known: impl IntoIterator<Item = &'a str>) -> String {
    let known: Vec<&str> = known.into_iter().collect();
    format!("unknown tool {name:?}: the scene's tools are {known:?}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::live::SurfaceInfo;

    fn info() -> EngineInfo {
        EngineInfo {
            scene: "t".into(),
            model: "m".into(),
            tools: vec![ToolInfo {
                name: "probe".into(),
                a_m: [0.0; 3],
                b_m: [0.0, 0.0, 0.1],
                radius_m: 0.001,
                trocar_m: None,
            }],
            surface: SurfaceInfo::default(),
            pose_delay_steps: 1,
            tool_travel_max_m: 1e-4,
        }
    }

    #[test]
    fn the_first_client_drives_and_the_second_is_told_who() {
        let mut t = Tools::new(&info());
        let now = Instant::now();
        let p = Pose::translation([0.0, 0.0, 1e-5]);
        assert_eq!(t.offer(1, "probe", p, now), Ok(Some(0)));
        assert_eq!(t.offer(1, "probe", p, now), Ok(None));
        let e = t.offer(2, "probe", p, now).unwrap_err();
        assert!(e.contains("driven by client 1"), "{e}");
        let e = t.offer(2, "scalpel", p, now).unwrap_err();
        assert!(e.contains("[\"probe\"]"), "{e}");
        assert!(t.release(2, "probe").is_err());
        assert_eq!(t.release_all(1), vec![0]);
        assert_eq!(t.offer(2, "probe", p, now), Ok(Some(0)));
        assert_eq!((t.poses_applied, t.poses_refused), (3, 2));
    }

    /// A 1 mm jump at 0.1 mm per step: ten moves, one notice, the latency's instant given
    /// with the first move only.
    #[test]
    fn a_far_pose_is_reached_over_several_steps_with_one_notice() {
        let mut t = Tools::new(&info());
        let now = Instant::now();
        t.offer(7, "probe", Pose::translation([1e-3, 0.0, 0.0]), now)
            .unwrap();
        let mut moves = Vec::new();
        let mut notices = Vec::new();
        for _ in 0..20 {
            let (m, n) = t.advance(1e-4, now);
            moves.extend(m);
            notices.extend(n);
        }
        assert!((10..=11).contains(&moves.len()), "{}", moves.len());
        assert!(moves[0].received.is_some() && moves[1].received.is_none());
        assert_eq!(notices.len(), 1);
        assert_eq!(notices[0].client, 7);
        assert!(
            notices[0].message.contains("1.000 mm"),
            "{}",
            notices[0].message
        );
        assert_eq!(t.applied[0], Pose::translation([1e-3, 0.0, 0.0]));
        assert_eq!(t.poses_clamped, 1);
    }
}
