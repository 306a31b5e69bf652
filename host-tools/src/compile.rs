//! The schedule compiler (`pe compile`): partitions a scene onto the board mesh and emits one
//! static schedule image per board (the seed's section 4).
//!
//! Per board: its elements in four batches (x border, y border, z border, inner), the nodes
//! it holds (own nodes and replicas), and one exchange list per face. A node is held by every
//! board in the bounding box of the boards whose elements touch it (at most 2 per axis, see
//! [`crate::partition`]); across a face both boards list the shared nodes in ascending
//! global order, so frames carry no addresses. The step (both ends know it):
//!
//! recover batch x; send ±x; recover batch y; add from ±x; send ±y; recover batch z;
//! add from ±y; send ±z; recover inner; add from ±z; update positions.
//!
//! After the x, y and z exchanges every holder of a node has the same total force, so all
//! replicas compute identical positions (two-term sums `a + b = b + a` are exact in IEEE).
//! Gravity and loads are applied once, by the node's owner (the lowest-numbered board whose
//! elements touch it), into its partial sum just before the node is first sent (or before
//! the update, if it is never sent).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use pe_firmware::image::*;
use pe_firmware::physics::{CentralDifference, MaterialLaw, Real};
use pe_firmware::profile::BoardProfile;
use serde::Serialize;

use crate::partition::{node_board_range, node_elements, partition, Machine};
use crate::problem::{NodeKind, Problem};

/// Faces in image order.
pub const FACE_NAMES: [&str; 6] = ["+x", "-x", "+y", "-y", "+z", "-z"];

/// One exchange round of one axis on one board: per face (+axis, −axis) the global nodes to
/// send and to receive (with how to combine), in wire order (ascending global id).
#[derive(Clone, Debug, Default)]
pub struct RoundPlan {
    pub send: [Vec<u32>; 2],
    pub recv: [Vec<(u32, Combine)>; 2],
}

/// One board's part of the schedule, in global numbering.
#[derive(Clone, Debug)]
pub struct BoardPlan {
    pub coords: [usize; 3],
    /// Global element ids in batch order.
    pub elements: Vec<u32>,
    /// Ends (exclusive) of batches x, y, z, inner in `elements`.
    pub batch_ends: [usize; 4],
    /// Global node ids, ascending: the local numbering.
    pub nodes: Vec<u32>,
    /// Whether this board owns each local node.
    pub owner: Vec<bool>,
    /// Distinct global nodes exchanged across each face (+x, −x, +y, −y, +z, −z).
    pub exchange: [Vec<u32>; 6],
    /// Exchange rounds per axis.
    pub rounds: [Vec<RoundPlan>; 3],
    /// Stage (0 = x, 1 = y, 2 = z, 3 = before the update) at which each owned node's
    /// external force is added; `u8::MAX` for nodes this board does not own.
    pub ext_stage: Vec<u8>,
}

/// The whole machine's schedule.
#[derive(Clone, Debug)]
pub struct Plan {
    pub machine: Machine,
    pub element_board: Vec<u32>,
    /// Owner board of every node.
    pub node_owner: Vec<u32>,
    pub rounds: [usize; 3],
    pub boards: Vec<BoardPlan>,
}

/// One transfer of a node's value along an axis line: in `round`, from line position
/// `from` to `to` (adjacent), combined at the receiver by `combine`.
struct Transfer {
    round: usize,
    from: usize,
    to: usize,
    combine: Combine,
}

/// The summation tree of a node held by `m + 1` boards in a line (positions 0..=m).
/// Two boards: one symmetric exchange (`p0 + p1` on both, exact since `a + b = b + a`).
/// More: reduce towards the middle board `r = m/2` (left prefix sums `((p0 + p1) + …)`, right
/// suffix sums), the middle forms `(left + p_r) + right`, then broadcasts the total back.
fn line_transfers(m: usize) -> Vec<Transfer> {
    let t = |round, from, to, combine| Transfer {
        round,
        from,
        to,
        combine,
    };
    if m == 1 {
        return vec![t(0, 0, 1, Combine::Before), t(0, 1, 0, Combine::After)];
    }
    let root = m / 2;
    let reduce = m - root;
    let mut v = Vec::new();
    for i in 0..root {
        v.push(t(i, i, i + 1, Combine::Before));
    }
    for j in root + 1..=m {
        v.push(t(m - j, j, j - 1, Combine::After));
    }
    for d in 1..=root {
        v.push(t(reduce + d - 1, root - d + 1, root - d, Combine::Replace));
    }
    for d in 1..=m - root {
        v.push(t(reduce + d - 1, root + d - 1, root + d, Combine::Replace));
    }
    v
}

/// Rounds the line of `m + 1` boards needs.
pub fn line_rounds(m: usize) -> usize {
    match m {
        0 => 0,
        1 => 1,
        _ => 2 * (m - m / 2),
    }
}

