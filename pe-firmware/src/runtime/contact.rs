//! Contact on the board array: every check interval each board that owns a pair-surface
//! node sends its bounding box to the other contact boards; boards whose boxes (grown by the
//! margin) overlap exchange their nodes' displacements every step until the next check.
//! Each board then computes the contact forces of the nodes it owns with the serial
//! solver's arithmetic ([`crate::physics::contact`]) and sends its share of the tool forces
//! to the host. The state of that protocol is [`ContactState`]; the tables and buffers are
//! in [`ContactStorage`].

use link_proto::payload::{
    emit_node_entry, node_entry, nodes_per_packet_max, BoxPayload, NodesHeader, ToolForcePayload,
};
use link_proto::{Links, PacketKind, PacketRepr, PACKET_HEADER_LEN};

use super::marks::cost_mark;
use super::storage::{ContactStorage, RemoteSlot};
use super::{Fault, FaultKind, Runtime, WireReal};
use crate::image::{path_value, ContactNode, ContactNodePlace, ContactPair, ElementRecord, Tool};
use crate::physics::contact::{
    build_candidates, check_travel, evaluate_kept_pairs_bounded, evaluate_tools,
    keep_applied_groups, search_tests, Capsule, ContactModel, ContactStats,
};
use crate::physics::Real;

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
    /// next (a partner runs at most one step ahead: it waits for this board's nodes).
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
                _ => return Err(self.fault(unexpected(now))),
            }
        }
    }

    /// The contact evaluation of a step that is not a check step (positions, travel check,
    /// tool and pair tests) at the current displacements and step index: the contact forces,
    /// tool forces and statistics that the next step's evaluation computes from the same
    /// state (nothing else changes). For the cost measurement (`pe-board-bench`,
    /// `scripts/board-cost.sh`: what a step's contact costs a board that owns contact
    /// nodes, the compile report's charge per contact node). A board without contact does
    /// nothing.
    pub fn evaluate_contact_again(&mut self) -> Result<(), Fault> {
        if self.header.counts.contact_nodes == 0 {
            return Ok(());
        }
        self.evaluate_contact_at(false)
    }

    /// The contact evaluation of a check step at the current displacements and step index:
    /// the candidate search and the groups kept for this board, then the evaluation of
    /// [`Self::evaluate_contact_again`]. For the cost measurement (`pe-board-bench`: a check
    /// step's search, the compile report's charge per search test); the candidates are
    /// then those of this state. A board without pairs (or without contact) does nothing.
    pub fn check_contact_again(&mut self) -> Result<(), Fault> {
        if self.header.counts.contact_nodes == 0 || !self.has_pairs() {
            return Ok(());
        }
        self.evaluate_contact_at(true)
    }

    /// The node-face tests of this board's candidate search with every position known
    /// ([`search_tests`] of its contact tables; 0 without pairs).
    pub fn contact_search_tests(&self) -> usize {
        let c = self.header.counts;
        if c.pairs == 0 {
            return 0;
        }
        let t = &self.st.contact;
        let model = ContactModel {
            nodes: t.nodes.get(..c.contact_nodes as usize).unwrap_or(&[]),
            faces: t.faces.get(..c.contact_faces as usize).unwrap_or(&[]),
            pairs: self.contact.pairs.get(..c.pairs as usize).unwrap_or(&[]),
            tools: &[],
        };
        search_tests(&model)
    }

    /// Contact forces of the owned nodes at this step (the serial solver's arithmetic, in
    /// its order, restricted to the owned nodes) and this board's share of the tool forces.
    fn evaluate_contact(&mut self) -> Result<(), Fault> {
        let check = self.has_pairs() && self.is_check_step();
        self.evaluate_contact_at(check)
    }

    /// [`Self::evaluate_contact`], with the candidate search if `check`.
    fn evaluate_contact_at(&mut self, check: bool) -> Result<(), Fault> {
        let c = self.header.counts;
        let (nc, np) = (c.contact_nodes as usize, c.path_points as usize);
        let p = self.header.contact;
        let t = self.step as f64 * self.header.params.dt_s;
        let fault = |kind| Fault {
            board: self.header.board,
            step: self.step,
            kind,
        };
        let state = &mut self.contact;
        if !state.owns_nodes {
            // Every result below is filtered by `own`, which is false for every node: they
            // would all be zero (`check` is false too: only owners of pair nodes hold a
            // slot). The contact forces stay as the load cleared them: nothing else writes
            // them.
            state.tool_force = [[0.0; 3]; TOOLS_MAX];
            state.stats = ContactStats::default();
            // The stage marks all the same, so that every step has the same marks.
            for id in 2..=5 {
                cost_mark(id);
            }
            return Ok(());
        }
        let mut capsules = [Capsule {
            a: [0.0; 3],
            b: [0.0; 3],
            radius_m: 0.0,
        }; TOOLS_MAX];
        for (k, tool) in state.tools.iter().enumerate().take(c.tools as usize) {
            let d = path_value(&self.st.path_points[..np], tool.path, t);
            capsules[k] = tool.capsule.translated(d);
        }
        let ContactStorage {
            nodes,
            places,
            faces,
            face_bounds,
            at_check,
            force,
            at_step,
            remote,
            candidates,
            ..
        } = &mut self.st.contact;
        let model = ContactModel {
            nodes: &nodes[..nc],
            faces: &faces[..c.contact_faces as usize],
            pairs: &state.pairs[..c.pairs as usize],
            tools: &state.tools[..c.tools as usize],
        };
        let positions = Positions {
            nodes: &nodes[..nc],
            places: &places[..nc],
            remote: &remote[..nc],
            u: &self.st.u[..c.nodes as usize],
            step: self.step,
        };
        // Each position once per step (the same values `Positions::at` gives), not once per
        // test that needs it: a candidate face reads four.
        let at_step = &mut at_step[..nc];
        for (k, x) in at_step.iter_mut().enumerate() {
            *x = positions.at(k);
        }
        let at_step = &*at_step;
        cost_mark(2);
        let pos = |k: usize| at_step.get(k).copied().flatten();
        let own = |k: usize| places.get(k).is_some_and(|p| p.owned);
        if check {
            for (k, x) in at_check.iter_mut().enumerate().take(nc) {
                *x = pos(k).unwrap_or([0.0; 3]);
            }
            let max = candidates.len() as u32;
            // The step's face bounds are computed again below: their storage lends the
            // search its boxes.
            let nf = model.faces.len().min(face_bounds.len());
            let boxes = &mut face_bounds[..nf];
            let n = build_candidates(&model, pos, p.candidate_margin_m, boxes, candidates)
                .map_err(|needed| {
                    fault(FaultKind::ContactCapacity {
                        what: "contact candidates",
                        needed: needed as u32,
                        max,
                    })
                })?;
            // Only the groups that give this board's nodes a force are evaluated each step.
            // (build_candidates wrote n <= candidates.len() of them.)
            let kept = &mut candidates[..n.min(max as usize)];
            state.candidates_len =
                keep_applied_groups(&model, kept, own).map_err(|e| fault(FaultKind::Physics(e)))?;
            state.faces_used = [0; FACE_MASK_WORDS];
            for c in &kept[..state.candidates_len.min(kept.len())] {
                let f = c.face as usize;
                if let Some(w) = state.faces_used.get_mut(f / 32) {
                    *w |= 1 << (f % 32);
                }
            }
            self.port.stats.checks += 1;
            self.port.stats.candidates_max = self.port.stats.candidates_max.max(n as u32);
        }
        cost_mark(3);
        let physics = |e| fault(FaultKind::Physics(e));
        let at_check = &at_check[..nc];
        check_travel(&model, pos, at_check, own, p.pair_surfaces, p.travel_max_m)
            .map_err(physics)?;
        cost_mark(4);
        let force = &mut force[..nc];
        force.fill([0.0; 3]);
        let mut tool_force = [[0.0; 3]; TOOLS_MAX];
        let mut stats = ContactStats::default();
        let capsules = &capsules[..c.tools as usize];
        let tol = p.tolerance_m;
        evaluate_tools(
            &model,
            capsules,
            pos,
            own,
            tol,
            force,
            &mut tool_force,
            &mut stats,
        )
        .map_err(physics)?;
        cost_mark(5);
        let cand = if c.pairs > 0 && state.slot.is_some() {
            &candidates[..state.candidates_len.min(candidates.len())]
        } else {
            &[]
        };
        // Each face's bounds once per step, not once per candidate that names it (a face is
        // a candidate of several slaves, most of them outside its bounds at a step), and
        // only for the faces the kept candidates name (the others' are never read).
        let bounds = if cand.is_empty() {
            &mut face_bounds[..0]
        } else {
            let nf = model.faces.len().min(face_bounds.len());
            let bounds = &mut face_bounds[..nf];
            for (f, b) in bounds.iter_mut().enumerate() {
                let used = state
                    .faces_used
                    .get(f / 32)
                    .is_none_or(|w| w & (1 << (f % 32)) != 0);
                if used {
                    *b = model.face_bounds(f, &pos).map_err(physics)?;
                }
            }
            bounds
        };
        // The candidates are the groups `keep_applied_groups` kept at the check, for the
        // same `own` (and their indices checked there).
        evaluate_kept_pairs_bounded(&model, cand, pos, bounds, own, tol, force, &mut stats)
            .map_err(physics)?;
        state.tool_force = tool_force;
        state.stats = stats;
        Ok(())
    }
}
