//! What an observer of the traffic (the fault injector, a sink, a report) reads of a frame
//! or a packet without taking it apart, and how it names a global address.

use link_proto::packet::{ADDR_BROADCAST, ADDR_GRAPHICS, ADDR_HOST};
use link_proto::{Frame, Machine, Packet, PACKET_HEADER_LEN};

/// The step of a frame, or of the frame in a recovery envelope; None for a recovery
/// control envelope (ack, nack, status) or what is no frame.
pub fn frame_step(frame: &[u8]) -> Option<u32> {
    let f = link_proto::recovery::face::carried_frame(frame)?;
    Frame::new_checked(f).ok().map(|f| f.step())
}

/// The header of a global packet, perhaps damaged (its length field included), as a view
/// of the header alone: read its `dst`, `src`, `msg_id`, `kind`; None for bytes shorter than
/// a header. For observers: what a packet says it is before (or without) its checks.
pub fn packet_header(packet: &[u8]) -> Option<Packet<&[u8]>> {
    packet.get(..PACKET_HEADER_LEN).map(Packet::new_unchecked)
}

/// The step a global packet belongs to, read from its payload (boxes, contact nodes and
/// tool forces carry it first, surface chunks after their frame number: the layouts of
/// `link_proto::payload`); None for other kinds or too short a packet. Unchecked (the
/// packet may be damaged, its length field included): for observers.
pub fn packet_step(packet: &[u8]) -> Option<u32> {
    let kind = packet_header(packet)?.kind();
    // What follows the header, whatever its (perhaps damaged) length field says.
    link_proto::payload::step_of(kind, Packet::new_unchecked(packet).after_header())
}

/// How a global address is named in reports: `(x,y,z)`, `host`, `graphics`, `broadcast`.
pub fn address_name(addr: u8) -> String {
    match addr {
        ADDR_GRAPHICS => "graphics".into(),
        ADDR_HOST => "host".into(),
        ADDR_BROADCAST => "broadcast".into(),
        a => match Machine::from_address(a) {
            Some([x, y, z]) => format!("({x},{y},{z})"),
            None => format!("address {a}"),
        },
    }
}

/// The "face" an injected global fault is recorded on: `global to (x,y,z)`, `global to host`...
pub fn global_face(dst: u8) -> String {
    format!("global to {}", address_name(dst))
}

#[cfg(test)]
mod tests {
    use super::*;
    use link_proto::payload::ToolForcePayload;
    use link_proto::{emit_values, FrameKind, PacketKind, PacketRepr, Values};

    /// The step of a frame (bare or in a recovery data envelope) and of a tool-force packet
    /// is the one written into it; a damaged packet length still gives its step; a control
    /// envelope and a hello packet have none.
    #[test]
    fn observers_read_the_step_written() {
        let mut f = vec![0u8; link_proto::FRAME_LEN_MAX];
        let n = emit_values(
            FrameKind::Forces,
            0x0102_0304,
            Values::F64(&[1.5, -2.0]),
            &mut f,
        )
        .expect("frame");
        assert_eq!(frame_step(&f[..n]), Some(0x0102_0304));
        assert_eq!(
            frame_step(&[link_proto::recovery::face::code::ACK, 0, 0, 0]),
            None
        );
        let mut payload = [0u8; ToolForcePayload::LEN];
        ToolForcePayload {
            step: 77,
            tool: 1,
            force: [1.0, 2.0, 3.0],
        }
        .emit(&mut payload)
        .expect("payload");
        let r = PacketRepr {
            dst: ADDR_HOST,
            src: 5,
            msg_id: 0,
            kind: PacketKind::ToolForce,
            payload: &payload,
        };
        let mut p = vec![0u8; r.buffer_len()];
        r.emit(&mut p).expect("packet");
        assert_eq!(packet_step(&p), Some(77));
        p[7] ^= 0x40; // the length field: no longer a valid packet
        assert!(Packet::new_checked(&p[..]).is_err());
        assert_eq!(packet_step(&p), Some(77));
        let hello = PacketRepr {
            kind: PacketKind::Hello,
            payload: &[0; 8],
            ..r
        };
        let mut h = vec![0u8; hello.buffer_len()];
        hello.emit(&mut h).expect("packet");
        assert_eq!(packet_step(&h), None);
        assert_eq!(address_name(5), "(1,1,0)");
        assert_eq!(global_face(ADDR_HOST), "global to host");
    }
}
