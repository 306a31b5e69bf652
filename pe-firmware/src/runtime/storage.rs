//! A board's storage: the one list of the runtime's arrays ([`Storage`], a view of slices
//! whose lengths are the capacities), their sizes ([`Capacities`]: exact for an image, or a
//! board profile's), and one owner of the arrays ([`StorageBuf`]) over a [`Shelf`]:
//! fixed-capacity `heapless` vectors in the firmware's statics ([`Heapless`]), growable
//! vectors in board-sim. Filling happens in place, so a board never moves its storage
//! through the stack.

use core::mem::size_of;

use link_proto::{FRAME_LEN_MAX, FRAME_RX_LEN, VALUES_PER_FRAME_MAX};

use crate::image::{
    zero_record, ContactFace, ContactNode, ContactNodePlace, Counts, ExternalRecord, ImageParts,
    LoadRecord, NodeRecord, PathPoint, RecvEntry,
};
use crate::image::{ElementRecord, Integration};
use crate::physics::contact::{Candidate, QuadBounds};
use crate::physics::{HexBox, HexCuboid, MaterialLaw};
use crate::profile::BoardProfile;

/// The link buffers a board keeps in a static beside its storage (the firmware's
/// `StreamLinks` over its streams, whose size the buffers make).
pub type LinkBuffers = link_proto::StreamLinks<(), ()>;

/// Displacements a partner sent for one contact node, by step parity: (step + 1, u).
pub type RemoteSlot = [(u32, [f64; 3]); 2];

/// How many records of each kind a board's storage holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Capacities {
    pub materials: usize,
    /// General-kernel elements (the integration's record).
    pub elements: usize,
    /// Parallelepipeds ([`HexBox`]; none with full integration).
    pub boxes: usize,
    /// Axis-aligned cuboids ([`HexCuboid`]; none with full integration).
    pub cuboids: usize,
    pub nodes: usize,
    /// Send entries and receive entries (each) over all rounds and faces.
    pub exchange: usize,
    pub path_points: usize,
    pub loads: usize,
    /// External-force records (at most one per node).
    pub external: usize,
    pub contact_nodes: usize,
    pub contact_faces: usize,
    /// Contact candidates (slave node, master face) found at a check.
    pub contact_candidates: usize,
    /// Contact-node displacements sent to partners until the next check.
    pub contact_sends: usize,
    pub graphics_nodes: usize,
}

impl Capacities {
    /// Exactly what an image with `c` needs, with room for the contact search, whose needs
    /// depend on the motion (board-sim's default).
    pub fn exact(c: &Counts) -> Capacities {
        let nc = c.contact_nodes as usize;
        let pairs = c.pairs > 0;
        Capacities {
            materials: c.materials as usize,
            elements: c.elements as usize,
            boxes: c.boxes as usize,
            cuboids: c.cuboids as usize,
            nodes: c.nodes as usize,
            exchange: c.sends.max(c.recvs) as usize,
            path_points: c.path_points as usize,
            loads: c.loads as usize,
            external: c.external_records(),
            contact_nodes: nc,
            contact_faces: c.contact_faces as usize,
            contact_candidates: if pairs { 64 * nc.max(16) } else { 0 },
            contact_sends: if pairs {
                nc * c.contact_boards as usize
            } else {
                0
            },
            graphics_nodes: c.graphics_nodes as usize,
        }
    }

