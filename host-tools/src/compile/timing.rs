//! The step model: would the board array keep the scene's step rate on the real links?
//! One home for `pe compile`'s verdict and board-sim's link model.
//!
//! Replays one step of every board's schedule (the firmware's own step program,
//! [`pe_firmware::runtime::Program`]) in model time: batches take
//! `elements × cycles_per_element / clock`, a frame arrives `latency + bytes / bandwidth`
//! after it is sent (links are full duplex, one frame at a time per direction), a receive
//! waits for its frame. The cycles per element-step and per node update are the firmware's
//! instruction counts measured under QEMU (`pe_firmware::profile::MEASURED_COST`, from
//! `scripts/board-cost.sh`), taking one instruction per cycle. With contact pairs it
//! replays a check step too: every board that owns a contact node then also searches the
//! candidates of the whole table (the compile report's charge).

use link_proto::frame::frame_len;
use link_proto::{Face, Machine};
use pe_firmware::image::{Integration, Precision};
use pe_firmware::profile::{link_time_s, measured_cost, BoardProfile, FirmwareCost, StepCost};
use pe_firmware::runtime::{Op, Program, ROUNDS_PER_AXIS_MAX};
use serde::{Deserialize, Serialize};

use super::DecodedImage;

/// Model inputs.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct SimTiming {
    pub clock_hz: f64,
    pub cycles_per_element_reduced: f64,
    pub cycles_per_element_full: f64,
    /// A parallelepiped (reduced integration's cheap kernel).
    pub cycles_per_box_element: f64,
    /// An axis-aligned cuboid (reduced integration's cheapest kernel).
    pub cycles_per_cuboid_element: f64,
    pub cycles_per_node_update: f64,
    /// Extra per contact-surface node.
    pub cycles_per_contact_node: f64,
    /// Per node-face test of a check step's candidate search.
    pub cycles_per_search_test: f64,
    pub link_bytes_per_s: f64,
    pub link_latency_s: f64,
    /// Bytes link recovery adds to every frame (its envelope,
    /// [`link_proto::recovery::OVERHEAD`]; 0 without recovery, as the board firmware's links
    /// run). Retransmissions are not modelled: at the loss rates recovery is
    /// for (1e-3 per frame) they add that fraction of a frame per frame.
    pub frame_overhead_bytes: usize,
}

impl SimTiming {
    /// From a board profile, with the measured f64 instruction counts (the seed's double
    /// precision) at one instruction per cycle.
    pub fn from_profile(p: &BoardProfile) -> Self {
        Self::for_precision(p, Precision::F64)
    }

    /// From a board profile and the measured instruction counts of `precision` (one
    /// instruction per cycle; the node update is the reduced variant's, the larger).
    pub fn for_precision(p: &BoardProfile, precision: Precision) -> Self {
        let reduced = measured_cost(precision, Integration::Reduced);
        let full = measured_cost(precision, Integration::Full);
        SimTiming {
            clock_hz: p.clock_hz as f64,
            cycles_per_element_reduced: reduced.per_element_step as f64,
            cycles_per_element_full: full.per_element_step as f64,
            cycles_per_box_element: reduced.box_per_element_step as f64,
            cycles_per_cuboid_element: reduced.cuboid_per_element_step as f64,
            cycles_per_node_update: reduced.per_node_update.max(full.per_node_update) as f64,
            cycles_per_contact_node: reduced.per_contact_node.max(full.per_contact_node) as f64,
            cycles_per_search_test: reduced.per_search_test.max(full.per_search_test) as f64,
            link_bytes_per_s: p.link_bytes_per_s as f64,
            link_latency_s: p.link_latency_s(),
            frame_overhead_bytes: 0,
        }
    }

    /// What a step of images of `integration` costs ([`StepCost`]: the general kernel's
    /// element of that integration, the others' as measured, the node update and the
    /// contact nodes).
    pub fn step_cost(&self, integration: Integration) -> StepCost {
        StepCost {
            per_element: [
                match integration {
                    Integration::Full => self.cycles_per_element_full,
                    Integration::Reduced => self.cycles_per_element_reduced,
                },
                self.cycles_per_box_element,
                self.cycles_per_cuboid_element,
            ],
            per_node_update: self.cycles_per_node_update,
            per_contact_node: self.cycles_per_contact_node,
        }
    }

    /// The time of a force frame of `values` values of `precision` on these links: its
    /// length ([`frame_len`]) and the recovery envelope's bytes, if any, at the link rate
    /// plus the frame's fixed cost ([`link_time_s`], the formula of the profile's links).
    pub fn frame_time_s(&self, values: usize, precision: Precision) -> f64 {
        let len = frame_len(values, precision.wire()) + self.frame_overhead_bytes;
        link_time_s(len, 1, self.link_bytes_per_s, self.link_latency_s)
    }
}

