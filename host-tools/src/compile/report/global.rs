//! The global network's figures: the contact traffic with the tissue at rest (each contact
//! board's global port) and the graphics stream.

use anyhow::Result;
use link_proto::packet::packet_len;
use link_proto::payload::{
    nodes_per_packet_max, NodesHeader, SurfaceHeader, SURFACE_NODES_PER_PACKET_MAX,
};
use pe_firmware::profile::BoardProfile;
use serde::{Deserialize, Serialize};

use crate::compile::image::graphics_params;
use crate::compile::plan::Plan;
use crate::problem::contact::ContactRun;
use crate::problem::Problem;

/// The graphics stream's cost.
#[derive(Clone, Debug, Serialize, Deserialize)]
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
#[derive(Clone, Debug, Serialize, Deserialize)]
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
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GlobalPortLoad {
    pub board: [usize; 3],
    pub bytes_in_per_step: usize,
    pub bytes_out_per_step: usize,
    /// The larger direction at the profile's global rate (s).
    pub time_per_step_s: f64,
}

/// The packets that carry `n` entries, at most `per_packet` in each and one (empty) when
/// `n` is 0, as the runtime sends them, and their bytes: each packet [`packet_len`] of its
/// payload, `payload_len(entries)` (no recovery envelope).
fn packets(n: usize, per_packet: usize, payload_len: impl Fn(usize) -> usize) -> (usize, usize) {
    let count = n.div_ceil(per_packet).max(1);
    let bytes = (0..count)
        .map(|k| packet_len(payload_len((n - k * per_packet).min(per_packet))))
        .sum();
    (count, bytes)
}

/// Bytes of the contact-node packets that carry `n` node entries of `precision`.
fn node_packet_bytes(n: usize, precision: link_proto::Precision) -> usize {
    let per_packet = nodes_per_packet_max(precision);
    packets(n, per_packet, |k| NodesHeader::payload_len(k, precision)).1
}

/// The contact traffic at rest: the runtime's box test on the reference positions, from
/// the contact tables (`contact_tables`) and their contact boards.
pub(super) fn contact_report(
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

/// The graphics stream's packets and bytes per frame and its rate.
pub(super) fn graphics_report(problem: &Problem, plan: &Plan, dt: f64) -> GraphicsReport {
    let gp = graphics_params(problem, dt);
    let mask = problem.surface_node_mask();
    let surface_nodes = mask.iter().filter(|m| **m).count();
    let spread = gp.spread_steps as usize;
    // Each board's owned surface nodes, one slice per spread step, each slice in one
    // packet (more if it overflows one).
    let (packets_per_frame, bytes_per_frame) = plan
        .boards
        .iter()
        .flat_map(|b| {
            let n = (b.nodes.iter().zip(&b.owner))
                .filter(|(n, o)| **o && mask[**n as usize])
                .count();
            (0..spread).map(move |j| (j + 1) * n / spread - j * n / spread)
        })
        .map(|slice| {
            packets(
                slice,
                SURFACE_NODES_PER_PACKET_MAX,
                SurfaceHeader::payload_len,
            )
        })
        .fold((0, 0), |(p, b), (pk, bk)| (p + pk, b + bk));
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
