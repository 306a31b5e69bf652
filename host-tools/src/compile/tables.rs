//! An image's sections as host vectors: what the compiler fills and writes, and what the
//! decoder reads back into, both through the firmware's codec ([`ImageParts`]).

use pe_firmware::image::*;
use pe_firmware::physics::{HexBox, HexCuboid, MaterialLaw};

/// One vector per image section.
#[derive(Clone, Debug)]
pub struct ImageTables<T, E> {
    pub laws: Vec<MaterialLaw<T>>,
    pub elements: Vec<E>,
    pub boxes: Vec<HexBox<T>>,
    pub cuboids: Vec<HexCuboid<T>>,
    pub nodes: Vec<NodeRecord<T>>,
    pub lists: Vec<ExchangeList>,
    pub sends: Vec<u16>,
    pub recvs: Vec<RecvEntry>,
    pub path_points: Vec<PathPoint>,
    pub loads: Vec<LoadRecord>,
    pub external: Vec<ExternalRecord<T>>,
    pub contact_nodes: Vec<ContactNode>,
    pub places: Vec<ContactNodePlace>,
    pub faces: Vec<ContactFace>,
    pub pairs: Vec<ContactPair>,
    pub tools: Vec<Tool>,
    pub contact_boards: Vec<u8>,
    pub graphics_nodes: Vec<u16>,
}

/// `n` zero records (what a reader overwrites).
fn zeros<R: Clone + serde::de::DeserializeOwned>(n: usize) -> Result<Vec<R>, ImageError> {
    let z = zero_record::<R>().ok_or(ImageError::Malformed {
        record: "zero record",
    })?;
    Ok(vec![z; n])
}

impl<T: ImageReal, E: ElementRecord<T>> ImageTables<T, E> {
    /// Zero records, exactly as many as `c` counts (to be read into).
    pub fn zeroed(c: &Counts) -> Result<Self, ImageError> {
        Ok(ImageTables {
            laws: zeros(c.materials as usize)?,
            elements: zeros(c.elements as usize)?,
            boxes: zeros(c.boxes as usize)?,
            cuboids: zeros(c.cuboids as usize)?,
            nodes: zeros(c.nodes as usize)?,
            lists: zeros(c.exchange_lists())?,
            sends: zeros(c.sends as usize)?,
            recvs: zeros(c.recvs as usize)?,
            path_points: zeros(c.path_points as usize)?,
            loads: zeros(c.loads as usize)?,
            external: zeros(c.external_records())?,
            contact_nodes: zeros(c.contact_nodes as usize)?,
            places: zeros(c.contact_nodes as usize)?,
            faces: zeros(c.contact_faces as usize)?,
            pairs: zeros(c.pairs as usize)?,
            tools: zeros(c.tools as usize)?,
            contact_boards: zeros(c.contact_boards as usize)?,
            graphics_nodes: zeros(c.graphics_nodes as usize)?,
        })
    }

    /// The counts of what the tables hold (batch ends of each kernel, exchanged nodes per
    /// face and rounds come from the plan, the external records per stage from their
    /// grouping).
    pub fn counts(
        &self,
        batch_ends: [u32; 4],
        box_batch_ends: [u32; 4],
        cuboid_batch_ends: [u32; 4],
        exchange: [u16; 6],
        (rounds, late_rounds): ([u8; 3], [u8; 3]),
        external: [u16; STAGES],
    ) -> Counts {
        Counts {
            materials: self.laws.len() as u16,
            elements: self.elements.len() as u32,
            batch_ends,
            boxes: self.boxes.len() as u32,
            box_batch_ends,
            cuboids: self.cuboids.len() as u32,
            cuboid_batch_ends,
            nodes: self.nodes.len() as u32,
            exchange,
            rounds,
            late_rounds,
            sends: self.sends.len() as u32,
            recvs: self.recvs.len() as u32,
            path_points: self.path_points.len() as u16,
            loads: self.loads.len() as u16,
            external,
            contact_nodes: self.contact_nodes.len() as u32,
            contact_faces: self.faces.len() as u32,
            pairs: self.pairs.len() as u8,
            tools: self.tools.len() as u8,
            contact_boards: self.contact_boards.len() as u8,
            graphics_nodes: self.graphics_nodes.len() as u16,
        }
    }

    /// The tables lent to the codec.
    pub fn parts(&mut self) -> ImageParts<'_, T, E> {
        ImageParts {
            laws: &mut self.laws,
            elements: &mut self.elements,
            boxes: &mut self.boxes,
            cuboids: &mut self.cuboids,
            nodes: &mut self.nodes,
            lists: &mut self.lists,
            sends: &mut self.sends,
            recvs: &mut self.recvs,
            path_points: &mut self.path_points,
            loads: &mut self.loads,
            external: &mut self.external,
            contact_nodes: &mut self.contact_nodes,
            contact_places: &mut self.places,
            contact_faces: &mut self.faces,
            pairs: &mut self.pairs,
            tools: &mut self.tools,
            contact_boards: &mut self.contact_boards,
            graphics_nodes: &mut self.graphics_nodes,
        }
    }
}
