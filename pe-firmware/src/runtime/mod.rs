//! The board runtime: loads a schedule image and runs steps by the seed's interleaved
//! schedule over the link interface. The only place where schedule, physics and links meet.
//!
//! Rooms: [`fault`] (what went wrong, where), [`storage`] (the arrays and their
//! capacities), `load` (an image into storage), [`program`] (the step's operations, also
//! walked by board-sim's timing model), `exchange` (force frames over the point-to-point
//! links), `hello` (the compilation ids checked with the neighbours before step 0), `global` (packets on the global network), `contact` (bounding boxes, node
//! exchange, contact and tool forces), [`pose`] (the host's tool poses, applied at their
//! step), `graphics` (surface nodes to the graphics engine);
//! this file holds the runtime itself and the step loop.
//!
//! Storage is the caller's ([`Storage`], lent by a [`StorageBuf`]). Time and idling come in
//! through [`Environment`]; links through [`link_proto::Links`]. Nothing here allocates or
//! panics: bad images, bad frames, stalled links and numerical failure become a [`Fault`]
//! naming the board, the link or the element, and the step.

mod contact;
mod exchange;
pub mod fault;
mod global;
mod graphics;
mod hello;
mod load;
mod marks;
mod path_values;
pub mod pose;
pub mod program;
pub mod storage;

use link_proto::{Face, Links, Values};

use crate::image::*;
use crate::physics::explicit::{accumulate_internal_forces, update_node, NodeMove};
use crate::physics::{
    CentralDifference, HexBox, HexCuboid, HexElement, HexFull, HexReduced, MaterialLaw,
    PhysicsError, Real,
};

pub use contact::{ContactState, BOARDS_MAX, PAIRS_MAX, TOOLS_MAX};
pub use fault::{Fault, FaultKind};
pub use global::GlobalStats;
pub use hello::HelloFrame;
pub use program::{Op, Program, ROUNDS_PER_AXIS_MAX};
pub use storage::{Capacities, ContactStorage, Heapless, Shelf, Storage, StorageBuf};

/// A scalar that travels in link frames.
pub trait WireReal: ImageReal {
    fn wire(values: &[Self]) -> Values<'_>;
}

impl WireReal for f32 {
    fn wire(values: &[f32]) -> Values<'_> {
        Values::F32(values)
    }
}

impl WireReal for f64 {
    fn wire(values: &[f64]) -> Values<'_> {
        Values::F64(values)
    }
}

/// Time and waiting, passed in (never read globally): the links' clock
/// ([`link_proto::Clock`], the one link recovery times its requests by) and a way to wait.
pub trait Environment: link_proto::Clock {
    /// Called while waiting for a link (spin, yield, sleep until an interrupt...).
    fn idle(&mut self);
}

/// One batch of the step program's elements, as [`BatchForces`] sees it: the batch's
/// general elements (numbered from `first_general` in errors), then its parallelepipeds
/// (numbered from `first_box`, after all the general ones), then its cuboids (numbered
/// from `first_cuboid`, after all the parallelepipeds).
pub struct BatchSlices<'s, T, E> {
    /// The batch's index (0 to 3: x, y, z, inner).
    pub index: usize,
    pub general: &'s [E],
    pub first_general: u32,
    pub boxes: &'s [HexBox<T>],
    pub first_box: u32,
    pub cuboids: &'s [HexCuboid<T>],
    pub first_cuboid: u32,
}

/// Batch `b`'s range (`b` < 4) in a kernel list cut at `ends` (the image counts'
/// `batch_ends`, `box_batch_ends` or `cuboid_batch_ends`).
#[inline(always)]
pub fn batch_range(ends: [u32; 4], b: usize) -> core::ops::Range<usize> {
    let start = if b == 0 { 0 } else { ends[b - 1] as usize };
    start..ends[b] as usize
}