pub fn plan(problem: &Problem, machine: Machine) -> Result<Plan> {
    let mesh = &problem.mesh;
    let element_board = partition(mesh, machine)?;
    let around = node_elements(mesh);
    let nb = machine.count();
    let mut node_box = Vec::with_capacity(mesh.nodes.len());
    let mut rounds = [0usize; 3];
    let mut node_owner = vec![0u32; mesh.nodes.len()];
    for (n, els) in around.iter().enumerate() {
        if els.is_empty() {
            bail!(
                "node {} of mesh {} belongs to no cell",
                mesh.node_tags[n],
                mesh.source
            );
        }
        let (lo, hi) = node_board_range(machine, &element_board, els);
        for a in 0..3 {
            rounds[a] = rounds[a].max(line_rounds(hi[a] - lo[a]));
        }
        node_owner[n] = els
            .iter()
            .map(|&e| element_board[e as usize])
            .min()
            .unwrap_or(0);
        node_box.push((lo, hi));
    }
    let mut boards: Vec<BoardPlan> = (0..nb)
        .map(|b| BoardPlan {
            coords: machine.coords(b),
            elements: Vec::new(),
            batch_ends: [0; 4],
            nodes: Vec::new(),
            owner: Vec::new(),
            exchange: Default::default(),
            rounds: core::array::from_fn(|a| vec![RoundPlan::default(); rounds[a]]),
            ext_stage: Vec::new(),
        })
        .collect();
    let trees: Vec<Vec<Transfer>> = (0..machine.dims.iter().copied().max().unwrap_or(1))
        .map(line_transfers)
        .collect();
    for (n, &(lo, hi)) in node_box.iter().enumerate() {
        let n32 = n as u32;
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let b = machine.index([x, y, z]);
                    boards[b].nodes.push(n32);
                    boards[b].owner.push(b as u32 == node_owner[n]);
                }
            }
        }
        for a in 0..3 {
            let m = hi[a] - lo[a];
            if m == 0 {
                continue;
            }
            // Every line of the box along axis a runs the same tree.
            let (o1, o2) = ((a + 1) % 3, (a + 2) % 3);
            for p in lo[o1]..=hi[o1] {
                for q in lo[o2]..=hi[o2] {
                    let at = |t: usize| {
                        let mut c = [0; 3];
                        c[a] = lo[a] + t;
                        c[o1] = p;
                        c[o2] = q;
                        machine.index(c)
                    };
                    for tr in &trees[m] {
                        // face index within the axis: 0 = +axis, 1 = −axis
                        let (send_face, recv_face) = if tr.to > tr.from { (0, 1) } else { (1, 0) };
                        boards[at(tr.from)].rounds[a][tr.round].send[send_face].push(n32);
                        boards[at(tr.to)].rounds[a][tr.round].recv[recv_face]
                            .push((n32, tr.combine));
                    }
                }
            }
        }
    }
    for (e, &b) in element_board.iter().enumerate() {
        boards[b as usize].elements.push(e as u32);
    }
    for bp in &mut boards {
        for a in 0..3 {
            for f in 0..2 {
                let mut all: Vec<u32> = bp.rounds[a]
                    .iter()
                    .flat_map(|r| {
                        r.send[f]
                            .iter()
                            .copied()
                            .chain(r.recv[f].iter().map(|x| x.0))
                    })
                    .collect();
                all.sort_unstable();
                all.dedup();
                bp.exchange[2 * a + f] = all;
            }
        }
        let axis_nodes: [std::collections::HashSet<u32>; 3] = core::array::from_fn(|a| {
            bp.exchange[2 * a]
                .iter()
                .chain(&bp.exchange[2 * a + 1])
                .copied()
                .collect()
        });
        let stage_of_element = |e: u32| {
            let cell = &mesh.cells[e as usize];
            (0..3)
                .find(|&a| cell.iter().any(|n| axis_nodes[a].contains(n)))
                .unwrap_or(3)
        };
        let mut staged: Vec<(usize, u32)> = bp
            .elements
            .iter()
            .map(|&e| (stage_of_element(e), e))
            .collect();
        staged.sort();
        for s in 0..4 {
            bp.batch_ends[s] = staged.iter().filter(|(st, _)| *st <= s).count();
        }
        bp.elements = staged.into_iter().map(|(_, e)| e).collect();
        bp.ext_stage = bp
            .nodes
            .iter()
            .zip(&bp.owner)
            .map(|(n, own)| {
                if !own {
                    u8::MAX
                } else {
                    (0..3).find(|&a| axis_nodes[a].contains(n)).unwrap_or(3) as u8
                }
            })
            .collect();
    }
    Ok(Plan {
        machine,
        element_board,
        node_owner,
        rounds,
        boards,
    })
}

/// Bytes of RAM the runtime needs for a board's image contents and state.
pub fn runtime_ram_bytes(h: &ImageHeader) -> u64 {
    let w = if h.precision == Precision::F64 { 8 } else { 4 };
    let c = &h.counts;
    let element = match h.integration {
        // nodes, material, volume, 8x3 gradients, 8x4 hourglass, stiffness
        Integration::Reduced => 32 + 8 + w * (1 + 24 + 32 + 1),
        Integration::Full => 32 + 8 + w * 8 * (24 + 1),
    };
    let node = 8 + w * 4 + 8 /* record */ + w * 9 /* u, u_prev, f */;
    let exchange: u64 = (c.sends as u64) * 2 + (c.recvs as u64) * 4;
    let link_buffers = 6 * 2 * (12 + 3 * w * link_proto::BORDER_NODES_PER_FACE_MAX as u64);
    let contact = c.contact_nodes as u64
        * (4 + 24 + 8 + 1 + 4 + 1 + 3 * 24 /* x, x at check, force */ + 8)
        + c.contact_faces as u64 * 17
        + c.pairs as u64 * 16
        + c.tools as u64 * 64
        + c.graphics_nodes as u64 * 2;
    contact
        + c.elements as u64 * element
        + c.nodes as u64 * node
        + exchange
        + c.path_points as u64 * 40
        + c.loads as u64 * 40
        + c.materials as u64 * 48
        + link_buffers
}

/// A compiled image with its figures.
pub struct BoardImage {
    pub coords: [usize; 3],
    pub header: ImageHeader,
    pub bytes: Vec<u8>,
    pub ram_bytes: u64,
}

