//! The compile report: elements and nodes per board, exchange traffic, bandwidth, the
//! capacity at the scene's step rate, contact and graphics figures, and its console summary.

use anyhow::Result;
use pe_firmware::image::*;
use pe_firmware::profile::{BoardProfile, FirmwareCost};
use serde::Serialize;

use super::image::BoardImage;
use super::image::{contact_tables, graphics_params, image_file_name};
use super::partition::Machine;
use super::plan::{plan_balanced, Balance, Plan, FACE_NAMES};
use crate::problem::contact::ContactRun;
use crate::problem::elements::kernel_of;
use crate::problem::Problem;

/// Figures of a compiled schedule (`DIR/report.json`).
#[derive(Clone, Debug, Serialize)]
pub struct CompileReport {
    pub scene: String,
    pub machine: String,
    /// Exchange rounds per axis ([`Plan::rounds`]: round 0 for the nodes first exchanged
    /// along the axis, round 1 for those summed along earlier axes first, more for nodes
    /// spanning over two boards), of which `late_rounds` run after the z exchange (the x and
    /// y broadcasts).
    pub rounds: [usize; 3],
    pub late_rounds: [usize; 3],
    pub profile: String,
    pub precision: String,
    pub integration: String,
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

/// The step as the boards would run it: every board walks the firmware's step program
/// ([`super::timing`], board-sim's link model), its batches and node update at the
/// measured instruction counts, each receive waiting for its frame (sent when the
/// neighbour's program sends it, arriving after the frame's fixed time and its bytes at
/// the link rate). The per-link figures ask whether each link carries its bytes within the
/// step; this asks whether the rounds, each waiting for the one before, end within it.
#[derive(Clone, Debug, Serialize)]
pub struct StepModel {
    pub timing: super::timing::StepTiming,
    /// The least link rate (bytes/s each way) at which the modelled step (and a check
    /// step) would fit; `None` when no rate would ([`super::timing::Needs`]).
    pub link_bytes_per_s_needed: Option<f64>,
    /// The least clock (Hz, one instruction per cycle) at which they would fit on the
    /// profile's links; `None` when no clock would: the frames alone take longer than dt.
    pub clock_hz_needed: Option<f64>,
    /// The modelled step with the compute free: the frames' chain alone (s).
    pub frames_alone_s: f64,
}

/// The graphics stream's cost.
#[derive(Clone, Debug, Serialize)]
pub struct GraphicsReport {
    pub interval_steps: u32,
    pub spread_steps: u16,
    pub surface_nodes: usize,
    /// Packets and bytes per frame (all boards), and the mean rate (bytes/s).
    pub packets_per_frame: usize,
    pub bytes_per_frame: usize,
    pub bytes_per_s: f64,
    pub seed_bytes_per_s: f64,
}

/// Contact figures: the tables and the collision traffic with the tissue at rest.
#[derive(Clone, Debug, Serialize)]
pub struct ContactCompileReport {
    pub contact_nodes: usize,
    pub contact_faces: usize,
    pub pairs: usize,
    pub tools: usize,
    pub contact_boards: usize,
    pub check_interval_steps: u32,
    pub travel_max_m: f64,
    pub box_margin_m: f64,
    /// With the tissue at rest: board pairs that open a channel, contact-node vectors sent
    /// per step, and bytes per second at the scene's step rate.
    pub channels_at_rest: usize,
    pub vectors_per_step_at_rest: usize,
    pub bytes_per_s_at_rest: f64,
    pub seed_vectors_per_step: usize,
    pub seed_bytes_per_s: f64,
    /// The contact board whose global port is busiest at rest (bytes in or out per step).
    pub global_busiest_at_rest: Option<GlobalPortLoad>,
}

/// What one board's global port carries per step for contact, with the tissue at rest:
/// a node packet to (and from) every partner each step, even an empty one (header, node
/// header, entries of 16 bytes in f32 and 28 in f64, CRC).
#[derive(Clone, Debug, Serialize)]
pub struct GlobalPortLoad {
    pub board: [usize; 3],
    pub bytes_in_per_step: usize,
    pub bytes_out_per_step: usize,
    /// The larger direction at the profile's global rate (s).
    pub time_per_step_s: f64,
}

/// Bytes of contact-node packets carrying `n` node entries.
fn node_packet_bytes(n: usize, precision: link_proto::Precision) -> usize {
    use link_proto::payload::{node_entry_len, nodes_per_packet_max, NODES_HEADER_LEN};
    let packets = n.div_ceil(nodes_per_packet_max(precision)).max(1);
    packets * (link_proto::PACKET_HEADER_LEN + NODES_HEADER_LEN + link_proto::CRC_LEN)
        + n * node_entry_len(precision)
}

/// The contact traffic at rest: the runtime's box test on the reference positions, from
/// the contact tables (`contact_tables`) and their contact boards.
fn contact_report(
    problem: &Problem,
    plan: &Plan,
    tables: Option<&(ContactRun, Vec<u8>)>,
    rate: f64,
    profile: &BoardProfile,
) -> Result<Option<ContactCompileReport>> {
    let Some((run, boards)) = tables else {
        return Ok(None);
    };
    let p = run.params;
    let wire = problem.solver.precision.wire();
    let owner_of = |c: &pe_firmware::physics::contact::ContactNode| {
        plan.node_owner[c.global as usize] as usize
    };
    let board_index: Vec<usize> = boards
        .iter()
        .map(|&a| link_proto::Machine::from_address(a).map_or(0, |c| plan.machine.index(c)))
        .collect();
    let pair_nodes = |b: usize| {
        run.nodes
            .iter()
            .filter(move |n| n.surfaces & p.pair_surfaces != 0 && owner_of(n) == b)
    };
    let bbox = |b: usize| {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for n in pair_nodes(b) {
            for i in 0..3 {
                lo[i] = lo[i].min(n.reference[i]);
                hi[i] = hi[i].max(n.reference[i]);
            }
        }
        (lo, hi)
    };
    let boxes: Vec<_> = board_index.iter().map(|&b| bbox(b)).collect();
    let grow = |b: &([f64; 3], [f64; 3])| -> ([f64; 3], [f64; 3]) {
        (
            core::array::from_fn(|i| b.0[i] - p.box_margin_m),
            core::array::from_fn(|i| b.1[i] + p.box_margin_m),
        )
    };
    let (mut channels, mut vectors) = (0, 0);
    let (mut bytes_in, mut bytes_out) = (vec![0; boards.len()], vec![0; boards.len()]);
    for (i, &bi) in board_index.iter().enumerate() {
        for (j, other) in boxes.iter().enumerate() {
            if i == j {
                continue;
            }
            let g = grow(&boxes[i]);
            if !(0..3).all(|k| other.0[k] <= g.1[k] && g.0[k] <= other.1[k]) {
                continue;
            }
            channels += 1;
            let r = grow(other);
            let sent = pair_nodes(bi)
                .filter(|n| (0..3).all(|k| r.0[k] <= n.reference[k] && n.reference[k] <= r.1[k]))
                .count();
            vectors += sent;
            bytes_out[i] += node_packet_bytes(sent, wire);
            bytes_in[j] += node_packet_bytes(sent, wire);
        }
    }
    let global_busiest_at_rest = (0..boards.len())
        .map(|i| GlobalPortLoad {
            board: plan.machine.coords(board_index[i]),
            bytes_in_per_step: bytes_in[i],
            bytes_out_per_step: bytes_out[i],
            time_per_step_s: bytes_in[i].max(bytes_out[i]) as f64
                / profile.global_bytes_per_s as f64,
        })
        .filter(|l| l.time_per_step_s > 0.0)
        .max_by(|a, b| a.time_per_step_s.total_cmp(&b.time_per_step_s));
    Ok(Some(ContactCompileReport {
        contact_nodes: run.nodes.len(),
        contact_faces: run.faces.len(),
        pairs: run.pairs.len(),
        tools: run.tools.len(),
        contact_boards: boards.len(),
        check_interval_steps: p.check_interval_steps,
        travel_max_m: p.travel_max_m,
        box_margin_m: p.box_margin_m,
        channels_at_rest: channels / 2,
        vectors_per_step_at_rest: vectors,
        bytes_per_s_at_rest: (vectors * link_proto::payload::node_entry_len(wire)) as f64 * rate,
        seed_vectors_per_step: 300,
        seed_bytes_per_s: 72e6,
        global_busiest_at_rest,
    }))
}

/// What the scene asks of the busiest board's processor, from measured instruction counts.
#[derive(Clone, Debug, Serialize)]
pub struct Capacity {
    pub clock_hz: u64,
    /// Per element-step of the general kernel, of the parallelepiped kernel and of the
    /// cuboid kernel.
    pub instructions_per_element_step: u32,
    pub instructions_per_box_element_step: u32,
    pub instructions_per_cuboid_element_step: u32,
    /// Elements of the scene that take each kernel (general, parallelepiped, cuboid).
    pub elements_per_kernel: [usize; 3],
    pub instructions_per_node_update: u32,
    pub instructions_per_contact_node: u32,
    /// Instructions of one step on the busiest board (no exchange), and that board.
    pub step_instructions_max: f64,
    pub busiest_board: [usize; 3],
    /// That step's time at one instruction per cycle (s), against the scene's `dt_s`.
    pub step_compute_s_max: f64,
    pub compute_keeps_real_time: bool,
    /// A check step's candidate search: instructions per node-face test (measured), the
    /// tests of one search (the whole contact table with every position known: what each
    /// board that owns a contact node searches; 0 without pairs) and the steps between
    /// checks (0 without pairs).
    pub instructions_per_search_test: u32,
    pub search_tests: usize,
    pub check_interval_steps: u32,
    /// The busiest board at a check step: its step plus the search if it owns a contact
    /// node (s, one instruction per cycle), and that board (the steady figures without
    /// pairs).
    pub check_step_s_max: f64,
    pub check_step_board: [usize; 3],
    /// Elements one board computes per step at the scene's rate and at 10 kHz, with this
    /// scene's nodes per element on its busiest board.
    pub elements_per_board_at_scene_rate: f64,
    pub elements_per_board_at_10_khz: f64,
    /// Boards the scene needs at 10 kHz (compute only).
    pub boards_needed_at_10_khz: usize,
}

#[derive(Clone, Debug, Serialize)]
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
    pub firmware_parts: Vec<&'static str>,
}

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
        profile: profile.name.to_string(),
        precision: problem.solver.precision.name().to_string(),
        integration: problem.solver.integration.name().to_string(),
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