/// Who computes a batch's internal forces: the board's scalar element loop
/// ([`ScalarBatches`], what the firmware runs) or, on the host, a batched kernel over the
/// same elements (board-sim). An implementation adds into `f` the bits of
/// [`accumulate_internal_forces`] over the general elements, the parallelepipeds and the cuboids,
/// and fails with its error on the same element.
pub trait BatchForces<T, E> {
    fn batch_forces(
        &self,
        batch: BatchSlices<'_, T, E>,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError>;
}

/// The scalar element loop ([`accumulate_internal_forces`]).
pub struct ScalarBatches;

impl<T: Real, E: HexElement<T>> BatchForces<T, E> for ScalarBatches {
    #[inline(always)]
    fn batch_forces(
        &self,
        b: BatchSlices<'_, T, E>,
        laws: &[MaterialLaw<T>],
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        accumulate_internal_forces(b.general, b.first_general, laws, u, f)
            .and_then(|()| accumulate_internal_forces(b.boxes, b.first_box, laws, u, f))
            .and_then(|()| accumulate_internal_forces(b.cuboids, b.first_cuboid, laws, u, f))
    }
}

/// Runtime settings that are not part of the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RuntimeConfig {
    /// A link that delivers nothing for this long is a fault (ns).
    pub link_timeout_ns: u64,
    /// The host's step gate ([`link_proto::gate`]): a board holding a tool starts no
    /// step's contact before the host permits it (a replay on boards faster than the
    /// host). Off on a live array, whose host sends poses ahead of the wall clock.
    pub host_gate: bool,
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        RuntimeConfig {
            link_timeout_ns: 10_000_000_000,
            host_gate: false,
        }
    }
}

/// Link statistics of one board (for reports).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LinkStats {
    pub frames_sent: [u64; 6],
    pub bytes_sent: [u64; 6],
    pub frames_received: [u64; 6],
    /// Time spent waiting for frames (ns, as the environment measures it).
    pub wait_ns: u64,
}

/// One board running its schedule image. `E` is the element type (reduced or full).
pub struct Runtime<'a, T, E> {
    pub header: ImageHeader,
    program: Program,
    /// Next operation of the current step.
    pc: usize,
    /// When the current operation started waiting (ns), if it is waiting.
    waiting_since: Option<u64>,
    st: Storage<'a, T, E>,
    exchange: exchange::Exchange<T>,
    cd: CentralDifference<T>,
    step: u64,
    config: RuntimeConfig,
    port: global::GlobalPort,
    contact: ContactState,
    graphics_cursor: usize,
    /// Faces whose Hello (compilation id) is still to send or to check before step 0.
    hello: hello::Hello,
    /// Range of each stage's records in the external-force list.
    external_stages: [(u32, u32); STAGES],
    pub stats: LinkStats,
    /// Sum of `f_int − f_ext` over this board's share of the prescribed and fixed nodes at
    /// the last step (N): a held node is not exchanged, so each board that holds it adds
    /// its own partial force, its owner the external force too, and the boards' sums add
    /// up to the reaction.
    pub reaction_prescribed: [f64; 3],
    pub reaction_fixed: [f64; 3],
    /// Kinetic energy of owned nodes at the last step (J).
    pub kinetic_energy: f64,
}

impl<'a, T: WireReal, E: ElementRecord<T>> Runtime<'a, T, E> {
    pub fn step_index(&self) -> u64 {
        self.step
    }

    /// (step, operation): changes whenever the runtime moves on.
    pub fn progress(&self) -> (u64, usize) {
        (self.step, self.pc)
    }

    pub fn is_finished(&self) -> bool {
        self.step >= self.header.params.steps
    }

    /// Local nodes (records) and their current displacements.
    pub fn nodes(&self) -> &[NodeRecord<T>] {
        &self.st.nodes[..self.header.counts.nodes as usize]
    }

    pub fn displacements(&self) -> &[[T; 3]] {
        &self.st.u[..self.header.counts.nodes as usize]
    }