/// Prescribed paths first, then the distinct load ramps.
fn path_table(problem: &Problem) -> (Vec<PathPoint>, Vec<Option<u16>>) {
    let mut points = Vec::new();
    for (k, p) in problem.paths.iter().enumerate() {
        for (t, v) in &p.points {
            points.push(PathPoint {
                path: k as u16,
                t_s: *t,
                value: *v,
            });
        }
    }
    let mut ramps: Vec<&crate::problem::Path1<1>> = Vec::new();
    let mut load_ramp = Vec::new();
    for l in &problem.loads {
        load_ramp.push(l.ramp.as_ref().map(|r| {
            let k = ramps.iter().position(|q| *q == r).unwrap_or_else(|| {
                ramps.push(r);
                ramps.len() - 1
            });
            (problem.paths.len() + k) as u16
        }));
    }
    for (k, r) in ramps.iter().enumerate() {
        for (t, v) in &r.points {
            points.push(PathPoint {
                path: (problem.paths.len() + k) as u16,
                t_s: *t,
                value: [v[0], 0.0, 0.0],
            });
        }
    }
    (points, load_ramp)
}

/// What every board's image shares: the contact tables, which nodes are on the surface, the
/// graphics timing (computed once per compilation).
struct Shared {
    contact: Option<(crate::problem::contact::ContactRun, Vec<u8>)>,
    on_surface: Vec<bool>,
    graphics: GraphicsParams,
}

fn write_image<T: Real + Serialize>(
    problem: &Problem,
    plan: &Plan,
    shared: &Shared,
    b: usize,
) -> Result<BoardImage> {
    let bp = &plan.boards[b];
    let (dt, _) = problem.time_step()?;
    let steps = problem.steps(dt);
    let cd = CentralDifference::<T>::new(dt, problem.solver.damping);
    let local: BTreeMap<u32, u16> = bp
        .nodes
        .iter()
        .enumerate()
        .map(|(i, &n)| (n, i as u16))
        .collect();
    let lid = |n: u32| -> Result<u16> {
        local
            .get(&n)
            .copied()
            .ok_or_else(|| anyhow!("internal: node {n} missing on board {:?}", bp.coords))
    };
    if bp.nodes.len() > u16::MAX as usize {
        bail!(
            "board {:?} holds {} nodes, more than an image can index",
            bp.coords,
            bp.nodes.len()
        );
    }
    let (points, load_ramp) = path_table(problem);
    let loads: Vec<LoadRecord> = problem
        .loads
        .iter()
        .zip(&load_ramp)
        .filter(|(l, _)| plan.node_owner[l.node as usize] as usize == b)
        .map(|(l, r)| {
            Ok(LoadRecord {
                node: lid(l.node)?,
                force: l.force,
                ramp: *r,
            })
        })
        .collect::<Result<_>>()?;
    let integration = if problem.solver.integration == Integration::Full {
        Integration::Full
    } else {
        Integration::Reduced
    };
    let contact = &shared.contact;
    let places: Vec<ContactNodePlace> = contact
        .as_ref()
        .map(|(run, _)| {
            run.nodes
                .iter()
                .map(|n| {
                    let l = local.get(&n.global).copied();
                    ContactNodePlace {
                        local: l,
                        owned: plan.node_owner[n.global as usize] as usize == b,
                    }
                })
                .collect()
        })
        .unwrap_or_default();
    let on_surface = &shared.on_surface;
    let graphics_nodes: Vec<u16> = bp
        .nodes
        .iter()
        .enumerate()
        .filter(|(k, &n)| bp.owner[*k] && on_surface[n as usize])
        .map(|(k, _)| k as u16)
        .collect();
    let graphics = shared.graphics;
    let header = ImageHeader {
        version: FORMAT_VERSION,
        board: bp.coords.map(|c| c as u8),
        machine: plan.machine.dims.map(|c| c as u8),
        precision: if T::NAME == "f32" {
            Precision::F32
        } else {
            Precision::F64
        },
        integration,
        counts: Counts {
            materials: problem.laws.len() as u16,
            elements: bp.elements.len() as u32,
            batch_ends: bp.batch_ends.map(|e| e as u32),
            nodes: bp.nodes.len() as u32,
            exchange: core::array::from_fn(|f| bp.exchange[f].len() as u16),
            rounds: plan.rounds.map(|r| r as u8),
            sends: bp
                .rounds
                .iter()
                .flatten()
                .map(|r| r.send[0].len() + r.send[1].len())
                .sum::<usize>() as u32,
            recvs: bp
                .rounds
                .iter()
                .flatten()
                .map(|r| r.recv[0].len() + r.recv[1].len())
                .sum::<usize>() as u32,
            path_points: points.len() as u16,
            loads: loads.len() as u16,
            contact_nodes: places.len() as u32,
            contact_faces: contact.as_ref().map_or(0, |(r, _)| r.faces.len() as u32),
            pairs: contact.as_ref().map_or(0, |(r, _)| r.pairs.len() as u8),
            tools: contact.as_ref().map_or(0, |(r, _)| r.tools.len() as u8),
            contact_boards: contact.as_ref().map_or(0, |(_, b)| b.len() as u8),
            graphics_nodes: graphics_nodes.len() as u16,
        },
        params: SceneParams {
            dt_s: dt,
            damping_per_s: problem.solver.damping,
            steps,
            speed_limit_m_per_s: problem.solver.speed_limit,
            mass_scaling: problem.solver.mass_scaling,
            hourglass: problem.solver.hourglass,
        },
        scene_elements: problem.mesh.cells.len() as u32,
        scene_nodes: problem.mesh.nodes.len() as u32,
        contact: contact.as_ref().map(|(r, _)| r.params).unwrap_or_default(),
        graphics,
    };
    let mut buf = vec![
        0u8;
        4096 + bp.elements.len() * 2048
            + bp.nodes.len() * 128
            + points.len() * 64
            + loads.len() * 64
            + places.len() * 64
            + contact.as_ref().map_or(0, |(r, _)| r.faces.len() * 32
                + r.tools.len() * 128
                + r.pairs.len() * 32)
            + graphics_nodes.len() * 4
            + 256
    ];
    let mut w = ImageWriter::new(&mut buf, &header).map_err(|e| anyhow!("{e}"))?;
    let err = |e: ImageError| anyhow!("board {:?}: {e}", bp.coords);
    for law in &problem.laws {
        w.push::<MaterialLaw<f64>>(law).map_err(err)?;
    }
    for &e in &bp.elements {
        let cell = problem.mesh.cells[e as usize];
        let nodes = cell.map(|n| local[&n] as u32);
        let r = &problem.reference[e as usize];
        let m = problem.cell_material[e as usize];
        match integration {
            Integration::Reduced => {
                let modulus = problem.laws[m as usize].hourglass_modulus();
                w.push(&r.reduced::<T>(nodes, m, modulus, problem.solver.hourglass))
                    .map_err(err)?
            }
            Integration::Full => w.push(&r.full::<T>(nodes, m)).map_err(err)?,
        }
    }
    for (k, &n) in bp.nodes.iter().enumerate() {
        let mass = problem.mass[n as usize];
        let own = bp.owner[k];
        let rec = NodeRecord::<T> {
            global: n,
            gain: cd.gain(mass * problem.solver.mass_scaling),
            motion: match problem.node_kind[n as usize] {
                NodeKind::Free => NodeMotion::Free,
                NodeKind::Fixed => NodeMotion::Fixed,
                NodeKind::Prescribed(p) => NodeMotion::Prescribed(p as u16),
            },
            owner: own,
            gravity: if own {
                problem.gravity.map(|g| T::from_f64(g * mass))
            } else {
                [T::ZERO; 3]
            },
        };
        w.push(&rec).map_err(err)?;
        w.push(&bp.ext_stage[k]).map_err(err)?;
    }
    for axis in &bp.rounds {
        for round in axis {
            for f in 0..2 {
                w.push(&(round.send[f].len() as u16)).map_err(err)?;
                for &n in &round.send[f] {
                    w.push(&lid(n)?).map_err(err)?;
                }
                w.push(&(round.recv[f].len() as u16)).map_err(err)?;
                for &(n, combine) in &round.recv[f] {
                    w.push(&RecvEntry {
                        node: lid(n)?,
                        combine,
                    })
                    .map_err(err)?;
                }
            }
        }
    }
    for p in &points {
        w.push(p).map_err(err)?;
    }
    for l in &loads {
        w.push(l).map_err(err)?;
    }
    if let Some((run, boards)) = contact {
        for (n, p) in run.nodes.iter().zip(&places) {
            w.push(n).map_err(err)?;
            w.push(p).map_err(err)?;
        }
        for f in &run.faces {
            w.push(f).map_err(err)?;
        }
        for p in &run.pairs {
            w.push(p).map_err(err)?;
        }
        for t in &run.tools {
            w.push(t).map_err(err)?;
        }
        for b in boards {
            w.push(b).map_err(err)?;
        }
    }
    for g in &graphics_nodes {
        w.push(g).map_err(err)?;
    }
    let len = w.finish().map_err(err)?;
    buf.truncate(len);
    let ram_bytes = runtime_ram_bytes(&header);
    Ok(BoardImage {
        coords: bp.coords,
        header,
        bytes: buf,
        ram_bytes,
    })
}

