//! The board runtime: loads a schedule image and runs steps by the seed's interleaved
//! schedule over the link interface. The only place where schedule, physics and links meet.
//!
//! Storage is the caller's ([`Storage`]): fixed arrays sized by const generics on the board
//! (see [`StaticStorage`]), exact-size buffers in board-sim. Time and idling come in through
//! [`Environment`]; links through [`link_proto::Links`]. Nothing here allocates or panics:
//! bad images, bad frames, stalled links and numerical failure become a [`Fault`] naming
//! the board, the link or the element, and the step.

use link_proto::{emit_values, Face, FrameKind, FrameRepr, Links, Values, FRAME_LEN_MAX};
use serde::de::DeserializeOwned;

use crate::image::*;
use crate::physics::explicit::accumulate_internal_forces;
use crate::physics::{
    CentralDifference, HexElement, HexFull, HexReduced, MaterialLaw, PhysicsError, Real,
};

/// Most exchange rounds per axis a runtime handles.
pub const ROUNDS_PER_AXIS_MAX: usize = 8;

/// A scalar that travels in link frames.
pub trait WireReal: Real + DeserializeOwned + serde::Serialize {
    const PRECISION: Precision;
    fn wire(values: &[Self]) -> Values<'_>;
}

impl WireReal for f32 {
    const PRECISION: Precision = Precision::F32;
    fn wire(values: &[f32]) -> Values<'_> {
        Values::F32(values)
    }
}

impl WireReal for f64 {
    const PRECISION: Precision = Precision::F64;
    fn wire(values: &[f64]) -> Values<'_> {
        Values::F64(values)
    }
}

/// Time and waiting, passed in (never read globally).
pub trait Environment {
    /// Monotonic time in ns.
    fn now_ns(&mut self) -> u64;
    /// Called while waiting for a link (spin, yield, sleep until an interrupt...).
    fn idle(&mut self);
}

/// What went wrong, where.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FaultKind {
    /// No frame arrived on `face` within the link timeout.
    LinkTimeout {
        face: Face,
    },
    /// The link reported an error (damaged frame, I/O).
    LinkError {
        face: Face,
        error: link_proto::RecvError,
    },
    /// A frame could not be sent.
    SendFailed {
        face: Face,
        error: link_proto::SendError,
    },
    /// A frame arrived intact but is not the one the schedule expects.
    UnexpectedFrame {
        face: Face,
        expected_step: u32,
        step: u32,
        expected_values: u16,
        values: u16,
    },
    /// The frame failed to parse (CRC, length).
    BadFrame {
        face: Face,
        error: link_proto::Error,
    },
    Physics(PhysicsError),
    /// The schedule image was refused.
    Image(ImageError),
}

/// A fault with its board and step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fault {
    pub board: [u8; 3],
    pub step: u64,
    pub kind: FaultKind,
}

impl core::fmt::Display for Fault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let [x, y, z] = self.board;
        write!(f, "board ({x},{y},{z}) step {}: ", self.step)?;
        match self.kind {
            FaultKind::LinkTimeout { face } => write!(f, "link {face:?}: no frame within the timeout"),
            FaultKind::LinkError { face, error } => write!(f, "link {face:?}: {error:?}"),
            FaultKind::SendFailed { face, error } => write!(f, "link {face:?}: send failed: {error:?}"),
            FaultKind::UnexpectedFrame { face, expected_step, step, expected_values, values } => write!(
                f,
                "link {face:?}: frame for step {step} with {values} values, expected step {expected_step} with {expected_values}"
            ),
            FaultKind::BadFrame { face, error } => write!(f, "link {face:?}: bad frame: {error}"),
            FaultKind::Physics(e) => write!(f, "{e}"),
            FaultKind::Image(e) => write!(f, "schedule image: {e}"),
        }
    }
}

