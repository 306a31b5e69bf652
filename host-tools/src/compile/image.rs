//! One schedule image per board: the plan's lists in local numbering, the scene's records
//! in the board's precision and element kind, written through the firmware's codec
//! ([`pe_firmware::image::write_image`]).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use pe_firmware::image::*;
use pe_firmware::physics::{CentralDifference, ElementKind, HexBox, HexCuboid};
use pe_firmware::runtime::Capacities;

use super::plan::{BoardPlan, Plan};
use super::tables::ImageTables;
use crate::problem::contact::ContactRun;
use crate::problem::elements::record_of;
use crate::problem::{NodeKind, Problem};

/// A compiled image with its figures.
pub struct BoardImage {
    pub coords: [usize; 3],
    pub header: ImageHeader,
    pub bytes: Vec<u8>,
    pub ram_bytes: u64,
}

/// The path table every board's image holds, and where each ramp is in it.
struct PathTable {
    points: Vec<PathPoint>,
    /// Each load's ramp (a path), if it has one.
    load_ramp: Vec<Option<u16>>,
    /// Gravity's ramp, if it has one.
    gravity_ramp: Option<u16>,
}

/// Prescribed paths first, then the distinct ramps of the loads and gravity
/// ([`Problem::ramp_curves`]).
fn path_table(problem: &Problem) -> PathTable {
    let mut points = Vec::new();
    for (k, p) in problem.paths.iter().enumerate() {
        for (t, v) in &p.points {
            points.push(PathPoint {
                path: k as u16,
                t_s: *t,
                value: *v,
                segment: p.segment,
            });
        }
    }
    let ramps = problem.ramp_curves();
    let path_of = |user: usize| ramps.index(user).map(|c| (problem.paths.len() + c) as u16);
    let load_ramp = (0..problem.loads.len()).map(path_of).collect();
    let gravity_ramp = path_of(problem.gravity_ramp_user());
    for (k, r) in ramps.curves().iter().enumerate() {
        for (t, v) in &r.points {
            points.push(PathPoint {
                path: (problem.paths.len() + k) as u16,
                t_s: *t,
                value: [v[0], 0.0, 0.0],
                segment: r.segment,
            });
        }
    }
    PathTable {
        points,
        load_ramp,
        gravity_ramp,
    }
}

/// What every board's image shares: the contact tables, which nodes are on the surface, the
/// graphics timing (computed once per compilation).
struct Shared {
    dt_s: f64,
    paths: PathTable,
    contact: Option<(ContactRun, Vec<u8>)>,
    on_surface: Vec<bool>,
    graphics: GraphicsParams,
}

/// Local numbering of one board: global node → local index.
struct Local<'a> {
    map: BTreeMap<u32, u16>,
    board: &'a BoardPlan,
}

impl Local<'_> {
    fn of(&self, n: u32) -> Result<u16> {
        self.map.get(&n).copied().ok_or_else(|| {
            anyhow!(
                "internal: node {n} missing on board {:?}",
                self.board.coords
            )
        })
    }
}