/// The contact tables for step `dt` and the global-network addresses of the boards that
/// own a node of a pair surface (they exchange bounding boxes).
pub fn contact_tables(
    problem: &Problem,
    plan: &Plan,
    dt: f64,
) -> Result<Option<(crate::problem::contact::ContactRun, Vec<u8>)>> {
    let Some(setup) = problem.contact.as_ref() else {
        return Ok(None);
    };
    let ms = problem.solver.mass_scaling;
    let inertial: Vec<f64> = problem.mass.iter().map(|m| m * ms).collect();
    let run = setup.for_step(&problem.mesh, &inertial, dt);
    let mut owners = std::collections::BTreeSet::new();
    for n in &run.nodes {
        if n.surfaces & run.params.pair_surfaces != 0 {
            owners.insert(plan.node_owner[n.global as usize] as usize);
        }
    }
    let mut boards = Vec::new();
    for b in owners {
        let c = plan.machine.coords(b);
        let id = link_proto::link::board_at(c[0], c[1], c[2]).ok_or_else(|| {
            anyhow!(
                "board {c:?} owns contact nodes but has no global-network address: contact needs a machine of at most {g}x{g}x{g} boards",
                g = link_proto::GRID_DIM
            )
        })?;
        boards.push(id);
    }
    Ok(Some((run, boards)))
}

/// Mesh nodes on the boundary (what the graphics engine draws).
pub fn surface_node_mask(problem: &Problem) -> Vec<bool> {
    problem.surface_node_mask()
}

/// The graphics stream's timing for step `dt`.
pub fn graphics_params(problem: &Problem, dt: f64) -> GraphicsParams {
    let interval =
        ((problem.solver.graphics_interval / dt).round() as u64).clamp(1, u32::MAX as u64) as u32;
    GraphicsParams {
        interval_steps: interval,
        spread_steps: problem
            .solver
            .graphics_spread_steps
            .min(interval)
            .clamp(1, u16::MAX as u32) as u16,
    }
}

/// Compiles every board's image.
pub fn compile_images(problem: &Problem, plan: &Plan) -> Result<Vec<BoardImage>> {
    let (dt, _) = problem.time_step()?;
    let shared = Shared {
        contact: contact_tables(problem, plan, dt)?,
        on_surface: surface_node_mask(problem),
        graphics: graphics_params(problem, dt),
    };
    (0..plan.boards.len())
        .map(|b| match problem.solver.precision {
            Precision::F32 => write_image::<f32>(problem, plan, &shared, b),
            Precision::F64 => write_image::<f64>(problem, plan, &shared, b),
        })
        .collect()
}