/// Caller-provided storage for one board (lengths are the capacities).
pub struct Storage<'a, T, E> {
    pub laws: &'a mut [MaterialLaw<T>],
    pub elements: &'a mut [E],
    pub nodes: &'a mut [NodeRecord<T>],
    pub ext_stage: &'a mut [u8],
    pub u: &'a mut [[T; 3]],
    pub u_prev: &'a mut [[T; 3]],
    pub force: &'a mut [[T; 3]],
    pub sends: &'a mut [u16],
    pub recvs: &'a mut [RecvEntry],
    pub path_points: &'a mut [PathPoint],
    pub loads: &'a mut [LoadRecord],
}

/// Fixed-capacity storage for the firmware: `NE` elements, `NN` nodes, `NX` exchange
/// entries, `NP` path points, `NL` loads, `NM` materials.
pub struct StaticStorage<
    T,
    E,
    const NE: usize,
    const NN: usize,
    const NX: usize,
    const NP: usize,
    const NL: usize,
    const NM: usize,
> {
    pub laws: [MaterialLaw<T>; NM],
    pub elements: [E; NE],
    pub nodes: [NodeRecord<T>; NN],
    pub ext_stage: [u8; NN],
    pub u: [[T; 3]; NN],
    pub u_prev: [[T; 3]; NN],
    pub force: [[T; 3]; NN],
    pub sends: [u16; NX],
    pub recvs: [RecvEntry; NX],
    pub path_points: [PathPoint; NP],
    pub loads: [LoadRecord; NL],
}

impl<
        T: Real,
        E,
        const NE: usize,
        const NN: usize,
        const NX: usize,
        const NP: usize,
        const NL: usize,
        const NM: usize,
    > StaticStorage<T, E, NE, NN, NX, NP, NL, NM>
{
    pub fn storage(&mut self) -> Storage<'_, T, E> {
        Storage {
            laws: &mut self.laws,
            elements: &mut self.elements,
            nodes: &mut self.nodes,
            ext_stage: &mut self.ext_stage,
            u: &mut self.u,
            u_prev: &mut self.u_prev,
            force: &mut self.force,
            sends: &mut self.sends,
            recvs: &mut self.recvs,
            path_points: &mut self.path_points,
            loads: &mut self.loads,
        }
    }
}

/// One operation of a step's fixed sequence (the seed's interleaved schedule).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Op {
    Begin,
    Batch(u8),
    External(u8),
    /// (axis, round, face 0 = +axis / 1 = −axis)
    Send(u8, u8, u8),
    Recv(u8, u8, u8),
    Update,
}

/// Most operations in a step: begin, 4 batches, 4 external stages, 3 axes × rounds × 2
/// faces × (send + receive), update.
const OPS_MAX: usize = 10 + 3 * ROUNDS_PER_AXIS_MAX * 4;

/// Ranges of one round's lists in the flat `sends` / `recvs` arrays, per face (+, −).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct RoundRanges {
    send: [(u32, u32); 2],
    recv: [(u32, u32); 2],
}

/// Runtime settings that are not part of the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RuntimeConfig {
    /// A link that delivers nothing for this long is a fault (ns).
    pub link_timeout_ns: u64,
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        RuntimeConfig {
            link_timeout_ns: 10_000_000_000,
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
    ops: [Op; OPS_MAX],
    ops_len: usize,
    /// Next operation of the current step.
    pc: usize,
    /// When the current operation started waiting (ns), if it is waiting.
    waiting_since: Option<u64>,
    st: Storage<'a, T, E>,
    rounds: [[RoundRanges; ROUNDS_PER_AXIS_MAX]; 3],
    cd: CentralDifference<T>,
    step: u64,
    config: RuntimeConfig,
    tx: [u8; FRAME_LEN_MAX],
    rx: [u8; FRAME_LEN_MAX],
    scratch: [T; link_proto::VALUES_PER_FRAME_MAX],
    pub stats: LinkStats,
    /// Sum of `f_int − f_ext` over owned prescribed and fixed nodes at the last step (N).
    pub reaction_prescribed: [f64; 3],
    pub reaction_fixed: [f64; 3],
    /// Kinetic energy of owned nodes at the last step (J).
    pub kinetic_energy: f64,
}

