//! The WebSocket session's messages (`docs/live.md` is the reference a client reads): text
//! JSON both ways ([`ClientMessage`], [`ServerMessage`]; the Rust types are the schema) and
//! binary frames from the server ([`Frame`], [`FrameHeader`]): the surface's topology, its
//! positions at the graphics rate and the tools' poses. The magic and version live here
//! and only here.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::engine::{Pose, SurfaceInfo, ToolInfo};

/// The session protocol's version: the `hello` message's `protocol` and every binary
/// frame's `version`.
pub const VERSION: u16 = 1;
/// A binary frame's first four bytes, little-endian: 0x50455346, the bytes `F S E P`
/// (0x46 0x53 0x45 0x50).
pub const MAGIC: u32 = 0x5045_5346;
/// The largest text message a client may send (bytes); a longer one is refused.
pub const CLIENT_MESSAGE_MAX: usize = 64 * 1024;
/// The rate of the force messages: one per millisecond of simulated time.
pub const FORCE_HZ: u32 = 1000;
/// The WebSocket session's path.
pub const SESSION_PATH: &str = "/session";

/// A text message from a client.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum ClientMessage {
    /// Move `tool` to the rigid motion (`orientation` a unit quaternion `[w, x, y, z]`,
    /// `position_m` in metres) from where the scene places it.
    Pose {
        tool: String,
        position_m: [f64; 3],
        orientation: [f64; 4],
    },
    /// Stop driving `tool` (it stays where it is).
    Release { tool: String },
}

/// A text message from the server.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum ServerMessage {
    Hello(Hello),
    /// The mean force of the tissue on `tool` over the millisecond of simulated time that
    /// ends at `time_s` (N).
    Force {
        time_s: f64,
        tool: String,
        force_n: [f64; 3],
    },
    Status(Status),
    /// Who drives `tool` now (`null`: nobody).
    Driver {
        tool: String,
        client: Option<u32>,
    },
    /// Something the client sent was refused; the session goes on.
    Error {
        message: String,
    },
    /// Something the client should know (a pose reached over several steps).
    Notice {
        message: String,
    },
}

/// The first message to a client.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hello {
    pub protocol: u16,
    /// This client's id (the `drivers` of a status and `driver` messages name clients so).
    pub client: u32,
    pub scene: String,
    pub model: String,
    /// The time step at the start (s); `status.dt_s` follows it.
    pub dt_s: f64,
    pub graphics_hz: f64,
    pub force_hz: u32,
    pub tools: Vec<HelloTool>,
    pub surface: HelloSurface,
    /// Steps from the step a pose is given for to the first step that can take it.
    pub pose_delay_steps: u64,
    /// The fastest a tool's capsule moves (m/s): the contact search's speed bound.
    pub tool_speed_max_m_s: f64,
    /// Lag (s) past which the session's clock slips (see `policy`).
    pub max_lag_s: f64,
    /// The pacing policy in words.
    pub policy: String,
}

/// A tool as the scene places it (the identity pose).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HelloTool {
    pub name: String,
    pub a_m: [f64; 3],
    pub b_m: [f64; 3],
    pub radius_m: f64,
    pub trocar_m: Option<[f64; 3]>,
}

impl From<&ToolInfo> for HelloTool {
    fn from(t: &ToolInfo) -> Self {
        HelloTool {
            name: t.name.clone(),
            a_m: t.a_m,
            b_m: t.b_m,
            radius_m: t.radius_m,
            trocar_m: t.trocar_m,
        }
    }
}

/// The surface's size, as the TOPOLOGY frame that follows gives it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HelloSurface {
    pub nodes: usize,
    pub triangles: usize,
    /// Body names by body id (the TOPOLOGY frame's per-node ids).
    pub bodies: Vec<String>,
}

/// The session's state, about four times a second.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Status {
    pub time_s: f64,
    pub step: u64,
    pub dt_s: f64,
    /// Simulated over wall time, over the last second.
    pub real_time_factor: f64,
    /// Wall time less simulated time since the session's start (s), less the slips.
    pub lag_s: f64,
    pub slips: u64,
    pub slipped_s: f64,
    pub model: String,
    /// Each tool's driver (a client id) or `null`.
    pub drivers: BTreeMap<String, Option<u32>>,
    pub clients: usize,
    /// Pose-to-force latency so far: a pose received to the first force message that
    /// reflects it (ms).
    pub latency_ms: LatencyMs,
    /// Surface frames dropped for this client (it read too slowly).
    pub surface_frames_dropped: u64,
}

