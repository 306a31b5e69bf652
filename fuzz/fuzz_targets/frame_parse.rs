//! Frame parser: never panics; anything accepted re-emits to the same bytes
//! and its accessors agree with the repr.
#![no_main]

use libfuzzer_sys::fuzz_target;
use link_proto::{Frame, FrameRepr, FRAME_LEN_MAX};

fuzz_target!(|data: &[u8]| {
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
    }
});
