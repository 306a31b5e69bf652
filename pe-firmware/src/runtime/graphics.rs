//! The graphics stream: on the first `spread` steps of every graphics interval, one slice
//! of the board's owned surface nodes (displacements as f32) to the graphics engine.

use link_proto::packet::packet_len;
use link_proto::payload::{emit_surface_entry, SurfaceHeader, SURFACE_NODES_PER_PACKET_MAX};
use link_proto::{Links, PacketKind, PACKET_HEADER_LEN};

use super::{Fault, FaultKind, Runtime, WireReal};
use crate::image::ElementRecord;

impl<T: WireReal, E: ElementRecord<T>> Runtime<'_, T, E> {
    /// The graphics operation; `Ok(false)` while the port's queue is full.
    pub(super) fn graphics_poll(&mut self, links: &mut impl Links) -> Result<bool, Fault> {
        // A build without graphics loads no image that streams (its program has no
        // graphics operation): nothing below is in it.
        if !cfg!(feature = "graphics") {
            return Ok(true);
        }
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
            let payload = &mut self.st.tx[PACKET_HEADER_LEN..];
            let mut ok = h.emit(payload).map(|l| plen = l);
            for e in 0..count {
                let l = self.st.contact.graphics[from + e] as usize;
                let u = self.st.u[l].map(|v| v.to_f64() as f32);
                let global = self.st.nodes[l].global;
                ok = ok.and(emit_surface_entry(payload, e, global, u));
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
            self.port.stats.graphics_packets += 1;
            self.port.stats.graphics_bytes += packet_len(plen) as u64;
            self.graphics_cursor += count.max(1);
            if start == end {
                break;
            }
        }
        self.graphics_cursor = 0;
        Ok(true)
    }
}
