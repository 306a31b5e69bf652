//! Frame parser: never panics; anything accepted re-emits to the same bytes
//! and its accessors agree with the repr. Each input is tried twice: as is
//! (almost always rejected by the CRC), and with its last four bytes replaced
//! by the correct CRC, so the fuzzer reaches the code behind the CRC check.
#![no_main]

use libfuzzer_sys::fuzz_target;
use link_proto::frame::crc32;
use link_proto::{Frame, FrameRepr, FRAME_LEN_MAX};

fn check(data: &[u8]) {
    if let Ok(frame) = Frame::new_checked(data) {
        // Accessors are safe after new_checked, whatever the CRC.
        let _ = (frame.kind(), frame.step(), frame.value_count(), frame.crc());
        let _ = frame.verify_crc();
        if let Ok(values) = frame.values() {
            let _ = values.iter().count();
        }
    }
    if let Ok(repr) = FrameRepr::parse_bytes(data) {
        let mut out = [0u8; FRAME_LEN_MAX];
        let n = repr.emit(&mut out).expect("a parsed frame re-emits");
        assert_eq!(&out[..n], data);
        assert_eq!(repr.payload.iter().count(), repr.payload.len());
        for i in 0..repr.payload.len() {
            assert!(repr.payload.get(i).is_some());
        }
    }
}

fuzz_target!(|data: &[u8]| {
    check(data);
    if let Some(body_len) = data.len().checked_sub(4) {
        let mut fixed = data.to_vec();
        let crc = crc32(&fixed[..body_len]);
        fixed[body_len..].copy_from_slice(&crc.to_le_bytes());
        check(&fixed);
        assert!(FrameRepr::parse_bytes(&fixed) != Err(link_proto::Error::BadCrc));
    }
});