fn capacity(what: &'static str, count: usize, max: usize) -> Result<(), ImageError> {
    if count > max {
        Err(ImageError::Capacity {
            what,
            count: count as u32,
            max: max as u32,
        })
    } else {
        Ok(())
    }
}

impl<'a, T: WireReal, E: HexElement<T> + DeserializeOwned> Runtime<'a, T, E> {
    /// Checks and loads `image` for board `board` into `st`.
    pub fn load(
        image: &[u8],
        board: [u8; 3],
        st: Storage<'a, T, E>,
        config: RuntimeConfig,
    ) -> Result<Self, ImageError> {
        let mut r = ImageReader::new(image, Some(board))?;
        let h = r.header;
        let c = h.counts;
        if h.precision != T::PRECISION {
            return Err(ImageError::Malformed {
                record: "precision differs from this runtime's",
            });
        }
        let reduced = core::mem::size_of::<E>() == core::mem::size_of::<HexReduced<T>>();
        if (h.integration == Integration::Reduced) != reduced {
            return Err(ImageError::Malformed {
                record: "integration differs from this runtime's",
            });
        }
        let (ne, nn) = (c.elements as usize, c.nodes as usize);
        capacity("materials", c.materials as usize, st.laws.len())?;
        capacity("elements", ne, st.elements.len())?;
        capacity(
            "nodes",
            nn,
            st.nodes
                .len()
                .min(st.u.len())
                .min(st.u_prev.len())
                .min(st.force.len())
                .min(st.ext_stage.len()),
        )?;
        capacity("exchange sends", c.sends as usize, st.sends.len())?;
        capacity("exchange receives", c.recvs as usize, st.recvs.len())?;
        capacity("path points", c.path_points as usize, st.path_points.len())?;
        capacity("loads", c.loads as usize, st.loads.len())?;
        for &n in &c.rounds {
            capacity("exchange rounds", n as usize, ROUNDS_PER_AXIS_MAX)?;
        }
        if !(c.batch_ends[0] <= c.batch_ends[1]
            && c.batch_ends[1] <= c.batch_ends[2]
            && c.batch_ends[2] <= c.batch_ends[3]
            && c.batch_ends[3] as usize == ne)
        {
            return Err(ImageError::Malformed {
                record: "batch ends",
            });
        }
        for k in 0..c.materials as usize {
            st.laws[k] = r.next::<MaterialLaw<f64>>("material")?.cast::<T>();
        }
        for k in 0..ne {
            let e: E = r.next("element")?;
            if e.nodes().iter().any(|&n| n as usize >= nn) {
                return Err(ImageError::BadIndex {
                    what: "node of element",
                    index: k as u32,
                });
            }
            if e.material() >= c.materials as usize {
                return Err(ImageError::BadIndex {
                    what: "material of element",
                    index: k as u32,
                });
            }
            st.elements[k] = e;
        }
        for k in 0..nn {
            let n: NodeRecord<T> = r.next("node")?;
            st.nodes[k] = n;
            st.ext_stage[k] = r.next("node stage")?;
            st.u[k] = [T::ZERO; 3];
            st.u_prev[k] = [T::ZERO; 3];
        }
        let mut rounds = [[RoundRanges::default(); ROUNDS_PER_AXIS_MAX]; 3];
        let (mut ns, mut nr) = (0usize, 0usize);
        for a in 0..3 {
            for round in rounds[a].iter_mut().take(c.rounds[a] as usize) {
                for f in 0..2 {
                    let n: u16 = r.next("send count")?;
                    let start = ns;
                    for _ in 0..n {
                        let v: u16 = r.next("send")?;
                        if v as usize >= nn {
                            return Err(ImageError::BadIndex {
                                what: "node of send list",
                                index: v as u32,
                            });
                        }
                        *st.sends.get_mut(ns).ok_or(ImageError::Capacity {
                            what: "exchange sends",
                            count: ns as u32 + 1,
                            max: c.sends,
                        })? = v;
                        ns += 1;
                    }
                    round.send[f] = (start as u32, ns as u32);
                    let n: u16 = r.next("receive count")?;
                    let start = nr;
                    for _ in 0..n {
                        let v: RecvEntry = r.next("receive")?;
                        if v.node as usize >= nn {
                            return Err(ImageError::BadIndex {
                                what: "node of receive list",
                                index: v.node as u32,
                            });
                        }
                        *st.recvs.get_mut(nr).ok_or(ImageError::Capacity {
                            what: "exchange receives",
                            count: nr as u32 + 1,
                            max: c.recvs,
                        })? = v;
                        nr += 1;
                    }
                    round.recv[f] = (start as u32, nr as u32);
                }
            }
        }
        for k in 0..c.path_points as usize {
            st.path_points[k] = r.next("path point")?;
        }
        for k in 0..c.loads as usize {
            let l: LoadRecord = r.next("load")?;
            if l.node as usize >= nn {
                return Err(ImageError::BadIndex {
                    what: "node of load",
                    index: k as u32,
                });
            }
            st.loads[k] = l;
        }
        if !r.is_done() {
            return Err(ImageError::Malformed {
                record: "trailing bytes",
            });
        }
        let (ops, ops_len) = program(&c.rounds);
        Ok(Runtime {
            header: h,
            ops,
            ops_len,
            pc: 0,
            waiting_since: None,
            st,
            rounds,
            cd: CentralDifference::new(h.params.dt_s, h.params.damping_per_s),
            step: 0,
            config,
            tx: [0; FRAME_LEN_MAX],
            rx: [0; FRAME_LEN_MAX],
            scratch: [T::ZERO; link_proto::VALUES_PER_FRAME_MAX],
            stats: LinkStats::default(),
            reaction_prescribed: [0.0; 3],
            reaction_fixed: [0.0; 3],
            kinetic_energy: 0.0,
        })
    }

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