/// Checks every image and its run-time state against the board profile; the error names
/// each board that does not fit and by how much.
pub fn check_fit(images: &[BoardImage], profile: &BoardProfile) -> Result<()> {
    let mut problems = Vec::new();
    let ram = profile.ram_bytes.saturating_sub(profile.ram_reserved_bytes);
    for im in images {
        let c = im.coords;
        if im.bytes.len() as u64 > profile.image_flash_bytes {
            problems.push(format!(
                "board ({},{},{}): image {} bytes exceeds the {} flash region of {} bytes by {} bytes",
                c[0], c[1], c[2], im.bytes.len(), profile.name, profile.image_flash_bytes,
                im.bytes.len() as u64 - profile.image_flash_bytes
            ));
        }
        if im.ram_bytes > ram {
            problems.push(format!(
                "board ({},{},{}): run-time state {} bytes exceeds the {} RAM available ({} of {} bytes, {} reserved) by {} bytes",
                c[0], c[1], c[2], im.ram_bytes, profile.name, ram, profile.ram_bytes, profile.ram_reserved_bytes,
                im.ram_bytes - ram
            ));
        }
        let counts = &im.header.counts;
        if counts.nodes as usize > link_proto::NODES_PER_BOARD_MAX {
            problems.push(format!(
                "board ({},{},{}): {} nodes exceed the firmware's {} nodes per board",
                c[0],
                c[1],
                c[2],
                counts.nodes,
                link_proto::NODES_PER_BOARD_MAX
            ));
        }
        for (f, &x) in counts.exchange.iter().enumerate() {
            if x as usize > link_proto::BORDER_NODES_PER_FACE_MAX {
                problems.push(format!(
                    "board ({},{},{}) link {}: {} border nodes exceed the {} a frame carries",
                    c[0],
                    c[1],
                    c[2],
                    FACE_NAMES[f],
                    x,
                    link_proto::BORDER_NODES_PER_FACE_MAX
                ));
            }
        }
    }
    // The contact tables are the same on every board.
    if let Some(im) = images.first() {
        let counts = &im.header.counts;
        for (what, n, max) in [
            (
                "contact-surface nodes",
                counts.contact_nodes,
                profile.contact_nodes_max,
            ),
            (
                "contact-surface faces",
                counts.contact_faces,
                profile.contact_faces_max,
            ),
        ] {
            if n > max {
                problems.push(format!(
                    "every board: {n} {what} exceed the {max} the {} firmware holds (declare smaller [[surface]]s)",
                    profile.name
                ));
            }
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        bail!(
            "the schedule does not fit the {} board profile:\n  {}",
            profile.name,
            problems.join("\n  ")
        )
    }
}

/// Writes `DIR/board-X-Y-Z.bin`.
pub fn write_images(dir: &Path, images: &[BoardImage]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for im in images {
        let p = dir.join(image_file_name(im.coords));
        std::fs::write(&p, &im.bytes).with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}

pub fn image_file_name(c: [usize; 3]) -> String {
    format!("board-{}-{}-{}.bin", c[0], c[1], c[2])
}

/// Figures of a compiled schedule (`DIR/report.json`).
#[derive(Clone, Debug, Serialize)]
pub struct CompileReport {
    pub scene: String,
    pub machine: String,
    /// Exchange rounds per axis (1 where every node spans at most two boards).
    pub rounds: [usize; 3],
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
    /// Force vectors sent per step, all links, both directions.
    pub force_vectors_per_step: usize,
    /// Force vectors per step on the busiest link direction.
    pub force_vectors_per_link_max: usize,
    pub bytes_per_step_per_link_max: usize,
    pub bytes_per_step_total: usize,
    /// Bandwidth needed at the scene's step rate (bytes/s).
    pub bandwidth_total_bytes_per_s: f64,
    pub bandwidth_per_link_max_bytes_per_s: f64,
    pub link_bandwidth_bytes_per_s: u64,
    /// Fraction of a step the busiest link is busy at the scene's step rate.
    pub link_utilisation_max: f64,
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
}

/// The contact traffic at rest: the runtime's box test on the reference positions.
fn contact_report(
    problem: &Problem,
    plan: &Plan,
    dt: f64,
    rate: f64,
) -> Result<Option<ContactCompileReport>> {
    let Some((run, boards)) = contact_tables(problem, plan, dt)? else {
        return Ok(None);
    };
    let p = run.params;
    let owner_of = |c: &pe_firmware::physics::contact::ContactNode| {
        plan.node_owner[c.global as usize] as usize
    };
    let board_index: Vec<usize> = boards
        .iter()
        .map(|&a| {
            let (x, y, z) = link_proto::link::board_coords(a).unwrap_or((0, 0, 0));
            plan.machine.index([x, y, z])
        })
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
            vectors += pair_nodes(bi)
                .filter(|n| (0..3).all(|k| r.0[k] <= n.reference[k] && n.reference[k] <= r.1[k]))
                .count();
        }
    }
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
        bytes_per_s_at_rest: (vectors * link_proto::payload::NODE_ENTRY_LEN) as f64 * rate,
        seed_vectors_per_step: 300,
        seed_bytes_per_s: 72e6,
    }))
}

/// What the scene asks of the busiest board's processor, from measured instruction counts.
#[derive(Clone, Debug, Serialize)]
pub struct Capacity {
    pub clock_hz: u64,
    pub instructions_per_element_step: u32,
    pub instructions_per_node_update: u32,
    /// Instructions of one step on the busiest board (no exchange).
    pub step_instructions_max: f64,
    /// That step's time at one instruction per cycle (s), against the scene's `dt_s`.
    pub step_compute_s_max: f64,
    pub compute_keeps_real_time: bool,
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
    pub exchange: [usize; 6],
    pub image_bytes: usize,
    pub ram_bytes: u64,
}