/// Model results.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StepTiming {
    pub inputs: SimTiming,
    /// Modelled time of one step on the slowest board (s).
    pub step_s: f64,
    /// Of which computing (s), on that board.
    pub compute_s: f64,
    /// The scene's time step (s) and whether the array keeps up with it (at a check step
    /// too).
    pub dt_s: f64,
    pub real_time: bool,
    pub slowest_board: [usize; 3],
    /// With contact pairs: a check step (every `check_interval_steps`) on its slowest
    /// board (s), and that board.
    pub check_interval_steps: u32,
    pub check_step_s: Option<f64>,
    pub check_slowest_board: [usize; 3],
}

/// The contact nodes a board's step is charged for ([`FirmwareCost::charged_contact_nodes`]).
fn charged_contact_nodes(im: &DecodedImage) -> usize {
    let owned = im.contact_nodes.iter().filter(|(_, p)| p.owned).count();
    FirmwareCost::charged_contact_nodes(im.contact_nodes.len(), owned)
}

/// Models one step of the machine of `dims` whose decoded images are `imgs` (one per
/// board, x fastest).
pub fn model(imgs: &[DecodedImage], dims: [usize; 3], t: SimTiming) -> anyhow::Result<StepTiming> {
    Ok(Replay::new(imgs, dims)?.run(t))
}

/// What the step model says the scene needs to keep its step, each figure with the other
/// inputs of `t` as they are ([`model_and_needs`]).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct Needs {
    /// The least link rate (bytes/s each way, the frames' fixed time as `t` has it) at
    /// which the modelled step, and a check step, fit within the scene's step; `None` when
    /// no rate would: the compute and the frames' fixed times alone exceed the step.
    pub link_bytes_per_s: Option<f64>,
    /// The least clock (Hz, one instruction per cycle) at which they fit at `t`'s links;
    /// `None` when no clock would: the frames alone exceed the step.
    pub clock_hz: Option<f64>,
    /// The modelled step (the longer of a step and a check step) with the compute taken
    /// as free (an infinite clock): the chain of frames alone, each round waiting for the
    /// one before (s).
    pub frames_alone_s: f64,
}