    fn fault(&self, kind: FaultKind) -> Fault {
        Fault {
            board: self.header.board,
            step: self.step,
            kind,
        }
    }

    fn batch(&mut self, b: usize) -> Result<(), Fault> {
        let ends = self.header.counts.batch_ends;
        let start = if b == 0 { 0 } else { ends[b - 1] as usize };
        let end = ends[b] as usize;
        let st = &mut self.st;
        let n = self.header.counts.nodes as usize;
        accumulate_internal_forces(
            &st.elements[start..end],
            start as u32,
            st.laws,
            &st.u[..n],
            &mut st.force[..n],
        )
        .map_err(|e| Fault {
            board: self.header.board,
            step: self.step,
            kind: FaultKind::Physics(e),
        })
    }

    /// Subtracts the external force of owned nodes whose stage is `stage`.
    fn external(&mut self, stage: u8, t: f64) {
        let n = self.header.counts.nodes as usize;
        for k in 0..n {
            if self.st.ext_stage[k] == stage {
                let g = self.st.nodes[k].gravity;
                let mut fe = g;
                for l in self.st.loads[..self.header.counts.loads as usize]
                    .iter()
                    .filter(|l| l.node as usize == k)
                {
                    let s = match l.ramp {
                        Some(p) => path_value(
                            &self.st.path_points[..self.header.counts.path_points as usize],
                            p,
                            t,
                        )[0],
                        None => 1.0,
                    };
                    for i in 0..3 {
                        fe[i] += T::from_f64(l.force[i] * s);
                    }
                }
                for i in 0..3 {
                    self.st.force[k][i] -= fe[i];
                }
            }
        }
    }

    /// Sends one face's frame of a round; `Ok(false)` if the link's queue is full.
    fn send_face(
        &mut self,
        links: &mut impl Links,
        axis: usize,
        round: usize,
        f: usize,
    ) -> Result<bool, Fault> {
        let (s, e) = self.rounds[axis][round].send[f];
        if s == e {
            return Ok(true);
        }
        let face = face_of(axis, f);
        let mut m = 0;
        for &k in &self.st.sends[s as usize..e as usize] {
            let v = self.st.force[k as usize];
            self.scratch[m..m + 3].copy_from_slice(&v);
            m += 3;
        }
        let len = emit_values(
            FrameKind::Forces,
            self.step as u32,
            T::wire(&self.scratch[..m]),
            &mut self.tx,
        )
        .map_err(|_| {
            self.fault(FaultKind::SendFailed {
                face,
                error: link_proto::SendError::TooLong,
            })
        })?;
        match links.try_send(face, &self.tx[..len]) {
            Ok(()) => {
                self.stats.frames_sent[face.index()] += 1;
                self.stats.bytes_sent[face.index()] += len as u64;
                Ok(true)
            }
            Err(link_proto::SendError::WouldBlock) => Ok(false),
            Err(error) => Err(self.fault(FaultKind::SendFailed { face, error })),
        }
    }