fn write_image<T: ImageReal, E: ElementRecord<T>>(
    problem: &Problem,
    plan: &Plan,
    shared: &Shared,
    b: usize,
) -> Result<BoardImage> {
    let bp = &plan.boards[b];
    if bp.nodes.len() > u16::MAX as usize {
        bail!(
            "board {:?} holds {} nodes, more than an image can index",
            bp.coords,
            bp.nodes.len()
        );
    }
    let local = Local {
        map: bp
            .nodes
            .iter()
            .enumerate()
            .map(|(i, &n)| (n, i as u16))
            .collect(),
        board: bp,
    };
    let mut t = ImageTables::<T, E>::zeroed(&Counts::default()).map_err(|e| anyhow!("{e}"))?;
    t.laws = problem.laws.iter().map(|l| l.cast::<T>()).collect();
    // Per batch: the general elements, then the parallelepipeds, then the cuboids (each in
    // plan order).
    let local_nodes = |e: u32| problem.mesh.cells[e as usize].map(|n| local.map[&n] as u32);
    let (mut batch_ends, mut box_batch_ends, mut cuboid_batch_ends) =
        ([0u32; 4], [0u32; 4], [0u32; 4]);
    let mut start = 0;
    for (k, &end) in bp.batch_ends.iter().enumerate() {
        for &e in &bp.elements[start..end] {
            let (e, nodes) = (e as usize, local_nodes(e));
            let r = crate::problem::elements::hex_of(problem, e)
                .ok_or_else(|| anyhow!("cell {e} is a tetrahedron: the boards have none"))?;
            match ElementKind::of(r, problem.solver.integration) {
                k if k == E::KIND => t.elements.push(record_of(problem, e, r, nodes)),
                ElementKind::HexBox => t
                    .boxes
                    .push(record_of::<T, HexBox<T>>(problem, e, r, nodes)),
                ElementKind::HexCuboid => t
                    .cuboids
                    .push(record_of::<T, HexCuboid<T>>(problem, e, r, nodes)),
                k => bail!(
                    "internal: cell {e} is a {k}, which an image of {} holds no table for",
                    E::KIND
                ),
            }
        }
        batch_ends[k] = t.elements.len() as u32;
        box_batch_ends[k] = t.boxes.len() as u32;
        cuboid_batch_ends[k] = t.cuboids.len() as u32;
        start = end;
    }
    t.nodes = node_records(problem, bp, shared.dt_s);
    exchange_tables(bp, &local, &mut t)?;
    contact_tables_of_board(shared, plan, b, &local, &mut t);
    let external_counts = external_tables(problem, &shared.paths, bp, &mut t)?;
    t.graphics_nodes = bp
        .nodes
        .iter()
        .enumerate()
        .filter(|(k, &n)| bp.owner[*k] && shared.on_surface[n as usize])
        .map(|(k, _)| k as u16)
        .collect();
    let dt = shared.dt_s;
    let header = ImageHeader {
        version: FORMAT_VERSION,
        // Stamped by `compile_images` once every image of the set is written.
        compilation: CompilationId::UNSET,
        board: bp.coords.map(|c| c as u8),
        machine: plan.machine.dims().map(|c| c as u8),
        precision: T::PRECISION,
        integration: E::INTEGRATION,
        counts: t.counts(
            batch_ends,
            box_batch_ends,
            cuboid_batch_ends,
            core::array::from_fn(|f| bp.exchange[f].len() as u16),
            (
                plan.rounds.map(|r| r as u8),
                plan.late_rounds.map(|r| r as u8),
            ),
            external_counts,
        ),
        params: SceneParams {
            dt_s: dt,
            damping_per_s: problem.solver.damping,
            steps: problem.steps(dt),
            speed_limit_m_per_s: problem.solver.speed_limit,
            gravity_ramp: shared.paths.gravity_ramp,
            mass_scaling: problem.solver.mass_scaling,
            hourglass: problem.solver.hourglass,
        },
        scene_elements: problem.mesh.cells.len() as u32,
        scene_nodes: problem.mesh.nodes.len() as u32,
        contact: shared
            .contact
            .as_ref()
            .map(|(r, _)| r.params)
            .unwrap_or_default(),
        graphics: shared.graphics,
    };
    let mut buf = vec![0u8; image_bytes_bound::<T, E>(&header.counts)];
    let len = pe_firmware::image::write_image(&mut buf, &header, &mut t.parts())
        .map_err(|e| anyhow!("board {:?}: {e}", bp.coords))?;
    buf.truncate(len);
    Ok(BoardImage {
        coords: bp.coords,
        header,
        bytes: buf,
        ram_bytes: storage_bytes::<T, E>(&header.counts),
    })
}

/// The board's nodes: central-difference gain, half inertial mass (owner only), motion,
/// owner.
fn node_records<T: ImageReal>(problem: &Problem, bp: &BoardPlan, dt: f64) -> Vec<NodeRecord<T>> {
    let cd = CentralDifference::<T>::new(dt, problem.solver.damping);
    let ms = problem.solver.mass_scaling;
    bp.nodes
        .iter()
        .enumerate()
        .map(|(k, &n)| {
            let mass = problem.mass[n as usize];
            let own = bp.owner[k];
            NodeRecord::<T> {
                global: n,
                gain: cd.gain(mass * ms),
                // The serial solver's kinetic-energy factor, `0.5 * m * ms`.
                half_mass_kg: if own { 0.5 * mass * ms } else { 0.0 },
                motion: match problem.node_kind[n as usize] {
                    NodeKind::Free => NodeMotion::Free,
                    NodeKind::Fixed => NodeMotion::Fixed,
                    NodeKind::Prescribed(p) => NodeMotion::Prescribed(p as u16),
                },
                owner: own,
            }
        })
        .collect()
}