    /// What a board of profile `p` holds for scalar `T` and element `E`: the profile's
    /// table (its nodes, at most the frames' limit; its parallelepipeds and cuboids with
    /// reduced integration, none with full), and as
    /// many general elements as the RAM allows after the reserve (stack, the runtime), the
    /// link buffers ([`LinkBuffers`], unless the profile gives them a region of their own)
    /// and the rest of the storage.
    pub const fn for_board<T: crate::physics::Real, E: ElementRecord<T>>(
        p: &BoardProfile,
    ) -> Capacities {
        let nodes = if (p.nodes_max as usize) < link_proto::NODES_PER_BOARD_MAX {
            p.nodes_max as usize
        } else {
            link_proto::NODES_PER_BOARD_MAX
        };
        let mut c = Capacities {
            materials: p.materials_max as usize,
            elements: 0,
            boxes: match E::INTEGRATION {
                Integration::Reduced => p.boxes_max as usize,
                Integration::Full => 0,
            },
            cuboids: match E::INTEGRATION {
                Integration::Reduced => p.cuboids_max as usize,
                Integration::Full => 0,
            },
            nodes,
            exchange: p.exchange_max as usize,
            path_points: p.path_points_max as usize,
            loads: p.loads_max as usize,
            external: nodes,
            contact_nodes: p.contact_nodes_max as usize,
            contact_faces: p.contact_faces_max as usize,
            contact_candidates: p.contact_candidates_max as usize,
            contact_sends: p.contact_sends_max as usize,
            graphics_nodes: nodes,
        };
        let links = if p.link_ram_bytes == 0 {
            size_of::<LinkBuffers>()
        } else {
            0 // in a region of their own
        };
        let ram = (p.ram_bytes.saturating_sub(p.ram_reserved_bytes) as usize).saturating_sub(links);
        c.elements = ram.saturating_sub(c.bytes::<T, E>()) / size_of::<E>();
        c
    }

    /// Bytes of storage at these capacities (what the firmware's statics take).
    pub const fn bytes<T, E>(&self) -> usize {
        self.materials * size_of::<MaterialLaw<T>>()
            + self.elements * size_of::<E>()
            + self.boxes * size_of::<HexBox<T>>()
            + self.cuboids * size_of::<HexCuboid<T>>()
            + self.nodes * (size_of::<NodeRecord<T>>() + 3 * size_of::<[T; 3]>())
            + self.exchange * (size_of::<u16>() + size_of::<RecvEntry>())
            + self.path_points * size_of::<PathPoint>()
            + self.loads * size_of::<LoadRecord>()
            + self.external * size_of::<ExternalRecord<T>>()
            + self.contact_nodes
                * (size_of::<ContactNode>()
                    + size_of::<ContactNodePlace>()
                    + 2 * size_of::<[f64; 3]>()
                    + size_of::<Option<[f64; 3]>>()
                    + size_of::<RemoteSlot>())
            + self.contact_faces * (size_of::<ContactFace>() + size_of::<QuadBounds>())
            + self.contact_candidates * size_of::<Candidate>()
            + self.contact_sends * size_of::<u32>()
            + self.graphics_nodes * size_of::<u16>()
            + FRAME_LEN_MAX
            + FRAME_RX_LEN
            + VALUES_PER_FRAME_MAX * size_of::<T>()
    }

    /// Every table of `c` that exceeds these capacities: (what, needed, held), in the
    /// loader's order (the loader refuses the first with the same figures).
    pub fn shortfalls(&self, c: &Counts) -> impl Iterator<Item = (&'static str, usize, usize)> {
        let nc = c.contact_nodes as usize;
        [
            ("materials", c.materials as usize, self.materials),
            ("elements", c.elements as usize, self.elements),
            ("parallelepipeds", c.boxes as usize, self.boxes),
            ("cuboids", c.cuboids as usize, self.cuboids),
            ("nodes", c.nodes as usize, self.nodes),
            ("exchange sends", c.sends as usize, self.exchange),
            ("exchange receives", c.recvs as usize, self.exchange),
            ("path points", c.path_points as usize, self.path_points),
            ("loads", c.loads as usize, self.loads),
            ("external forces", c.external_records(), self.external),
            ("contact nodes", nc, self.contact_nodes),
            (
                "contact faces",
                c.contact_faces as usize,
                self.contact_faces,
            ),
            (
                "graphics nodes",
                c.graphics_nodes as usize,
                self.graphics_nodes,
            ),
        ]
        .into_iter()
        .filter(|&(_, n, max)| n > max)
    }
}