    /// Receives and combines one face's frame of a round; `Ok(false)` if it has not arrived.
    fn recv_face(
        &mut self,
        links: &mut impl Links,
        axis: usize,
        round: usize,
        f: usize,
    ) -> Result<bool, Fault> {
        let (s, e) = self.rounds[axis][round].recv[f];
        if s == e {
            return Ok(true);
        }
        let face = face_of(axis, f);
        let len = match links.try_recv(face, &mut self.rx) {
            Ok(Some(len)) => len,
            Ok(None) => return Ok(false),
            Err(error) => return Err(self.fault(FaultKind::LinkError { face, error })),
        };
        self.stats.frames_received[face.index()] += 1;
        let repr = FrameRepr::parse_bytes(&self.rx[..len])
            .map_err(|error| self.fault(FaultKind::BadFrame { face, error }))?;
        let expected = 3 * (e - s) as usize;
        if repr.kind != FrameKind::Forces
            || repr.step != self.step as u32
            || repr.payload.len() != expected
            || repr.payload.precision() != T::wire(&[]).precision()
        {
            return Err(self.fault(FaultKind::UnexpectedFrame {
                face,
                expected_step: self.step as u32,
                step: repr.step,
                expected_values: expected as u16,
                values: repr.payload.len() as u16,
            }));
        }
        for (j, entry) in self.st.recvs[s as usize..e as usize].iter().enumerate() {
            let k = entry.node as usize;
            for i in 0..3 {
                let v = T::from_f64(repr.payload.get(3 * j + i).unwrap_or(f64::NAN));
                let cur = self.st.force[k][i];
                self.st.force[k][i] = match entry.combine {
                    Combine::Before => v + cur,
                    Combine::After => cur + v,
                    Combine::Replace => v,
                };
            }
        }
        Ok(true)
    }