/// Force vectors and bytes sent per step on every link direction (board, face), over all
/// rounds (one frame per round).
struct LinkTraffic {
    vectors: Vec<usize>,
    bytes: Vec<usize>,
    frames: Vec<usize>,
}

impl LinkTraffic {
    fn of(plan: &Plan, precision: Precision) -> LinkTraffic {
        let w = if precision == Precision::F32 { 4 } else { 8 };
        let overhead = link_proto::FRAME_HEADER_LEN + link_proto::CRC_LEN;
        let mut t = LinkTraffic {
            vectors: Vec::new(),
            bytes: Vec::new(),
            frames: Vec::new(),
        };
        for b in &plan.boards {
            for f in 0..6 {
                let rounds = &b.rounds[f / 2];
                let n: usize = rounds.iter().map(|r| r.send[f % 2].len()).sum();
                let frames = rounds.iter().filter(|r| !r.send[f % 2].is_empty()).count();
                t.vectors.push(n);
                t.bytes.push(3 * w * n + frames * overhead);
                t.frames.push(frames);
            }
        }
        t
    }

    /// Every link direction that sends, with its time per step on `profile`'s links.
    fn loads(&self, plan: &Plan, profile: &BoardProfile) -> Vec<LinkLoad> {
        (0..self.bytes.len())
            .filter(|&i| self.frames[i] > 0)
            .map(|i| {
                let (bytes, frames) = (self.bytes[i], self.frames[i]);
                LinkLoad {
                    board: plan.boards[i / 6].coords,
                    face: FACE_NAMES[i % 6].to_string(),
                    bytes_per_step: bytes,
                    frames_per_step: frames,
                    time_per_step_s: link_time_s(bytes, frames, profile),
                }
            })
            .collect()
    }
}

