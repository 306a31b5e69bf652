//! Packet parser: never panics; anything accepted re-emits to the same bytes.
//! Each input is tried as is and with a correct CRC in its last four bytes,
//! so the fuzzer reaches the code behind the CRC check.
#![no_main]

use libfuzzer_sys::fuzz_target;
use link_proto::frame::crc32;
use link_proto::{Packet, PacketRepr, PACKET_LEN_MAX};

fn check(data: &[u8]) {
    if let Ok(p) = Packet::new_checked(data) {
        let _ = (
            p.dst(),
            p.src(),
            p.msg_id(),
            p.kind(),
            p.version(),
            p.payload(),
            p.crc(),
        );
        let _ = p.verify_crc();
    }
    if let Ok(repr) = PacketRepr::parse_bytes(data) {
        let mut out = [0u8; PACKET_LEN_MAX];
        let n = repr.emit(&mut out).expect("a parsed packet re-emits");
        assert_eq!(&out[..n], data);
    }
}

fuzz_target!(|data: &[u8]| {
    check(data);
    if let Some(body_len) = data.len().checked_sub(4) {
        let mut fixed = data.to_vec();
        let crc = crc32(&fixed[..body_len]);
        fixed[body_len..].copy_from_slice(&crc.to_le_bytes());
        check(&fixed);
        assert!(PacketRepr::parse_bytes(&fixed) != Err(link_proto::Error::BadCrc));
    }
});
