//! The session's messages to a client as OpenIGTLink messages (header version 1, which
//! every OpenIGTLink reader takes; the header timestamp is the wall clock at sending):
//!
//! | [`Outbound`]  | message                                                               |
//! |---------------|-----------------------------------------------------------------------|
//! | `Force`       | POINT, device = tool name, one point: name = tool, group [`FORCE_GROUP`], **X Y Z = the force of the tissue on the tool in newtons**, diameter 0; the mean of [`FORCE_DECIMATION`] consecutive 1 ms means, so one POINT per tool per 10 ms of simulated time (100 Hz at real time: a rate Slicer and pyigtl's one-message-per-device inbox take; 1 kHz would flood them) |
//! | `Surface`     | POLYDATA, device = the scene's name (cut to 20 bytes): the surface nodes' positions in millimetres, every triangle a 3-index polygon, at the session's graphics rate |
//! | `Error`       | STRING, device `error`                                                |
//! | `Notice`      | STRING, device `notice`                                               |
//! | `Driver`      | STRING, device `driver`: `TOOL: client N` or `TOOL: nobody`           |
//! | `Hello`       | STRING, device `hello`: the session's hello JSON (`docs/live.md`)     |
//! | `Status`      | STRING, device `status`: the session's status JSON                    |
//! | `Topology`    | nothing (every POLYDATA carries its triangles)                        |

use std::collections::HashMap;
use std::sync::Arc;

use super::body::Framing;
use super::error::{Error, Result};
use super::header::{cut_to, device_name_of};
use super::message::{encode, encode_with, Content};
use super::point::{PointRepr, FORCE_GROUP};
use super::polydata::{
    triangle_cells, triangles_len, Cells, PolyData, POINT_LEN, POLYDATA_HEADER_LEN,
};
use super::string::StringRepr;
use super::transform::MM_PER_M;
use crate::live::hub::Outbound;

/// Forces averaged into one POINT: 10 one-millisecond means (10 ms of simulated time).
pub const FORCE_DECIMATION: u32 = 10;
/// Colour of the force points (orange, opaque).
pub const FORCE_RGBA: [u8; 4] = [255, 128, 0, 255];
/// Longest POINT name.
const POINT_NAME_MAX: usize = 64;

/// What the encoder needs of the scene.
#[derive(Clone, Debug)]
pub struct SurfaceTopology {
    /// The POLYDATA's device name.
    pub device: String,
    pub nodes: usize,
    pub triangles: Vec<[u32; 3]>,
}

/// Turns one client's [`Outbound`] messages into OpenIGTLink messages.
#[derive(Debug)]
pub struct Encoder {
    surface_device: String,
    nodes: usize,
    triangles: usize,
    /// The polygon cell array, the same in every frame.
    polygons: Vec<u8>,
    forces: HashMap<Arc<str>, ForceMean>,
}

/// A running sum of forces for one tool.
#[derive(Debug, Default)]
struct ForceMean {
    sum_n: [f64; 3],
    count: u32,
}

impl Encoder {
    /// Refuses a topology whose triangles name nodes past its count, or too large for a
    /// POLYDATA's u32 counts.
    pub fn new(topology: &SurfaceTopology) -> Result<Encoder> {
        let nodes = topology.nodes;
        if let Some(&index) = topology
            .triangles
            .iter()
            .flatten()
            .find(|&&i| i as usize >= nodes)
        {
            return Err(Error::BadIndex {
                what: "surface triangles",
                index,
                count: nodes,
            });
        }
        let polygons = triangle_cells(&topology.triangles);
        let too_big = POLYDATA_HEADER_LEN + POINT_LEN * nodes + polygons.len() > u32::MAX as usize;
        if too_big {
            return Err(Error::TooLong {
                field: "surface",
                text: format!("{nodes} nodes, {} triangles", topology.triangles.len()),
                max: u32::MAX as usize,
            });
        }
        Ok(Encoder {
            surface_device: device_name_of(&topology.device).to_string(),
            nodes,
            triangles: topology.triangles.len(),
            polygons,
            forces: HashMap::new(),
        })
    }

