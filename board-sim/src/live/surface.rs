//! The live graphics engine: the boards' surface chunks (the images' graphics stream, one
//! frame every graphics interval of simulated time, spread over its first steps) assembled
//! into the surface nodes' positions, in the order the session's [`SurfaceInfo`] declares.

use std::collections::BTreeMap;

use anyhow::{anyhow, bail, Result};
use host_tools::live::engine::SurfaceInfo;
use link_proto::payload::{surface_entry, SurfaceHeader};
use link_proto::{PacketKind, PacketRepr};

/// Frames being assembled and the latest complete one.
pub struct SurfaceStream {
    /// Surface index of each mesh node (`u32::MAX`: not on the surface).
    index: Vec<u32>,
    /// Reference positions (m), `3n` values.
    reference: Vec<f32>,
    /// Frame number → (surface nodes received, positions `3n`).
    pending: BTreeMap<u32, (usize, Vec<f32>)>,
    /// The latest complete frame's positions (m): the reference until the first.
    latest: Vec<f32>,
    /// Number of the latest complete frame.
    pub frame: Option<u32>,
}

impl SurfaceStream {
    /// For `surface`, whose node `k` is mesh node `mesh_nodes[k]`, of `n_nodes` mesh nodes.
    pub fn new(surface: &SurfaceInfo, mesh_nodes: &[u32], n_nodes: usize) -> SurfaceStream {
        let mut index = vec![u32::MAX; n_nodes];
        for (k, &n) in mesh_nodes.iter().enumerate() {
            if let Some(slot) = index.get_mut(n as usize) {
                *slot = k as u32;
            }
        }
        let reference: Vec<f32> = surface.reference_m.iter().flatten().copied().collect();
        SurfaceStream {
            index,
            latest: reference.clone(),
            reference,
            pending: BTreeMap::new(),
            frame: None,
        }
    }

    /// The latest complete frame's positions (m), `3n` values.
    pub fn latest(&self) -> &[f32] {
        &self.latest
    }

    /// Files the graphics sink's `packets`; a frame whose every surface node has come
    /// becomes the latest (older incomplete ones are dropped).
    pub fn file(&mut self, packets: &[Vec<u8>]) -> Result<()> {
        let n = self.reference.len() / 3;
        for p in packets {
            let r = PacketRepr::parse_bytes(p)
                .map_err(|e| anyhow!("graphics engine: bad packet: {e}"))?;
            if r.kind != PacketKind::GraphicsSurface {
                bail!(
                    "graphics engine: unexpected packet {:?} from address {}",
                    r.kind,
                    r.src
                );
            }
            let h = SurfaceHeader::parse(r.payload)
                .map_err(|e| anyhow!("graphics engine: bad surface payload from {}: {e}", r.src))?;
            if self.frame.is_some_and(|f| h.frame <= f) {
                continue;
            }
            let reference = &self.reference;
            let (got, x) = self
                .pending
                .entry(h.frame)
                .or_insert_with(|| (0, reference.clone()));
            for k in 0..h.count as usize {
                let (node, u) = surface_entry(r.payload, k).map_err(|e| {
                    anyhow!("graphics engine: bad surface entry from {}: {e}", r.src)
                })?;
                let s = match self.index.get(node as usize) {
                    Some(&s) if s != u32::MAX => s as usize,
                    _ => bail!(
                        "graphics engine: address {} sent node {node}, not a surface node",
                        r.src
                    ),
                };
                for i in 0..3 {
                    x[3 * s + i] = self.reference[3 * s + i] + u[i];
                }
                *got += 1;
            }
            if *got >= n {
                if let Some((_, x)) = self.pending.remove(&h.frame) {
                    self.latest = x;
                }
                self.frame = Some(h.frame);
                self.pending.retain(|&f, _| f > h.frame);
            }
        }
        Ok(())
    }
}
