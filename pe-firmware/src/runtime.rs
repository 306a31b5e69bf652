//! The board runtime: loads a schedule image and runs steps by the seed's interleaved
//! schedule over the link interface. The only place where schedule, physics and links meet.
//!
//! Storage is the caller's ([`Storage`]): fixed arrays sized by const generics on the board
//! (see [`StaticStorage`]), exact-size buffers in board-sim. Time and idling come in through
//! [`Environment`]; links through [`link_proto::Links`]. Nothing here allocates or panics:
//! bad images, bad frames, stalled links and numerical failure become a [`Fault`] naming
//! the board, the link or the element, and the step.

use link_proto::payload::{
    emit_node_entry, emit_surface_entry, node_entry, BoxPayload, NodesHeader, SurfaceHeader,
    ToolForcePayload, NODES_PER_PACKET_MAX, SURFACE_NODES_PER_PACKET_MAX,
};
use link_proto::{
    emit_values, Face, FrameKind, FrameRepr, Links, Packet, PacketKind, PacketRepr, Values,
    FRAME_LEN_MAX, PACKET_HEADER_LEN,
};
use serde::de::DeserializeOwned;

use crate::image::*;
use crate::physics::contact::{
    build_candidates, check_travel, evaluate_pairs, evaluate_tools, Candidate, Capsule,
    ContactModel, ContactStats,
};
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
    /// The global port refused a packet to `dst`.
    GlobalSendFailed {
        dst: u8,
        error: link_proto::SendError,
    },
    /// The global port reported an error.
    GlobalError {
        error: link_proto::RecvError,
    },
    /// A global packet failed to parse (CRC, length, payload layout).
    BadPacket {
        error: link_proto::Error,
    },
    /// A global packet arrived intact but is not one the schedule expects now.
    UnexpectedPacket {
        src: u8,
        kind: u8,
        step: u32,
    },
    /// No packet from board `src` (global address) within the link timeout.
    GlobalTimeout {
        src: u8,
    },
    /// The contact search needs more room than this firmware has.
    ContactCapacity {
        what: &'static str,
        needed: u32,
        max: u32,
    },
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
            FaultKind::GlobalSendFailed { dst, error } => {
                write!(f, "global network: send to {dst} failed: {error:?}")
            }
            FaultKind::GlobalError { error } => write!(f, "global network: {error:?}"),
            FaultKind::BadPacket { error } => write!(f, "global network: bad packet: {error}"),
            FaultKind::UnexpectedPacket { src, kind, step } => write!(
                f,
                "global network: unexpected packet of kind {kind:#04x} for step {step} from {src}"
            ),
            FaultKind::GlobalTimeout { src } => {
                write!(f, "global network: nothing from board {src} within the timeout")
            }
            FaultKind::ContactCapacity { what, needed, max } => write!(
                f,
                "contact: {needed} {what} needed, this firmware holds {max}"
            ),
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

/// Caller-provided storage for contact and the graphics stream (lengths are the
/// capacities; all may be empty when the scene has neither).
pub struct ContactStorage<'a> {
    pub nodes: &'a mut [ContactNode],
    pub places: &'a mut [ContactNodePlace],
    pub faces: &'a mut [ContactFace],
    /// Per contact node: position at the last check, and contact force this step (f64).
    pub at_check: &'a mut [[f64; 3]],
    pub force: &'a mut [[f64; 3]],
    /// Received displacements by step parity (index `2 c + step % 2`) and the step + 1
    /// each belongs to (twice the contact nodes).
    pub remote_u: &'a mut [[f64; 3]],
    pub remote_stamp: &'a mut [u32],
    pub candidates: &'a mut [Candidate],
    /// Contact-node indices sent to the partners until the next check (flat).
    pub send_list: &'a mut [u32],
    /// Per local node: its contact-node index, or `u32::MAX` (as many as nodes).
    pub contact_of: &'a mut [u32],
    /// Local indices of the owned surface nodes sent to the graphics engine.
    pub graphics: &'a mut [u16],
}

/// Fixed-capacity contact storage: `NC` contact nodes, `NF` faces, `NK` candidates, `NS`
/// send entries, `NN` nodes (as [`StaticStorage`]), `NG` graphics nodes.
pub struct StaticContactStorage<
    const NC: usize,
    const NC2: usize,
    const NF: usize,
    const NK: usize,
    const NS: usize,
    const NN: usize,
    const NG: usize,