/// The exchange rounds as lists (axis, round, face) over flat send and receive sections.
fn exchange_tables<T, E>(bp: &BoardPlan, local: &Local, t: &mut ImageTables<T, E>) -> Result<()> {
    for round in bp.rounds.iter().flatten() {
        for f in 0..2 {
            t.lists.push(ExchangeList {
                sends: round.send[f].len() as u16,
                recvs: round.recv[f].len() as u16,
            });
            for &n in &round.send[f] {
                t.sends.push(local.of(n)?);
            }
            for &(n, combine) in &round.recv[f] {
                t.recvs.push(RecvEntry {
                    node: local.of(n)?,
                    combine,
                });
            }
        }
    }
    Ok(())
}

/// The path table (every board has all paths) and the external forces of the nodes the
/// board owns: one record per owned node with non-zero gravity, a load or a contact node
/// (the board's contact places must be filled), grouped by stage, and the loads in record
/// order (each node's in the scene's order). Returns the records per stage.
fn external_tables<T: ImageReal, E>(
    problem: &Problem,
    paths: &PathTable,
    bp: &BoardPlan,
    t: &mut ImageTables<T, E>,
) -> Result<[u16; STAGES]> {
    t.path_points = paths.points.clone();
    let mut loads_of: BTreeMap<u32, Vec<usize>> = BTreeMap::new();
    for (j, l) in problem.loads.iter().enumerate() {
        loads_of.entry(l.node).or_default().push(j);
    }
    let mut contact_of = BTreeMap::new();
    for (c, pl) in t.places.iter().enumerate() {
        if let (true, Some(l)) = (pl.owned, pl.local) {
            contact_of.insert(l, c as u32);
        }
    }
    let mut staged = Vec::new();
    for (k, &n) in bp.nodes.iter().enumerate() {
        if !bp.owner[k] {
            continue;
        }
        let mass = problem.mass[n as usize];
        let gravity = problem.gravity.map(|g| T::from_f64(g * mass));
        let loads = loads_of.get(&n).map_or(&[][..], |v| &v[..]);
        let contact = contact_of.get(&(k as u16)).copied();
        let zero = gravity.iter().all(|g| g.to_f64().to_bits() == 0);
        if zero && loads.is_empty() && contact.is_none() {
            continue;
        }
        let stage = bp.ext_stage[k] as usize;
        if stage >= STAGES {
            bail!(
                "internal: owned node {n} has no stage on board {:?}",
                bp.coords
            );
        }
        staged.push((stage, k as u16, gravity, loads, contact));
    }
    // Stage order; within a stage, local order.
    staged.sort_by_key(|r| (r.0, r.1));
    let mut counts = [0u16; STAGES];
    for (stage, node, gravity, loads, contact) in staged {
        counts[stage] += 1;
        t.external.push(ExternalRecord {
            node,
            gravity,
            first_load: t.loads.len() as u16,
            loads: loads.len() as u16,
            contact,
        });
        for &j in loads {
            let l = &problem.loads[j];
            t.loads.push(LoadRecord {
                node,
                force: l.force,
                ramp: paths.load_ramp[j],
            });
        }
    }
    if t.loads.len() > u16::MAX as usize {
        bail!(
            "board {:?} owns {} loaded nodes' loads, more than an image can index",
            bp.coords,
            t.loads.len()
        );
    }
    Ok(counts)
}

/// The contact tables (the whole scene's, the same on every board that has them) and
/// where each contact node lives on board `b`, for a board that owns a contact node. A
/// board that owns none gets none: it computes no contact force, tool force or statistic
/// (each is for owned nodes), exchanges no contact node and takes part in no check, so its
/// step program has no contact operation and its image and storage no contact tables.
fn contact_tables_of_board<T, E>(
    shared: &Shared,
    plan: &Plan,
    b: usize,
    local: &Local,
    t: &mut ImageTables<T, E>,
) {
    let Some((run, boards)) = &shared.contact else {
        return;
    };
    let places: Vec<ContactNodePlace> = run
        .nodes
        .iter()
        .map(|n| ContactNodePlace {
            local: local.map.get(&n.global).copied(),
            owned: plan.node_owner[n.global as usize] as usize == b,
        })
        .collect();
    if !places.iter().any(|p| p.owned) {
        return;
    }
    t.contact_nodes = run.nodes.clone();
    t.faces = run.faces.clone();
    t.pairs = run.pairs.clone();
    t.tools = run.tools.clone();
    t.contact_boards = boards.clone();
    t.places = places;
}

/// An upper bound of an image's length: every record at most its in-memory size plus
/// postcard's varint overhead (a varint takes at most one byte more per 7 bytes).
fn image_bytes_bound<T, E>(c: &Counts) -> usize {
    let caps = Capacities::exact(c);
    let records = caps.bytes::<T, E>() + c.exchange_lists() * 8 + 64 * 8;
    1024 + 2 * records
}

