//! The board's port on the global network: packets to other boards, the host and the
//! graphics engine, with their statistics.

use link_proto::packet::packet_len;
use link_proto::{Links, Packet, PacketKind};

use super::{Fault, FaultKind, Runtime, WireReal};
use crate::image::ElementRecord;

/// Global-network statistics of one board (for reports).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct GlobalStats {
    pub packets_sent: u64,
    pub bytes_sent: u64,
    pub box_packets: u64,
    pub node_packets: u64,
    /// Contact-node displacement vectors sent.
    pub node_vectors: u64,
    pub graphics_packets: u64,
    pub graphics_bytes: u64,
    pub tool_packets: u64,
    /// Bounding-box checks done and the most candidates one found.
    pub checks: u64,
    pub candidates_max: u32,
    /// Partners at the last check.
    pub partners: u32,
}

/// This board's address, the next message id and the traffic so far.
pub(super) struct GlobalPort {
    pub address: u8,
    pub msg_id: u16,
    pub stats: GlobalStats,
}

impl<T: WireReal, E: ElementRecord<T>> Runtime<'_, T, E> {
    /// Sends the packet whose payload (`len` bytes) is already in `tx[PACKET_HEADER_LEN..]`
    /// (the packet is [`packet_len`]`(len)` bytes); `Ok(false)` if the port's queue is full.
    pub(super) fn send_global(
        &mut self,
        links: &mut impl Links,
        dst: u8,
        kind: PacketKind,
        len: usize,
    ) -> Result<bool, Fault> {
        let total = packet_len(len);
        let Some(buf) = self.st.tx.get_mut(..total) else {
            return Err(self.fault(FaultKind::GlobalSendFailed {
                dst,
                error: link_proto::SendError::TooLong,
            }));
        };
        let mut p = Packet::new_unchecked(buf);
        p.set_dst(dst);
        p.set_src(self.port.address);
        p.set_msg_id(self.port.msg_id);
        p.set_kind(kind);
        p.set_version(link_proto::packet::PACKET_VERSION);
        p.set_payload_len(len as u16);
        p.fill_crc();
        match links.try_send_global(&self.st.tx[..total]) {
            Ok(()) => {
                self.port.msg_id = self.port.msg_id.wrapping_add(1);
                self.port.stats.packets_sent += 1;
                self.port.stats.bytes_sent += total as u64;
                Ok(true)
            }
            Err(link_proto::SendError::WouldBlock) => Ok(false),
            Err(error) => Err(self.fault(FaultKind::GlobalSendFailed { dst, error })),
        }
    }
}