/// Percentiles of the pose-to-force latency (ms); zeros before any sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LatencyMs {
    pub samples: u64,
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl ServerMessage {
    pub fn to_json(&self) -> String {
        // A message of plain numbers and strings always serialises.
        serde_json::to_string(self).unwrap_or_else(|e| {
            format!(r#"{{"type":"error","message":"message not serialisable: {e}"}}"#)
        })
    }
}

/// What a binary frame carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum FrameKind {
    /// The surface's triangles, reference positions and body ids (once, after `hello`).
    Topology = 1,
    /// The surface nodes' current positions (m), at the graphics rate.
    Positions = 2,
    /// Each tool's applied pose, with each POSITIONS frame.
    Tools = 3,
}

impl FrameKind {
    fn from_u16(v: u16) -> Option<FrameKind> {
        match v {
            1 => Some(FrameKind::Topology),
            2 => Some(FrameKind::Positions),
            3 => Some(FrameKind::Tools),
            _ => None,
        }
    }
}

/// A binary frame's header (24 bytes, little-endian): u32 magic, u16 version, u16 kind,
/// u32 seq, u32 count, f64 time_s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameHeader {
    pub kind: FrameKind,
    /// Frame number (POSITIONS and TOOLS sent together share it; TOPOLOGY: 0).
    pub seq: u32,
    /// Triangles (TOPOLOGY), nodes (POSITIONS) or tools (TOOLS).
    pub count: u32,
    /// Simulated time of the state (s).
    pub time_s: f64,
}

/// Byte offsets of the header's fields and the payload.
mod field {
    pub const MAGIC: usize = 0;
    pub const VERSION: usize = 4;
    pub const KIND: usize = 6;
    pub const SEQ: usize = 8;
    pub const COUNT: usize = 12;
    pub const TIME: usize = 16;
    pub const PAYLOAD: usize = 24;
}

/// The header's length (bytes).
pub const HEADER_LEN: usize = field::PAYLOAD;

/// Why bytes are not a frame.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FrameError {
    #[error("frame of {0} bytes is shorter than its 24-byte header")]
    Short(usize),
    #[error("magic {0:#010x} is not {MAGIC:#010x}")]
    Magic(u32),
    #[error("version {0}, this is version {VERSION}")]
    Version(u16),
    #[error("unknown frame kind {0}")]
    Kind(u16),
    #[error("{kind:?} frame of {count} is {got} bytes long, not {want}")]
    Length {
        kind: FrameKind,
        count: u32,
        got: usize,
        want: usize,
    },
}

impl FrameHeader {
    /// The header at the start of `bytes`.
    pub fn parse(bytes: &[u8]) -> Result<FrameHeader, FrameError> {
        if bytes.len() < HEADER_LEN {
            return Err(FrameError::Short(bytes.len()));
        }
        let magic = u32_at(bytes, field::MAGIC);
        if magic != MAGIC {
            return Err(FrameError::Magic(magic));
        }
        let version = u16_at(bytes, field::VERSION);
        if version != VERSION {
            return Err(FrameError::Version(version));
        }
        let kind = u16_at(bytes, field::KIND);
        Ok(FrameHeader {
            kind: FrameKind::from_u16(kind).ok_or(FrameError::Kind(kind))?,
            seq: u32_at(bytes, field::SEQ),
            count: u32_at(bytes, field::COUNT),
            time_s: f64::from_le_bytes(array_at(bytes, field::TIME)),
        })
    }

    /// Appends the header to `out`.
    pub fn emit(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&MAGIC.to_le_bytes());
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(self.kind as u16).to_le_bytes());
        out.extend_from_slice(&self.seq.to_le_bytes());
        out.extend_from_slice(&self.count.to_le_bytes());
        out.extend_from_slice(&self.time_s.to_le_bytes());
    }
}

