//! The emulated global network: one inbox per board address, and the two sinks (the
//! graphics engine and the host) that keep what they receive for the run's outputs, with
//! the receiving end of global recovery when it is on.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use link_proto::packet::{ADDR_BROADCAST, ADDR_GRAPHICS, ADDR_HOST};
use link_proto::recovery::global::FlowRx;
use link_proto::recovery::GlobalRecovery;
use link_proto::{PacketRepr, SendError};

use super::channel::Channel;
use super::observe::{packet_header, packet_step};

/// Packets a board's inbox holds before senders see `WouldBlock`.
pub const GLOBAL_QUEUE_PACKETS: usize = 4096;

/// The emulated global network and its sinks.
pub struct GlobalNet {
    /// Inbox per global address ([`link_proto::Machine::address`]), with the board's doorbell.
    inboxes: Vec<Option<Arc<Channel>>>,
    /// The packets the graphics engine took (unwrapped, in order per board, once each).
    pub graphics: Mutex<Vec<Vec<u8>>>,
    /// The packets the host took.
    pub host: Mutex<Vec<Vec<u8>>>,
    /// The sinks run the receiving end of global recovery (`link_proto::recovery::global`):
    /// they take envelopes, acknowledge them into the sender's inbox, drop duplicates and
    /// deliver each board's flow in order.
    sink_recovery: bool,
    /// Per (sink, source) flow: the receiver's state.
    sink_flows: Mutex<HashMap<(u8, u8), FlowRx>>,
    /// What the sinks' recovery cost (acks and nacks sent, damaged, duplicates, gaps).
    pub sink_stats: Mutex<GlobalRecovery>,
    /// Packets the sinks received damaged, without recovery (each stops the run).
    pub sink_faults: Mutex<Vec<SinkFault>>,
}

/// A damaged packet a sink received (without recovery): the sink, the source address the
/// packet names (perhaps damaged itself) and the step in its payload if readable.
#[derive(Clone, Debug, PartialEq)]
pub struct SinkFault {
    pub sink: u8,
    pub src: u8,
    pub step: Option<u32>,
    pub error: link_proto::Error,
}

impl GlobalNet {
    /// A network of these inboxes (by address) and the two sinks.
    pub(crate) fn new(inboxes: Vec<Option<Arc<Channel>>>, sink_recovery: bool) -> GlobalNet {
        GlobalNet {
            inboxes,
            graphics: Mutex::new(Vec::new()),
            host: Mutex::new(Vec::new()),
            sink_recovery,
            sink_flows: Mutex::new(Default::default()),
            sink_stats: Mutex::new(Default::default()),
            sink_faults: Mutex::new(Vec::new()),
        }
    }

    /// A network of only the graphics and host sinks (no board inboxes, no recovery): what
    /// an emulated array's host keeps; packets between boards are routed by the caller.
    pub fn sinks() -> Arc<GlobalNet> {
        Arc::new(GlobalNet::new(vec![None; link_proto::BOARD_COUNT], false))
    }

    /// The inbox of the board at global address `addr`.
    pub(crate) fn inbox(&self, addr: u8) -> Option<&Arc<Channel>> {
        self.inboxes.get(addr as usize)?.as_ref()
    }

    /// Routes what board `src` sent, a packet or (with recovery) its envelope, on the
    /// destination, as a switch would: the envelope
    /// (`link_proto::recovery::global`) keeps the destination where a packet has it.
    pub(crate) fn send(&self, src: u8, bytes: &[u8]) -> Result<(), SendError> {
        let dst = link_proto::recovery::global::destination(bytes).ok_or(SendError::TooLong)?;
        self.deliver(dst, src, bytes)
    }