/// The runtime's arrays, lent by their owner; each slice's length is its capacity.
pub struct Storage<'a, T, E> {
    pub laws: &'a mut [MaterialLaw<T>],
    pub elements: &'a mut [E],
    pub boxes: &'a mut [HexBox<T>],
    pub cuboids: &'a mut [HexCuboid<T>],
    pub nodes: &'a mut [NodeRecord<T>],
    pub u: &'a mut [[T; 3]],
    /// The last step's increment `u − u⁻` of each node (the central difference's state
    /// besides `u`).
    pub du: &'a mut [[T; 3]],
    pub force: &'a mut [[T; 3]],
    pub sends: &'a mut [u16],
    pub recvs: &'a mut [RecvEntry],
    pub path_points: &'a mut [PathPoint],
    pub loads: &'a mut [LoadRecord],
    /// External-force records by stage; the runtime's stage ranges index them.
    pub external: &'a mut [ExternalRecord<T>],
    pub contact: ContactStorage<'a>,
    /// The link frame (or global packet) being sent and the one being received, and the
    /// values of a frame: [`FRAME_LEN_MAX`] bytes each and [`VALUES_PER_FRAME_MAX`] values,
    /// in the storage so that the runtime itself stays small on the stack.
    pub tx: &'a mut [u8],
    pub rx: &'a mut [u8],
    pub scratch: &'a mut [T],
}

/// The contact and graphics part of [`Storage`] (empty slices when a scene has neither).
pub struct ContactStorage<'a> {
    pub nodes: &'a mut [ContactNode],
    pub places: &'a mut [ContactNodePlace],
    pub faces: &'a mut [ContactFace],
    /// Per contact face: its bounds this step, computed once per step for the pair tests,
    /// for the faces the kept candidates name
    /// ([`crate::physics::contact::evaluate_kept_pairs_bounded`]).
    pub face_bounds: &'a mut [QuadBounds],
    /// Per contact node: position at the last check, and contact force this step (f64).
    pub at_check: &'a mut [[f64; 3]],
    pub force: &'a mut [[f64; 3]],
    /// Per contact node: its position this step, computed once per step for the contact
    /// tests (`None`: a partner's node not received for this step).
    pub at_step: &'a mut [Option<[f64; 3]>],
    /// Per contact node: what the partners sent, by step parity.
    pub remote: &'a mut [RemoteSlot],
    pub candidates: &'a mut [Candidate],
    /// Contact-node indices sent to the partners until the next check (flat).
    pub send_list: &'a mut [u32],
    /// Local indices of the owned surface nodes sent to the graphics engine.
    pub graphics: &'a mut [u16],
}

impl<'a, T, E> Storage<'a, T, E> {
    /// The image sections that load straight into storage; the small fixed tables (lists,
    /// pairs, tools, contact boards) are the runtime's own.
    pub(crate) fn image_parts<'b>(&'b mut self, small: SmallTables<'b>) -> ImageParts<'b, T, E> {
        ImageParts {
            laws: self.laws,
            elements: self.elements,
            boxes: self.boxes,
            cuboids: self.cuboids,
            nodes: self.nodes,
            lists: small.lists,
            sends: self.sends,
            recvs: self.recvs,
            path_points: self.path_points,
            loads: self.loads,
            external: self.external,
            contact_nodes: self.contact.nodes,
            contact_places: self.contact.places,
            contact_faces: self.contact.faces,
            pairs: small.pairs,
            tools: small.tools,
            contact_boards: small.contact_boards,
            graphics_nodes: self.contact.graphics,
        }
    }
}

/// The image sections a runtime keeps in fixed arrays of its own.
pub(crate) struct SmallTables<'b> {
    pub lists: &'b mut [crate::image::ExchangeList],
    pub pairs: &'b mut [crate::image::ContactPair],
    pub tools: &'b mut [crate::image::Tool],
    pub contact_boards: &'b mut [u8],
}

/// A kind of vector [`StorageBuf`] is made of: `N` is the capacity of a fixed-capacity
/// vector (ignored by a growable one).
pub trait Shelf {
    type Of<R: Copy, const N: usize>: core::ops::DerefMut<Target = [R]>;
    /// An empty vector.
    fn empty<R: Copy, const N: usize>() -> Self::Of<R, N>;
    /// Makes `v` hold `len` copies of `value`; `false` if it cannot hold that many.
    fn fill<R: Copy, const N: usize>(v: &mut Self::Of<R, N>, len: usize, value: R) -> bool;
}