> {
    pub nodes: [ContactNode; NC],
    pub places: [ContactNodePlace; NC],
    pub faces: [ContactFace; NF],
    pub at_check: [[f64; 3]; NC],
    pub force: [[f64; 3]; NC],
    pub remote_u: [[f64; 3]; NC2],
    pub remote_stamp: [u32; NC2],
    pub candidates: [Candidate; NK],
    pub send_list: [u32; NS],
    pub contact_of: [u32; NN],
    pub graphics: [u16; NG],
}

impl<
        const NC: usize,
        const NC2: usize,
        const NF: usize,
        const NK: usize,
        const NS: usize,
        const NN: usize,
        const NG: usize,
    > StaticContactStorage<NC, NC2, NF, NK, NS, NN, NG>
{
    /// Empty storage (a `const` so it can initialise a `static`).
    pub const EMPTY: Self = StaticContactStorage {
        nodes: [ContactNode {
            global: 0,
            reference: [0.0; 3],
            penalty_n_per_m: 0.0,
            surfaces: 0,
        }; NC],
        places: [ContactNodePlace {
            local: None,
            owned: false,
        }; NC],
        faces: [ContactFace {
            nodes: [0; 4],
            surface: 0,
        }; NF],
        at_check: [[0.0; 3]; NC],
        force: [[0.0; 3]; NC],
        remote_u: [[0.0; 3]; NC2],
        remote_stamp: [0; NC2],
        candidates: [Candidate {
            direction: 0,
            slave: 0,
            face: 0,
        }; NK],
        send_list: [0; NS],
        contact_of: [0; NN],
        graphics: [0; NG],
    };

    pub fn storage(&mut self) -> ContactStorage<'_> {
        ContactStorage {
            nodes: &mut self.nodes,
            places: &mut self.places,
            faces: &mut self.faces,
            at_check: &mut self.at_check,
            force: &mut self.force,
            remote_u: &mut self.remote_u,
            remote_stamp: &mut self.remote_stamp,
            candidates: &mut self.candidates,
            send_list: &mut self.send_list,
            contact_of: &mut self.contact_of,
            graphics: &mut self.graphics,
        }
    }
}

/// Most contact pairs and tools a runtime handles.
pub const PAIRS_MAX: usize = 4;
pub const TOOLS_MAX: usize = 4;
/// Most boards on the global network.
pub const BOARDS_MAX: usize = link_proto::BOARD_COUNT;

/// A received bounding box: (step + 1, min, max).
type BoxEntry = (u32, [f64; 3], [f64; 3]);
/// What evaluating contact yields: tool forces, statistics, new candidate count.
type ContactOutcome = ([[f64; 3]; TOOLS_MAX], ContactStats, Option<usize>);

/// Where the contact operation of a step stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Start,
    /// Sending the box to the contact board with this slot next.
    SendBoxes(usize),
    AwaitBoxes,
    /// Sending nodes: partner slot and offset in its list.
    SendNodes(usize, usize),
    AwaitNodes,
    Evaluate,
    /// Sending tool forces from this tool on.
    SendTools(usize),
}

/// Global-network statistics of one board (for reports).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct GlobalStats {
    pub packets_sent: u64,
    pub bytes_sent: u64,
    pub box_packets: u64,
    pub node_packets: u64,
    /// Contact-node displacement vectors sent.
    pub node_vectors: u64,
    pub graphics_packets: u64,
    pub graphics_bytes: u64,
    pub tool_packets: u64,
    /// Bounding-box checks done and the most candidates one found.
    pub checks: u64,
    pub candidates_max: u32,
    /// Partners at the last check.
    pub partners: u32,
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
    /// Surface nodes to the graphics engine (on the steps of a graphics update).
    Graphics,
    /// Contact: bounding boxes (every check interval), node exchange with the partners,
    /// contact forces of owned nodes, tool forces to the host.
    Contact,
    Batch(u8),
    External(u8),
    /// (axis, round, face 0 = +axis / 1 = −axis)
    Send(u8, u8, u8),
    Recv(u8, u8, u8),
    Update,
}