    /// The loaded elements (batch order) and material laws.
    pub fn elements(&self) -> (&[E], &[MaterialLaw<T>]) {
        (
            &self.st.elements[..self.header.counts.elements as usize],
            &self.st.laws[..self.header.counts.materials as usize],
        )
    }

    /// The loaded parallelepipeds (batch order).
    pub fn boxes(&self) -> &[HexBox<T>] {
        &self.st.boxes[..self.header.counts.boxes as usize]
    }

    /// The loaded cuboids (batch order).
    pub fn cuboids(&self) -> &[HexCuboid<T>] {
        &self.st.cuboids[..self.header.counts.cuboids as usize]
    }

    /// Global-network traffic of this board.
    pub fn global_stats(&self) -> GlobalStats {
        self.port.stats
    }

    /// Force of the tissue on each tool from this board's nodes at the last step (N).
    pub fn tool_forces(&self) -> &[[f64; 3]] {
        &self.contact.tool_force[..self.header.counts.tools as usize]
    }

    /// Tool `t`'s pose from the host now (`None`: it follows its path), and the poses
    /// received and not yet due.
    pub fn tool_pose(&self, t: usize) -> (Option<crate::physics::pose::Pose>, usize) {
        let q = &self.contact.poses;
        (q.current(t), q.pending())
    }

    /// What the last step's contact evaluation found.
    pub fn contact_stats(&self) -> crate::physics::contact::ContactStats {
        self.contact.stats
    }

    /// Contact nodes, where they live on this board, and their contact force at the last
    /// step (non-zero only for owned nodes).
    pub fn contact_forces(&self) -> (&[ContactNode], &[ContactNodePlace], &[[f64; 3]]) {
        let n = self.header.counts.contact_nodes as usize;
        let cs = &self.st.contact;
        (&cs.nodes[..n], &cs.places[..n], &cs.force[..n])
    }

    fn fault(&self, kind: FaultKind) -> Fault {
        Fault {
            board: self.header.board,
            step: self.step,
            kind,
        }
    }

    /// Batch `b`: its general elements, then its parallelepipeds (numbered after all the
    /// general ones in faults), by `kernel`.
    fn batch(&mut self, b: usize, kernel: &impl BatchForces<T, E>) -> Result<(), Fault> {
        let c = self.header.counts;
        let (general, boxes, cuboids) = (
            batch_range(c.batch_ends, b),
            batch_range(c.box_batch_ends, b),
            batch_range(c.cuboid_batch_ends, b),
        );
        let st = &mut self.st;
        let n = c.nodes as usize;
        let slices = BatchSlices {
            index: b,
            general: &st.elements[general.clone()],
            first_general: general.start as u32,
            boxes: &st.boxes[boxes.clone()],
            first_box: c.elements + boxes.start as u32,
            cuboids: &st.cuboids[cuboids.clone()],
            first_cuboid: c.elements + c.boxes + cuboids.start as u32,
        };
        kernel
            .batch_forces(slices, st.laws, &st.u[..n], &mut st.force[..n])
            .map_err(|e| self.fault(FaultKind::Physics(e)))
    }

