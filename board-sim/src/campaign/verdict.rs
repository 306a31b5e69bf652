//! How a campaign's run ended, against the clean run: its bits, or stopped naming the true
//! first cause; anything else is counted, a silent wrong answer above all.

use anyhow::Result;
use link_proto::machine::across;
use pe_firmware::runtime::FaultKind;

use crate::check::SimFault;
use crate::results::SimOutput;

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum Verdict {
    /// Finished with the clean run's bits.
    Identical,
    /// Stopped, naming an injected fault that explains what was detected.
    TrueCause,
    /// Stopped, naming something else.
    WrongCause,
    /// Finished with other results: a silent wrong answer.
    SilentWrong,
}

/// Whether a finished run has the clean run's bits.
pub(super) fn identical(out: &SimOutput, clean: &SimOutput) -> bool {
    out.steps == clean.steps
        && out.displacements.len() == clean.displacements.len()
        && out
            .displacements
            .iter()
            .zip(&clean.displacements)
            .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits))
}

/// Whether a swapped run was refused naming the odd board `b`: by the host before any
/// board ran (its message names exactly that board), or by the boards, every mismatch on a
/// link of `b` (and at least one).
pub(super) fn names_swap(result: &Result<SimOutput>, b: [usize; 3]) -> bool {
    let b8 = b.map(|c| c as u8);
    match result {
        Ok(_) => false,
        Err(e) => match e.downcast_ref::<SimFault>() {
            None => {
                let m = format!("{e:#}");
                let name = format!("board ({},{},{})", b[0], b[1], b[2]);
                m.contains(&name) && m.matches("board (").count() == 1
            }
            Some(f) => {
                let mismatches: Vec<bool> = f
                    .observed
                    .iter()
                    .filter_map(|o| match o.fault.kind {
                        FaultKind::CompilationMismatch { face, .. } => Some(
                            o.fault.board == b8
                                || across(o.fault.board.map(usize::from), face)
                                    == Some(b8.map(usize::from)),
                        ),
                        _ => None,
                    })
                    .collect();
                let detected = f
                    .observed
                    .get(f.cause.detected)
                    .is_some_and(|o| matches!(o.fault.kind, FaultKind::CompilationMismatch { .. }));
                detected && !mismatches.is_empty() && mismatches.iter().all(|&x| x)
            }
        },
    }
}

/// Whether a stopped run names the true first cause: an injected fault (ground truth) that
/// explains the observation that detected it (which attribution checks), and no injected
/// stall earlier than it (a stall stops a run for certain; faults before it may have been
/// recovered).
pub(super) fn true_cause(f: &SimFault) -> bool {
    let c = &f.cause;
    let injected = f.injected.iter().any(|i| {
        Some(&i.face) == c.face.as_ref()
            && i.board == c.board
            && i.step as u64 == c.step
            && c.what == format!("injected {}", i.what)
    });
    let stall_before = f
        .injected
        .iter()
        .any(|i| i.what == "stall" && (i.step as u64) < c.step);
    c.injected && injected && (!stall_before || c.what == "injected stall")
}