/// A binary frame, its length checked against its kind and count.
#[derive(Clone, Debug)]
pub struct Frame<T: AsRef<[u8]>> {
    buffer: T,
    header: FrameHeader,
}

/// The TOPOLOGY frame's content.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Topology {
    pub triangles: Vec<[u32; 3]>,
    pub reference_m: Vec<[f32; 3]>,
    pub body: Vec<u16>,
}

impl<T: AsRef<[u8]>> Frame<T> {
    /// Views `buffer` as a frame: header valid and the length its kind and count say.
    pub fn new_checked(buffer: T) -> Result<Frame<T>, FrameError> {
        let bytes = buffer.as_ref();
        let header = FrameHeader::parse(bytes)?;
        let count = header.count as usize;
        let want = match header.kind {
            FrameKind::Topology => {
                let nodes_at = HEADER_LEN + 12 * count;
                if bytes.len() < nodes_at + 4 {
                    nodes_at + 4
                } else {
                    topology_len(count, u32_at(bytes, nodes_at) as usize)
                }
            }
            FrameKind::Positions => HEADER_LEN + 12 * count,
            FrameKind::Tools => HEADER_LEN + 56 * count,
        };
        if bytes.len() != want {
            return Err(FrameError::Length {
                kind: header.kind,
                count: header.count,
                got: bytes.len(),
                want,
            });
        }
        Ok(Frame { buffer, header })
    }

    pub fn header(&self) -> FrameHeader {
        self.header
    }

    fn payload(&self) -> &[u8] {
        &self.buffer.as_ref()[HEADER_LEN..]
    }

    /// A TOPOLOGY frame's triangles, reference positions and body ids (None: another kind).
    pub fn topology(&self) -> Option<Topology> {
        if self.header.kind != FrameKind::Topology {
            return None;
        }
        let p = self.payload();
        let t = self.header.count as usize;
        let triangles = (0..t)
            .map(|k| std::array::from_fn(|i| u32_at(p, 12 * k + 4 * i)))
            .collect();
        let n = u32_at(p, 12 * t) as usize;
        let pos = 12 * t + 4;
        let reference_m = (0..n)
            .map(|k| std::array::from_fn(|i| f32_at(p, pos + 12 * k + 4 * i)))
            .collect();
        let body = (0..n).map(|k| u16_at(p, pos + 12 * n + 2 * k)).collect();
        Some(Topology {
            triangles,
            reference_m,
            body,
        })
    }

    /// A POSITIONS frame's `3n` coordinates (m) (None: another kind).
    pub fn positions(&self) -> Option<Vec<f32>> {
        (self.header.kind == FrameKind::Positions).then(|| {
            let p = self.payload();
            (0..3 * self.header.count as usize)
                .map(|k| f32_at(p, 4 * k))
                .collect()
        })
    }

    /// A TOOLS frame's poses, one per tool (None: another kind).
    pub fn tools(&self) -> Option<Vec<Pose>> {
        (self.header.kind == FrameKind::Tools).then(|| {
            let p = self.payload();
            (0..self.header.count as usize)
                .map(|k| {
                    let v = |i: usize| f64::from_le_bytes(array_at(p, 56 * k + 8 * i));
                    Pose {
                        q: std::array::from_fn(v),
                        p_m: std::array::from_fn(|i| v(4 + i)),
                    }
                })
                .collect()
        })
    }
}

/// A TOPOLOGY frame's length: the header, `triangles` × 3 u32, the u32 node count,
/// `nodes` × 3 f32 and `nodes` u16, padded to a multiple of 4.
fn topology_len(triangles: usize, nodes: usize) -> usize {
    (HEADER_LEN + 12 * triangles + 4 + 12 * nodes + 2 * nodes).next_multiple_of(4)
}