    /// Subtracts the external force of the owned nodes of `stage`: their records' gravity,
    /// loads and contact force, added in the serial solver's order. Nodes without a record
    /// have none (`f − 0 = f`), so they cost nothing here; a record with gravity alone (most
    /// of them) takes the short path, `f − g`, the same bits as `f − (g + nothing)`. Out of
    /// line: its loop keeps its values in registers.
    #[inline(never)]
    fn external(&mut self, stage: u8, t: f64) {
        let Some(&(start, end)) = self.external_stages.get(stage as usize) else {
            return;
        };
        let c = self.header.counts;
        let Storage {
            path_points,
            loads,
            external,
            force,
            contact,
            ..
        } = &mut self.st;
        let points = &path_points[..c.path_points as usize];
        let loads = &loads[..c.loads as usize];
        let records = external.get(start as usize..end as usize).unwrap_or(&[]);
        // Each load ramp once at `t`, however many records share it; gravity's too.
        let mut ramps = path_values::RampValues::new();
        let gravity_factor = self
            .header
            .params
            .gravity_ramp
            .map(|p| T::from_f64(ramps.factor(points, p, t)));
        let ext = External {
            points,
            loads,
            contact_force: contact.force,
            t,
            gravity_factor,
        };
        // One loop per case, so the records with gravity alone (most) take no branch on it.
        match gravity_factor {
            None => subtract_external::<T, false>(records, force, &ext, &mut ramps),
            Some(_) => subtract_external::<T, true>(records, force, &ext, &mut ramps),
        }
    }

    /// Advances the current step as far as the links allow without waiting. Returns
    /// `Ok(true)` when the step is complete, `Ok(false)` when it waits for a link (call
    /// again later). A link that keeps it waiting longer than the timeout is a fault.
    pub fn poll_step(
        &mut self,
        links: &mut impl Links,
        env: &mut impl Environment,
    ) -> Result<bool, Fault> {
        self.poll_step_with(links, env, &ScalarBatches)
    }

    /// [`Self::poll_step`] with the batches' internal forces computed by `kernel`.
    pub fn poll_step_with(
        &mut self,
        links: &mut impl Links,
        env: &mut impl Environment,
        kernel: &impl BatchForces<T, E>,
    ) -> Result<bool, Fault> {
        if !self.hello.is_done() {
            if !self.hello_poll(links)? {
                let now = env.now_ns();
                let since = *self.waiting_since.get_or_insert(now);
                if now.saturating_sub(since) > self.config.link_timeout_ns {
                    return Err(self.fault(FaultKind::LinkTimeout {
                        face: self.hello.missing(),
                    }));
                }
                return Ok(false);
            }
            if let Some(since) = self.waiting_since.take() {
                self.stats.wait_ns += env.now_ns().saturating_sub(since);
            }
        }
        let t = self.step as f64 * self.header.params.dt_s;
        while let Some(op) = self.program.get(self.pc) {
            let done = match op {
                Op::Graphics => self.graphics_poll(links)?,
                Op::Contact => self.contact_poll(links)?,
                Op::Batch(k) => {
                    self.batch(k as usize, kernel)?;
                    true
                }
                Op::External(stage) => {
                    self.external(stage, t);
                    true
                }
                Op::Send(a, r, f) => self.send_face(links, (a, r, f))?,
                Op::Recv(a, r, f) => self.recv_face(links, (a, r, f))?,
                Op::Update => {
                    self.update(t + self.header.params.dt_s)?;
                    true
                }
            };
            if !done {
                let now = env.now_ns();
                let since = *self.waiting_since.get_or_insert(now);
                if now.saturating_sub(since) > self.config.link_timeout_ns {
                    return Err(self.timeout(op));
                }
                return Ok(false);
            }
            if let Some(since) = self.waiting_since.take() {
                self.stats.wait_ns += env.now_ns().saturating_sub(since);
            }
            self.pc += 1;
        }
        self.pc = 0;
        Ok(true)
    }

    /// The operation the step is at (the one that faulted, after a fault).
    pub fn current_op(&self) -> Option<Op> {
        self.program.get(self.pc)
    }

    /// If the runtime is waiting for a link: the fault its wait would become on timing out
    /// (board, step, link), and how long it has waited (ns, at `now_ns`). For a host that
    /// stops a run and asks every board where it stood.
    pub fn waiting(&self, now_ns: u64) -> Option<(Fault, u64)> {
        let since = self.waiting_since?;
        Some((
            self.timeout(self.current_op()?),
            now_ns.saturating_sub(since),
        ))
    }

