//! The real-time verdict (compute, every link, every global port, the step model) and the
//! balance `pe compile` chooses by it.

use anyhow::Result;
use pe_firmware::profile::BoardProfile;
use serde::{Deserialize, Serialize};

use super::{real_time_of, Capacity, GlobalPortLoad, LinkLoad};
use crate::compile::image::BoardImage;
use crate::compile::plan::{plan_balanced, Balance, Plan};
use crate::problem::Problem;
use link_proto::Machine;

/// Whether the board array keeps the scene's step: the busiest board's compute within
/// `dt / COMPUTE_MARGIN`, every link direction's time per step within `dt`, and, with
/// contact, every contact board's global port (the node packets with the tissue at rest, a
/// lower bound: a deformed scene opens more channels) within `dt`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RealTimeVerdict {
    pub keeps_real_time: bool,
    /// The step (s) and the compute budget, the step over [`COMPUTE_MARGIN`] (s).
    pub dt_s: f64,
    pub compute_budget_s: f64,
    /// The busiest board's compute per step (s, from [`Capacity`]) and that board.
    pub compute_s_max: f64,
    pub compute_board: [usize; 3],
    pub compute_fits: bool,
    /// A check step (every `check_interval_steps`, 0 without pairs): the busiest board's
    /// compute then (s, from [`Capacity`]), that board, and whether it fits the budget too:
    /// a board that owns a contact node searches the candidates of the whole table.
    pub check_interval_steps: u32,
    pub check_step_s_max: f64,
    pub check_step_board: [usize; 3],
    pub check_step_fits: bool,
    /// The busiest link direction, if any link sends.
    pub link_busiest: Option<LinkLoad>,
    pub links: usize,
    /// Link directions whose time per step exceeds `dt_s`, the worst first (at most
    /// [`LINKS_OVER_LISTED`] listed; `links_over_count` counts them all).
    pub links_over_count: usize,
    pub links_over: Vec<LinkLoad>,
    /// The busiest global port's contact traffic at rest, if the scene has contact.
    pub global_busiest: Option<GlobalPortLoad>,
    pub global_fits: bool,
    /// The largest of a steady step's compute over its budget, the busiest link's and the
    /// busiest global port's time over the step and, in a compile report, the step model's
    /// steady step over the step (at most 1 when it keeps real time; the check step's ratio
    /// is `check_step_s_max / compute_budget_s`, which the search of the whole table on
    /// each contact board makes nearly the same whatever the partition, so the balances
    /// are compared on this).
    pub worst_ratio: f64,
    /// Why not, one line each (empty when it keeps real time).
    pub reasons: Vec<String>,
}

/// A balance the compiler tried and the verdict's worst time ratio with it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BalanceTried {
    pub balance: Balance,
    pub worst_ratio: f64,
}

/// The schedule `pe compile` uses: the partition balancing elements and the one balancing
/// cost (when the elements' costs differ), the one whose worst time ratio
/// ([`RealTimeVerdict::worst_ratio`], with the step model's steady step: each is compiled
/// and replayed) is smaller (elements on a tie); with its images and the other's ratio.
pub fn plan_for_real_time(
    problem: &Problem,
    machine: Machine,
    profile: &BoardProfile,
) -> Result<(Plan, Vec<BoardImage>, Option<BalanceTried>)> {
    let by_elements = plan_balanced(problem, machine, Balance::Elements)?;
    if crate::compile::partition::equal_weights(&crate::compile::partition::cost_weights(problem)) {
        let images = crate::compile::compile_images(problem, &by_elements)?;
        return Ok((by_elements, images, None));
    }
    let by_cost = plan_balanced(problem, machine, Balance::Cost)?;
    // The report's worst ratio: the verdict's figures and the step model's steady step.
    let compiled = |plan: Plan| -> Result<(Plan, Vec<BoardImage>, f64)> {
        let v = real_time_of(problem, &plan, profile)?;
        let images = crate::compile::compile_images(problem, &plan)?;
        let t = crate::compile::timing::SimTiming::for_precision(profile, problem.solver.precision);
        let m = crate::compile::timing::model(
            &super::step_model::decoded(&images)?,
            plan.machine.dims(),
            t,
        )?;
        Ok((plan, images, v.worst_ratio.max(m.step_s / m.dt_s)))
    };
    let (pe, ie, re) = compiled(by_elements)?;
    let (pc, ic, rc) = compiled(by_cost)?;
    Ok(if rc < re {
        let other = BalanceTried {
            balance: Balance::Elements,
            worst_ratio: re,
        };
        (pc, ic, Some(other))
    } else {
        let other = BalanceTried {
            balance: Balance::Cost,
            worst_ratio: rc,
        };
        (pe, ie, Some(other))
    })
}

