//! The force of the tissue on each tool every step (`--tool-force FILE` of `pe solve` and
//! board-sim): `step,time_s,tool,fx_n,fy_n,fz_n`, one row per step and tool; `time_s` is the
//! time of the state the force was computed at (the step's start), `tool` the tool's index
//! in the scene.

use std::path::Path;

use anyhow::Result;

use crate::solver::RunOutput;

/// The header.
pub const TOOL_FORCE_HEADER: [&str; 6] = ["step", "time_s", "tool", "fx_n", "fy_n", "fz_n"];

/// Writes `tool_force` (per step, `tools` forces, N) with each step's time from
/// `time_of_step`.
pub fn write_tool_force_csv(
    path: &Path,
    tool_force: &[[f64; 3]],
    tools: usize,
    time_of_step: impl Fn(u64) -> f64,
) -> Result<()> {
    let rows = tool_force.iter().enumerate().map(|(k, f)| {
        let (step, t) = (k / tools.max(1), k % tools.max(1));
        [
            step.to_string(),
            format!("{:e}", time_of_step(step as u64)),
            t.to_string(),
            format!("{:e}", f[0]),
            format!("{:e}", f[1]),
            format!("{:e}", f[2]),
        ]
    });
    super::write_csv(path, &TOOL_FORCE_HEADER, rows)
}

/// The tool forces of a `pe solve` run, each step at the time the solver gave it (the
/// step changes `dt_history` records included).
pub fn write_run_tool_force(path: &Path, out: &RunOutput) -> Result<()> {
    let r = &out.report;
    let tools = r.contact.as_ref().map_or(0, |c| c.tools.len());
    write_tool_force_csv(path, &out.tool_force, tools, |step| {
        match r.dt_history.iter().rev().find(|c| c.step <= step) {
            Some(c) => c.time_s + (step - c.step) as f64 * c.dt_s,
            None => step as f64 * r.dt_s,
        }
    })
}
