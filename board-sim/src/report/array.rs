//! The report (JSON) of `board-sim qemu`: a finished array's figures, or a failed one's
//! account.

use std::path::Path;

use anyhow::Result;

use super::json::write_json;
use crate::qemu::{ArrayFault, ArrayOutput};

/// A finished array run: wall time per step, the final state's largest component, packets,
/// and every board's exit and bytes.
pub fn write_array_report(p: &Path, out: &ArrayOutput, max_u: f64, per_step: f64) -> Result<()> {
    let j = serde_json::json!({
        "finished": true,
        "machine": out.machine,
        "steps": out.steps,
        "wall_s": out.wall_s,
        "wall_s_per_step": per_step,
        "max_displacement_component_m": max_u,
        "packets_between_boards": out.packets_between_boards,
        "packets_to_sinks": out.packets_to_sinks,
        "graphics_frames": out.graphics_frames,
        "boards": out.boards,
    });
    write_json(p, &j)
}

/// A failed array run: the boards' account, line by line, and every board's exit.
pub fn write_array_fault_report(p: &Path, f: &ArrayFault) -> Result<()> {
    let j = serde_json::json!({
        "finished": false,
        "faults": f.lines,
        "boards": f.boards,
    });
    write_json(p, &j)
}
