//! An image read back on the host through the firmware's own codec and checks
//! ([`pe_firmware::image::read_image`]), for `pe inspect`, board-sim's timing model and
//! tests. Scalars are widened to `f64`.

use super::tables::ImageTables;
use pe_firmware::image::*;

/// One decoded exchange round (local node indices).
#[derive(Clone, Debug, Default)]
pub struct DecodedRound {
    pub send: [Vec<u16>; 2],
    pub recv: [Vec<RecvEntry>; 2],
}

/// An image decoded on the host, scalars as `f64`.
#[derive(Clone, Debug)]
pub struct DecodedImage {
    pub header: ImageHeader,
    /// Element node lists (local indices).
    pub element_nodes: Vec<[u32; 8]>,
    pub nodes: Vec<NodeRecord<f64>>,
    /// External forces per stage (0/1/2 before the x/y/z exchange, 3 before the update).
    pub external: [Vec<ExternalRecord<f64>>; STAGES],
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

fn decode_typed<T: ImageReal, E: ElementRecord<T>>(
    bytes: &[u8],
    expected_board: Option<[u8; 3]>,
    c: &Counts,
) -> Result<DecodedImage, ImageError> {
    let mut t = ImageTables::<T, E>::zeroed(c)?;
    let header = read_image(bytes, expected_board, &mut t.parts())?;
    let mut rounds: [Vec<DecodedRound>; 3] = Default::default();
    let (mut s, mut r, mut k) = (0usize, 0usize, 0usize);
    for (a, &n) in c.rounds.iter().enumerate() {
        for _ in 0..n {
            let mut round = DecodedRound::default();
            for f in 0..2 {
                let l = t.lists[k];
                round.send[f] = t.sends[s..s + l.sends as usize].to_vec();
                round.recv[f] = t.recvs[r..r + l.recvs as usize].to_vec();
                (s, r, k) = (s + l.sends as usize, r + l.recvs as usize, k + 1);
            }
            rounds[a].push(round);
        }
    }
    let mut records = t.external.iter().map(|x| ExternalRecord {
        node: x.node,
        gravity: x.gravity.map(|g| g.to_f64()),
        first_load: x.first_load,
        loads: x.loads,
        contact: x.contact,
    });
    let external = c
        .external
        .map(|n| records.by_ref().take(n as usize).collect());
    Ok(DecodedImage {
        header,
        element_nodes: t
            .elements
            .iter()
            .map(|e| *e.nodes())
            .chain(t.boxes.iter().map(|e| e.connectivity.nodes))
            .chain(t.cuboids.iter().map(|e| e.connectivity.nodes))
            .collect(),
        nodes: t
            .nodes
            .iter()
            .map(|n| NodeRecord {
                global: n.global,
                gain: n.gain.to_f64(),
                half_mass_kg: n.half_mass_kg,
                motion: n.motion,
                owner: n.owner,
            })
            .collect(),
        external,
        rounds,
        path_points: t.path_points,
        loads: t.loads,
        contact_nodes: t.contact_nodes.into_iter().zip(t.places).collect(),
        contact_faces: t.faces,
        pairs: t.pairs,
        tools: t.tools,
        contact_boards: t.contact_boards,
        graphics_nodes: t.graphics_nodes,
    })
}

/// Decodes and checks a whole image (for board `expected_board`, if given).
pub fn decode_image(
    bytes: &[u8],
    expected_board: Option<[u8; 3]>,
) -> Result<DecodedImage, ImageError> {
    let h = ImageReader::new(bytes, expected_board)?.header;
    let c = &h.counts;
    pe_firmware::with_element_types!(h.precision, h.integration, |T, E| {
        decode_typed::<T, E>(bytes, expected_board, c)
    })
}
