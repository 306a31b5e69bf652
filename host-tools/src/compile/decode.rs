//! An image read back on the host through the firmware's own codec and checks
//! ([`pe_firmware::image::read_image`]), for `pe inspect`, board-sim's timing model and
//! tests. Scalars are widened to `f64`.

use pe_firmware::image::*;
use pe_firmware::physics::{HexFull, HexReduced, MaterialLaw};
use pe_firmware::runtime::Capacities;

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

/// `n` zero records (what the loader overwrites).
fn zeros<R: Clone + serde::de::DeserializeOwned>(n: usize) -> Result<Vec<R>, ImageError> {
    let z = zero_record::<R>().ok_or(ImageError::Malformed {
        record: "zero record",
    })?;
    Ok(vec![z; n])
}

fn decode_typed<T: ImageReal, E: ElementRecord<T>>(
    bytes: &[u8],
    expected_board: Option<[u8; 3]>,
    c: &Counts,
) -> Result<DecodedImage, ImageError> {
    let caps = Capacities::exact(c);
    let (nc, lists) = (caps.contact_nodes, c.exchange_lists());
    let mut laws = zeros::<MaterialLaw<T>>(caps.materials)?;
    let mut elements = zeros::<E>(caps.elements)?;
    let mut nodes = zeros::<NodeRecord<T>>(caps.nodes)?;
    let mut list = zeros::<ExchangeList>(lists)?;
    let mut sends = zeros::<u16>(c.sends as usize)?;
    let mut recvs = zeros::<RecvEntry>(c.recvs as usize)?;
    let mut path_points = zeros::<PathPoint>(caps.path_points)?;
    let mut loads = zeros::<LoadRecord>(caps.loads)?;
    let mut contact_nodes = zeros::<ContactNode>(nc)?;
    let mut places = zeros::<ContactNodePlace>(nc)?;
    let mut contact_faces = zeros::<ContactFace>(caps.contact_faces)?;
    let mut pairs = zeros::<ContactPair>(c.pairs as usize)?;
    let mut tools = zeros::<Tool>(c.tools as usize)?;
    let mut contact_boards = zeros::<u8>(c.contact_boards as usize)?;
    let mut graphics_nodes = zeros::<u16>(caps.graphics_nodes)?;
    let header = read_image(
        bytes,
        expected_board,
        &mut ImageParts {
            laws: &mut laws,
            elements: &mut elements,
            nodes: &mut nodes,
            lists: &mut list,
            sends: &mut sends,
            recvs: &mut recvs,
            path_points: &mut path_points,
            loads: &mut loads,
            contact_nodes: &mut contact_nodes,
            contact_places: &mut places,
            contact_faces: &mut contact_faces,
            pairs: &mut pairs,
            tools: &mut tools,
            contact_boards: &mut contact_boards,
            graphics_nodes: &mut graphics_nodes,
        },
    )?;
    let mut rounds: [Vec<DecodedRound>; 3] = Default::default();
    let (mut s, mut r, mut k) = (0usize, 0usize, 0usize);
    for (a, &n) in c.rounds.iter().enumerate() {
        for _ in 0..n {
            let mut round = DecodedRound::default();
            for f in 0..2 {
                let l = list[k];
                round.send[f] = sends[s..s + l.sends as usize].to_vec();
                round.recv[f] = recvs[r..r + l.recvs as usize].to_vec();
                (s, r, k) = (s + l.sends as usize, r + l.recvs as usize, k + 1);
            }
            rounds[a].push(round);
        }
    }
    Ok(DecodedImage {
        header,
        element_nodes: elements.iter().map(|e| *e.nodes()).collect(),
        nodes: nodes
            .iter()
            .map(|n| NodeRecord {
                global: n.global,
                gain: n.gain.to_f64(),
                motion: n.motion,
                owner: n.owner,
                gravity: n.gravity.map(|g| g.to_f64()),
                stage: n.stage,
            })
            .collect(),
        rounds,
        path_points,
        loads,
        contact_nodes: contact_nodes.into_iter().zip(places).collect(),
        contact_faces,
        pairs,
        tools,
        contact_boards,
        graphics_nodes,
    })
}

/// Decodes and checks a whole image (for board `expected_board`, if given).
pub fn decode_image(
    bytes: &[u8],
    expected_board: Option<[u8; 3]>,
) -> Result<DecodedImage, ImageError> {
    let h = ImageReader::new(bytes, expected_board)?.header;
    let c = &h.counts;
    match (h.precision, h.integration) {
        (Precision::F32, Integration::Reduced) => {
            decode_typed::<f32, HexReduced<f32>>(bytes, expected_board, c)
        }
        (Precision::F32, Integration::Full) => {
            decode_typed::<f32, HexFull<f32>>(bytes, expected_board, c)
        }
        (Precision::F64, Integration::Reduced) => {
            decode_typed::<f64, HexReduced<f64>>(bytes, expected_board, c)
        }
        (Precision::F64, Integration::Full) => {
            decode_typed::<f64, HexFull<f64>>(bytes, expected_board, c)
        }
    }
}
