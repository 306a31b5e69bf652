//! The report of `board-sim run`: a finished run's figures, or a stopped run's cause.

use std::path::Path;

use anyhow::Result;
use host_tools::compile::Manifest;

use super::global::GlobalSummary;
use super::json::write_json;
use super::recovery::recovery_summary;
use crate::check::{Observed, SimFault};
use crate::results::SimOutput;
use crate::timing::StepTiming;

/// Figures of a run the report states besides the run's own output.
pub struct RunFacts {
    pub elements: usize,
    pub sim_s: f64,
    pub max_displacement: f64,
    /// Frames in the ParaView series (`--vtk`).
    pub paraview_frames: Option<usize>,
}

/// The run report (JSON): as `pe solve`'s, plus per-link traffic, waiting and the link model.
pub fn write_report(
    p: &Path,
    manifest: &Manifest,
    out: &SimOutput,
    facts: &RunFacts,
    modelled: &StepTiming,
    global: Option<&GlobalSummary>,
) -> Result<()> {
    let RunFacts {
        elements,
        sim_s,
        max_displacement,
        paraview_frames,
    } = *facts;
    let links: Vec<serde_json::Value> = out
        .boards
        .iter()
        .map(|b| serde_json::json!({ "board": b.board, "frames_sent": b.frames_sent, "bytes_sent": b.bytes_sent, "wait_s": b.wait_s, "recovery": b.recovery }))
        .collect();
    let rep = serde_json::json!({
        "scene": manifest.scene,
        "machine": manifest.machine,
        "precision": manifest.precision.name(),
        "integration": manifest.integration.name(),
        "steps": out.steps,
        "dt_s": manifest.dt_s,
        "simulated_s": sim_s,
        "elements": elements,
        "nodes": out.displacements.len(),
        "wall_s": out.wall_s,
        "element_steps_per_s": elements as f64 * out.steps as f64 / out.wall_s,
        "real_time_factor": sim_s / out.wall_s,
        "kinetic_energy_final": out.kinetic_energy,
        "max_displacement": max_displacement,
        "prescribed_reaction_n": out.reaction_prescribed,
        "fixed_reaction_n": out.reaction_fixed,
        "wait_s_total": out.boards.iter().map(|b| b.wait_s).sum::<f64>(),
        "bytes_sent_total": out.boards.iter().map(|b| b.bytes_sent.iter().sum::<u64>()).sum::<u64>(),
        "boards": links,
        "link_model": modelled,
        "faults_injected": out.injected,
        "recovery": recovery_summary(out),
        "paraview_frames": paraview_frames,
        "global_network": global.map(|g| &g.json),
    });
    write_json(p, &rep)
}

/// The report of a run that stopped on a fault: the first cause, the observation that
/// detected it, the consequences (every other board's fault or wait) and what was injected.
pub fn write_fault_report(p: &Path, manifest: &Manifest, f: &SimFault) -> Result<()> {
    let obs = |o: &Observed| {
        serde_json::json!({
            "board": o.fault.board,
            "step": o.fault.step,
            "link": o.face().map(|f| format!("{f:?}")),
            "waiting": o.waiting,
            "text": o.to_string(),
        })
    };
    let rep = serde_json::json!({
        "scene": manifest.scene,
        "machine": manifest.machine,
        "stopped": true,
        "cause": f.cause,
        "detected": f.observed.get(f.cause.detected).map(obs),
        "consequences": f.consequences().map(obs).collect::<Vec<_>>(),
        "faults_injected": f.injected,
    });
    write_json(p, &rep)
}