/// Time one link direction needs per step for `bytes` in `frames` frames: the bytes at the
/// link's rate plus each frame's fixed cost.
pub fn link_time_s(bytes: usize, frames: usize, profile: &BoardProfile) -> f64 {
    bytes as f64 / profile.link_bytes_per_s as f64
        + frames as f64 * profile.link_latency_ns as f64 * 1e-9
}

/// One link direction (a board's face) and what it sends per step.
#[derive(Clone, Debug, Serialize)]
pub struct LinkLoad {
    pub board: [usize; 3],
    pub face: String,
    pub bytes_per_step: usize,
    pub frames_per_step: usize,
    /// Bytes at the link's rate plus the frames' fixed cost (s).
    pub time_per_step_s: f64,
}

/// Whether the board array keeps the scene's step: the busiest board's compute within
/// `dt / COMPUTE_MARGIN`, every link direction's time per step within `dt`, and, with
/// contact, every contact board's global port (the node packets with the tissue at rest, a
/// lower bound: a deformed scene opens more channels) within `dt`.
#[derive(Clone, Debug, Serialize)]
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

/// The step model of the compiled images ([`StepModel`]), with the profile's figures and
/// the scene's precision.
fn step_model(
    problem: &Problem,
    plan: &Plan,
    images: &[BoardImage],
    profile: &BoardProfile,
) -> Result<StepModel> {
    let decoded = decoded(images)?;
    let dims = plan.machine.dims();
    let t = super::timing::SimTiming::for_precision(profile, problem.solver.precision);
    let (timing, needs) = super::timing::model_and_needs(&decoded, dims, t)?;
    Ok(StepModel {
        timing,
        link_bytes_per_s_needed: needs.link_bytes_per_s,
        clock_hz_needed: needs.clock_hz,
        frames_alone_s: needs.frames_alone_s,
    })
}