    /// The fault of an operation that waited longer than the link timeout.
    fn timeout(&self, op: Op) -> Fault {
        match op {
            Op::Contact if self.waits_for_permit() => self.fault(FaultKind::GlobalTimeout {
                src: link_proto::packet::ADDR_HOST,
            }),
            Op::Contact => self.fault(FaultKind::GlobalTimeout {
                src: self
                    .contact
                    .missing_partner(self.step, self.header.counts.contact_boards as usize),
            }),
            Op::Send(a, _, f) | Op::Recv(a, _, f) => self.fault(FaultKind::LinkTimeout {
                face: program::face_of(a as usize, f as usize),
            }),
            _ => self.fault(FaultKind::LinkTimeout { face: Face::PosX }),
        }
    }

    /// One explicit step by the seed's interleaved schedule, waiting (through
    /// `env.idle()`) for the links as needed.
    pub fn step(
        &mut self,
        links: &mut impl Links,
        env: &mut impl Environment,
    ) -> Result<(), Fault> {
        while !self.poll_step(links, env)? {
            links.poll();
            env.idle();
        }
        Ok(())
    }

    /// Central-difference update of every held node from its total force
    /// ([`update_node`], the serial solver's function), so replicas and the serial run
    /// agree; clears the forces for the next step on the way. A free node takes the short
    /// path (its gain and force); a fixed or prescribed node (held: not exchanged, so its
    /// force is this board's part) adds its force to the reaction. Out of line: its loop keeps its values in registers.
    #[inline(never)]
    fn update(&mut self, t_next: f64) -> Result<(), Fault> {
        let c = self.header.counts;
        let inv_2dt = 1.0 / (2.0 * self.header.params.dt_s);
        let limit = self.header.params.speed_limit_m_per_s;
        let (mut rp, mut rf, mut ke) = ([0.0; 3], [0.0; 3], 0.0);
        let cd = self.cd;
        let (board, step) = (self.header.board, self.step);
        let Storage {
            nodes,
            u,
            du,
            force,
            path_points,
            ..
        } = &mut self.st;
        let points = &path_points[..c.path_points as usize];
        // Each motion path once at `t_next`, however many held nodes follow it.
        let paths = path_values::PathsAt::new(points, t_next);
        let n = c.nodes as usize;
        // Each array cut to the nodes (the loader checked they hold them): one count.
        let all = (nodes.get(..n).unwrap_or(&[]).iter())
            .zip(u.get_mut(..n).unwrap_or(&mut []))
            .zip(du.get_mut(..n).unwrap_or(&mut []))
            .zip(force.get_mut(..n).unwrap_or(&mut []));
        for (((rec, u), du), f) in all {
            let total = *f;
            *f = [T::ZERO; 3];
            // One call per motion, so the free node's (the common one's) copy of the
            // update has no branch on the motion left in it.
            let r = match rec.motion {
                NodeMotion::Free => {
                    let residual = [-total[0], -total[1], -total[2]];
                    let mv = NodeMove::Free {
                        gain: rec.gain,
                        residual,
                    };
                    update_node(&cd, u, du, mv, inv_2dt, limit, rec.global)
                }
                NodeMotion::Fixed => {
                    add_reaction(&mut rf, total);
                    let mv = NodeMove::Held([T::ZERO; 3]);
                    update_node(&cd, u, du, mv, inv_2dt, limit, rec.global)
                }
                NodeMotion::Prescribed(p) => {
                    add_reaction(&mut rp, total);
                    let mv = NodeMove::Held(prescribed(&paths, p));
                    update_node(&cd, u, du, mv, inv_2dt, limit, rec.global)
                }
            };
            let v2 = r.map_err(|e| Fault {
                board,
                step,
                kind: FaultKind::Physics(e),
            })?;
            ke += rec.half_mass_kg * v2;
        }
        self.reaction_prescribed = rp;
        self.reaction_fixed = rf;
        self.kinetic_energy = ke;
        self.step += 1;
        Ok(())
    }
}

