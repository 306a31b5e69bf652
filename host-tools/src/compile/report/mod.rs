//! The compile report (`DIR/report.json`): elements and nodes per board, exchange traffic,
//! bandwidth, the capacity at the scene's step rate, contact and graphics figures, the
//! step model and the real-time verdict; its console summary.
//!
//! Rooms: [`capacity`] (the boards' compute from measured instruction counts), [`link`]
//! (the face links' traffic and time per step), [`global`] (the global network: contact
//! traffic at rest and the graphics stream), [`step_model`] (the step as the boards run
//! it), [`verdict`] (whether the array keeps the step, and the balance `pe compile`
//! chooses by it), [`summary`] (the console text).

mod capacity;
mod global;
mod link;
mod step_model;
mod summary;
mod verdict;

use std::path::Path;

use anyhow::Result;
use pe_firmware::image::{Feature, Integration, Precision};
use pe_firmware::profile::BoardProfile;
use serde::{Deserialize, Serialize};

use super::image::{contact_tables, image_file_name, BoardImage};
use super::plan::{Balance, Plan};
use crate::problem::Problem;
use crate::scene::settings::{integration_text, precision_text};

pub use capacity::Capacity;
use capacity::{board_contact_nodes, capacity_report, contact_node_mask};
use global::{contact_report, graphics_report};
pub use global::{ContactCompileReport, GlobalPortLoad, GraphicsReport};
pub use link::LinkLoad;
use link::LinkTraffic;
pub use step_model::StepModel;
use step_model::{step_model, step_model_reason};
pub use summary::summary;
pub use verdict::{plan_for_real_time, verdict, BalanceTried, RealTimeVerdict, COMPUTE_MARGIN};

/// Figures of a compiled schedule (`DIR/report.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CompileReport {
    pub scene: String,
    pub machine: String,
    /// Exchange rounds per axis ([`Plan::rounds`]: round 0 for the nodes first exchanged
    /// along the axis, round 1 for those summed along earlier axes first, more for nodes
    /// spanning over two boards), of which `late_rounds` run after the z exchange (the x and
    /// y broadcasts).
    pub rounds: [usize; 3],
    pub late_rounds: [usize; 3],
    #[serde(with = "pe_firmware::profile::by_name")]
    pub profile: &'static BoardProfile,
    #[serde(with = "precision_text")]
    pub precision: Precision,
    #[serde(with = "integration_text")]
    pub integration: Integration,
    pub dt_s: f64,
    pub steps_per_s: f64,
    pub elements: usize,
    pub nodes: usize,
    pub elements_per_board: Vec<usize>,
    pub nodes_per_board: Vec<usize>,
    /// max / mean elements per board.
    pub load_imbalance: f64,
    /// Node copies beyond one per node (replicas), in all.
    pub replicated_nodes: usize,
    pub border_nodes_per_face_max: [usize; 6],
    /// Force vectors sent per step, all links, both directions: one vector is one node's
    /// partial or summed force one board sends to a neighbour over one link in one exchange
    /// round (every round counted).
    pub force_vectors_per_step: usize,
    /// Force vectors per step on the busiest link direction.
    pub force_vectors_per_link_max: usize,
    pub bytes_per_step_per_link_max: usize,
    pub bytes_per_step_total: usize,
    /// Bandwidth needed at the scene's step rate (bytes/s).
    pub bandwidth_total_bytes_per_s: f64,
    pub bandwidth_per_link_max_bytes_per_s: f64,
    pub link_bandwidth_bytes_per_s: u64,
    /// The global network's rate into (and out of) one board (bytes/s).
    pub global_bytes_per_s: u64,
    /// Fraction of a step the busiest link is busy at the scene's step rate.
    pub link_utilisation_max: f64,
    /// Per-frame cost of a link (s), beside `link_bandwidth_bytes_per_s`.
    pub link_frame_latency_s: f64,
    /// Whether the array keeps the scene's step: compute, every link, and the step as the
    /// boards run it ([`StepModel`]).
    pub real_time: RealTimeVerdict,
    pub step_model: StepModel,
    /// What the partition balances, and the other balance's worst time ratio when
    /// [`plan_for_real_time`] compared both.
    pub balance: Balance,
    pub balance_other: Option<BalanceTried>,
    pub image_bytes_max: usize,
    pub ram_bytes_max: u64,
    /// Board compute capacity from the firmware's measured instruction counts
    /// (`pe_firmware::profile::MEASURED_COST`), one instruction per cycle.
    pub capacity: Capacity,
    pub boards: Vec<BoardSummary>,
    pub graphics: GraphicsReport,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact: Option<ContactCompileReport>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BoardSummary {
    pub board: [usize; 3],
    pub file: String,
    pub elements: usize,
    pub batches: [usize; 4],
    pub nodes: usize,
    pub owned_nodes: usize,
    /// Nodes on a contact surface the board holds, and how many of them it owns (the
    /// compute figure charges a board that owns one the whole contact table, one that
    /// owns none nothing: [`FirmwareCost::charged_contact_nodes`]).
    pub contact_nodes: usize,
    pub owned_contact_nodes: usize,
    pub exchange: [usize; 6],
    pub image_bytes: usize,
    pub ram_bytes: u64,
    /// The firmware's parts its image needs (`pe_firmware::image::Feature`: contact,
    /// graphics, loads): a board that owns no contact node, surface node or loaded node
    /// runs none of that part's code.
    #[serde(with = "crate::compile::feature_names")]
    pub firmware_parts: Vec<Feature>,
}