/// Most operations in a step: begin, 4 batches, 4 external stages, 3 axes × rounds × 2
/// faces × (send + receive), update.
const OPS_MAX: usize = 12 + 3 * ROUNDS_PER_AXIS_MAX * 4;

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
    cs: ContactStorage<'a>,
    pairs: [ContactPair; PAIRS_MAX],
    tools: [Tool; TOOLS_MAX],
    contact_boards: [u8; BOARDS_MAX],
    /// This board's global address and its slot in `contact_boards`.
    address: u8,
    slot: Option<usize>,
    phase: Phase,
    /// Boxes by step parity and slot: (step + 1, min, max).
    boxes: [[BoxEntry; BOARDS_MAX]; 2],
    my_box: ([f64; 3], [f64; 3]),
    /// Partner slots (bit mask) until the next check and their send-list ranges.
    partners: u64,
    send_ranges: [(u32, u32); BOARDS_MAX],
    /// Per step parity: (step + 1, slots whose last node packet arrived).
    done: [(u32, u64); 2],
    candidates_len: usize,
    graphics_cursor: usize,
    msg_id: u16,
    /// Force of the tissue on each tool from this board's nodes at the last step (N).
    pub tool_force: [[f64; 3]; TOOLS_MAX],
    pub contact_stats: ContactStats,
    pub global: GlobalStats,
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
        cs: ContactStorage<'a>,
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
        let nc = c.contact_nodes as usize;
        capacity("contact nodes", nc, cs.nodes.len().min(cs.places.len()))?;
        capacity("contact nodes", nc, cs.at_check.len().min(cs.force.len()))?;
        capacity(
            "contact nodes (received)",
            2 * nc,
            cs.remote_u.len().min(cs.remote_stamp.len()),
        )?;
        capacity("contact faces", c.contact_faces as usize, cs.faces.len())?;
        capacity("contact pairs", c.pairs as usize, PAIRS_MAX)?;
        capacity("tools", c.tools as usize, TOOLS_MAX)?;
        capacity("contact boards", c.contact_boards as usize, BOARDS_MAX)?;
        capacity(
            "graphics nodes",
            c.graphics_nodes as usize,
            cs.graphics.len(),
        )?;
        if nc > 0 {
            capacity("nodes (contact map)", nn, cs.contact_of.len())?;
        }
        for v in cs.contact_of.iter_mut().take(nn) {
            *v = u32::MAX;
        }
        for k in 0..nc {
            let node: ContactNode = r.next("contact node")?;
            let place: ContactNodePlace = r.next("contact node place")?;
            if let Some(l) = place.local {
                if l as usize >= nn {
                    return Err(ImageError::BadIndex {
                        what: "local node of contact node",
                        index: k as u32,
                    });
                }
                cs.contact_of[l as usize] = k as u32;
            }
            cs.nodes[k] = node;
            cs.places[k] = place;
            cs.force[k] = [0.0; 3];
            cs.at_check[k] = [0.0; 3];
            cs.remote_stamp[2 * k] = 0;
            cs.remote_stamp[2 * k + 1] = 0;
        }
        for k in 0..c.contact_faces as usize {
            let f: ContactFace = r.next("contact face")?;
            if f.nodes.iter().any(|&n| n as usize >= nc) {
                return Err(ImageError::BadIndex {
                    what: "node of contact face",
                    index: k as u32,
                });
            }
            cs.faces[k] = f;
        }
        let mut pairs = [ContactPair {
            a: 0,
            b: 0,
            depth_max_m: 0.0,
        }; PAIRS_MAX];
        for (k, p) in pairs.iter_mut().enumerate().take(c.pairs as usize) {
            *p = r.next("contact pair")?;
            if p.a as usize >= crate::physics::contact::SURFACES_MAX
                || p.b as usize >= crate::physics::contact::SURFACES_MAX
            {
                return Err(ImageError::BadIndex {
                    what: "surface of contact pair",
                    index: k as u32,
                });
            }
        }
        let mut tools = [Tool {
            capsule: Capsule {
                a: [0.0; 3],
                b: [0.0; 3],
                radius_m: 0.0,
            },
            path: 0,
            surface: 0,
        }; TOOLS_MAX];
        for (k, t) in tools.iter_mut().enumerate().take(c.tools as usize) {
            *t = r.next("tool")?;
            if t.surface as usize >= crate::physics::contact::SURFACES_MAX {
                return Err(ImageError::BadIndex {
                    what: "surface of tool",
                    index: k as u32,
                });
            }
        }
        let address =
            link_proto::link::board_at(board[0] as usize, board[1] as usize, board[2] as usize)
                .unwrap_or(u8::MAX);
        let mut contact_boards = [0u8; BOARDS_MAX];
        let mut slot = None;
        for k in 0..c.contact_boards as usize {
            contact_boards[k] = r.next("contact board")?;
            if contact_boards[k] == address {
                slot = Some(k);
            }
        }
        for k in 0..c.graphics_nodes as usize {
            let g: u16 = r.next("graphics node")?;
            if g as usize >= nn {
                return Err(ImageError::BadIndex {
                    what: "graphics node",
                    index: k as u32,
                });
            }
            cs.graphics[k] = g;
        }
        if !r.is_done() {
            return Err(ImageError::Malformed {
                record: "trailing bytes",
            });
        }
        let has_contact = c.tools > 0 || c.pairs > 0;
        let has_graphics = c.graphics_nodes > 0 && h.graphics.interval_steps > 0;
        let (ops, ops_len) = program(&c.rounds, has_contact, has_graphics);
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
            cs,
            pairs,
            tools,
            contact_boards,
            address,
            slot,
            phase: Phase::Start,
            boxes: [[(0, [0.0; 3], [0.0; 3]); BOARDS_MAX]; 2],
            my_box: ([0.0; 3], [0.0; 3]),
            partners: 0,
            send_ranges: [(0, 0); BOARDS_MAX],
            done: [(0, 0); 2],
            candidates_len: 0,
            graphics_cursor: 0,
            msg_id: 0,
            tool_force: [[0.0; 3]; TOOLS_MAX],
            contact_stats: ContactStats::default(),
            global: GlobalStats::default(),
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
                let c = self.cs.contact_of.get(k).copied().unwrap_or(u32::MAX);
                if let Some(f) = self.cs.force.get(c as usize) {
                    for i in 0..3 {
                        fe[i] += T::from_f64(f[i]);
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
                Op::Graphics => self.graphics_poll(links)?,
                Op::Contact => self.contact_poll(links)?,
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
                    if self.ops[self.pc] == Op::Contact {
                        return Err(self.fault(FaultKind::GlobalTimeout {
                            src: self.missing_partner(),
                        }));
                    }
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

fn grow(b: &([f64; 3], [f64; 3]), r: f64) -> ([f64; 3], [f64; 3]) {
    (
        core::array::from_fn(|i| b.0[i] - r),
        core::array::from_fn(|i| b.1[i] + r),
    )
}

fn overlaps(a: &([f64; 3], [f64; 3]), b: &([f64; 3], [f64; 3])) -> bool {
    (0..3).all(|i| b.0[i] <= a.1[i] && a.0[i] <= b.1[i])
}

/// Contact and the graphics stream: the runtime's use of the global network.
impl<'a, T: WireReal, E: HexElement<T> + DeserializeOwned> Runtime<'a, T, E> {
    fn contact_model(&self) -> ContactModel<'_> {
        let c = &self.header.counts;
        ContactModel {
            nodes: &self.cs.nodes[..c.contact_nodes as usize],
            faces: &self.cs.faces[..c.contact_faces as usize],
            pairs: &self.pairs[..c.pairs as usize],
            tools: &self.tools[..c.tools as usize],
        }
    }

    /// Position of contact node `c` at this step, if this board knows it: held nodes from
    /// their displacement, others from what the partners sent for this step.
    fn contact_position(&self, c: usize) -> Option<[f64; 3]> {
        let node = self.cs.nodes.get(c)?;
        let u = match self.cs.places.get(c)?.local {
            Some(l) => self.st.u.get(l as usize)?.map(|v| v.to_f64()),
            None => {
                let k = 2 * c + (self.step % 2) as usize;
                if *self.cs.remote_stamp.get(k)? != self.step as u32 + 1 {
                    return None;
                }
                *self.cs.remote_u.get(k)?
            }
        };
        Some(core::array::from_fn(|i| node.reference[i] + u[i]))
    }

    /// Contact nodes, where they live on this board, and their contact force at the last
    /// step (non-zero only for owned nodes).
    pub fn contact_forces(&self) -> (&[ContactNode], &[ContactNodePlace], &[[f64; 3]]) {
        let n = self.header.counts.contact_nodes as usize;
        (
            &self.cs.nodes[..n],
            &self.cs.places[..n],
            &self.cs.force[..n],
        )
    }

    fn owns_contact(&self, c: usize) -> bool {
        self.cs.places.get(c).is_some_and(|p| p.owned)
    }

    /// An owned node of a surface that takes part in a pair (its owner exchanges it).
    fn owns_pair_node(&self, c: usize) -> bool {
        self.owns_contact(c)
            && self
                .cs
                .nodes
                .get(c)
                .is_some_and(|n| n.surfaces & self.header.contact.pair_surfaces != 0)
    }

    fn is_check_step(&self) -> bool {
        self.step
            .is_multiple_of(self.header.contact.check_interval_steps.max(1) as u64)
    }

    /// The first partner (or contact board) this board still waits for.
    fn missing_partner(&self) -> u8 {
        let n = self.header.counts.contact_boards as usize;
        let par = (self.step % 2) as usize;
        let want = self.step as u32 + 1;
        for k in 0..n {
            if Some(k) == self.slot {
                continue;
            }
            let waiting = match self.phase {
                Phase::AwaitBoxes => self.boxes[par][k].0 != want,
                _ => {
                    self.partners & (1 << k) != 0
                        && !(self.done[par].0 == want && self.done[par].1 & (1 << k) != 0)
                }
            };
            if waiting {
                return self.contact_boards[k];
            }
        }
        u8::MAX
    }

    /// Sends the packet whose payload (`len` bytes) is already in `tx[8..]`.
    fn send_global(
        &mut self,
        links: &mut impl Links,
        dst: u8,
        kind: PacketKind,
        len: usize,
    ) -> Result<bool, Fault> {
        let total = PACKET_HEADER_LEN + len + link_proto::CRC_LEN;
        let Some(buf) = self.tx.get_mut(..total) else {
            return Err(self.fault(FaultKind::GlobalSendFailed {
                dst,
                error: link_proto::SendError::TooLong,
            }));
        };
        let mut p = Packet::new_unchecked(buf);
        p.set_dst(dst);
        p.set_src(self.address);
        p.set_msg_id(self.msg_id);
        p.set_kind(kind);
        p.set_version(link_proto::packet::PACKET_VERSION);
        p.set_payload_len(len as u16);
        p.fill_crc();
        match links.try_send_global(&self.tx[..total]) {
            Ok(()) => {
                self.msg_id = self.msg_id.wrapping_add(1);
                self.global.packets_sent += 1;
                self.global.bytes_sent += total as u64;
                Ok(true)
            }
            Err(link_proto::SendError::WouldBlock) => Ok(false),
            Err(error) => Err(self.fault(FaultKind::GlobalSendFailed { dst, error })),
        }
    }

    /// Files every packet that has arrived: boxes and contact nodes of this step or the
    /// next (a partner runs at most one step ahead: it waits for this board's nodes).
    fn drain_global(&mut self, links: &mut impl Links) -> Result<(), Fault> {
        loop {
            let len = match links.try_recv_global(&mut self.rx) {
                Ok(Some(len)) => len,
                Ok(None) => return Ok(()),
                Err(error) => return Err(self.fault(FaultKind::GlobalError { error })),
            };
            let repr = PacketRepr::parse_bytes(&self.rx[..len.min(self.rx.len())])
                .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
            let (src, kind, payload) = (repr.src, repr.kind, repr.payload);
            let n_boards = self.header.counts.contact_boards as usize;
            let slot = self.contact_boards[..n_boards]
                .iter()
                .position(|&b| b == src);
            let now = self.step as u32;
            let unexpected = |step: u32| FaultKind::UnexpectedPacket {
                src,
                kind: kind.code(),
                step,
            };
            match (kind, slot) {
                (PacketKind::BoundingBox, Some(k)) => {
                    let b = BoxPayload::parse(payload)
                        .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
                    if b.step != now && b.step != now.wrapping_add(1) {
                        return Err(self.fault(unexpected(b.step)));
                    }
                    self.boxes[(b.step % 2) as usize][k] = (b.step.wrapping_add(1), b.min, b.max);
                }
                (PacketKind::CollisionExchange, Some(k)) => {
                    let h = NodesHeader::parse(payload)
                        .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
                    if h.step != now && h.step != now.wrapping_add(1) {
                        return Err(self.fault(unexpected(h.step)));
                    }
                    let par = (h.step % 2) as usize;
                    let nc = self.header.counts.contact_nodes as usize;
                    for e in 0..h.count as usize {
                        let (c, u) = node_entry(payload, e)
                            .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
                        if c as usize >= nc {
                            return Err(self.fault(unexpected(h.step)));
                        }
                        self.cs.remote_u[2 * c as usize + par] = u;
                        self.cs.remote_stamp[2 * c as usize + par] = h.step.wrapping_add(1);
                    }
                    if h.last {
                        let d = &mut self.done[par];
                        if d.0 != h.step.wrapping_add(1) {
                            *d = (h.step.wrapping_add(1), 0);
                        }
                        d.1 |= 1 << k;
                    }
                }
                _ => return Err(self.fault(unexpected(now))),
            }
        }
    }

    /// The graphics operation: on the first `spread` steps of every graphics interval,
    /// one slice of the owned surface nodes (displacements as f32) to the graphics engine.
    fn graphics_poll(&mut self, links: &mut impl Links) -> Result<bool, Fault> {
        let g = self.header.graphics;
        let len = self.header.counts.graphics_nodes as usize;
        let interval = g.interval_steps.max(1) as u64;
        let spread = (g.spread_steps.max(1) as u64).min(interval) as usize;
        let j = (self.step % interval) as usize;
        if j >= spread {
            return Ok(true);
        }
        let (start, end) = (j * len / spread, (j + 1) * len / spread);
        while start + self.graphics_cursor < end || (start == end && self.graphics_cursor == 0) {
            let from = start + self.graphics_cursor;
            let count = (end - from).min(SURFACE_NODES_PER_PACKET_MAX);
            let h = SurfaceHeader {
                frame: (self.step / interval) as u32,
                step: self.step as u32,
                chunk: j as u8,
                chunks: spread as u8,
                count: count as u16,
            };
            let mut plen = 0;
            let mut ok = h.emit(&mut self.tx[PACKET_HEADER_LEN..]).map(|l| plen = l);
            for e in 0..count {
                let l = self.cs.graphics[from + e] as usize;
                let u = self.st.u[l].map(|v| v.to_f64() as f32);
                let global = self.st.nodes[l].global;
                ok = ok.and(emit_surface_entry(
                    &mut self.tx[PACKET_HEADER_LEN..],
                    e,
                    global,
                    u,
                ));
            }
            ok.map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
            if !self.send_global(
                links,
                link_proto::packet::ADDR_GRAPHICS,
                PacketKind::GraphicsSurface,
                plen,
            )? {
                return Ok(false);
            }
            self.global.graphics_packets += 1;
            self.global.graphics_bytes += (PACKET_HEADER_LEN + plen + link_proto::CRC_LEN) as u64;
            self.graphics_cursor += count.max(1);
            if start == end {
                break;
            }
        }
        self.graphics_cursor = 0;
        Ok(true)
    }

    /// The contact operation (see [`Phase`]); `Ok(false)` while it waits for the network.
    fn contact_poll(&mut self, links: &mut impl Links) -> Result<bool, Fault> {
        let n_boards = self.header.counts.contact_boards as usize;
        let has_pairs = self.header.counts.pairs > 0 && self.slot.is_some();
        let p = self.header.contact;
        loop {
            self.drain_global(links)?;
            match self.phase {
                Phase::Start => {
                    if !has_pairs {
                        self.phase = Phase::Evaluate;
                    } else if self.is_check_step() {
                        let mut lo = [f64::INFINITY; 3];
                        let mut hi = [f64::NEG_INFINITY; 3];
                        for c in 0..self.header.counts.contact_nodes as usize {
                            if !self.owns_pair_node(c) {
                                continue;
                            }
                            if let Some(x) = self.contact_position(c) {
                                for i in 0..3 {
                                    lo[i] = lo[i].min(x[i]);
                                    hi[i] = hi[i].max(x[i]);
                                }
                            }
                        }
                        self.my_box = (lo, hi);
                        self.phase = Phase::SendBoxes(0);
                    } else {
                        self.phase = Phase::SendNodes(0, 0);
                    }
                }
                Phase::SendBoxes(k) => {
                    if k >= n_boards {
                        self.phase = Phase::AwaitBoxes;
                        continue;
                    }
                    if Some(k) == self.slot {
                        self.phase = Phase::SendBoxes(k + 1);
                        continue;
                    }
                    let b = BoxPayload {
                        step: self.step as u32,
                        min: self.my_box.0,
                        max: self.my_box.1,
                    };
                    let len = b
                        .emit(&mut self.tx[PACKET_HEADER_LEN..])
                        .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
                    if !self.send_global(
                        links,
                        self.contact_boards[k],
                        PacketKind::BoundingBox,
                        len,
                    )? {
                        return Ok(false);
                    }
                    self.global.box_packets += 1;
                    self.phase = Phase::SendBoxes(k + 1);
                }
                Phase::AwaitBoxes => {
                    let par = (self.step % 2) as usize;
                    let want = self.step as u32 + 1;
                    if (0..n_boards).any(|k| Some(k) != self.slot && self.boxes[par][k].0 != want) {
                        return Ok(false);
                    }
                    // Partners: boxes within the margin (the same test on both sides).
                    let mine = grow(&self.my_box, p.box_margin_m);
                    let mut partners = 0u64;
                    let mut used = 0usize;
                    for k in 0..n_boards {
                        self.send_ranges[k] = (used as u32, used as u32);
                        if Some(k) == self.slot {
                            continue;
                        }
                        let other = (self.boxes[par][k].1, self.boxes[par][k].2);
                        if !overlaps(&mine, &other) {
                            continue;
                        }
                        partners |= 1 << k;
                        // Own pair-surface nodes the partner may need until the next check.
                        let reach = grow(&other, p.box_margin_m);
                        for c in 0..self.header.counts.contact_nodes as usize {
                            if !self.owns_pair_node(c) {
                                continue;
                            }
                            let Some(x) = self.contact_position(c) else {
                                continue;
                            };
                            if (0..3).all(|i| reach.0[i] <= x[i] && x[i] <= reach.1[i]) {
                                let cap = self.cs.send_list.len() as u32;
                                let slot = self.cs.send_list.get_mut(used).ok_or(Fault {
                                    board: self.header.board,
                                    step: self.step,
                                    kind: FaultKind::ContactCapacity {
                                        what: "contact-node send entries",
                                        needed: used as u32 + 1,
                                        max: cap,
                                    },
                                })?;
                                *slot = c as u32;
                                used += 1;
                            }
                        }
                        self.send_ranges[k].1 = used as u32;
                    }
                    self.partners = partners;
                    self.global.partners = partners.count_ones();
                    self.phase = Phase::SendNodes(0, 0);
                }
                Phase::SendNodes(k, off) => {
                    if k >= n_boards {
                        self.phase = Phase::AwaitNodes;
                        continue;
                    }
                    if self.partners & (1 << k) == 0 {
                        self.phase = Phase::SendNodes(k + 1, 0);
                        continue;
                    }
                    let (s, e) = self.send_ranges[k];
                    let total = (e - s) as usize;
                    let count = (total - off.min(total)).min(NODES_PER_PACKET_MAX);
                    let last = off + count >= total;
                    let h = NodesHeader {
                        step: self.step as u32,
                        last,
                        count: count as u16,
                    };
                    let mut len = 0;
                    let mut ok = h.emit(&mut self.tx[PACKET_HEADER_LEN..]).map(|l| len = l);
                    for j in 0..count {
                        let c = self.cs.send_list[s as usize + off + j] as usize;
                        let u = match self.cs.places[c].local {
                            Some(l) => self.st.u[l as usize].map(|v| v.to_f64()),
                            None => [f64::NAN; 3],
                        };
                        ok = ok.and(emit_node_entry(
                            &mut self.tx[PACKET_HEADER_LEN..],
                            j,
                            c as u32,
                            u,
                        ));
                    }
                    ok.map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
                    if !self.send_global(
                        links,
                        self.contact_boards[k],
                        PacketKind::CollisionExchange,
                        len,
                    )? {
                        return Ok(false);
                    }
                    self.global.node_packets += 1;
                    self.global.node_vectors += count as u64;
                    self.phase = if last {
                        Phase::SendNodes(k + 1, 0)
                    } else {
                        Phase::SendNodes(k, off + count)
                    };
                }
                Phase::AwaitNodes => {
                    let par = (self.step % 2) as usize;
                    let want = self.step as u32 + 1;
                    let arrived = if self.done[par].0 == want {
                        self.done[par].1
                    } else {
                        0
                    };
                    if arrived & self.partners != self.partners {
                        return Ok(false);
                    }
                    self.phase = Phase::Evaluate;
                }
                Phase::Evaluate => {
                    self.evaluate_contact()?;
                    self.phase = Phase::SendTools(0);
                }
                Phase::SendTools(t) => {
                    if t >= self.header.counts.tools as usize {
                        self.phase = Phase::Start;
                        return Ok(true);
                    }
                    let f = self.tool_force[t];
                    if f == [0.0; 3] {
                        self.phase = Phase::SendTools(t + 1);
                        continue;
                    }
                    let pl = ToolForcePayload {
                        step: self.step as u32,
                        tool: t as u8,
                        force: f,
                    };
                    let len = pl
                        .emit(&mut self.tx[PACKET_HEADER_LEN..])
                        .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
                    if !self.send_global(
                        links,
                        link_proto::packet::ADDR_HOST,
                        PacketKind::ToolForce,
                        len,
                    )? {
                        return Ok(false);
                    }
                    self.global.tool_packets += 1;
                    self.phase = Phase::SendTools(t + 1);
                }
            }
        }
    }

    /// Contact forces of the owned nodes at this step (the serial solver's arithmetic, in
    /// its order, restricted to the owned nodes) and this board's share of the tool forces.
    fn evaluate_contact(&mut self) -> Result<(), Fault> {
        let c = self.header.counts;
        let nc = c.contact_nodes as usize;
        let p = self.header.contact;
        let t = self.step as f64 * self.header.params.dt_s;
        let np = c.path_points as usize;
        let mut capsules = [Capsule {
            a: [0.0; 3],
            b: [0.0; 3],
            radius_m: 0.0,
        }; TOOLS_MAX];
        for k in 0..c.tools as usize {
            let d = path_value(&self.st.path_points[..np], self.tools[k].path, t);
            capsules[k] = self.tools[k].capsule.translated(d);
        }
        let force = core::mem::take(&mut self.cs.force);
        let at_check = core::mem::take(&mut self.cs.at_check);
        let candidates = core::mem::take(&mut self.cs.candidates);
        let result = (|| -> Result<ContactOutcome, Fault> {
            let mut new_len = None;
            let fault = |kind| Fault {
                board: self.header.board,
                step: self.step,
                kind,
            };
            let m = self.contact_model();
            let pos = |k: usize| self.contact_position(k);
            let own = |k: usize| self.owns_contact(k);
            if c.pairs > 0 && self.slot.is_some() && self.is_check_step() {
                for (k, x) in at_check.iter_mut().enumerate().take(nc) {
                    *x = pos(k).unwrap_or([0.0; 3]);
                }
                let n = build_candidates(&m, pos, p.candidate_margin_m, candidates).map_err(
                    |needed| {
                        fault(FaultKind::ContactCapacity {
                            what: "contact candidates",
                            needed: needed as u32,
                            max: candidates.len() as u32,
                        })
                    },
                )?;
                new_len = Some(n);
            }
            check_travel(
                &m,
                pos,
                &at_check[..nc],
                own,
                p.pair_surfaces,
                p.travel_max_m,
            )
            .map_err(|e| fault(FaultKind::Physics(e)))?;
            for f in force.iter_mut().take(nc) {
                *f = [0.0; 3];
            }
            let mut tool_force = [[0.0; 3]; TOOLS_MAX];
            let mut stats = ContactStats::default();
            evaluate_tools(
                &m,
                &capsules[..c.tools as usize],
                pos,
                own,
                p.tolerance_m,
                &mut force[..nc],
                &mut tool_force,
                &mut stats,
            )
            .map_err(|e| fault(FaultKind::Physics(e)))?;
            let cand = if c.pairs > 0 && self.slot.is_some() {
                &candidates[..new_len.unwrap_or(self.candidates_len).min(candidates.len())]
            } else {
                &[]
            };
            evaluate_pairs(
                &m,
                cand,
                pos,
                own,
                p.tolerance_m,
                &mut force[..nc],
                &mut stats,
            )
            .map_err(|e| fault(FaultKind::Physics(e)))?;
            Ok((tool_force, stats, new_len))
        })();
        self.cs.force = force;
        self.cs.at_check = at_check;
        self.cs.candidates = candidates;
        let (tool_force, stats, new_len) = result?;
        if let Some(n) = new_len {
            self.candidates_len = n;
            self.global.checks += 1;
            self.global.candidates_max = self.global.candidates_max.max(n as u32);
        }
        self.tool_force = tool_force;
        self.contact_stats = stats;
        Ok(())
    }
}

/// The step's operations: batch x; send ±x; batch y; receive ±x (and further x rounds);
/// send ±y; batch z; receive ±y...; send ±z; inner batch; receive ±z...; update. External
/// forces of owned nodes go in just before their first exchange.
fn program(rounds: &[u8; 3], contact: bool, graphics: bool) -> ([Op; OPS_MAX], usize) {
    let mut ops = [Op::Update; OPS_MAX];
    let mut n = 0;
    let mut push = |op| {
        if n < OPS_MAX {
            ops[n] = op;
            n += 1;
        }
    };
    push(Op::Begin);
    if graphics {
        push(Op::Graphics);
    }
    if contact {
        push(Op::Contact);
    }
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