/// Fixed-capacity vectors (the firmware's statics).
pub struct Heapless;

impl Shelf for Heapless {
    type Of<R: Copy, const N: usize> = heapless::Vec<R, N>;
    fn empty<R: Copy, const N: usize>() -> heapless::Vec<R, N> {
        heapless::Vec::new()
    }
    fn fill<R: Copy, const N: usize>(v: &mut heapless::Vec<R, N>, len: usize, value: R) -> bool {
        v.clear();
        v.resize(len, value).is_ok()
    }
}

/// The owner of a board's arrays. Capacities: `NM` materials, `NE` elements, `NB`
/// parallelepipeds, `NQ` cuboids, `NN` nodes,
/// `NX` exchange entries, `NP` path points, `NL` loads, `NC` contact nodes, `NF` contact
/// faces, `NK` candidates, `NS` contact sends (a growable [`Shelf`] ignores them).
pub struct StorageBuf<
    S: Shelf,
    T: Copy,
    E: Copy,
    const NM: usize,
    const NE: usize,
    const NB: usize,
    const NQ: usize,
    const NN: usize,
    const NX: usize,
    const NP: usize,
    const NL: usize,
    const NC: usize,
    const NF: usize,
    const NK: usize,
    const NS: usize,
> {
    laws: S::Of<MaterialLaw<T>, NM>,
    elements: S::Of<E, NE>,
    boxes: S::Of<HexBox<T>, NB>,
    cuboids: S::Of<HexCuboid<T>, NQ>,
    nodes: S::Of<NodeRecord<T>, NN>,
    u: S::Of<[T; 3], NN>,
    du: S::Of<[T; 3], NN>,
    force: S::Of<[T; 3], NN>,
    sends: S::Of<u16, NX>,
    recvs: S::Of<RecvEntry, NX>,
    path_points: S::Of<PathPoint, NP>,
    loads: S::Of<LoadRecord, NL>,
    external: S::Of<ExternalRecord<T>, NN>,
    contact_nodes: S::Of<ContactNode, NC>,
    places: S::Of<ContactNodePlace, NC>,
    faces: S::Of<ContactFace, NF>,
    face_bounds: S::Of<QuadBounds, NF>,
    at_check: S::Of<[f64; 3], NC>,
    contact_force: S::Of<[f64; 3], NC>,
    at_step: S::Of<Option<[f64; 3]>, NC>,
    remote: S::Of<RemoteSlot, NC>,
    candidates: S::Of<Candidate, NK>,
    send_list: S::Of<u32, NS>,
    graphics: S::Of<u16, NN>,
    tx: S::Of<u8, FRAME_LEN_MAX>,
    rx: S::Of<u8, FRAME_RX_LEN>,
    scratch: S::Of<T, VALUES_PER_FRAME_MAX>,
}