/// The least `x` in `[1, 1e15]` for which `fits(x)` holds, to 0.1% (by bisection on a
/// log scale: `fits` must hold from some `x` on); `None` when not even `1e15` fits.
fn least(fits: impl Fn(f64) -> bool) -> Option<f64> {
    let (mut lo, mut hi) = (1.0f64, 1e15f64);
    if !fits(hi) {
        return None;
    }
    while hi / lo > 1.001 {
        let mid = (lo * hi).sqrt();
        if fits(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(hi)
}

/// One step of the model at `t` ([`model`]) and its needs ([`Needs`]): the least link
/// rate at `t`'s clock and the least clock at `t`'s links (the modelled step only shortens
/// as either grows), and the frames' chain with the compute free. One replay for all.
pub fn model_and_needs(
    imgs: &[DecodedImage],
    dims: [usize; 3],
    t: SimTiming,
) -> anyhow::Result<(StepTiming, Needs)> {
    let replay = Replay::new(imgs, dims)?;
    let free = replay.run(SimTiming {
        clock_hz: f64::INFINITY,
        ..t
    });
    let needs = Needs {
        link_bytes_per_s: least(|rate| {
            replay
                .run(SimTiming {
                    link_bytes_per_s: rate,
                    ..t
                })
                .real_time
        }),
        clock_hz: least(|clock_hz| replay.run(SimTiming { clock_hz, ..t }).real_time),
        frames_alone_s: free.check_step_s.unwrap_or(0.0).max(free.step_s),
    };
    Ok((replay.run(t), needs))
}

/// What replaying a step needs besides the timing figures, worked out once from the
/// images: the step program, and each board's candidate search at a check step.
struct Replay<'a> {
    imgs: &'a [DecodedImage],
    machine: Machine,
    /// Every board walks the firmware's own step program in model time. Sends of an
    /// operation happen before the receives that wait for them (the program's order), so
    /// walking it operation by operation across the boards is exact.
    program: Program,
    /// Node-face tests of a check step's search per board: the whole table's, on a board
    /// that owns a contact node (0 elsewhere, and without pairs).
    search_tests: Vec<usize>,
}

impl<'a> Replay<'a> {
    fn new(imgs: &'a [DecodedImage], dims: [usize; 3]) -> anyhow::Result<Replay<'a>> {
        let machine = Machine::new(dims).ok_or_else(|| {
            anyhow::anyhow!(
                "a {}x{}x{} machine: 1..16 boards per axis",
                dims[0],
                dims[1],
                dims[2]
            )
        })?;
        let Some(first) = imgs.first().filter(|_| imgs.len() == machine.count()) else {
            anyhow::bail!(
                "the step model needs one image per board: {} for a {}x{}x{} machine",
                imgs.len(),
                dims[0],
                dims[1],
                dims[2]
            );
        };
        let c = &first.header.counts;
        let search_tests = imgs
            .iter()
            .map(|im| {
                if charged_contact_nodes(im) == 0 {
                    return 0;
                }
                let nodes: Vec<_> = im.contact_nodes.iter().map(|(n, _)| *n).collect();
                pe_firmware::physics::contact::search_tests(
                    &pe_firmware::physics::contact::ContactModel {
                        nodes: &nodes,
                        faces: &im.contact_faces,
                        pairs: &im.pairs,
                        tools: &im.tools,
                    },
                )
            })
            .collect();
        Ok(Replay {
            imgs,
            machine,
            program: Program::new(&c.rounds, &c.late_rounds, false, false),
            search_tests,
        })
    }

    /// One step, and a check step if any board searches, with the figures of `t`.
    fn run(&self, t: SimTiming) -> StepTiming {
        let h = self.imgs[0].header;
        let search: Vec<f64> = self
            .search_tests
            .iter()
            .map(|&n| n as f64 * t.cycles_per_search_test / t.clock_hz)
            .collect();
        let (step_s, b, compute_s) = self.walk(&t, &vec![0.0; search.len()]);
        let check = search
            .iter()
            .any(|&s| s > 0.0)
            .then(|| self.walk(&t, &search));
        let dt_s = h.params.dt_s;
        StepTiming {
            inputs: t,
            step_s,
            compute_s,
            dt_s,
            real_time: step_s <= dt_s && check.is_none_or(|c| c.0 <= dt_s),
            slowest_board: self.machine.coords(b),
            check_interval_steps: if check.is_some() {
                h.contact.check_interval_steps
            } else {
                0
            },
            check_step_s: check.map(|c| c.0),
            check_slowest_board: self.machine.coords(check.map_or(b, |c| c.1)),
        }
    }

    /// One step of every board in model time, each board computing `extra[b]` (s) more in
    /// its node update: the slowest board's step (s), that board, and its compute (s).
    fn walk(&self, t: &SimTiming, extra: &[f64]) -> (f64, usize, f64) {
        let (imgs, program, machine) = (self.imgs, &self.program, self.machine);
        let h = imgs[0].header;
        let cost = t.step_cost(h.integration);
        let count = imgs.len();
        let mut now = vec![0.0f64; count];
        let mut compute = vec![0.0f64; count];
        // Send time per board, axis, round and face.
        let mut sent = vec![[[[0.0f64; 2]; ROUNDS_PER_AXIS_MAX]; 3]; count];
        for &op in program.ops() {
            for b in 0..count {
                let im = &imgs[b];
                match op {
                    Op::Batch(k) => {
                        let k = k as usize;
                        let size = |e: [u32; 4]| if k == 0 { e[0] } else { e[k] - e[k - 1] } as f64;
                        let n = &im.header.counts;
                        let c = cost.elements([
                            size(n.batch_ends),
                            size(n.box_batch_ends),
                            size(n.cuboid_batch_ends),
                        ]) / t.clock_hz;
                        now[b] += c;
                        compute[b] += c;
                    }
                    Op::Update => {
                        let c = cost.update(
                            im.header.counts.nodes as f64,
                            charged_contact_nodes(im) as f64,
                        ) / t.clock_hz
                            + extra[b];
                        now[b] += c;
                        compute[b] += c;
                    }
                    Op::Send(a, r, f) => sent[b][a as usize][r as usize][f as usize] = now[b],
                    Op::Recv(a, r, f) => {
                        let (a, r, f) = (a as usize, r as usize, f as usize);
                        let n_recv = im.rounds[a].get(r).map_or(0, |x| x.recv[f].len());
                        if n_recv == 0 {
                            continue;
                        }
                        // Face 0 (+axis) receives what the +axis neighbour sent on its −axis
                        // face (a face that receives has a neighbour: the image's rounds).
                        let Some(d) = machine.neighbour(machine.coords(b), Face::ALL[2 * a + f])
                        else {
                            continue;
                        };
                        let from = sent[machine.index(d)][a][r][1 - f];
                        now[b] = now[b].max(from + t.frame_time_s(3 * n_recv, h.precision));
                    }
                    Op::Graphics | Op::Contact | Op::External(_) => {}
                }
            }
        }
        let (step_s, b) = now
            .iter()
            .enumerate()
            .fold((0.0, 0), |w, (b, &s)| if s > w.0 { (s, b) } else { w });
        (step_s, b, compute[b])
    }
}
