//! What a session reports at its end (`pe live` prints it).

use std::fmt;

use serde::Serialize;

use super::clients::ClientSummary;
use crate::live::protocol::LatencyMs;

#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    pub scene: String,
    pub model: String,
    pub steps: u64,
    pub simulated_s: f64,
    pub wall_s: f64,
    /// Simulated over wall time, over the whole session.
    pub real_time_factor: f64,
    pub lag_max_s: f64,
    pub slips: u64,
    pub slipped_s: f64,
    /// Force messages (one per tool per simulated millisecond) and surface frames sent.
    pub force_ms: u64,
    pub surface_frames: u64,
    /// Client poses taken, of those reached over several steps (clamped), and refused
    /// (unknown tool, another client's tool); malformed messages answered with an error.
    pub poses_applied: u64,
    pub poses_clamped: u64,
    pub poses_refused: u64,
    pub bad_messages: u64,
    /// Poses given to the engine (and recorded): every step of a clamped motion is one.
    pub poses_given: u64,
    pub latency_ms: LatencyMs,
    pub clients: Vec<ClientSummary>,
    /// Why the session ended early (a step that failed), if it did.
    pub error: Option<String>,
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = self;
        writeln!(
            f,
            "{}: {} steps, {:.3} s simulated in {:.3} s wall: real-time factor {:.3}; lag max {:.1} ms, {} slips ({:.3} s slipped)",
            s.scene, s.steps, s.simulated_s, s.wall_s, s.real_time_factor, 1e3 * s.lag_max_s, s.slips, s.slipped_s
        )?;
        writeln!(f, "  model: {}", s.model)?;
        writeln!(
            f,
            "  poses: {} applied ({} reached over several steps), {} refused, {} malformed messages; {} poses given to the engine",
            s.poses_applied, s.poses_clamped, s.poses_refused, s.bad_messages, s.poses_given
        )?;
        let l = s.latency_ms;
        writeln!(
            f,
            "  pose-to-force latency over {} poses: p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms",
            l.samples, l.p50, l.p99, l.max
        )?;
        writeln!(
            f,
            "  sent: {} ms of tool forces, {} surface frames ({:.1} per s of wall time); {} client(s)",
            s.force_ms,
            s.surface_frames,
            s.surface_frames as f64 / s.wall_s.max(1e-9),
            s.clients.len()
        )?;
        for c in &s.clients {
            writeln!(
                f,
                "    client {} ({:?}, {}): {} surface frames queued, {} dropped{}",
                c.client,
                c.transport,
                c.peer,
                c.surface_frames,
                c.surface_frames_dropped,
                c.left
                    .as_ref()
                    .map(|r| format!("; left: {r}"))
                    .unwrap_or_default()
            )?;
        }
        if let Some(e) = &s.error {
            writeln!(f, "  ended by an error: {e}")?;
        }
        Ok(())
    }
}