/// Bytes of storage the runtime's arrays take for exactly an image's records and state
/// (the contact search's working room, which depends on the motion, left out).
pub fn storage_bytes<T, E>(c: &Counts) -> u64 {
    let caps = Capacities {
        contact_candidates: 0,
        contact_sends: 0,
        ..Capacities::exact(c)
    };
    caps.bytes::<T, E>() as u64
}

/// The contact tables for step `dt` and the global-network addresses of the boards that
/// own a node of a pair surface (they exchange bounding boxes).
pub fn contact_tables(
    problem: &Problem,
    plan: &Plan,
    dt: f64,
) -> Result<Option<(ContactRun, Vec<u8>)>> {
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
        let id = link_proto::Machine::address(c).ok_or_else(|| {
            anyhow!(
                "board {c:?} owns contact nodes but has no global-network address: contact needs a machine of at most {g}x{g}x{g} boards",
                g = link_proto::GRID_DIM
            )
        })?;
        boards.push(id);
    }
    Ok(Some((run, boards)))
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

/// 64-bit FNV-1a: the compilation id's hash (the host computes it, boards only compare).
struct Fnv1a(u64);

impl Fnv1a {
    fn new() -> Self {
        Fnv1a(0xcbf2_9ce4_8422_2325)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

/// The id of a compilation: FNV-1a over the scene's mesh (node coordinates and cells, which
/// the images hold only as derived records) and every image in board order, each as
/// written with the id unset and preceded by its length. Everything a board computes with
/// is in its image, so a different modulus, step, partition or scene gives a different id;
/// compiling the same scene twice gives the same images and the same id.
pub fn compilation_id(problem: &Problem, images: &[BoardImage]) -> CompilationId {
    let mut h = Fnv1a::new();
    h.write(b"pe compilation v1");
    h.write(&(problem.mesh.nodes.len() as u64).to_le_bytes());
    for p in &problem.mesh.nodes {
        for v in p {
            h.write(&v.to_bits().to_le_bytes());
        }
    }
    h.write(&(problem.mesh.cells.len() as u64).to_le_bytes());
    for c in &problem.mesh.cells {
        for n in c {
            h.write(&n.to_le_bytes());
        }
    }
    h.write(&(images.len() as u64).to_le_bytes());
    for im in images {
        h.write(&(im.bytes.len() as u64).to_le_bytes());
        h.write(&im.bytes);
    }
    CompilationId::from_u64(h.0)
}

/// Compiles every board's image, each stamped with the set's [`compilation_id`].
pub fn compile_images(problem: &Problem, plan: &Plan) -> Result<Vec<BoardImage>> {
    let mut images = compile_unstamped(problem, plan)?;
    let id = compilation_id(problem, &images);
    for im in &mut images {
        stamp_compilation(&mut im.bytes, id)
            .map_err(|e| anyhow!("board {:?}: stamping the compilation id: {e}", im.coords))?;
        im.header.compilation = id;
    }
    Ok(images)
}

/// Every board's image, with the compilation id unset.
fn compile_unstamped(problem: &Problem, plan: &Plan) -> Result<Vec<BoardImage>> {
    let dt = problem.time_step.dt_s;
    let shared = Shared {
        dt_s: dt,
        paths: path_table(problem),
        contact: contact_tables(problem, plan, dt)?,
        on_surface: problem.surface_node_mask(),
        graphics: graphics_params(problem, dt),
    };
    let (precision, integration) = (problem.solver.precision, problem.solver.integration);
    (0..plan.boards.len())
        .map(|b| {
            pe_firmware::with_element_types!(precision, integration, |T, E| {
                write_image::<T, E>(problem, plan, &shared, b)
            })
        })
        .collect()
}

/// Writes `DIR/board-X-Y-Z.bin`, after removing every earlier `board-*.bin` of `DIR`.
pub fn write_images(dir: &Path, images: &[BoardImage]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    // A recompile into an old directory: the images of boards this machine lacks go.
    crate::output::file::remove_owned(dir, |n| n.starts_with("board-") && n.ends_with(".bin"))?;
    for im in images {
        let p = dir.join(image_file_name(im.coords));
        crate::output::file::write_atomic(&p, &im.bytes)?;
    }
    Ok(())
}

pub fn image_file_name(c: [usize; 3]) -> String {
    format!("board-{}-{}-{}.bin", c[0], c[1], c[2])
}
