//! Link recovery's totals over a run's boards.

use link_proto::recovery::{FaceRecovery, GlobalRecovery};

use crate::results::{LinkRecovery, SimOutput};

/// Link recovery's totals over the boards (None without recovery): retransmitted frames
/// and bytes, nacks, and the bytes recovery added against the frames' own.
pub fn recovery_summary(out: &SimOutput) -> Option<serde_json::Value> {
    let rs: Vec<&LinkRecovery> = out
        .boards
        .iter()
        .filter_map(|b| b.recovery.as_ref())
        .collect();
    if rs.is_empty() {
        return None;
    }
    let sum = |g: fn(&FaceRecovery) -> u64| rs.iter().map(|r| r.faces_sum(g)).sum::<u64>();
    let frame_bytes: u64 = out
        .boards
        .iter()
        .map(|b| b.bytes_sent.iter().sum::<u64>())
        .sum();
    let overhead: u64 = rs.iter().map(|r| r.overhead_bytes()).sum();
    let gs: Vec<&GlobalRecovery> = rs.iter().filter_map(|r| r.global.as_ref()).collect();
    let global_overhead: u64 = gs.iter().map(|g| g.overhead_bytes()).sum();
    Some(serde_json::json!({
        "global": global_totals(out, &gs),
        "faces_overhead_bytes": overhead - global_overhead,
        "retransmitted_frames": sum(|f| f.retransmitted_frames),
        "retransmitted_bytes": sum(|f| f.retransmitted_bytes),
        "nacks_sent": sum(|f| f.nacks_sent),
        "acks_sent": sum(|f| f.acks_sent),
        "statuses_sent": sum(|f| f.statuses_sent),
        "control_bytes": sum(|f| f.control_bytes),
        "damaged_received": sum(|f| f.damaged),
        "gaps": sum(|f| f.gaps),
        "duplicates": sum(|f| f.duplicates),
        "overhead_bytes": overhead + out.sink_recovery.unwrap_or_default().control_bytes,
        "overhead_fraction_of_frame_bytes": (overhead - global_overhead) as f64 / frame_bytes.max(1) as f64,
    }))
}

/// Global recovery's totals over the boards' ports `gs` and the sinks (None without it).
fn global_totals(out: &SimOutput, gs: &[&GlobalRecovery]) -> Option<serde_json::Value> {
    if gs.is_empty() {
        return None;
    }
    let sink = out.sink_recovery.unwrap_or_default();
    let packet_bytes: u64 = out.boards.iter().map(|b| b.global.bytes_sent).sum();
    let global_overhead: u64 = gs.iter().map(|g| g.overhead_bytes()).sum();
    let gsum = |f: fn(&GlobalRecovery) -> u64| gs.iter().map(|g| f(g)).sum::<u64>();
    Some(serde_json::json!({
        "data_packets": gsum(|g| g.data_packets),
        "retransmitted_packets": gsum(|g| g.retransmitted_packets),
        "retransmitted_bytes": gsum(|g| g.retransmitted_bytes),
        "timeouts": gsum(|g| g.timeouts),
        "nacks_sent": gsum(|g| g.nacks_sent) + sink.nacks_sent,
        "nacks_received": gsum(|g| g.nacks_received),
        "acks_sent": gsum(|g| g.acks_sent) + sink.acks_sent,
        "control_bytes": gsum(|g| g.control_bytes) + sink.control_bytes,
        "damaged_received": gsum(|g| g.damaged) + sink.damaged,
        "gaps": gsum(|g| g.gaps) + sink.gaps,
        "duplicates": gsum(|g| g.duplicates) + sink.duplicates,
        "sinks": sink,
        "overhead_bytes": global_overhead + sink.control_bytes,
        "overhead_fraction_of_packet_bytes":
            (global_overhead + sink.control_bytes) as f64 / packet_bytes.max(1) as f64,
    }))
}