/// The images as the step model reads them.
fn decoded(images: &[BoardImage]) -> Result<Vec<super::DecodedImage>> {
    images
        .iter()
        .map(|im| {
            super::decode_image(&im.bytes, None).map_err(|e| {
                anyhow::anyhow!(
                    "board {:?}: the step model cannot read its image: {e}",
                    im.coords
                )
            })
        })
        .collect()
}

/// The verdict's line for a modelled step over dt.
fn step_model_reason(m: &StepModel) -> String {
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
fn step_model_needs(m: &StepModel) -> String {
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

/// A balance the compiler tried and the verdict's worst time ratio with it.
#[derive(Clone, Debug, Serialize)]
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
    if super::partition::equal_weights(&super::partition::cost_weights(problem)) {
        let images = super::compile_images(problem, &by_elements)?;
        return Ok((by_elements, images, None));
    }
    let by_cost = plan_balanced(problem, machine, Balance::Cost)?;
    // The report's worst ratio: the verdict's figures and the step model's steady step.
    let compiled = |plan: Plan| -> Result<(Plan, Vec<BoardImage>, f64)> {
        let v = real_time_of(problem, &plan, profile)?;
        let images = super::compile_images(problem, &plan)?;
        let t = super::timing::SimTiming::for_precision(profile, problem.solver.precision);
        let m = super::timing::model(&decoded(&images)?, plan.machine.dims(), t)?;
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
    let check_step_fits = capacity.check_step_s_max <= budget;
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

/// The busiest board's compute per step from the measured firmware cost, and the boards a
/// 10 kHz step would need.
/// `search`: the tests of a check step's candidate search and the steps between checks.
fn capacity_report(
    problem: &Problem,
    plan: &Plan,
    profile: &BoardProfile,
    dt: f64,
    search: (usize, u32),
) -> Capacity {
    let cost =
        pe_firmware::profile::measured_cost(problem.solver.precision, problem.solver.integration);
    let per_kernel = |elements: &mut dyn Iterator<Item = usize>| {
        let mut n = [0usize; 3];
        for e in elements {
            n[kernel_of(problem, e) as usize] += 1;
        }
        n
    };
    let on_contact = contact_node_mask(problem);
    let table_nodes = on_contact.iter().filter(|&&c| c).count();
    let contact_nodes = |b: &super::plan::BoardPlan| {
        let (_, owned) = board_contact_nodes(b, &on_contact);
        FirmwareCost::charged_contact_nodes(table_nodes, owned)
    };
    let (search_tests, check_interval_steps) = search;
    let search_instructions = search_tests as f64 * cost.per_search_test as f64;
    // Per board: a steady step, and a check step (the search if it owns a contact node).
    let steps: Vec<(f64, f64, [usize; 3])> = plan
        .boards
        .iter()
        .map(|b| {
            let kinds = per_kernel(&mut b.elements.iter().map(|&e| e as usize));
            let charged = contact_nodes(b);
            let step = cost.step_instructions(kinds, b.nodes.len(), charged);
            let searches = charged > 0 && search_tests > 0;
            let check = step + if searches { search_instructions } else { 0.0 };
            (step, check, b.coords)
        })
        .collect();
    let (busiest, busiest_board) = steps
        .iter()
        .map(|&(step, _, c)| (step, c))
        .fold((0.0f64, [0; 3]), |m, b| if b.0 > m.0 { b } else { m });
    let (check_busiest, check_board) = steps
        .iter()
        .map(|&(_, check, c)| (check, c))
        .fold((0.0f64, [0; 3]), |m, b| if b.0 > m.0 { b } else { m });
    let npe = plan
        .boards
        .iter()
        .max_by_key(|b| b.elements.len())
        .map(|b| b.nodes.len() as f64 / b.elements.len().max(1) as f64)
        .unwrap_or(2.0);
    let cpe = table_nodes as f64 / problem.mesh.cells.len().max(1) as f64;
    let n = problem.mesh.cells.len();
    let elements_per_kernel = per_kernel(&mut (0..n));
    let mix = elements_per_kernel.map(|k| k as f64 / n.max(1) as f64);
    let at_10k = cost.elements_per_board(profile, 1e4, npe, cpe, mix);
    Capacity {
        clock_hz: profile.clock_hz,
        instructions_per_element_step: cost.per_element_step,
        instructions_per_box_element_step: cost.box_per_element_step,
        instructions_per_cuboid_element_step: cost.cuboid_per_element_step,
        elements_per_kernel,
        instructions_per_node_update: cost.per_node_update,
        instructions_per_contact_node: cost.per_contact_node,
        step_instructions_max: busiest,
        busiest_board,
        step_compute_s_max: busiest / profile.clock_hz as f64,
        compute_keeps_real_time: busiest / profile.clock_hz as f64 <= dt,
        instructions_per_search_test: cost.per_search_test,
        search_tests,
        check_interval_steps,
        check_step_s_max: check_busiest / profile.clock_hz as f64,
        check_step_board: check_board,
        elements_per_board_at_scene_rate: cost.elements_per_board(profile, 1.0 / dt, npe, cpe, mix),
        elements_per_board_at_10_khz: at_10k,
        boards_needed_at_10_khz: (n as f64 / at_10k).ceil() as usize,
    }
}

/// Whether each mesh node lies on a contact surface.
fn contact_node_mask(problem: &Problem) -> Vec<bool> {
    let mut on_contact = vec![false; problem.mesh.nodes.len()];
    if let Some(c) = &problem.contact {
        for &n in &c.node_globals {
            on_contact[n as usize] = true;
        }
    }
    on_contact
}

/// The contact nodes board `b` holds, and how many of them it owns.
fn board_contact_nodes(b: &super::plan::BoardPlan, on_contact: &[bool]) -> (usize, usize) {
    let contact = |n: &u32| on_contact.get(*n as usize).copied().unwrap_or(false);
    let held = b.nodes.iter().filter(|n| contact(n)).count();
    let owned = (b.nodes.iter().zip(&b.owner))
        .filter(|(n, o)| **o && contact(n))
        .count();
    (held, owned)
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
                firmware_parts: crate::firmware::parts_needed(std::iter::once(&im.header)),
            },
        )
        .collect()
}

/// The graphics stream's packets and bytes per frame and its rate.
fn graphics_report(problem: &Problem, plan: &Plan, dt: f64) -> GraphicsReport {
    let gp = graphics_params(problem, dt);
    let mask = problem.surface_node_mask();
    let surface_nodes = mask.iter().filter(|m| **m).count();
    let spread = gp.spread_steps as usize;
    let packets_per_frame: usize = plan
        .boards
        .iter()
        .map(|b| {
            let n = b
                .nodes
                .iter()
                .zip(&b.owner)
                .filter(|(n, o)| **o && mask[**n as usize])
                .count();
            // One packet per spread step (more if a slice overflows a packet).
            (0..spread)
                .map(|j| {
                    let len = (j + 1) * n / spread - j * n / spread;
                    len.div_ceil(link_proto::payload::SURFACE_NODES_PER_PACKET_MAX)
                        .max(1)
                })
                .sum::<usize>()
        })
        .sum();
    let overhead = link_proto::PACKET_HEADER_LEN
        + link_proto::CRC_LEN
        + link_proto::payload::SURFACE_HEADER_LEN;
    let bytes_per_frame =
        packets_per_frame * overhead + surface_nodes * link_proto::payload::SURFACE_ENTRY_LEN;
    GraphicsReport {
        interval_steps: gp.interval_steps,
        spread_steps: gp.spread_steps,
        surface_nodes,
        packets_per_frame,
        bytes_per_frame,
        bytes_per_s: bytes_per_frame as f64 / (gp.interval_steps as f64 * dt),
        seed_bytes_per_s: 18e6,
    }
}

/// The readable summary printed by `pe compile`.
pub fn summary(r: &CompileReport) -> String {
    let min = r.elements_per_board.iter().min().copied().unwrap_or(0);
    let max = r.elements_per_board.iter().max().copied().unwrap_or(0);
    let mut s = String::new();
    s += &format!(
        "{}: {} elements, {} nodes on {} boards ({}), {} {}\n",
        r.scene,
        r.elements,
        r.nodes,
        r.elements_per_board.len(),
        r.machine,
        r.precision,
        r.integration
    );
    s += &format!("  elements per board {min}..{max} (imbalance max/mean {:.3}); nodes per board {}..{}; {} replicas\n",
        r.load_imbalance, r.nodes_per_board.iter().min().copied().unwrap_or(0), r.nodes_per_board.iter().max().copied().unwrap_or(0), r.replicated_nodes);
    s += &format!(
        "  exchange rounds per step: x {}, y {}, z {} (of which after the z exchange, the broadcasts: x {}, y {})\n",
        r.rounds[0], r.rounds[1], r.rounds[2], r.late_rounds[0], r.late_rounds[1]
    );
    s += &format!(
        "  border nodes per face (max over boards): +x {} -x {} +y {} -y {} +z {} -z {}\n",
        r.border_nodes_per_face_max[0],
        r.border_nodes_per_face_max[1],
        r.border_nodes_per_face_max[2],
        r.border_nodes_per_face_max[3],
        r.border_nodes_per_face_max[4],
        r.border_nodes_per_face_max[5]
    );
    s += &format!(
        "  force vectors per step: {} in all, {} on the busiest link direction\n",
        r.force_vectors_per_step, r.force_vectors_per_link_max
    );
    s += "  (a force vector: one node's partial or summed force that one board sends to a neighbour over one link in one exchange round; every round and both directions counted. A node on k boards of one line costs 2(k - 1): its partial sums go to one board and the total comes back; a node on a 2x2 block of boards costs 6, on 2x2x2 14: reduced along x, then y, exchanged along z, broadcast back along y, then x)\n";
    s += &format!(
        "  partition: slabs refined by simulated annealing (seed {}) within {:.2} x the mean {} per board{}\n",
        crate::compile::partition::refine::ANNEAL_SEED,
        crate::compile::partition::BALANCE_MAX,
        match r.balance {
            Balance::Elements => "elements",
            Balance::Cost => "cost (kernel and contact instructions)",
        },
        match &r.balance_other {
            Some(o) => format!(
                "; chosen over balancing {}: worst time ratio {:.2} against {:.2}",
                o.balance.name(),
                r.real_time.worst_ratio,
                o.worst_ratio
            ),
            None => String::new(),
        }
    );
    s += &format!("  bytes per step: {} in all, {} on the busiest link; at dt = {:.3e} s ({:.0} steps/s): {:.3} GB/s in all, {:.1} MB/s on the busiest link ({:.0}% of its {:.3} MB/s)\n",
        r.bytes_per_step_total, r.bytes_per_step_per_link_max, r.dt_s, r.steps_per_s, r.bandwidth_total_bytes_per_s / 1e9,
        r.bandwidth_per_link_max_bytes_per_s / 1e6, 100.0 * r.link_utilisation_max, r.link_bandwidth_bytes_per_s as f64 / 1e6);
    s += &format!(
        "  largest image {} bytes, largest run-time state {} bytes ({} profile)\n",
        r.image_bytes_max, r.ram_bytes_max, r.profile
    );
    let parts: Vec<String> = pe_firmware::image::Feature::ALL
        .iter()
        .map(|f| {
            let n = r
                .boards
                .iter()
                .filter(|b| b.firmware_parts.contains(&f.name()))
                .count();
            format!("{} on {n} of {} boards", f.name(), r.boards.len())
        })
        .collect();
    s += &format!(
        "  firmware parts the images need (cargo features; `pe image` builds the firmware with those some board needs, and no other): {}\n",
        parts.join(", ")
    );
    let c = &r.capacity;
    s += &format!(
        "  element kernels: {} cuboids, {} parallelepipeds, {} general\n  board compute ({} profile, {:.0} MHz, measured {} instructions per element-step (general), {} (parallelepiped), {} (cuboid), {} per node update, {} more per contact node of the whole table on a board that owns one, one instruction per cycle assumed): busiest board {:.1} us per step against dt = {:.1} us ({}); {:.1} elements per board at this scene's rate, {:.1} at 10 kHz, so {} boards for this scene at 10 kHz\n",
        c.elements_per_kernel[2], c.elements_per_kernel[1], c.elements_per_kernel[0],
        r.profile, c.clock_hz as f64 / 1e6, c.instructions_per_element_step, c.instructions_per_box_element_step, c.instructions_per_cuboid_element_step, c.instructions_per_node_update, c.instructions_per_contact_node,
        c.step_compute_s_max * 1e6, r.dt_s * 1e6,
        if c.compute_keeps_real_time { "within dt" } else { "over dt" },
        c.elements_per_board_at_scene_rate, c.elements_per_board_at_10_khz, c.boards_needed_at_10_khz
    );
    if c.check_interval_steps > 0 {
        let [x, y, z] = c.check_step_board;
        s += &format!(
            "  check step (every {} steps): the candidate search, {} node-face tests at {} instructions each on every board that owns a contact node; busiest board ({x},{y},{z}) {:.1} us\n",
            c.check_interval_steps, c.search_tests, c.instructions_per_search_test, c.check_step_s_max * 1e6
        );
    }
    let g = &r.graphics;
    s += &format!(
        "  graphics: {} surface nodes every {} steps ({:.1} ms) spread over {} steps: {} packets, {} bytes per frame, {:.3} MB/s (the seed: 18 MB/s)\n",
        g.surface_nodes, g.interval_steps, g.interval_steps as f64 * r.dt_s * 1e3, g.spread_steps, g.packets_per_frame, g.bytes_per_frame, g.bytes_per_s / 1e6
    );
    if let Some(c) = &r.contact {
        s += &format!(
            "  contact: {} nodes, {} faces, {} pairs, {} tools on {} boards; bounding boxes every {} steps (travel {:.2} mm, box margin {:.2} mm); at rest {} channels, {} node vectors per step, {:.2} MB/s (the seed: ~300 vectors, 72 MB/s)\n",
            c.contact_nodes, c.contact_faces, c.pairs, c.tools, c.contact_boards, c.check_interval_steps, c.travel_max_m * 1e3, c.box_margin_m * 1e3,
            c.channels_at_rest, c.vectors_per_step_at_rest, c.bytes_per_s_at_rest / 1e6
        );
        if let Some(g) = &c.global_busiest_at_rest {
            let [x, y, z] = g.board;
            s += &format!(
                "  global ports ({:.1} MB/s into and out of each board): busiest at rest ({x},{y},{z}): {} bytes in, {} out per step, {:.1} us against dt = {:.1} us\n",
                r.global_bytes_per_s as f64 / 1e6, g.bytes_in_per_step, g.bytes_out_per_step, g.time_per_step_s * 1e6, r.dt_s * 1e6
            );
        }
    }
    s += &real_time_lines(r);
    s += "  seed's reference case: 2000 elements on 4x4x4 boards at dt = 100 us: 5600 force vectors per step, 1.35 GB/s in all\n";
    s += &format!(
        "  this scene at dt = 100 us: {} force vectors per step, {:.3} GB/s in all\n",
        r.force_vectors_per_step,
        r.bytes_per_step_total as f64 * 1e4 / 1e9
    );
    s
}

/// The links against the step and the verdict, for the summary.
fn real_time_lines(r: &CompileReport) -> String {
    let v = &r.real_time;
    let mut s = String::new();
    match &v.link_busiest {
        Some(l) => {
            let [x, y, z] = l.board;
            s += &format!(
                "  links ({:.3} MB/s each way, {:.1} us per frame): busiest ({x},{y},{z}) {}: {} bytes in {} frames per step, {:.1} us against dt = {:.1} us; {} of {} link directions over dt\n",
                r.link_bandwidth_bytes_per_s as f64 / 1e6,
                r.link_frame_latency_s * 1e6,
                l.face,
                l.bytes_per_step,
                l.frames_per_step,
                l.time_per_step_s * 1e6,
                v.dt_s * 1e6,
                v.links_over_count,
                v.links
            );
        }
        None => s += "  links: nothing exchanged\n",
    }
    let m = &r.step_model.timing;
    let [x, y, z] = m.slowest_board;
    s += &format!(
        "  step model (every board runs the firmware's step program; a round waits for its frames): a step ends at {:.1} us on board ({x},{y},{z}) ({:.1} us computing){} against dt = {:.1} us; {}\n",
        m.step_s * 1e6,
        m.compute_s * 1e6,
        match m.check_step_s {
            Some(c) => {
                let [x, y, z] = m.check_slowest_board;
                format!(", a check step at {:.1} us on board ({x},{y},{z})", c * 1e6)
            }
            None => String::new(),
        },
        m.dt_s * 1e6,
        step_model_needs(&r.step_model)
    );
    if v.keeps_real_time {
        s += &format!(
            "  verdict: keeps real time (busiest board's compute {:.1} us{} within dt / {COMPUTE_MARGIN} = {:.1} us, every link within dt{}, the modelled step within dt)\n",
            v.compute_s_max * 1e6,
            if v.check_interval_steps > 0 {
                format!(", {:.1} us at a check step", v.check_step_s_max * 1e6)
            } else {
                String::new()
            },
            v.compute_budget_s * 1e6,
            if v.global_busiest.is_some() { ", every global port's contact traffic at rest within dt" } else { "" }
        );
    } else {
        s += "  verdict: does NOT keep real time:\n";
        for why in &v.reasons {
            s += &format!("    {why}\n");
        }
    }
    s
}
