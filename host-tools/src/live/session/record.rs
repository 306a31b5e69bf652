//! The record of a live session (`pe live --record FILE`): JSON lines, a header, then
//! every pose as it was given to the engine (after the session's clamping), with the step
//! it took effect at. `pe solve --replay FILE` reads it back as these types and applies
//! the poses at the same steps: the same bits as the session.
//!
//! ```text
//! {"record":"pe-live","version":1,"scene":"builtin:medium","dt_s":2.1e-5,"tools":["probe"]}
//! {"step":0,"tool":"probe","orientation":[1.0,0.0,0.0,0.0],"position_m":[0.0,0.0,0.0]}
//! ```

use std::io::{BufRead, BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use super::tools::unknown_tool;
use crate::live::engine::Pose;
use crate::problem::Problem;
use crate::solver::PoseSchedule;

/// What the header's `record` says.
pub const RECORD_KIND: &str = "pe-live";
/// The record format's version.
pub const RECORD_VERSION: u32 = 1;

/// The first line.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordHeader {
    pub record: String,
    pub version: u32,
    /// The scene as `pe live` named it (a file's path as given, or `builtin:LEVEL`).
    pub scene: String,
    /// The time step at the start (s).
    pub dt_s: f64,
    pub tools: Vec<String>,
}

/// A pose as applied: from step `step` on, `tool` is at this rigid motion.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecordPose {
    pub step: u64,
    pub tool: String,
    pub orientation: [f64; 4],
    pub position_m: [f64; 3],
}

/// Writes a record as the session goes.
pub struct Recorder {
    path: PathBuf,
    out: BufWriter<std::fs::File>,
    tools: Vec<String>,
    pub poses: u64,
}

impl Recorder {
    pub fn create(path: &Path, header: &RecordHeader) -> Result<Recorder> {
        let file = std::fs::File::create(path)
            .with_context(|| format!("--record {}: creating it", path.display()))?;
        let mut r = Recorder {
            path: path.to_path_buf(),
            out: BufWriter::new(file),
            tools: header.tools.clone(),
            poses: 0,
        };
        r.line(header)?;
        Ok(r)
    }

    fn line<T: Serialize>(&mut self, v: &T) -> Result<()> {
        serde_json::to_writer(&mut self.out, v)?;
        self.out
            .write_all(b"\n")
            .with_context(|| format!("writing {}", self.path.display()))
    }

    /// `tool` is at `pose` from step `step` on.
    pub fn pose(&mut self, step: u64, tool: usize, pose: &Pose) -> Result<()> {
        let line = RecordPose {
            step,
            tool: self.tools.get(tool).cloned().unwrap_or_default(),
            orientation: pose.q,
            position_m: pose.p_m,
        };
        self.poses += 1;
        self.line(&line)
    }

    pub fn flush(&mut self) -> Result<()> {
        self.out
            .flush()
            .with_context(|| format!("writing {}", self.path.display()))
    }
}

/// The poses of the record `path`, to replay on `problem` (the scene `scene`, as `pe`
/// names it). Refused before any step: another scene or time step, an unknown tool, a
/// malformed line (each named by its line).
pub fn replay_schedule(path: &Path, scene: &str, problem: &Problem) -> Result<PoseSchedule> {
    let tools: Vec<&str> = problem
        .contact
        .as_ref()
        .map(|c| c.tool_names.iter().map(String::as_str).collect())
        .unwrap_or_default();
    replay_schedule_for(path, scene, problem.time_step.dt_s, &tools)
}

/// [`replay_schedule`] for a run of the scene `scene` stepping at `dt` with the tools
/// `tools` (a compiled directory's: its manifest and `mesh.json`).
pub fn replay_schedule_for(
    path: &Path,
    scene: &str,
    dt: f64,
    tools: &[&str],
) -> Result<PoseSchedule> {
    let name = path.display();
    let file = std::fs::File::open(path).with_context(|| format!("--replay {name}"))?;
    let mut lines = std::io::BufReader::new(file).lines();
    let first = lines
        .next()
        .transpose()
        .with_context(|| format!("reading {name}"))?
        .with_context(|| format!("{name}: empty, not a pe live record"))?;
    let header: RecordHeader = serde_json::from_str(&first)
        .with_context(|| format!("{name} line 1: not a pe live record header"))?;
    if header.record != RECORD_KIND || header.version != RECORD_VERSION {
        bail!(
            "{name} line 1: record {:?} version {}, expected {RECORD_KIND:?} version {RECORD_VERSION}",
            header.record,
            header.version
        );
    }
    if !same_scene(&header.scene, scene) {
        bail!(
            "{name}: recorded on scene {:?}, this is {scene:?}",
            header.scene
        );
    }
    if header.dt_s.to_bits() != dt.to_bits() {
        bail!(
            "{name}: recorded at dt = {:e} s, this scene steps at {dt:e} s (another scene, or changed settings)",
            header.dt_s
        );
    }
    if header.tools != tools {
        bail!(
            "{name}: recorded with the tools {:?}, this scene has {tools:?}",
            header.tools
        );
    }
    let mut poses = PoseSchedule::default();
    for (k, line) in lines.enumerate() {
        let at = k + 2;
        let line = line.with_context(|| format!("reading {name}"))?;
        if line.trim().is_empty() {
            continue;
        }
        let p: RecordPose = serde_json::from_str(&line)
            .with_context(|| format!("{name} line {at}: not a recorded pose"))?;
        let tool = tools.iter().position(|t| *t == p.tool).with_context(|| {
            format!(
                "{name} line {at}: {}",
                unknown_tool(&p.tool, tools.iter().copied())
            )
        })?;
        if let Some(&(last, _, _)) = poses.poses.last() {
            if p.step < last {
                bail!("{name} line {at}: step {} comes after step {last}", p.step);
            }
        }
        let pose = Pose {
            q: p.orientation,
            p_m: p.position_m,
        };
        poses.poses.push((p.step, tool, pose));
    }
    Ok(poses)
}

/// Whether two scene names are the same scene: equal, or paths to the same file.
fn same_scene(a: &str, b: &str) -> bool {
    a == b
        || matches!(
            (std::fs::canonicalize(a), std::fs::canonicalize(b)),
            (Ok(x), Ok(y)) if x == y
        )
}