impl CompileReport {
    /// Reads `DIR/report.json`, as the type that wrote it.
    pub fn read(dir: &Path) -> Result<CompileReport> {
        super::manifest::read_json(&dir.join("report.json"))
    }
}

/// The report of `plan` and its `images` on `profile` (a registered profile's name: the
/// report names it).
pub fn report(
    scene: &str,
    problem: &Problem,
    plan: &Plan,
    images: &[BoardImage],
    profile: &BoardProfile,
) -> Result<CompileReport> {
    let dt = problem.time_step.dt_s;
    let epb: Vec<usize> = plan.boards.iter().map(|b| b.elements.len()).collect();
    let npb: Vec<usize> = plan.boards.iter().map(|b| b.nodes.len()).collect();
    let mean = epb.iter().sum::<usize>() as f64 / epb.len() as f64;
    let rate = 1.0 / dt;
    let Figures {
        links,
        capacity,
        contact,
        mut real_time,
    } = figures(problem, plan, profile)?;
    let step_model = step_model(problem, plan, images, profile)?;
    real_time.worst_ratio = real_time
        .worst_ratio
        .max(step_model.timing.step_s / step_model.timing.dt_s);
    if !step_model.timing.real_time {
        real_time.keeps_real_time = false;
        real_time.reasons.push(step_model_reason(&step_model));
    }
    let frame_bytes_max = links.bytes.iter().copied().max().unwrap_or(0);
    let bytes_total: usize = links.bytes.iter().sum();
    let balance = plan.balance;
    Ok(CompileReport {
        graphics: graphics_report(problem, plan, dt),
        contact,
        scene: scene.to_string(),
        machine: plan.machine.to_string(),
        rounds: plan.rounds,
        late_rounds: plan.late_rounds,
        profile: BoardProfile::by_name(profile.name)?,
        precision: problem.solver.precision,
        integration: problem.solver.integration,
        dt_s: dt,
        steps_per_s: rate,
        elements: problem.mesh.cells.len(),
        nodes: problem.mesh.nodes.len(),
        load_imbalance: epb.iter().copied().max().unwrap_or(0) as f64 / mean,
        elements_per_board: epb,
        replicated_nodes: npb.iter().sum::<usize>() - problem.mesh.nodes.len(),
        nodes_per_board: npb,
        border_nodes_per_face_max: core::array::from_fn(|f| {
            plan.boards
                .iter()
                .map(|b| b.exchange[f].len())
                .max()
                .unwrap_or(0)
        }),
        force_vectors_per_step: links.vectors.iter().sum(),
        force_vectors_per_link_max: links.vectors.iter().copied().max().unwrap_or(0),
        bytes_per_step_per_link_max: frame_bytes_max,
        bytes_per_step_total: bytes_total,
        bandwidth_total_bytes_per_s: bytes_total as f64 * rate,
        bandwidth_per_link_max_bytes_per_s: frame_bytes_max as f64 * rate,
        link_bandwidth_bytes_per_s: profile.link_bytes_per_s,
        global_bytes_per_s: profile.global_bytes_per_s,
        link_utilisation_max: frame_bytes_max as f64 * rate / profile.link_bytes_per_s as f64,
        link_frame_latency_s: profile.link_latency_ns as f64 * 1e-9,
        real_time,
        step_model,
        balance,
        balance_other: None,
        image_bytes_max: images.iter().map(|i| i.bytes.len()).max().unwrap_or(0),
        ram_bytes_max: images.iter().map(|i| i.ram_bytes).max().unwrap_or(0),
        capacity,
        boards: board_summaries(problem, plan, images),
    })
}