    /// Routes a packet from `src` to `dst` (a board's inbox, a sink, or every other board).
    pub(crate) fn deliver(&self, dst: u8, src: u8, packet: &[u8]) -> Result<(), SendError> {
        match dst {
            ADDR_GRAPHICS => self.sink(ADDR_GRAPHICS, &self.graphics, packet),
            ADDR_HOST => self.sink(ADDR_HOST, &self.host, packet),
            ADDR_BROADCAST => {
                for (a, ch) in self.inboxes.iter().enumerate() {
                    if a != src as usize {
                        if let Some(ch) = ch {
                            ch.push(packet, GLOBAL_QUEUE_PACKETS)?;
                        }
                    }
                }
                Ok(())
            }
            d => match self.inbox(d) {
                Some(ch) => ch.push(packet, GLOBAL_QUEUE_PACKETS),
                None => Err(SendError::NoLink),
            },
        }
    }

    /// A packet (or envelope, with recovery) arrives at sink `addr`, which keeps `m`.
    fn sink(&self, addr: u8, m: &Mutex<Vec<Vec<u8>>>, bytes: &[u8]) -> Result<(), SendError> {
        if self.sink_recovery {
            self.sink_envelope(addr, m, bytes)
        } else {
            self.sink_packet(addr, m, bytes)
        }
    }

    /// Without recovery: a packet is kept; a damaged one is dropped and reported (the run
    /// stops on it).
    fn sink_packet(
        &self,
        addr: u8,
        m: &Mutex<Vec<Vec<u8>>>,
        bytes: &[u8],
    ) -> Result<(), SendError> {
        match PacketRepr::parse_bytes(bytes) {
            Ok(_) => keep(m, bytes),
            Err(error) => {
                // The source the (perhaps damaged) header names.
                let src = packet_header(bytes).map_or(u8::MAX, |h| h.src());
                if let Ok(mut f) = self.sink_faults.lock() {
                    f.push(SinkFault {
                        sink: addr,
                        src,
                        step: packet_step(bytes),
                        error,
                    });
                }
                Ok(())
            }
        }
    }

    /// With recovery: an envelope is checked, its packet delivered in its flow's order, and
    /// acknowledged (or a gap answered with a nack) into the sender's inbox.
    fn sink_envelope(
        &self,
        addr: u8,
        m: &Mutex<Vec<Vec<u8>>>,
        bytes: &[u8],
    ) -> Result<(), SendError> {
        use link_proto::recovery::global::{code, control, parse, Envelope, Verdict};
        use link_proto::recovery::OVERHEAD;
        let mut st = self.sink_stats.lock().map_err(|_| SendError::NoLink)?;
        let (src, seq, packet) = match parse(bytes) {
            Envelope::Data { src, seq, packet } => (src, seq, packet),
            // A sink sends no data: nothing to acknowledge.
            Envelope::Ack { .. } | Envelope::Nack { .. } => return Ok(()),
            Envelope::Damaged => {
                st.damaged += 1;
                return Ok(());
            }
        };
        let mut flows = self.sink_flows.lock().map_err(|_| SendError::NoLink)?;
        let flow = flows.entry((addr, src)).or_insert_with(|| {
            st.peers += 1;
            Default::default()
        });
        let kind = match flow.take(seq) {
            Verdict::Deliver => {
                keep(m, packet)?;
                code::ACK
            }
            Verdict::Duplicate => {
                st.duplicates += 1;
                code::ACK
            }
            Verdict::Gap { nack } => {
                st.gaps += 1;
                if !nack {
                    return Ok(());
                }
                code::NACK
            }
        };
        let reply = control(src, addr, kind, flow.expected());
        drop(flows);
        if let Some(ch) = self.inbox(src) {
            if ch.push(&reply, GLOBAL_QUEUE_PACKETS).is_ok() {
                st.control_bytes += OVERHEAD as u64;
                if kind == code::ACK {
                    st.acks_sent += 1;
                } else {
                    st.nacks_sent += 1;
                }
            }
        }
        Ok(())
    }
}

/// A sink keeps packet `p`.
fn keep(m: &Mutex<Vec<Vec<u8>>>, p: &[u8]) -> Result<(), SendError> {
    m.lock()
        .map(|mut v| v.push(p.to_vec()))
        .map_err(|_| SendError::NoLink)
}