pub fn report(
    scene: &str,
    problem: &Problem,
    plan: &Plan,
    images: &[BoardImage],
    profile: &BoardProfile,
) -> Result<CompileReport> {
    let (dt, _) = problem.time_step()?;
    let w = if problem.solver.precision == Precision::F32 {
        4
    } else {
        8
    };
    let epb: Vec<usize> = plan.boards.iter().map(|b| b.elements.len()).collect();
    let npb: Vec<usize> = plan.boards.iter().map(|b| b.nodes.len()).collect();
    let mean = epb.iter().sum::<usize>() as f64 / epb.len() as f64;
    // Values sent per link direction per step, over all rounds (one frame per round).
    let per_link: Vec<usize> = plan
        .boards
        .iter()
        .flat_map(|b| {
            (0..6).map(move |f| {
                b.rounds[f / 2]
                    .iter()
                    .map(|r| r.send[f % 2].len())
                    .sum::<usize>()
            })
        })
        .collect();
    let frames_per_link: Vec<usize> = plan
        .boards
        .iter()
        .flat_map(|b| {
            (0..6).map(move |f| {
                b.rounds[f / 2]
                    .iter()
                    .filter(|r| !r.send[f % 2].is_empty())
                    .count()
            })
        })
        .collect();
    let vectors: usize = per_link.iter().sum();
    let link_max = per_link.iter().copied().max().unwrap_or(0);
    let overhead = link_proto::FRAME_HEADER_LEN + link_proto::CRC_LEN;
    let link_bytes: Vec<usize> = per_link
        .iter()
        .zip(&frames_per_link)
        .map(|(&n, &f)| 3 * w * n + f * overhead)
        .collect();
    let frame_bytes_max = link_bytes.iter().copied().max().unwrap_or(0);
    let bytes_total: usize = link_bytes.iter().sum();
    let rate = 1.0 / dt;
    let cost = pe_firmware::profile::measured_cost(
        if problem.solver.precision == Precision::F32 {
            Precision::F32
        } else {
            Precision::F64
        },
        if problem.solver.integration == Integration::Full {
            Integration::Full
        } else {
            Integration::Reduced
        },
    );
    let busiest = plan
        .boards
        .iter()
        .map(|b| cost.step_instructions(b.elements.len(), b.nodes.len()))
        .fold(0.0f64, f64::max);
    let npe = plan
        .boards
        .iter()
        .max_by_key(|b| b.elements.len())
        .map(|b| b.nodes.len() as f64 / b.elements.len().max(1) as f64)
        .unwrap_or(2.0);
    let at_10k = cost.elements_per_board(profile, 1e4, npe);
    let capacity = Capacity {
        clock_hz: profile.clock_hz,
        instructions_per_element_step: cost.per_element_step,
        instructions_per_node_update: cost.per_node_update,
        step_instructions_max: busiest,
        step_compute_s_max: busiest / profile.clock_hz as f64,
        compute_keeps_real_time: busiest / profile.clock_hz as f64 <= dt,
        elements_per_board_at_scene_rate: cost.elements_per_board(profile, rate, npe),
        elements_per_board_at_10_khz: at_10k,
        boards_needed_at_10_khz: (problem.mesh.cells.len() as f64 / at_10k).ceil() as usize,
    };
    let boards = plan
        .boards
        .iter()
        .zip(images)
        .map(|(b, im)| BoardSummary {
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
            exchange: core::array::from_fn(|f| b.exchange[f].len()),
            image_bytes: im.bytes.len(),
            ram_bytes: im.ram_bytes,
        })
        .collect();
    let gp = graphics_params(problem, dt);
    let mask = surface_node_mask(problem);
    let surface_nodes = mask.iter().filter(|m| **m).count();
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
            (0..gp.spread_steps as usize)
                .map(|j| {
                    let len =
                        (j + 1) * n / gp.spread_steps as usize - j * n / gp.spread_steps as usize;
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
    let graphics = GraphicsReport {
        interval_steps: gp.interval_steps,
        spread_steps: gp.spread_steps,
        surface_nodes,
        packets_per_frame,
        bytes_per_frame,
        bytes_per_s: bytes_per_frame as f64 / (gp.interval_steps as f64 * dt),
        seed_bytes_per_s: 18e6,
    };
    let contact = contact_report(problem, plan, dt, rate)?;
    Ok(CompileReport {
        graphics,
        contact,
        scene: scene.to_string(),
        machine: plan.machine.to_string(),
        rounds: plan.rounds,
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
        force_vectors_per_step: vectors,
        force_vectors_per_link_max: link_max,
        bytes_per_step_per_link_max: frame_bytes_max,
        bytes_per_step_total: bytes_total,
        bandwidth_total_bytes_per_s: bytes_total as f64 * rate,
        bandwidth_per_link_max_bytes_per_s: frame_bytes_max as f64 * rate,
        link_bandwidth_bytes_per_s: profile.link_bytes_per_s,
        link_utilisation_max: frame_bytes_max as f64 * rate / profile.link_bytes_per_s as f64,
        image_bytes_max: images.iter().map(|i| i.bytes.len()).max().unwrap_or(0),
        ram_bytes_max: images.iter().map(|i| i.ram_bytes).max().unwrap_or(0),
        capacity,
        boards,
    })
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
        "  exchange rounds per step: x {}, y {}, z {}\n",
        r.rounds[0], r.rounds[1], r.rounds[2]
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
    s += &format!("  bytes per step: {} in all, {} on the busiest link; at dt = {:.3e} s ({:.0} steps/s): {:.3} GB/s in all, {:.1} MB/s on the busiest link ({:.0}% of its {:.0} MB/s)\n",
        r.bytes_per_step_total, r.bytes_per_step_per_link_max, r.dt_s, r.steps_per_s, r.bandwidth_total_bytes_per_s / 1e9,
        r.bandwidth_per_link_max_bytes_per_s / 1e6, 100.0 * r.link_utilisation_max, r.link_bandwidth_bytes_per_s as f64 / 1e6);
    s += &format!(
        "  largest image {} bytes, largest run-time state {} bytes ({} profile)\n",
        r.image_bytes_max, r.ram_bytes_max, r.profile
    );
    let c = &r.capacity;
    s += &format!(
        "  board compute ({} profile, {:.0} MHz, measured {} instructions per element-step and {} per node update, one instruction per cycle assumed): busiest board {:.1} us per step against dt = {:.1} us ({}); {:.1} elements per board at this scene's rate, {:.1} at 10 kHz, so {} boards for this scene at 10 kHz\n",
        r.profile, c.clock_hz as f64 / 1e6, c.instructions_per_element_step, c.instructions_per_node_update,
        c.step_compute_s_max * 1e6, r.dt_s * 1e6,
        if c.compute_keeps_real_time { "keeps real time" } else { "does NOT keep real time" },
        c.elements_per_board_at_scene_rate, c.elements_per_board_at_10_khz, c.boards_needed_at_10_khz
    );
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
    }
    s += "  seed's reference case: 2000 elements on 4x4x4 boards at dt = 100 us: 5600 force vectors per step, 1.35 GB/s in all\n";
    s += &format!(
        "  this scene at dt = 100 us: {} force vectors per step, {:.3} GB/s in all\n",
        r.force_vectors_per_step,
        r.bytes_per_step_total as f64 * 1e4 / 1e9
    );
    s
}

/// One decoded exchange round (local node indices).
#[derive(Clone, Debug, Default)]
pub struct DecodedRound {
    pub send: [Vec<u16>; 2],
    pub recv: [Vec<RecvEntry>; 2],
}

/// An image decoded on the host (for `pe inspect` and tests), elements as `f64`.
#[derive(Clone, Debug)]
pub struct DecodedImage {
    pub header: ImageHeader,
    pub materials: Vec<MaterialLaw<f64>>,
    /// Element node lists (local indices).
    pub element_nodes: Vec<[u32; 8]>,
    pub nodes: Vec<NodeRecord<f64>>,
    pub ext_stage: Vec<u8>,
    /// Exchange rounds per axis: per face (+axis, −axis) the sends and receives.
    pub rounds: [Vec<DecodedRound>; 3],
    pub path_points: Vec<PathPoint>,
    pub loads: Vec<LoadRecord>,
    pub contact_nodes: Vec<(ContactNode, ContactNodePlace)>,
    pub contact_faces: Vec<ContactFace>,
    pub pairs: Vec<ContactPair>,
    pub tools: Vec<Tool>,
    pub contact_boards: Vec<u8>,
    pub graphics_nodes: Vec<u16>,
}

fn decode_typed<T: Real + serde::de::DeserializeOwned>(
    mut r: ImageReader<'_>,
) -> Result<DecodedImage, ImageError> {
    use pe_firmware::physics::{HexElement, HexFull, HexReduced};
    let h = r.header;
    let c = h.counts;
    let mut d = DecodedImage {
        header: h,
        materials: Vec::new(),
        element_nodes: Vec::new(),
        nodes: Vec::new(),
        ext_stage: Vec::new(),
        rounds: Default::default(),
        path_points: Vec::new(),
        loads: Vec::new(),
        contact_nodes: Vec::new(),
        contact_faces: Vec::new(),
        pairs: Vec::new(),
        tools: Vec::new(),
        contact_boards: Vec::new(),
        graphics_nodes: Vec::new(),
    };
    for _ in 0..c.materials {
        d.materials.push(r.next("material")?);
    }
    for _ in 0..c.elements {
        let nodes = match h.integration {
            Integration::Reduced => *r.next::<HexReduced<T>>("element")?.nodes(),
            Integration::Full => *r.next::<HexFull<T>>("element")?.nodes(),
        };
        d.element_nodes.push(nodes);
    }
    for _ in 0..c.nodes {
        let n: NodeRecord<T> = r.next("node")?;
        d.nodes.push(NodeRecord {
            global: n.global,
            gain: n.gain.to_f64(),
            motion: n.motion,
            owner: n.owner,
            gravity: n.gravity.map(|g| g.to_f64()),
        });
        d.ext_stage.push(r.next("node stage")?);
    }
    for a in 0..3 {
        for _ in 0..c.rounds[a] {
            let mut round = DecodedRound::default();
            for f in 0..2 {
                let n: u16 = r.next("send count")?;
                for _ in 0..n {
                    round.send[f].push(r.next("send")?);
                }
                let n: u16 = r.next("receive count")?;
                for _ in 0..n {
                    round.recv[f].push(r.next("receive")?);
                }
            }
            d.rounds[a].push(round);
        }
    }
    for _ in 0..c.path_points {
        d.path_points.push(r.next("path point")?);
    }
    for _ in 0..c.loads {
        d.loads.push(r.next("load")?);
    }
    for _ in 0..c.contact_nodes {
        d.contact_nodes
            .push((r.next("contact node")?, r.next("contact node place")?));
    }
    for _ in 0..c.contact_faces {
        d.contact_faces.push(r.next("contact face")?);
    }
    for _ in 0..c.pairs {
        d.pairs.push(r.next("contact pair")?);
    }
    for _ in 0..c.tools {
        d.tools.push(r.next("tool")?);
    }
    for _ in 0..c.contact_boards {
        d.contact_boards.push(r.next("contact board")?);
    }
    for _ in 0..c.graphics_nodes {
        d.graphics_nodes.push(r.next("graphics node")?);
    }
    if !r.is_done() {
        return Err(ImageError::Malformed {
            record: "trailing bytes",
        });
    }
    Ok(d)
}

/// Decodes and checks a whole image.
pub fn decode_image(
    bytes: &[u8],
    expected_board: Option<[u8; 3]>,
) -> Result<DecodedImage, ImageError> {
    let r = ImageReader::new(bytes, expected_board)?;
    match r.header.precision {
        Precision::F32 => decode_typed::<f32>(r),
        Precision::F64 => decode_typed::<f64>(r),
    }
}

/// `DIR/manifest.json`.
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct Manifest {
    pub format_version: u16,
    pub scene: String,
    /// How to load the scene again (its mesh, for outputs): `builtin:LEVEL` or a file path.
    pub scene_source: String,
    pub machine: [usize; 3],
    pub profile: String,
    pub precision: String,
    pub integration: String,
    pub dt_s: f64,
    pub steps: u64,
    pub boards: Vec<ManifestBoard>,
}

#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct ManifestBoard {
    pub board: [usize; 3],
    pub file: String,
    pub bytes: usize,
    pub crc32: String,
}

