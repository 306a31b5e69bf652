//! After the array ran: each board's account (its exit, its fault as its console and its
//! fault packet said, the bytes it sent), the failed run's lines ordered by step, and the
//! final state merged from every board's report.

use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::{bail, Result};
use link_proto::machine::across;
use link_proto::Face;

use super::output::{ArrayFault, BoardRun};
use super::relay::Network;
use super::start::Emulated;
use super::wiring::{address, name, parse_board, Connector};
use crate::fabric::address_name;

/// How each board's QEMU ended (boards still running at the end ended at `wall_s`).
pub(crate) fn account(boards: &[Emulated], net: &Network, wall_s: f64) -> Vec<BoardRun> {
    let faults = net
        .switch
        .faults
        .lock()
        .map(|f| f.clone())
        .unwrap_or_default();
    boards
        .iter()
        .map(|e| {
            let fault = e
                .console()
                .lines()
                .find_map(|l| l.split_once("pe-board: FAULT ").map(|(_, f)| f.to_string()))
                .or_else(|| {
                    faults
                        .iter()
                        .find(|(src, _)| *src == address(e.board))
                        .map(|(_, t)| t.clone())
                });
            let mut face_bytes_sent = [0; 6];
            for (f, sent) in face_bytes_sent.iter_mut().enumerate() {
                if let Some(s) = net.face_sent.get(&Connector {
                    board: e.board,
                    face: f,
                }) {
                    *sent = s.load(Ordering::Relaxed);
                }
            }
            BoardRun {
                board: e.board,
                status: e.exited.and_then(|x| x.0),
                killed_by_harness: e.killed.clone(),
                exit_s: e.exited.map_or(wall_s, |x| x.1),
                fault,
                face_bytes_sent,
                global_bytes_sent: net.global_sent[&e.board].load(Ordering::Relaxed),
            }
        })
        .collect()
}

/// The boards' account of a failed run (a board that faulted, died, was ended or exited
/// otherwise, or a damaged packet on the global network), or the runs when it finished.
pub(crate) fn failure(
    runs: Vec<BoardRun>,
    net: &Network,
    timeout: Duration,
) -> Result<Vec<BoardRun>> {
    let failed = runs
        .iter()
        .any(|r| r.status != Some(0) || r.killed_by_harness.is_some() || r.fault.is_some());
    let damaged = net
        .switch
        .damaged
        .lock()
        .map(|d| d.clone())
        .unwrap_or_default();
    if !failed && damaged.is_empty() {
        return Ok(runs);
    }
    let mut lines: Vec<String> = runs
        .iter()
        .filter_map(|r| {
            r.killed_by_harness
                .as_ref()
                .map(|w| format!("board {}: {w}", name(r.board)))
        })
        .collect();
    lines.extend(fault_lines(&runs, timeout));
    for r in &runs {
        if r.fault.is_none() && r.killed_by_harness.is_none() && r.status != Some(0) {
            lines.push(format!(
                "board {}: QEMU exited with {:?} without a fault report",
                name(r.board),
                r.status
            ));
        }
    }
    lines.extend(damaged.iter().map(|(src, e)| {
        format!(
            "global network: a damaged packet from {}: {e}",
            address_name(*src)
        )
    }));
    Err(ArrayFault {
        boards: runs,
        lines,
    }
    .into())
}

/// Every board's fault ordered by step (then exit), each wait on a link whose far board had
/// already gone saying so (the cause is that board, the wait its consequence).
fn fault_lines(runs: &[BoardRun], timeout: Duration) -> Vec<String> {
    let mut said: Vec<(u64, f64, String)> = runs
        .iter()
        .filter_map(|r| {
            let f = r.fault.as_ref()?;
            Some((fault_step(f).unwrap_or(u64::MAX), r.exit_s, f.clone()))
        })
        .collect();
    said.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let stopped = |c: [usize; 3]| runs.iter().find(|r| r.board == c);
    said.into_iter()
        .map(|(_, t, f)| {
            let mut l = format!("{f} (reported over the global port; exited at {t:.2} s)");
            if let Some(far) = timed_out_neighbour(&f) {
                match stopped(far) {
                    Some(r) if r.killed_by_harness.is_some() => l.push_str(&format!(
                        "; across that link: board {}, dead ({})",
                        name(far),
                        r.killed_by_harness.as_deref().unwrap_or_default()
                    )),
                    // Gone before this board's wait began (one link timeout before its
                    // report): that board's stop is what it waited on.
                    Some(r) if r.fault.is_some() && r.exit_s < t - 0.9 * timeout.as_secs_f64() => l
                        .push_str(&format!(
                            "; across that link: board {}, stopped by its own fault at {:.2} s",
                            name(far),
                            r.exit_s
                        )),
                    _ => {}
                }
            }
            l
        })
        .collect()
}

/// The step a fault message names (`board (x,y,z) step N: ...`), for ordering.
fn fault_step(text: &str) -> Option<u64> {
    let rest = text.split(" step ").nth(1)?;
    rest.split(|c: char| !c.is_ascii_digit())
        .next()?
        .parse()
        .ok()
}

/// The board across the link a fault message says timed out (`board (x,y,z) step N: link
/// FACE: no frame within the timeout`, FACE as the firmware prints it: `PosX`, `NegY`...).
fn timed_out_neighbour(text: &str) -> Option<[usize; 3]> {
    if !text.contains("no frame within the timeout") {
        return None;
    }
    let board = parse_board(text.strip_prefix("board (")?.split(')').next()?)?;
    let face = text.split(": link ").nth(1)?.split(':').next()?;
    let f = Face::ALL.into_iter().find(|f| format!("{f:?}") == face)?;
    across(board, f)
}

/// The final state: every board's owned nodes, as its console reported them; each node
/// from exactly one board.
pub(crate) fn merged_state(boards: &[Emulated]) -> Result<Vec<[f64; 3]>> {
    let mut merged: Vec<Option<[f64; 3]>> = Vec::new();
    for e in boards {
        let own = host_tools::compare::parse_displacements(
            &e.console(),
            &format!("board {}", name(e.board)),
        )?;
        if merged.len() < own.len() {
            merged.resize(own.len(), None);
        }
        for (n, u) in own.into_iter().enumerate() {
            if let Some(u) = u {
                if merged[n].replace(u).is_some() {
                    bail!(
                        "node {n} reported by two boards (board {} the second)",
                        name(e.board)
                    );
                }
            }
        }
    }
    let missing: Vec<usize> = (0..merged.len()).filter(|&n| merged[n].is_none()).collect();
    if !missing.is_empty() {
        bail!(
            "{} nodes reported by no board (first: {:?})",
            missing.len(),
            &missing[..missing.len().min(10)]
        );
    }
    Ok(merged.into_iter().flatten().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fault messages of the firmware name the board across a timed-out link.
    #[test]
    fn a_timed_out_link_names_the_board_across_it() {
        let t = "board (1,1,0) step 19: link NegY: no frame within the timeout";
        assert_eq!(timed_out_neighbour(t), Some([1, 0, 0]));
        assert_eq!(fault_step(t), Some(19));
        let other = "board (1,1,0) step 19: link NegY: bad frame: CRC mismatch";
        assert_eq!(timed_out_neighbour(other), None);
    }
}
