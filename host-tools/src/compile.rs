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
    /// Global node ids exchanged across each face, in wire order.
    pub exchange: [Vec<u32>; 6],
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
    pub boards: Vec<BoardPlan>,
}

pub fn plan(problem: &Problem, machine: Machine) -> Result<Plan> {
    let mesh = &problem.mesh;
    let element_board = partition(mesh, machine)?;
    let around = node_elements(mesh);
    let nb = machine.count();
    let mut boards: Vec<BoardPlan> = (0..nb)
        .map(|b| BoardPlan {
            coords: machine.coords(b),
            elements: Vec::new(),
            batch_ends: [0; 4],
            nodes: Vec::new(),
            owner: Vec::new(),
            exchange: Default::default(),
            ext_stage: Vec::new(),
        })
        .collect();
    let mut node_owner = vec![0u32; mesh.nodes.len()];
    for (n, els) in around.iter().enumerate() {
        if els.is_empty() {
            bail!("node {} of mesh {} belongs to no cell", mesh.node_tags[n], mesh.source);
        }
        let (lo, hi) = node_board_range(machine, &element_board, els);
        let owner = els.iter().map(|&e| element_board[e as usize]).min().unwrap_or(0);
        node_owner[n] = owner;
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let c = [x, y, z];
                    let b = machine.index(c);
                    boards[b].nodes.push(n as u32);
                    boards[b].owner.push(b as u32 == owner);
                    for a in 0..3 {
                        if c[a] < hi[a] {
                            let mut d = c;
                            d[a] += 1;
                            boards[b].exchange[2 * a].push(n as u32);
                            boards[machine.index(d)].exchange[2 * a + 1].push(n as u32);
                        }
                    }
                }
            }
        }
    }
    for (e, &b) in element_board.iter().enumerate() {
        boards[b as usize].elements.push(e as u32);
    }
    for bp in &mut boards {
        let axis_nodes: [std::collections::HashSet<u32>; 3] = core::array::from_fn(|a| {
            bp.exchange[2 * a].iter().chain(&bp.exchange[2 * a + 1]).copied().collect()
        });
        let stage_of_element = |e: u32| {
            let cell = &mesh.cells[e as usize];
            (0..3).find(|&a| cell.iter().any(|n| axis_nodes[a].contains(n))).unwrap_or(3)
        };
        let mut staged: Vec<(usize, u32)> = bp.elements.iter().map(|&e| (stage_of_element(e), e)).collect();
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
    Ok(Plan { machine, element_board, node_owner, boards })
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
    let exchange: u64 = c.exchange.iter().map(|&x| x as u64 * 2).sum();
    let link_buffers = 6 * 2 * (12 + 3 * w * link_proto::BORDER_NODES_PER_FACE_MAX as u64);
    c.elements as u64 * element
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
            points.push(PathPoint { path: k as u16, t_s: *t, value: *v });
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
            points.push(PathPoint { path: (problem.paths.len() + k) as u16, t_s: *t, value: [v[0], 0.0, 0.0] });
        }
    }
    (points, load_ramp)
}

fn write_image<T: Real + Serialize>(problem: &Problem, plan: &Plan, b: usize) -> Result<BoardImage> {
    let bp = &plan.boards[b];
    let (dt, _) = problem.time_step()?;
    let steps = problem.steps(dt);
    let cd = CentralDifference::<T>::new(dt, problem.solver.damping);
    let local: BTreeMap<u32, u16> = bp.nodes.iter().enumerate().map(|(i, &n)| (n, i as u16)).collect();
    let lid = |n: u32| -> Result<u16> {
        local.get(&n).copied().ok_or_else(|| anyhow!("internal: node {n} missing on board {:?}", bp.coords))
    };
    if bp.nodes.len() > u16::MAX as usize {
        bail!("board {:?} holds {} nodes, more than an image can index", bp.coords, bp.nodes.len());
    }
    let (points, load_ramp) = path_table(problem);
    let loads: Vec<LoadRecord> = problem
        .loads
        .iter()
        .zip(&load_ramp)
        .filter(|(l, _)| plan.node_owner[l.node as usize] as usize == b)
        .map(|(l, r)| Ok(LoadRecord { node: lid(l.node)?, force: l.force, ramp: *r }))
        .collect::<Result<_>>()?;
    let integration = if problem.solver.integration == "full" { Integration::Full } else { Integration::Reduced };
    let header = ImageHeader {
        version: FORMAT_VERSION,
        board: bp.coords.map(|c| c as u8),
        machine: plan.machine.dims.map(|c| c as u8),
        precision: if T::NAME == "f32" { Precision::F32 } else { Precision::F64 },
        integration,
        counts: Counts {
            materials: problem.laws.len() as u16,
            elements: bp.elements.len() as u32,
            batch_ends: bp.batch_ends.map(|e| e as u32),
            nodes: bp.nodes.len() as u32,
            exchange: core::array::from_fn(|f| bp.exchange[f].len() as u16),
            path_points: points.len() as u16,
            loads: loads.len() as u16,
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
    };
    let mut buf = vec![0u8; 4096 + bp.elements.len() * 2048 + bp.nodes.len() * 128 + points.len() * 64 + loads.len() * 64];
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
                w.push(&r.reduced::<T>(nodes, m, modulus, problem.solver.hourglass)).map_err(err)?
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
            gravity: if own { problem.gravity.map(|g| T::from_f64(g * mass)) } else { [T::ZERO; 3] },
        };
        w.push(&rec).map_err(err)?;
        w.push(&bp.ext_stage[k]).map_err(err)?;
    }
    for list in &bp.exchange {
        for &n in list {
            w.push(&lid(n)?).map_err(err)?;
        }
    }
    for p in &points {
        w.push(p).map_err(err)?;
    }
    for l in &loads {
        w.push(l).map_err(err)?;
    }
    let len = w.finish().map_err(err)?;
    buf.truncate(len);
    let ram_bytes = runtime_ram_bytes(&header);
    Ok(BoardImage { coords: bp.coords, header, bytes: buf, ram_bytes })
}

/// Compiles every board's image.
pub fn compile_images(problem: &Problem, plan: &Plan) -> Result<Vec<BoardImage>> {
    (0..plan.boards.len())
        .map(|b| match problem.solver.precision.as_str() {
            "f32" => write_image::<f32>(problem, plan, b),
            _ => write_image::<f64>(problem, plan, b),
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
                c[0], c[1], c[2], counts.nodes, link_proto::NODES_PER_BOARD_MAX
            ));
        }
        for (f, &x) in counts.exchange.iter().enumerate() {
            if x as usize > link_proto::BORDER_NODES_PER_FACE_MAX {
                problems.push(format!(
                    "board ({},{},{}) link {}: {} border nodes exceed the {} a frame carries",
                    c[0], c[1], c[2], FACE_NAMES[f], x, link_proto::BORDER_NODES_PER_FACE_MAX
                ));
            }
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        bail!("the schedule does not fit the {} board profile:\n  {}", profile.name, problems.join("\n  "))
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