impl<
        S: Shelf,
        T: Copy + serde::de::DeserializeOwned,
        E: Copy + serde::de::DeserializeOwned,
        const NM: usize,
        const NE: usize,
        const NB: usize,
        const NQ: usize,
        const NN: usize,
        const NX: usize,
        const NP: usize,
        const NL: usize,
        const NC: usize,
        const NF: usize,
        const NK: usize,
        const NS: usize,
    > StorageBuf<S, T, E, NM, NE, NB, NQ, NN, NX, NP, NL, NC, NF, NK, NS>
{
    /// Empty storage. (The firmware's, 4 MiB of fixed-capacity vectors on the emulated
    /// board, is a zeroed static instead: an all-zero `heapless::Vec` is empty.)
    pub fn empty() -> Self {
        StorageBuf {
            laws: S::empty(),
            elements: S::empty(),
            boxes: S::empty(),
            cuboids: S::empty(),
            nodes: S::empty(),
            u: S::empty(),
            du: S::empty(),
            force: S::empty(),
            sends: S::empty(),
            recvs: S::empty(),
            path_points: S::empty(),
            loads: S::empty(),
            external: S::empty(),
            contact_nodes: S::empty(),
            places: S::empty(),
            faces: S::empty(),
            face_bounds: S::empty(),
            at_check: S::empty(),
            contact_force: S::empty(),
            at_step: S::empty(),
            remote: S::empty(),
            candidates: S::empty(),
            send_list: S::empty(),
            graphics: S::empty(),
            tx: S::empty(),
            rx: S::empty(),
            scratch: S::empty(),
        }
    }

    /// Fills every array to its capacity in `caps` with zero records and lends them; `None`
    /// if a fixed-capacity vector is smaller than `caps` (or a zero record fails to decode,
    /// which would be a bug).
    pub fn fill(&mut self, caps: &Capacities) -> Option<Storage<'_, T, E>> {
        fn put<S: Shelf, R: Copy + serde::de::DeserializeOwned, const N: usize>(
            v: &mut S::Of<R, N>,
            len: usize,
        ) -> Option<()> {
            S::fill(v, len, zero_record::<R>()?).then_some(())
        }
        put::<S, _, NM>(&mut self.laws, caps.materials)?;
        put::<S, _, NE>(&mut self.elements, caps.elements)?;
        put::<S, _, NB>(&mut self.boxes, caps.boxes)?;
        put::<S, _, NQ>(&mut self.cuboids, caps.cuboids)?;
        put::<S, _, NN>(&mut self.nodes, caps.nodes)?;
        put::<S, _, NN>(&mut self.u, caps.nodes)?;
        put::<S, _, NN>(&mut self.du, caps.nodes)?;
        put::<S, _, NN>(&mut self.force, caps.nodes)?;
        put::<S, _, NX>(&mut self.sends, caps.exchange)?;
        put::<S, _, NX>(&mut self.recvs, caps.exchange)?;
        put::<S, _, NP>(&mut self.path_points, caps.path_points)?;
        put::<S, _, NL>(&mut self.loads, caps.loads)?;
        put::<S, _, NN>(&mut self.external, caps.external)?;
        put::<S, _, NC>(&mut self.contact_nodes, caps.contact_nodes)?;
        put::<S, _, NC>(&mut self.places, caps.contact_nodes)?;
        put::<S, _, NF>(&mut self.faces, caps.contact_faces)?;
        put::<S, _, NF>(&mut self.face_bounds, caps.contact_faces)?;
        put::<S, _, NC>(&mut self.at_check, caps.contact_nodes)?;
        put::<S, _, NC>(&mut self.contact_force, caps.contact_nodes)?;
        put::<S, _, NC>(&mut self.at_step, caps.contact_nodes)?;
        put::<S, _, NC>(&mut self.remote, caps.contact_nodes)?;
        put::<S, _, NK>(&mut self.candidates, caps.contact_candidates)?;
        put::<S, _, NS>(&mut self.send_list, caps.contact_sends)?;
        put::<S, _, NN>(&mut self.graphics, caps.graphics_nodes)?;
        put::<S, _, FRAME_LEN_MAX>(&mut self.tx, FRAME_LEN_MAX)?;
        put::<S, _, FRAME_RX_LEN>(&mut self.rx, FRAME_RX_LEN)?;
        put::<S, _, VALUES_PER_FRAME_MAX>(&mut self.scratch, VALUES_PER_FRAME_MAX)?;
        Some(Storage {
            laws: &mut self.laws,
            elements: &mut self.elements,
            boxes: &mut self.boxes,
            cuboids: &mut self.cuboids,
            nodes: &mut self.nodes,
            u: &mut self.u,
            du: &mut self.du,
            force: &mut self.force,
            sends: &mut self.sends,
            recvs: &mut self.recvs,
            path_points: &mut self.path_points,
            loads: &mut self.loads,
            external: &mut self.external,
            contact: ContactStorage {
                nodes: &mut self.contact_nodes,
                places: &mut self.places,
                faces: &mut self.faces,
                face_bounds: &mut self.face_bounds,
                at_check: &mut self.at_check,
                force: &mut self.contact_force,
                at_step: &mut self.at_step,
                remote: &mut self.remote,
                candidates: &mut self.candidates,
                send_list: &mut self.send_list,
                graphics: &mut self.graphics,
            },
            tx: &mut self.tx,
            rx: &mut self.rx,
            scratch: &mut self.scratch,
        })
    }
}