/// The TOPOLOGY frame of `surface`.
pub fn topology_frame(surface: &SurfaceInfo) -> Vec<u8> {
    let (t, n) = (surface.triangles.len(), surface.reference_m.len());
    let mut out = Vec::with_capacity(topology_len(t, n));
    FrameHeader {
        kind: FrameKind::Topology,
        seq: 0,
        count: t as u32,
        time_s: 0.0,
    }
    .emit(&mut out);
    for v in surface.triangles.iter().flatten() {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&(n as u32).to_le_bytes());
    for v in surface.reference_m.iter().flatten() {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for k in 0..n {
        let b = surface.body.get(k).copied().unwrap_or(0);
        out.extend_from_slice(&b.to_le_bytes());
    }
    out.resize(topology_len(t, n), 0);
    out
}

/// A POSITIONS frame: `positions_m` holds `3n` coordinates (m).
pub fn positions_frame(seq: u32, time_s: f64, positions_m: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + 4 * positions_m.len());
    FrameHeader {
        kind: FrameKind::Positions,
        seq,
        count: (positions_m.len() / 3) as u32,
        time_s,
    }
    .emit(&mut out);
    for v in &positions_m[..positions_m.len() / 3 * 3] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// A TOOLS frame: per tool 7 f64, `q` (w, x, y, z) then `p` (x, y, z, m).
pub fn tools_frame(seq: u32, time_s: f64, poses: &[Pose]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + 56 * poses.len());
    FrameHeader {
        kind: FrameKind::Tools,
        seq,
        count: poses.len() as u32,
        time_s,
    }
    .emit(&mut out);
    for p in poses {
        for v in p.q.iter().chain(&p.p_m) {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

fn array_at<const N: usize>(b: &[u8], at: usize) -> [u8; N] {
    let mut a = [0; N];
    if let Some(s) = b.get(at..at + N) {
        a.copy_from_slice(s);
    }
    a
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes(array_at(b, at))
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(array_at(b, at))
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(array_at(b, at))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_magic_reads_fsep_as_bytes() {
        let f = positions_frame(7, 0.25, &[1.0, 2.0, 3.0]);
        assert_eq!(&f[..4], b"FSEP");
        assert_eq!(f.len(), HEADER_LEN + 12);
        let v = Frame::new_checked(&f[..]).unwrap();
        assert_eq!(
            v.header(),
            FrameHeader {
                kind: FrameKind::Positions,
                seq: 7,
                count: 1,
                time_s: 0.25
            }
        );
        assert_eq!(v.positions().unwrap(), vec![1.0, 2.0, 3.0]);
        assert!(matches!(
            Frame::new_checked(&f[..f.len() - 1]),
            Err(FrameError::Length { .. })
        ));
    }

    /// Three nodes (odd: the u16 body ids need two bytes of padding) and one triangle.
    #[test]
    fn a_topology_frame_reads_back_as_written() {
        let s = SurfaceInfo {
            reference_m: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]],
            triangles: vec![[0, 1, 2]],
            body: vec![0, 1, 1],
            body_names: vec!["a".into(), "b".into()],
        };
        let f = topology_frame(&s);
        assert_eq!(f.len(), 24 + 12 + 4 + 36 + 6 + 2);
        let t = Frame::new_checked(&f).unwrap().topology().unwrap();
        assert_eq!(t.triangles, s.triangles);
        assert_eq!(t.reference_m, s.reference_m);
        assert_eq!(t.body, s.body);
    }

    #[test]
    fn a_tools_frame_reads_back_as_written() {
        let poses = [
            Pose::IDENTITY,
            Pose {
                q: [0.5, -0.5, 0.5, 0.5],
                p_m: [1e-3, -2e-3, 3e-3],
            },
        ];
        let f = tools_frame(3, 1.5, &poses);
        let v = Frame::new_checked(f).unwrap();
        assert_eq!(v.header().count, 2);
        assert_eq!(v.tools().unwrap(), poses);
        assert!(v.positions().is_none());
    }

    #[test]
    fn messages_are_tagged_by_type() {
        let m: ClientMessage = serde_json::from_str(
            r#"{"type":"pose","tool":"probe","position_m":[0,0,0.001],"orientation":[1,0,0,0]}"#,
        )
        .unwrap();
        assert!(matches!(m, ClientMessage::Pose { ref tool, .. } if tool == "probe"));
        let e = ServerMessage::Error {
            message: "x".into(),
        }
        .to_json();
        assert_eq!(e, r#"{"type":"error","message":"x"}"#);
        let d = ServerMessage::Driver {
            tool: "probe".into(),
            client: None,
        }
        .to_json();
        assert_eq!(d, r#"{"type":"driver","tool":"probe","client":null}"#);
    }
}
