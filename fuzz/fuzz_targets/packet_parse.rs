//! Packet parser: never panics; anything accepted re-emits to the same bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use link_proto::{Packet, PacketRepr, PACKET_LEN_MAX};

fuzz_target!(|data: &[u8]| {
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
});
