//! Contact on the board array: every check interval each board that owns a pair-surface
//! node sends its bounding box to the other contact boards; boards whose boxes (grown by the
//! margin) overlap exchange their nodes' displacements every step until the next check.
//! Each board then computes the contact forces of the nodes it owns with the serial
//! solver's arithmetic ([`crate::physics::contact`]) and sends its share of the tool forces
//! to the host. The state of that protocol is [`ContactState`]; the tables and buffers are
//! in [`ContactStorage`](super::storage::ContactStorage); the evaluation of a step's contact is [`evaluate`]'s.

use link_proto::gate::StepMarkRepr;
use link_proto::payload::{
    emit_node_entry, node_entry, nodes_per_packet_max, BoxPayload, NodesHeader, ToolForcePayload,
};
use link_proto::tool_pose::ToolPoseRepr;
use link_proto::{Control, Links, PacketKind, PacketRepr, PACKET_HEADER_LEN};

use super::marks::cost_mark;
use super::pose::PoseQueue;
use super::storage::RemoteSlot;
use super::{Fault, FaultKind, Runtime, WireReal};
use crate::image::{ContactNode, ContactNodePlace, ContactPair, ElementRecord, Tool};
use crate::physics::contact::{Capsule, ContactStats};
use crate::physics::Real;

mod evaluate;

/// Most contact pairs and tools a runtime handles.
pub const PAIRS_MAX: usize = 4;
pub const TOOLS_MAX: usize = 4;
/// Most boards on the global network.
pub const BOARDS_MAX: usize = link_proto::BOARD_COUNT;
/// Contact faces the used-face mask covers ([`ContactState`]); the bounds of a face beyond
/// it are computed every step whether a candidate names it or not.
const FACE_MASK_FACES: usize = 1024;
const FACE_MASK_WORDS: usize = FACE_MASK_FACES / 32;

/// An axis-aligned box (min, max).
type Aabb = ([f64; 3], [f64; 3]);

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

/// The contact tables a board keeps whole (pairs, tools, contact boards) and the state of
/// the contact protocol.
pub struct ContactState {
    pub(super) pairs: [ContactPair; PAIRS_MAX],
    pub(super) tools: [Tool; TOOLS_MAX],
    /// Global-network addresses of the contact boards, and this board's slot among them.
    pub(super) boards: [u8; BOARDS_MAX],
    pub(super) slot: Option<usize>,
    /// Whether this board owns a contact node: every contact force, tool force and
    /// statistic a board computes is for its owned nodes, so a board that owns none skips
    /// the evaluation (its results are zero).
    pub(super) owns_nodes: bool,
    phase: Phase,
    /// Received boxes by step parity and slot: (step + 1, box).
    boxes: [[(u32, Aabb); BOARDS_MAX]; 2],
    my_box: Aabb,
    /// Partner slots (bit mask) until the next check and their send-list ranges.
    partners: u64,
    send_ranges: [(u32, u32); BOARDS_MAX],
    /// Per step parity: (step + 1, slots whose last node packet arrived).
    done: [(u32, u64); 2],
    candidates_len: usize,
    /// The faces the kept candidates name (bit `f % 32` of word `f / 32`), set at each
    /// check: only their bounds are computed at a step.
    faces_used: [u32; FACE_MASK_WORDS],
    /// Force of the tissue on each tool from this board's nodes at the last step (N).
    pub(super) tool_force: [[f64; 3]; TOOLS_MAX],
    pub(super) stats: ContactStats,
    /// The tools' poses from the host ([`super::pose`]).
    pub(super) poses: PoseQueue,
}

impl ContactState {
    pub(super) fn new() -> Self {
        ContactState {
            pairs: [ContactPair {
                a: 0,
                b: 0,
                depth_max_m: 0.0,
            }; PAIRS_MAX],
            tools: [Tool {
                capsule: Capsule {
                    a: [0.0; 3],
                    b: [0.0; 3],
                    radius_m: 0.0,
                },
                path: 0,
                surface: 0,
            }; TOOLS_MAX],
            boards: [0; BOARDS_MAX],
            slot: None,
            owns_nodes: false,
            phase: Phase::Start,
            boxes: [[(0, ([0.0; 3], [0.0; 3])); BOARDS_MAX]; 2],
            my_box: ([0.0; 3], [0.0; 3]),
            partners: 0,
            send_ranges: [(0, 0); BOARDS_MAX],
            done: [(0, 0); 2],
            candidates_len: 0,
            faces_used: [0; FACE_MASK_WORDS],
            tool_force: [[0.0; 3]; TOOLS_MAX],
            stats: ContactStats::default(),
            poses: PoseQueue::new(),
        }
    }