    /// The message for `m`, if one is due; `timestamp` goes into its header. An error is
    /// the server's own fault (a frame that does not fit the topology), never the client's.
    pub fn encode(&mut self, m: &Outbound, timestamp: u64) -> Result<Option<Vec<u8>>> {
        let string = |device: &str, text: &str| {
            encode(
                &Framing::V1,
                device,
                timestamp,
                &Content::String(StringRepr::new(text)),
            )
            .map(Some)
        };
        match m {
            Outbound::Force { tool, force_n, .. } => match self.force_mean(tool, force_n) {
                Some(mean) => self.force_point(tool, mean, timestamp).map(Some),
                None => Ok(None),
            },
            Outbound::Surface { positions_m, .. } => self.surface(positions_m, timestamp).map(Some),
            Outbound::Error(text) => string("error", text),
            Outbound::Notice(text) => string("notice", text),
            Outbound::Driver { tool, client } => {
                let who = client.map_or("nobody".to_string(), |c| format!("client {c}"));
                string("driver", &format!("{tool}: {who}"))
            }
            Outbound::Hello(json) => string("hello", &json.to_string()),
            Outbound::Status(json) => string("status", &json.to_string()),
            Outbound::Topology(_) => Ok(None),
        }
    }

    /// Adds a 1 ms mean; every [`FORCE_DECIMATION`]-th gives the mean of the last ones.
    fn force_mean(&mut self, tool: &Arc<str>, force_n: &[f64; 3]) -> Option<[f64; 3]> {
        let m = self.forces.entry(tool.clone()).or_default();
        for (s, f) in m.sum_n.iter_mut().zip(force_n) {
            *s += f;
        }
        m.count += 1;
        if m.count < FORCE_DECIMATION {
            return None;
        }
        let n = f64::from(m.count);
        let mean = m.sum_n.map(|s| s / n);
        *m = ForceMean::default();
        Some(mean)
    }

    fn force_point(&self, tool: &str, mean_n: [f64; 3], timestamp: u64) -> Result<Vec<u8>> {
        let point = PointRepr {
            name: cut_to(tool, POINT_NAME_MAX).to_string(),
            group: FORCE_GROUP.to_string(),
            rgba: FORCE_RGBA,
            xyz: mean_n.map(|f| f as f32),
            diameter: 0.0,
            owner: String::new(),
        };
        encode(
            &Framing::V1,
            device_name_of(tool),
            timestamp,
            &Content::Point(vec![point]),
        )
    }

    fn surface(&self, positions_m: &[f32], timestamp: u64) -> Result<Vec<u8>> {
        let n = positions_m.len() / 3;
        if positions_m.len() != 3 * self.nodes {
            // A frame not of this surface: say so to the client rather than send garbage.
            let text = format!(
                "surface frame of {} values for {} nodes: not sent",
                positions_m.len(),
                self.nodes
            );
            return encode(
                &Framing::V1,
                "error",
                timestamp,
                &Content::String(StringRepr::new(&text)),
            );
        }
        let len = POLYDATA_HEADER_LEN + POINT_LEN * n + triangles_len(self.triangles);
        encode_with(
            &Framing::V1,
            "POLYDATA",
            &self.surface_device,
            timestamp,
            len,
            |buf| {
                let mut v = PolyData::new_unchecked(buf);
                let polygons = (self.triangles as u32, self.polygons.len() as u32);
                v.set_header(n as u32, [(0, 0), (0, 0), polygons, (0, 0)]);
                for (i, p) in positions_m.chunks_exact(3).enumerate() {
                    v.set_point(
                        i,
                        [p[0], p[1], p[2]].map(|x| (f64::from(x) * MM_PER_M) as f32),
                    );
                }
                v.cells_mut(Cells::Polygons).copy_from_slice(&self.polygons);
                Ok(())
            },
        )
    }
}