/// Compiles a problem into `dir`: images, manifest.json, report.json; returns the report.
pub fn compile_to_dir(
    scene: &str,
    scene_source: &str,
    problem: &Problem,
    machine: Machine,
    profile: &BoardProfile,
    dir: &Path,
) -> Result<CompileReport> {
    let plan = plan(problem, machine)?;
    let images = compile_images(problem, &plan)?;
    check_fit(&images, profile)?;
    write_images(dir, &images)?;
    let (dt, _) = problem.time_step()?;
    let manifest = Manifest {
        format_version: FORMAT_VERSION,
        scene: scene.to_string(),
        scene_source: scene_source.to_string(),
        machine: machine.dims,
        profile: profile.name.to_string(),
        precision: problem.solver.precision.name().to_string(),
        integration: problem.solver.integration.name().to_string(),
        dt_s: dt,
        steps: problem.steps(dt),
        boards: images
            .iter()
            .map(|im| ManifestBoard {
                board: im.coords,
                file: image_file_name(im.coords),
                bytes: im.bytes.len(),
                crc32: format!(
                    "{:08x}",
                    link_proto::frame::crc32(&im.bytes[..im.bytes.len() - 4])
                ),
            })
            .collect(),
    };
    let p = dir.join("manifest.json");
    std::fs::write(&p, serde_json::to_string_pretty(&manifest)?)
        .with_context(|| format!("writing {}", p.display()))?;
    let rep = report(scene, problem, &plan, &images, profile)?;
    let p = dir.join("report.json");
    std::fs::write(&p, serde_json::to_string_pretty(&rep)?)
        .with_context(|| format!("writing {}", p.display()))?;
    Ok(rep)
}