    /// The first partner (or contact board) this board still waits for at `step`.
    pub(super) fn missing_partner(&self, step: u64, n_boards: usize) -> u8 {
        let par = (step % 2) as usize;
        let want = step as u32 + 1;
        for (k, &board) in self.boards.iter().enumerate().take(n_boards) {
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
                return board;
            }
        }
        u8::MAX
    }
}

/// Positions of contact nodes at one step: held nodes from their displacement, others
/// from what the partners sent for this step.
struct Positions<'b, T> {
    nodes: &'b [ContactNode],
    places: &'b [ContactNodePlace],
    remote: &'b [RemoteSlot],
    u: &'b [[T; 3]],
    step: u64,
}

impl<T: Real> Positions<'_, T> {
    fn at(&self, c: usize) -> Option<[f64; 3]> {
        let node = self.nodes.get(c)?;
        let u = match self.places.get(c)?.local {
            Some(l) => self.u.get(l as usize)?.map(|v| v.to_f64()),
            None => {
                let (stamp, u) = self.remote.get(c)?[(self.step % 2) as usize];
                if stamp != self.step as u32 + 1 {
                    return None;
                }
                u
            }
        };
        Some(core::array::from_fn(|i| node.reference[i] + u[i]))
    }
}

fn grow(b: &Aabb, r: f64) -> Aabb {
    (
        core::array::from_fn(|i| b.0[i] - r),
        core::array::from_fn(|i| b.1[i] + r),
    )
}

fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    (0..3).all(|i| b.0[i] <= a.1[i] && a.0[i] <= b.1[i])
}

fn contains(b: &Aabb, x: &[f64; 3]) -> bool {
    (0..3).all(|i| b.0[i] <= x[i] && x[i] <= b.1[i])
}