    /// Advances the current step as far as the links allow without waiting. Returns
    /// `Ok(true)` when the step is complete, `Ok(false)` when it waits for a link (call
    /// again later). A link that keeps it waiting longer than the timeout is a fault.
    pub fn poll_step(
        &mut self,
        links: &mut impl Links,
        env: &mut impl Environment,
    ) -> Result<bool, Fault> {
        let n = self.header.counts.nodes as usize;
        let t = self.step as f64 * self.header.params.dt_s;
        while self.pc < self.ops_len {
            let done = match self.ops[self.pc] {
                Op::Begin => {
                    for f in self.st.force[..n].iter_mut() {
                        *f = [T::ZERO; 3];
                    }
                    true
                }
                Op::Batch(k) => {
                    self.batch(k as usize)?;
                    true
                }
                Op::External(stage) => {
                    self.external(stage, t);
                    true
                }
                Op::Send(a, r, f) => self.send_face(links, a as usize, r as usize, f as usize)?,
                Op::Recv(a, r, f) => self.recv_face(links, a as usize, r as usize, f as usize)?,
                Op::Update => {
                    self.update(t + self.header.params.dt_s)?;
                    true
                }
            };
            if !done {
                let now = env.now_ns();
                let since = *self.waiting_since.get_or_insert(now);
                if now.saturating_sub(since) > self.config.link_timeout_ns {
                    let face = match self.ops[self.pc] {
                        Op::Send(a, _, f) | Op::Recv(a, _, f) => face_of(a as usize, f as usize),
                        _ => Face::PosX,
                    };
                    return Err(self.fault(FaultKind::LinkTimeout { face }));
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

    /// Central-difference update of every held node from its total force; the same
    /// arithmetic as the serial solver, so replicas and the serial run agree.
    fn update(&mut self, t_next: f64) -> Result<(), Fault> {
        let n = self.header.counts.nodes as usize;
        let inv2dt = 1.0 / (2.0 * self.header.params.dt_s);
        let limit = self.header.params.speed_limit_m_per_s;
        let (mut rp, mut rf, mut ke) = ([0.0; 3], [0.0; 3], 0.0);
        let np = self.header.counts.path_points as usize;
        for k in 0..n {
            let rec = self.st.nodes[k];
            let total = self.st.force[k];
            let next = match rec.motion {
                NodeMotion::Free => {
                    let r = [-total[0], -total[1], -total[2]];
                    let next = self
                        .cd
                        .advance(&self.st.u[k], &self.st.u_prev[k], rec.gain, &r);
                    if !next.iter().all(|v| v.is_finite()) {
                        return Err(self.fault(FaultKind::Physics(PhysicsError::NonFinite {
                            node: rec.global,
                        })));
                    }
                    next
                }
                NodeMotion::Fixed => {
                    if rec.owner {
                        for i in 0..3 {
                            rf[i] += total[i].to_f64();
                        }
                    }
                    [T::ZERO; 3]
                }
                NodeMotion::Prescribed(p) => {
                    if rec.owner {
                        for i in 0..3 {
                            rp[i] += total[i].to_f64();
                        }
                    }
                    path_value(&self.st.path_points[..np], p, t_next).map(T::from_f64)
                }
            };
            let v: [f64; 3] =
                core::array::from_fn(|i| (next[i] - self.st.u_prev[k][i]).to_f64() * inv2dt);
            let v2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            if v2 > limit * limit {
                return Err(self.fault(FaultKind::Physics(PhysicsError::SpeedLimit {
                    node: rec.global,
                    speed_m_per_s: libm::sqrt(v2),
                })));
            }
            if rec.owner {
                // m_inertial = C / gain
                ke += 0.5 * (self.cd.c.to_f64() / rec.gain.to_f64()) * v2;
            }
            self.st.u_prev[k] = self.st.u[k];
            self.st.u[k] = next;
        }
        self.reaction_prescribed = rp;
        self.reaction_fixed = rf;
        self.kinetic_energy = ke;
        self.step += 1;
        Ok(())
    }
}

/// The step's operations: batch x; send ±x; batch y; receive ±x (and further x rounds);
/// send ±y; batch z; receive ±y...; send ±z; inner batch; receive ±z...; update. External
/// forces of owned nodes go in just before their first exchange.
fn program(rounds: &[u8; 3]) -> ([Op; OPS_MAX], usize) {
    let mut ops = [Op::Update; OPS_MAX];
    let mut n = 0;
    let mut push = |op| {
        if n < OPS_MAX {
            ops[n] = op;
            n += 1;
        }
    };
    push(Op::Begin);
    push(Op::Batch(0));
    for axis in 0..3u8 {
        let r = rounds[axis as usize].min(ROUNDS_PER_AXIS_MAX as u8);
        push(Op::External(axis));
        if r > 0 {
            push(Op::Send(axis, 0, 0));
            push(Op::Send(axis, 0, 1));
        }
        push(Op::Batch(axis + 1));
        for round in 0..r {
            if round > 0 {
                push(Op::Send(axis, round, 0));
                push(Op::Send(axis, round, 1));
            }
            // The −axis face first: the summation trees put the lower board on the left.
            push(Op::Recv(axis, round, 1));
            push(Op::Recv(axis, round, 0));
        }
    }
    push(Op::External(3));
    push(Op::Update);
    (ops, n)
}

fn face_of(axis: usize, f: usize) -> Face {
    Face::from_index(2 * axis + f).unwrap_or(Face::PosX)
}

/// The two element kinds a runtime can be built for.
pub type ReducedRuntime<'a, T> = Runtime<'a, T, HexReduced<T>>;
pub type FullRuntime<'a, T> = Runtime<'a, T, HexFull<T>>;
