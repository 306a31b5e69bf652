//! The global network's figures of a run, beside the seed's.

use pe_firmware::physics::vec3::norm;
use pe_firmware::runtime::GlobalStats;

use crate::results::SimOutput;

/// The global network's figures: a line for the console and the report's JSON.
pub struct GlobalSummary {
    pub text: String,
    pub json: serde_json::Value,
}

/// Global-network figures of a run beside the seed's (about 300 collision vectors per
/// step, 72 MB/s, and 18 MB/s of graphics for its 2000-element model). `complete`: the
/// graphics frames with every surface node received (the surface series' frames); the
/// others were started too close to the end of the run to finish (a frame's chunks are
/// spread over several steps). `entry_bytes`: one contact-node entry's bytes (the index and
/// three values of the run's precision).
pub fn global_summary(
    out: &SimOutput,
    sim_s: f64,
    complete: usize,
    entry_bytes: f64,
) -> Option<GlobalSummary> {
    let g: Vec<&GlobalStats> = out.boards.iter().map(|b| &b.global).collect();
    let packets: u64 = g.iter().map(|s| s.packets_sent).sum();
    if packets == 0 {
        return None;
    }
    let steps = out.steps.max(1) as f64;
    let vectors = g.iter().map(|s| s.node_vectors).sum::<u64>() as f64 / steps;
    let bytes = g.iter().map(|s| s.bytes_sent).sum::<u64>() as f64;
    let gbytes = g.iter().map(|s| s.graphics_bytes).sum::<u64>() as f64;
    let boxes = g.iter().map(|s| s.box_packets).sum::<u64>();
    let checks = g.iter().map(|s| s.checks).max().unwrap_or(0);
    let cand = g.iter().map(|s| s.candidates_max).max().unwrap_or(0);
    let (last, peak) = tool_force_figures(out);
    let incomplete = out.graphics.len().saturating_sub(complete);
    let text = format!(
        "global network: {packets} packets, {:.1} MB/s in all; contact: {vectors:.1} node vectors per step ({:.1} MB/s at this step rate; the seed: ~300 vectors, 72 MB/s), {boxes} bounding-box packets over {checks} checks, at most {cand} candidates on a board; graphics: {complete} complete frames (the surface series' frames){}, {:.2} MB/s (the seed: 18 MB/s); tool force at the end {:?} N, peak {:?} N",
        bytes / sim_s / 1e6,
        vectors * entry_bytes / (sim_s / steps) / 1e6,
        match incomplete {
            0 => String::new(),
            n => format!(" and {n} started too close to the end to complete"),
        },
        gbytes / sim_s / 1e6,
        last,
        peak
    );
    let json = serde_json::json!({
        "packets": packets,
        "bytes_per_s": bytes / sim_s,
        "contact_vectors_per_step": vectors,
        "contact_bytes_per_s": vectors * entry_bytes / (sim_s / steps),
        "seed_contact_vectors_per_step": 300,
        "seed_contact_bytes_per_s": 72e6,
        "box_packets": boxes,
        "checks": checks,
        "candidates_max": cand,
        "graphics_frames": complete,
        "graphics_frames_incomplete": incomplete,
        "graphics_bytes_per_s": gbytes / sim_s,
        "seed_graphics_bytes_per_s": 18e6,
        "tool_force_final_n": last,
        "tool_force_peak_n": peak,
    });
    Some(GlobalSummary { text, json })
}

/// Each tool's force at the end and its peak magnitude over the run (N).
fn tool_force_figures(out: &SimOutput) -> (Vec<[f64; 3]>, Vec<f64>) {
    let peak: Vec<f64> = (0..out.tools)
        .map(|t| {
            out.tool_force
                .iter()
                .skip(t)
                .step_by(out.tools.max(1))
                .map(|f| norm(*f))
                .fold(0.0, f64::max)
        })
        .collect();
    let last: Vec<[f64; 3]> = if out.tools > 0 {
        out.tool_force[out.tool_force.len().saturating_sub(out.tools)..].to_vec()
    } else {
        vec![]
    };
    (last, peak)
}