impl<T: WireReal, E: ElementRecord<T>> Runtime<'_, T, E> {
    fn positions(&self) -> Positions<'_, T> {
        let nc = self.header.counts.contact_nodes as usize;
        let cs = &self.st.contact;
        Positions {
            nodes: &cs.nodes[..nc],
            places: &cs.places[..nc],
            remote: &cs.remote[..nc],
            u: &self.st.u[..self.header.counts.nodes as usize],
            step: self.step,
        }
    }

    /// An owned node of a surface that takes part in a pair (its owner exchanges it).
    fn owns_pair_node(&self, c: usize) -> bool {
        let cs = &self.st.contact;
        cs.places.get(c).is_some_and(|p| p.owned)
            && cs
                .nodes
                .get(c)
                .is_some_and(|n| n.surfaces & self.header.contact.pair_surfaces != 0)
    }

    fn is_check_step(&self) -> bool {
        self.step
            .is_multiple_of(self.header.contact.check_interval_steps.max(1) as u64)
    }

    fn has_pairs(&self) -> bool {
        self.header.counts.pairs > 0 && self.contact.slot.is_some()
    }

    /// The contact operation (see [`Phase`]); `Ok(false)` while it waits for the network.
    pub(super) fn contact_poll(&mut self, links: &mut impl Links) -> Result<bool, Fault> {
        // A build without contact loads no image with contact tables (its program has no
        // contact operation): nothing below is in it.
        if !cfg!(feature = "contact") {
            return Ok(true);
        }
        let n_boards = self.header.counts.contact_boards as usize;
        loop {
            self.receive_contact(links)?;
            match self.contact.phase {
                Phase::Start => {
                    if !self.gate_open(links)? {
                        return Ok(false);
                    }
                    self.contact.phase = if !self.has_pairs() {
                        Phase::Evaluate
                    } else if self.is_check_step() {
                        self.contact.my_box = self.own_box();
                        Phase::SendBoxes(0)
                    } else {
                        Phase::SendNodes(0, 0)
                    };
                }
                Phase::SendBoxes(k) if k >= n_boards => self.contact.phase = Phase::AwaitBoxes,
                Phase::SendBoxes(k) => {
                    if Some(k) != self.contact.slot && !self.send_box(links, k)? {
                        return Ok(false);
                    }
                    self.contact.phase = Phase::SendBoxes(k + 1);
                }
                Phase::AwaitBoxes => {
                    let par = (self.step % 2) as usize;
                    let want = self.step as u32 + 1;
                    let c = &self.contact;
                    if (0..n_boards).any(|k| Some(k) != c.slot && c.boxes[par][k].0 != want) {
                        return Ok(false);
                    }
                    self.choose_partners()?;
                    self.contact.phase = Phase::SendNodes(0, 0);
                }
                Phase::SendNodes(k, _) if k >= n_boards => self.contact.phase = Phase::AwaitNodes,
                Phase::SendNodes(k, _) if self.contact.partners & (1 << k) == 0 => {
                    self.contact.phase = Phase::SendNodes(k + 1, 0)
                }
                Phase::SendNodes(k, off) => match self.send_nodes(links, k, off)? {
                    None => return Ok(false),
                    Some(true) => self.contact.phase = Phase::SendNodes(k + 1, 0),
                    Some(false) => {
                        let max = nodes_per_packet_max(T::wire(&[]).precision());
                        self.contact.phase = Phase::SendNodes(k, off + max)
                    }
                },
                Phase::AwaitNodes => {
                    let par = (self.step % 2) as usize;
                    let want = self.step as u32 + 1;
                    let c = &self.contact;
                    let arrived = if c.done[par].0 == want {
                        c.done[par].1
                    } else {
                        0
                    };
                    if arrived & c.partners != c.partners {
                        return Ok(false);
                    }
                    self.contact.phase = Phase::Evaluate;
                }
                Phase::Evaluate => {
                    self.apply_poses();
                    cost_mark(0);
                    let done = self.evaluate_contact();
                    cost_mark(1);
                    done?;
                    self.contact.phase = Phase::SendTools(0);
                }
                Phase::SendTools(t) if t >= self.header.counts.tools as usize => {
                    self.contact.phase = Phase::Start;
                    return Ok(true);
                }
                Phase::SendTools(t) => {
                    if !self.send_tool_force(links, t)? {
                        return Ok(false);
                    }
                    self.contact.phase = Phase::SendTools(t + 1);
                }
            }
        }
    }

    /// The bounding box of the owned pair-surface nodes.
    fn own_box(&self) -> Aabb {
        let mut b = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let pos = self.positions();
        for c in 0..self.header.counts.contact_nodes as usize {
            if let (true, Some(x)) = (self.owns_pair_node(c), pos.at(c)) {
                for i in 0..3 {
                    b.0[i] = b.0[i].min(x[i]);
                    b.1[i] = b.1[i].max(x[i]);
                }
            }
        }
        b
    }

    /// Sends this board's box to the contact board in slot `k`; `Ok(false)` if the port is
    /// busy.
    fn send_box(&mut self, links: &mut impl Links, k: usize) -> Result<bool, Fault> {
        let (min, max) = self.contact.my_box;
        let b = BoxPayload {
            step: self.step as u32,
            min,
            max,
        };
        let len = b
            .emit(&mut self.st.tx[PACKET_HEADER_LEN..])
            .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
        let dst = self.contact.boards[k];
        let sent = self.send_global(links, dst, PacketKind::BoundingBox, len)?;
        if sent {
            self.port.stats.box_packets += 1;
        }
        Ok(sent)
    }

    /// Partners: boards whose boxes are within the margin (the same test on both sides),
    /// and for each the own pair-surface nodes it may need until the next check.
    fn choose_partners(&mut self) -> Result<(), Fault> {
        let n_boards = self.header.counts.contact_boards as usize;
        let margin = self.header.contact.box_margin_m;
        let par = (self.step % 2) as usize;
        let mine = grow(&self.contact.my_box, margin);
        let (mut partners, mut used) = (0u64, 0usize);
        for k in 0..n_boards {
            self.contact.send_ranges[k] = (used as u32, used as u32);
            let other = self.contact.boxes[par][k].1;
            if Some(k) == self.contact.slot || !overlaps(&mine, &other) {
                continue;
            }
            partners |= 1 << k;
            let reach = grow(&other, margin);
            for c in 0..self.header.counts.contact_nodes as usize {
                let near = self.owns_pair_node(c)
                    && self.positions().at(c).is_some_and(|x| contains(&reach, &x));
                if !near {
                    continue;
                }
                let cap = self.st.contact.send_list.len() as u32;
                let Some(slot) = self.st.contact.send_list.get_mut(used) else {
                    return Err(self.fault(FaultKind::ContactCapacity {
                        what: "contact-node send entries",
                        needed: used as u32 + 1,
                        max: cap,
                    }));
                };
                *slot = c as u32;
                used += 1;
            }
            self.contact.send_ranges[k].1 = used as u32;
        }
        self.contact.partners = partners;
        self.port.stats.partners = partners.count_ones();
        Ok(())
    }

    /// Sends the next packet of nodes to partner slot `k` from offset `off` of its list:
    /// `None` if the port is busy, `Some(last)` once sent.
    fn send_nodes(
        &mut self,
        links: &mut impl Links,
        k: usize,
        off: usize,
    ) -> Result<Option<bool>, Fault> {
        let (s, e) = self.contact.send_ranges[k];
        let total = (e - s) as usize;
        // The displacements go in this board's own precision: exact, and f32 halves them.
        let precision = T::wire(&[]).precision();
        let count = (total - off.min(total)).min(nodes_per_packet_max(precision));
        let last = off + count >= total;
        let h = NodesHeader {
            step: self.step as u32,
            last,
            precision,
            count: count as u16,
        };
        let mut len = 0;
        let payload = &mut self.st.tx[PACKET_HEADER_LEN..];
        let mut ok = h.emit(payload).map(|l| len = l);
        let cs = &self.st.contact;
        for j in 0..count {
            let c = cs.send_list[s as usize + off + j] as usize;
            let u = match cs.places[c].local {
                Some(l) => self.st.u[l as usize].map(|v| v.to_f64()),
                None => [f64::NAN; 3],
            };
            ok = ok.and(emit_node_entry(payload, precision, j, c as u32, u));
        }
        ok.map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
        let dst = self.contact.boards[k];
        if !self.send_global(links, dst, PacketKind::CollisionExchange, len)? {
            return Ok(None);
        }
        self.port.stats.node_packets += 1;
        self.port.stats.node_vectors += count as u64;
        Ok(Some(last))
    }

    /// Sends this board's share of tool `t`'s force to the host (nothing if it is zero);
    /// `Ok(false)` if the port is busy.
    fn send_tool_force(&mut self, links: &mut impl Links, t: usize) -> Result<bool, Fault> {
        let force = self.contact.tool_force[t];
        if force == [0.0; 3] {
            return Ok(true);
        }
        let pl = ToolForcePayload {
            step: self.step as u32,
            tool: t as u8,
            force,
        };
        let len = pl
            .emit(&mut self.st.tx[PACKET_HEADER_LEN..])
            .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
        let host = link_proto::packet::ADDR_HOST;
        let sent = self.send_global(links, host, PacketKind::ToolForce, len)?;
        if sent {
            self.port.stats.tool_packets += 1;
        }
        Ok(sent)
    }

    /// Files every packet that has arrived: boxes and contact nodes of this step or the
    /// next (a partner runs at most one step ahead: it waits for this board's nodes), and
    /// the host's tool poses ([`super::pose`]).
    fn receive_contact(&mut self, links: &mut impl Links) -> Result<(), Fault> {
        loop {
            let len = match links.try_recv_global(self.st.rx) {
                Ok(Some(len)) => len,
                Ok(None) => return Ok(()),
                Err(error) => return Err(self.fault(FaultKind::GlobalError { error })),
            };
            let repr = PacketRepr::parse_bytes(&self.st.rx[..len.min(self.st.rx.len())])
                .map_err(|error| self.fault(FaultKind::BadPacket { error }))?;
            let (src, kind, payload) = (repr.src, repr.kind, repr.payload);
            let n_boards = self.header.counts.contact_boards as usize;
            let slot = self.contact.boards[..n_boards]
                .iter()
                .position(|&b| b == src);
            let now = self.step as u32;
            let unexpected = |step: u32| FaultKind::UnexpectedPacket {
                src,
                kind: kind.code(),
                step,
            };
            let bad = |error| Fault {
                board: self.header.board,
                step: self.step,
                kind: FaultKind::BadPacket { error },
            };
            match (kind, slot) {
                (PacketKind::BoundingBox, Some(k)) => {
                    let b = BoxPayload::parse(payload).map_err(bad)?;
                    if b.step != now && b.step != now.wrapping_add(1) {
                        return Err(self.fault(unexpected(b.step)));
                    }
                    self.contact.boxes[(b.step % 2) as usize][k] =
                        (b.step.wrapping_add(1), (b.min, b.max));
                }
                (PacketKind::CollisionExchange, Some(k)) => {
                    let h = NodesHeader::parse(payload).map_err(bad)?;
                    // Every board of a compilation computes in one precision.
                    if (h.step != now && h.step != now.wrapping_add(1))
                        || h.precision != T::wire(&[]).precision()
                    {
                        return Err(self.fault(unexpected(h.step)));
                    }
                    let par = (h.step % 2) as usize;
                    let nc = self.header.counts.contact_nodes as usize;
                    for e in 0..h.count as usize {
                        let (c, u) = node_entry(payload, h.precision, e).map_err(bad)?;
                        let Some(slot) = self.st.contact.remote[..nc].get_mut(c as usize) else {
                            return Err(self.fault(unexpected(h.step)));
                        };
                        slot[par] = (h.step.wrapping_add(1), u);
                    }
                    if h.last {
                        let d = &mut self.contact.done[par];
                        if d.0 != h.step.wrapping_add(1) {
                            *d = (h.step.wrapping_add(1), 0);
                        }
                        d.1 |= 1 << k;
                    }
                }
                (PacketKind::ToolPose, _) if src == link_proto::packet::ADDR_HOST => {
                    let pose = ToolPoseRepr::parse_bytes(payload).map_err(bad)?;
                    self.file_pose(&pose)?
                }
                (PacketKind::Control(Control::Start), _)
                    if src == link_proto::packet::ADDR_HOST =>
                {
                    let mark = StepMarkRepr::parse_bytes(payload).map_err(bad)?;
                    self.file_permit(mark.step)
                }
                _ => return Err(self.fault(unexpected(now))),
            }
        }
    }
}