/// `r += total` (in f64).
#[inline(always)]
fn add_reaction<T: Real>(r: &mut [f64; 3], total: [T; 3]) {
    for i in 0..3 {
        r[i] += total[i].to_f64();
    }
}

/// A record's gravity `g`, times gravity's ramp factor `s` when it has one (`g · s`, in
/// the node's precision: the host's `f_ext` is the same product).
#[inline(always)]
fn scaled<T: Real>(g: [T; 3], factor: Option<T>) -> [T; 3] {
    match factor {
        Some(s) => g.map(|gi| gi * s),
        None => g,
    }
}

/// `f −= f_ext` for each record's node: gravity alone (most records) on the short path,
/// `f − g` (`f − g · s` when `RAMPED`, `s` the ramp's factor), the same bits as `f − (g +
/// nothing)`; the others through [`external_force`].
#[inline(always)]
fn subtract_external<T: Real, const RAMPED: bool>(
    records: &[ExternalRecord<T>],
    force: &mut [[T; 3]],
    ext: &External<'_, T>,
    ramps: &mut path_values::RampValues,
) {
    let s = ext.gravity_factor.unwrap_or(T::from_f64(1.0));
    for x in records {
        let Some(f) = force.get_mut(x.node as usize) else {
            continue;
        };
        if x.loads == 0 && x.contact.is_none() {
            // Both read before `f` is written (the compiler cannot tell that the record and
            // the force array never overlap): two multiple loads, one store.
            let (g, mut v) = (x.gravity, *f);
            for i in 0..3 {
                v[i] -= if RAMPED { g[i] * s } else { g[i] };
            }
            *f = v;
        } else {
            let fe = external_force(x, ext, ramps);
            for i in 0..3 {
                f[i] -= fe[i];
            }
        }
    }
}

/// What the external force of a stage reads besides its records: the path table, the
/// loads, the contact forces, the stage's time and gravity's ramp factor at it.
struct External<'a, T> {
    points: &'a [PathPoint],
    loads: &'a [LoadRecord],
    contact_force: &'a [[f64; 3]],
    t: f64,
    gravity_factor: Option<T>,
}

/// The external force of a record with loads or a contact node: gravity (ramped), then
/// each load (ramped by its path at `t`, from `ramps`), then the contact force, in the
/// serial solver's order.
#[inline(always)]
fn external_force<T: Real>(
    x: &ExternalRecord<T>,
    e: &External<'_, T>,
    ramps: &mut path_values::RampValues,
) -> [T; 3] {
    let (points, loads, contact_force, t) = (e.points, e.loads, e.contact_force, e.t);
    let mut fe = scaled(x.gravity, e.gravity_factor);
    // (A build without loads or contact loads no image that has them.)
    if cfg!(feature = "loads") {
        let first = x.first_load as usize;
        for l in loads.get(first..first + x.loads as usize).unwrap_or(&[]) {
            let s = l.ramp.map_or(1.0, |p| ramps.factor(points, p, t));
            for i in 0..3 {
                fe[i] += T::from_f64(l.force[i] * s);
            }
        }
    }
    if cfg!(feature = "contact") {
        if let Some(f) = x.contact.and_then(|cn| contact_force.get(cn as usize)) {
            for i in 0..3 {
                fe[i] += T::from_f64(f[i]);
            }
        }
    }
    fe
}

/// Prescribed path `p` at the update's `t_next` (from `paths`, each path evaluated once per
/// update), in the node's precision.
#[inline(never)]
fn prescribed<T: Real>(paths: &path_values::PathsAt<'_>, p: u16) -> [T; 3] {
    paths.value(p).map(T::from_f64)
}

/// The two element kinds a runtime can be built for.
pub type ReducedRuntime<'a, T> = Runtime<'a, T, HexReduced<T>>;
pub type FullRuntime<'a, T> = Runtime<'a, T, HexFull<T>>;