/// Reads `DIR/manifest.json`.
pub fn read_manifest(dir: &Path) -> Result<Manifest> {
    let p = dir.join("manifest.json");
    let text = std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", p.display()))
}

/// `pe inspect`: a readable dump of one board's schedule.
pub fn inspect(dir: &Path, board: [usize; 3]) -> Result<String> {
    let p = dir.join(image_file_name(board));
    let bytes = std::fs::read(&p).with_context(|| format!("reading {}", p.display()))?;
    let d = decode_image(&bytes, Some(board.map(|c| c as u8)))
        .map_err(|e| anyhow!("{}: {e}", p.display()))?;
    let h = &d.header;
    let c = &h.counts;
    let mut s = format!(
        "{}: board ({},{},{}) of a {}x{}x{} machine, format v{}, {:?} {:?}, {} bytes\n",
        p.display(),
        h.board[0],
        h.board[1],
        h.board[2],
        h.machine[0],
        h.machine[1],
        h.machine[2],
        h.version,
        h.precision,
        h.integration,
        bytes.len()
    );
    s += &format!(
        "  dt = {:.4e} s, {} steps, damping {} 1/s\n",
        h.params.dt_s, h.params.steps, h.params.damping_per_s
    );
    let b = c.batch_ends;
    s += &format!(
        "  {} elements: batch x {}, batch y {}, batch z {}, inner {}\n",
        c.elements,
        b[0],
        b[1] - b[0],
        b[2] - b[1],
        b[3] - b[2]
    );
    let owned = d.nodes.iter().filter(|n| n.owner).count();
    s += &format!(
        "  {} nodes ({} owned, {} replicas), {} materials, {} path points, {} loads\n",
        c.nodes,
        owned,
        c.nodes as usize - owned,
        c.materials,
        c.path_points,
        c.loads
    );
    s += "  schedule: recover x | send ±x | recover y | add ±x | send ±y | recover z | add ±y | send ±z | recover inner | add ±z | update\n";
    let g = |l: u16| {
        d.nodes
            .get(l as usize)
            .map(|n| n.global)
            .unwrap_or(u32::MAX)
    };
    let list = |v: Vec<u32>| {
        let shown: Vec<String> = v.iter().take(20).map(|x| x.to_string()).collect();
        format!(
            "{} [{}{}]",
            v.len(),
            shown.join(" "),
            if v.len() > 20 { " ..." } else { "" }
        )
    };
    for a in 0..3 {
        for (k, round) in d.rounds[a].iter().enumerate() {
            for f in 0..2 {
                let face = FACE_NAMES[2 * a + f];
                s += &format!(
                    "  {} round {k} face {face}: send {}\n",
                    ["x", "y", "z"][a],
                    list(round.send[f].iter().map(|&l| g(l)).collect())
                );
                s += &format!(
                    "  {} round {k} face {face}: recv {}\n",
                    ["x", "y", "z"][a],
                    list(round.recv[f].iter().map(|e| g(e.node)).collect())
                );
            }
        }
    }
    Ok(s)
}

/// Largest `|a − b|` over all components, relative to the largest `|a|`.
pub fn max_rel_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let scale = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    let d = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    if scale > 0.0 {
        d / scale
    } else {
        d
    }
}
