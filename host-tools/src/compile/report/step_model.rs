//! The step model in the report: the compiled images replayed ([`crate::compile::timing`]),
//! and what the modelled step would need to fit the scene's step.

use anyhow::Result;
use pe_firmware::profile::BoardProfile;
use serde::{Deserialize, Serialize};

use crate::compile::image::BoardImage;
use crate::compile::plan::Plan;
use crate::problem::Problem;

/// The step as the boards would run it: every board walks the firmware's step program
/// ([`crate::compile::timing`], board-sim's link model), its batches and node update at the
/// measured instruction counts, each receive waiting for its frame (sent when the
/// neighbour's program sends it, arriving after the frame's fixed time and its bytes at
/// the link rate). The per-link figures ask whether each link carries its bytes within the
/// step; this asks whether the rounds, each waiting for the one before, end within it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StepModel {
    pub timing: crate::compile::timing::StepTiming,
    /// The least link rate (bytes/s each way) at which the modelled step (and a check
    /// step) would fit; `None` when no rate would ([`crate::compile::timing::Needs`]).
    pub link_bytes_per_s_needed: Option<f64>,
    /// The least clock (Hz, one instruction per cycle) at which they would fit on the
    /// profile's links; `None` when no clock would: the frames alone take longer than dt.
    pub clock_hz_needed: Option<f64>,
    /// The modelled step with the compute free: the frames' chain alone (s).
    pub frames_alone_s: f64,
}

/// The step model of the compiled images ([`StepModel`]), with the profile's figures and
/// the scene's precision.
pub(super) fn step_model(
    problem: &Problem,
    plan: &Plan,
    images: &[BoardImage],
    profile: &BoardProfile,
) -> Result<StepModel> {
    let decoded = decoded(images)?;
    let dims = plan.machine.dims();
    let t = crate::compile::timing::SimTiming::for_precision(profile, problem.solver.precision);
    let (timing, needs) = crate::compile::timing::model_and_needs(&decoded, dims, t)?;
    Ok(StepModel {
        timing,
        link_bytes_per_s_needed: needs.link_bytes_per_s,
        clock_hz_needed: needs.clock_hz,
        frames_alone_s: needs.frames_alone_s,
    })
}

/// The images as the step model reads them.
pub(super) fn decoded(images: &[BoardImage]) -> Result<Vec<crate::compile::DecodedImage>> {
    images
        .iter()
        .map(|im| {
            crate::compile::decode_image(&im.bytes, None).map_err(|e| {
                anyhow::anyhow!(
                    "board {:?}: the step model cannot read its image: {e}",
                    im.coords
                )
            })
        })
        .collect()
}

/// The verdict's line for a modelled step over dt.
pub(super) fn step_model_reason(m: &StepModel) -> String {
    let t = &m.timing;
    let (what, step, [x, y, z]) = match t.check_step_s {
        Some(c) if c > t.step_s => (
            format!("a check step (every {} steps)", t.check_interval_steps),
            c,
            t.check_slowest_board,
        ),
        _ => ("a step".to_string(), t.step_s, t.slowest_board),
    };
    format!(
        "the step model (the boards' program, each round waiting for its frames): {what} ends at {:.1} us on board ({x},{y},{z}), over dt = {:.1} us by {:.1} us ({:.2}x); {}",
        step * 1e6,
        t.dt_s * 1e6,
        (step - t.dt_s) * 1e6,
        step / t.dt_s,
        step_model_needs(m)
    )
}

/// What the modelled step would need to fit dt, on its own or at the profile's other
/// figure: a link rate at the profile's clock, a clock at the profile's links (or why
/// none would). One home for the verdict's line and the summary's.
pub(super) fn step_model_needs(m: &StepModel) -> String {
    let t = &m.timing.inputs;
    let links = match m.link_bytes_per_s_needed {
        Some(r) => format!(
            "it fits with links of {:.3} MB/s each way or faster ({:.2}x the profile's {:.3} MB/s)",
            r / 1e6,
            r / t.link_bytes_per_s,
            t.link_bytes_per_s / 1e6
        ),
        None => "no link rate would fit it: the compute and the frames' fixed time alone exceed dt"
            .to_string(),
    };
    let clock = match m.clock_hz_needed {
        Some(c) => format!(
            "on the profile's links it fits with a clock of {:.0} MHz or faster ({:.2}x the profile's {:.0} MHz; the step model only, not the compute margin)",
            c / 1e6,
            c / t.clock_hz,
            t.clock_hz / 1e6
        ),
        None => format!(
            "no clock would fit it on the profile's links: with the compute free, the frames alone end a step at {:.1} us",
            m.frames_alone_s * 1e6
        ),
    };
    format!("{links}; {clock}")
}
