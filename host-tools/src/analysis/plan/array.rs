//! The schedule compiler's figures of a problem on an array: boards needed, bytes per
//! step, real time, and what each board runs.

use anyhow::Result;

use super::BoardUse;
use crate::compile::partition::Machine;
use crate::problem::Problem;

/// A problem on an array, from the schedule compiler.
pub(super) struct ArrayFigures {
    pub boards_needed_at_10_khz: usize,
    pub bytes_per_step: usize,
    pub keeps_real_time: bool,
    /// Why not, from the compiler's verdict.
    pub reasons: Vec<String>,
    pub boards: Vec<BoardUse>,
}

/// Array figures of a problem: boards needed at 10 kHz, bytes per step, real time, and
/// each board's use.
pub(super) fn array_figures(
    p: &Problem,
    machine: Machine,
    profile: &pe_firmware::profile::BoardProfile,
) -> Result<ArrayFigures> {
    // The schedule `pe compile` would make (the better of the two balances).
    let (plan, images, other) = crate::compile::plan_for_real_time(p, machine, profile)?;
    let mut r = crate::compile::report("plan", p, &plan, &images, profile)?;
    r.balance_other = other;
    let boards = plan
        .boards
        .iter()
        .zip(&r.boards)
        .map(|(b, s)| {
            let contact = p.contact.as_ref().map_or(0, |c| {
                c.node_globals
                    .iter()
                    .filter(|n| b.nodes.binary_search(n).is_ok())
                    .count()
            });
            let loads = p
                .loads
                .iter()
                .filter(|l| b.nodes.binary_search(&l.node).is_ok())
                .count();
            let mut runs = vec![format!("{} elements", s.elements)];
            if contact > 0 {
                runs.push(format!("contact on {contact} nodes"));
            }
            if loads > 0 {
                runs.push(format!("loads on {loads} nodes"));
            }
            if s.elements == 0 {
                runs = vec!["idle (no element)".into()];
            }
            BoardUse {
                board: s.board,
                elements: s.elements,
                nodes: s.nodes,
                runs: runs.join(", "),
            }
        })
        .collect();
    Ok(ArrayFigures {
        boards_needed_at_10_khz: r.capacity.boards_needed_at_10_khz,
        bytes_per_step: r.bytes_per_step_total,
        keeps_real_time: r.real_time.keeps_real_time,
        reasons: r.real_time.reasons.clone(),
        boards,
    })
}