/// Compute may take at most the step over this (room for the exchange, interrupts, jitter).
pub const COMPUTE_MARGIN: f64 = 2.0;

/// Links over their rate listed in the report (the count covers all).
pub const LINKS_OVER_LISTED: usize = 8;

/// The real-time verdict from the compute figure and the links' loads.
pub fn verdict(
    capacity: &Capacity,
    links: &[LinkLoad],
    global: Option<&GlobalPortLoad>,
    dt_s: f64,
) -> RealTimeVerdict {
    let budget = dt_s / COMPUTE_MARGIN;
    let compute_fits = capacity.step_compute_s_max <= budget;
    // A scene without contact has no check step (the steady step is the only one: judged
    // above, not listed twice as a check step "every 0 steps").
    let check_step_fits = capacity.check_interval_steps == 0 || capacity.check_step_s_max <= budget;
    // Slowest first; equal times keep board and face order.
    let mut sorted: Vec<&LinkLoad> = links.iter().collect();
    sorted.sort_by(|a, b| b.time_per_step_s.total_cmp(&a.time_per_step_s));
    let link_busiest = sorted.first().map(|l| (*l).clone());
    let over: Vec<LinkLoad> = sorted
        .into_iter()
        .take_while(|l| l.time_per_step_s > dt_s)
        .cloned()
        .collect();
    let mut reasons = Vec::new();
    if !compute_fits {
        let [x, y, z] = capacity.busiest_board;
        reasons.push(format!(
            "board ({x},{y},{z}) computes {:.1} us per step, over the {:.1} us budget (dt / {COMPUTE_MARGIN}) by {:.1} us ({:.2}x)",
            capacity.step_compute_s_max * 1e6,
            budget * 1e6,
            (capacity.step_compute_s_max - budget) * 1e6,
            capacity.step_compute_s_max / budget
        ));
    }
    if !check_step_fits {
        let [x, y, z] = capacity.check_step_board;
        reasons.push(format!(
            "a check step (every {} steps: the candidate search, {} node-face tests on each board that owns a contact node) computes {:.1} us on board ({x},{y},{z}), over the {:.1} us budget ({:.2}x)",
            capacity.check_interval_steps,
            capacity.search_tests,
            capacity.check_step_s_max * 1e6,
            budget * 1e6,
            capacity.check_step_s_max / budget
        ));
    }
    for l in over.iter().take(LINKS_OVER_LISTED) {
        let [x, y, z] = l.board;
        reasons.push(format!(
            "link ({x},{y},{z}) {} needs {:.1} us per step ({} bytes in {} frames), over dt = {:.1} us by {:.1} us ({:.2}x)",
            l.face,
            l.time_per_step_s * 1e6,
            l.bytes_per_step,
            l.frames_per_step,
            dt_s * 1e6,
            (l.time_per_step_s - dt_s) * 1e6,
            l.time_per_step_s / dt_s
        ));
    }
    if over.len() > LINKS_OVER_LISTED {
        reasons.push(format!(
            "and {} more links over dt",
            over.len() - LINKS_OVER_LISTED
        ));
    }
    let global_fits = global.is_none_or(|g| g.time_per_step_s <= dt_s);
    if let Some(g) = global.filter(|_| !global_fits) {
        let [x, y, z] = g.board;
        reasons.push(format!(
            "board ({x},{y},{z})'s global port carries {} bytes in and {} out of contact-node packets per step with the tissue at rest: {:.1} us per step, over dt = {:.1} us ({:.2}x)",
            g.bytes_in_per_step,
            g.bytes_out_per_step,
            g.time_per_step_s * 1e6,
            dt_s * 1e6,
            g.time_per_step_s / dt_s
        ));
    }
    let worst_ratio = [
        capacity.step_compute_s_max / budget,
        link_busiest
            .as_ref()
            .map_or(0.0, |l| l.time_per_step_s / dt_s),
        global.map_or(0.0, |g| g.time_per_step_s / dt_s),
    ]
    .into_iter()
    .fold(0.0, f64::max);
    RealTimeVerdict {
        worst_ratio,
        keeps_real_time: compute_fits && check_step_fits && over.is_empty() && global_fits,
        global_busiest: global.cloned(),
        global_fits,
        dt_s,
        compute_budget_s: budget,
        compute_s_max: capacity.step_compute_s_max,
        compute_board: capacity.busiest_board,
        compute_fits,
        check_interval_steps: capacity.check_interval_steps,
        check_step_s_max: capacity.check_step_s_max,
        check_step_board: capacity.check_step_board,
        check_step_fits,
        link_busiest,
        links: links.len(),
        links_over_count: over.len(),
        links_over: over.into_iter().take(LINKS_OVER_LISTED).collect(),
        reasons,
    }
}