/// What the verdict is made of, and the verdict: one home for [`report`] and
/// [`real_time_of`].
struct Figures {
    links: LinkTraffic,
    capacity: Capacity,
    contact: Option<ContactCompileReport>,
    real_time: RealTimeVerdict,
}

fn figures(problem: &Problem, plan: &Plan, profile: &BoardProfile) -> Result<Figures> {
    let dt = problem.time_step.dt_s;
    let links = LinkTraffic::of(plan, problem.solver.precision);
    let tables = contact_tables(problem, plan, dt)?;
    let search = tables.as_ref().map(|(run, _)| {
        let model = pe_firmware::physics::contact::ContactModel {
            nodes: &run.nodes,
            faces: &run.faces,
            pairs: &run.pairs,
            tools: &run.tools,
        };
        let tests = pe_firmware::physics::contact::search_tests(&model);
        (
            tests,
            if tests > 0 {
                run.params.check_interval_steps
            } else {
                0
            },
        )
    });
    let capacity = capacity_report(problem, plan, profile, dt, search.unwrap_or((0, 0)));
    let contact = contact_report(problem, plan, tables.as_ref(), 1.0 / dt, profile)?;
    let global = contact
        .as_ref()
        .and_then(|c| c.global_busiest_at_rest.as_ref());
    let real_time = verdict(&capacity, &links.loads(plan, profile), global, dt);
    Ok(Figures {
        links,
        capacity,
        contact,
        real_time,
    })
}

/// The verdict of `plan` on `profile` without images (what [`report`] says of it).
pub fn real_time_of(
    problem: &Problem,
    plan: &Plan,
    profile: &BoardProfile,
) -> Result<RealTimeVerdict> {
    Ok(figures(problem, plan, profile)?.real_time)
}

fn board_summaries(problem: &Problem, plan: &Plan, images: &[BoardImage]) -> Vec<BoardSummary> {
    let on_contact = contact_node_mask(problem);
    plan.boards
        .iter()
        .zip(images)
        .map(|(b, im)| (b, im, board_contact_nodes(b, &on_contact)))
        .map(
            |(b, im, (contact_nodes, owned_contact_nodes))| BoardSummary {
                board: b.coords,
                file: image_file_name(b.coords),
                elements: b.elements.len(),
                batches: [
                    b.batch_ends[0],
                    b.batch_ends[1] - b.batch_ends[0],
                    b.batch_ends[2] - b.batch_ends[1],
                    b.batch_ends[3] - b.batch_ends[2],
                ],
                nodes: b.nodes.len(),
                owned_nodes: b.owner.iter().filter(|o| **o).count(),
                contact_nodes,
                owned_contact_nodes,
                exchange: core::array::from_fn(|f| b.exchange[f].len()),
                image_bytes: im.bytes.len(),
                ram_bytes: im.ram_bytes,
                firmware_parts: crate::compile::parts_of(std::iter::once(&im.header)),
            },
        )
        .collect()
}
