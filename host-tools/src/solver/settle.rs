//! One time step for the reference and the boards.
//!
//! `pe solve` lowers `dt` as the stable step shrinks under deformation
//! ([`super::DtMonitor`], `adapt_dt`), but a board runs one step, the one its image holds:
//! where the reference lowered `dt`, the two silently disagreed (1% of the motion on a
//! pushed box). So the step is settled before either runs: a run with tracking (the
//! pilot); if it lowered `dt`, the scene runs again from rest at the smallest step the
//! pilot reached, tracking still on, until a run lowers nothing (at most [`RUNS_MAX`]
//! runs). That last run is `pe solve`'s result, and its step is the one `pe compile` writes
//! into the images and the manifest ([`SettledStep`]): the reference and the boards then
//! run the same step from the first and agree bit for bit.
//!
//! A scene whose step cannot move costs nothing: with contact (`adapt_dt` is refused with
//! contact, and a check that finds the step too large stops the run, naming it), with
//! `adapt_dt = false`, with no tracking, or with a forced step, the step at rest is kept
//! without a pilot. Otherwise the pilot is one more run of the scene on the host at
//! compile time (measured in `docs/measurements/settled-step.md`), and `pe solve` runs
//! twice only where `dt` moved.

use std::borrow::Cow;

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use super::run::{run_with_poses, Observer, PoseSchedule, RunOutput};
use crate::problem::Problem;

/// Runs at most (the pilot included) before settling is given up.
pub const RUNS_MAX: u32 = 4;

/// How a scene's one step was found (`manifest.json`'s `dt_settled`, `pe solve`'s report).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SettledStep {
    /// The step the boards and the reference run (s).
    pub dt_s: f64,
    /// The step at rest (`dt_safety ×` the critical step at rest, or `[solver] dt`) (s).
    pub dt_at_rest_s: f64,
    /// Runs on the host it took: 0 when the step cannot move (no pilot), 1 when the pilot
    /// kept it, more when it was lowered and run again.
    pub runs: u32,
    /// Why, in words.
    pub how: String,
}

/// Whether a run of `problem` may lower its step: tracking on, `adapt_dt` on, the step
/// not forced.
pub fn may_lower_dt(problem: &Problem) -> bool {
    let s = &problem.solver;
    let tracks = (s.dt_track_interval > 0 || s.dt_recheck_interval.is_some()) && !s.force_dt;
    tracks && super::monitor::adapts(problem)
}

/// The settled run: its problem (at the settled step), its output and how the step was
/// found.
pub struct Settled {
    pub problem: Problem,
    pub output: Option<RunOutput>,
    pub step: SettledStep,
}

/// Settles `problem`'s step (module doc), running it with `poses` on `threads` threads;
/// `observer` sees every run's steps and is restarted ([`Observer::restart`]) before each
/// run after the first. `output` is the last run's (None when no pilot ran: the caller
/// runs the problem itself).
pub fn settle(
    problem: Problem,
    name: &str,
    threads: usize,
    poses: &PoseSchedule,
    observer: &mut dyn Observer,
) -> Result<Settled> {
    let dt_at_rest_s = problem.time_step.dt_s;
    if !may_lower_dt(&problem) {
        return Ok(Settled {
            problem,
            output: None,
            step: at_rest(dt_at_rest_s),
        });
    }
    // One problem, its step changed in place between runs (a second copy of a large mesh's
    // problem was a third of `pe solve`'s peak memory).
    let mut current = problem;
    for runs in 1..=RUNS_MAX {
        if runs > 1 {
            observer.restart(current.time_step.dt_s)?;
        }
        let out = run_with_poses(&current, name, observer, threads, poses.clone())?;
        let r = &out.report;
        if r.dt_reductions == 0 {
            let how = if runs == 1 {
                "the step at rest: a pilot run with tracking did not lower it".to_string()
            } else {
                format!(
                    "the smallest step tracking reached: {} runs from rest, the last lowering nothing",
                    runs
                )
            };
            return Ok(Settled {
                step: SettledStep {
                    dt_s: current.time_step.dt_s,
                    dt_at_rest_s,
                    runs,
                    how,
                },
                problem: current,
                output: Some(out),
            });
        }
        let dt_next = r.dt_final_s;
        if !(dt_next > 0.0 && dt_next < current.time_step.dt_s) {
            bail!(
                "{name}: settling the step: run {runs} lowered dt to {dt_next:e} s, not below its {:e} s",
                current.time_step.dt_s
            );
        }
        eprintln!(
            "{name}: run {runs} lowered dt {} time(s), to {dt_next:.4e} s (at rest {dt_at_rest_s:.4e} s): running again from rest at that step, so that the boards (one step, from their images) and this reference agree",
            r.dt_reductions
        );
        current.time_step.dt_s = dt_next;
    }
    bail!(
        "{name}: the step did not settle in {RUNS_MAX} runs from rest (each lowered dt again; last {:e} s): lower dt_safety or set [solver] dt",
        current.time_step.dt_s
    )
}

/// [`settle`] with no observer or poses: the step `pe compile` writes (the problem at it,
/// borrowed when its step cannot move, and how it was found).
pub fn settled_problem<'p>(
    problem: &'p Problem,
    name: &str,
) -> Result<(Cow<'p, Problem>, SettledStep)> {
    if !may_lower_dt(problem) {
        return Ok((Cow::Borrowed(problem), at_rest(problem.time_step.dt_s)));
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let s = settle(
        problem.clone(),
        name,
        threads,
        &PoseSchedule::default(),
        &mut (),
    )?;
    Ok((Cow::Owned(s.problem), s.step))
}

/// How a step that cannot move was found.
fn at_rest(dt_s: f64) -> SettledStep {
    SettledStep {
        dt_s,
        dt_at_rest_s: dt_s,
        runs: 0,
        how: "the step at rest: this scene's step does not move (contact, adapt_dt = false, no tracking or a forced step)".into(),
    }
}
