//! COBS stream decoder: never panics on any byte stream; each yielded frame
//! fits the buffer and re-encodes to a run that decodes to itself; every
//! frame parses or is rejected without panicking. The first input byte sets
//! the chunk size, to exercise `push` across arbitrary splits.
#![no_main]

use libfuzzer_sys::fuzz_target;
use link_proto::{cobs_len_max, encode_wire, FrameRepr, StreamDecoder, FRAME_COBS_LEN_MAX};

fuzz_target!(|data: &[u8]| {
    let Some((&chunk, data)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(chunk).max(1);
    let mut dec: Box<StreamDecoder<FRAME_COBS_LEN_MAX>> = Box::default();
    let mut small: StreamDecoder<16> = StreamDecoder::new();
    let mut wire = vec![0u8; cobs_len_max(FRAME_COBS_LEN_MAX) + 2];
    for piece in data.chunks(chunk) {
        let mut rest = piece;
        while !rest.is_empty() {
            let (used, ev) = dec.push(rest);
            assert!(used >= 1 && used <= rest.len());
            rest = &rest[used..];
            if let Some(Ok(frame)) = ev {
                assert!(frame.len() <= FRAME_COBS_LEN_MAX);
                let _ = FrameRepr::parse_bytes(frame);
                // Re-encode and decode again: must give the same frame.
                let frame = frame.to_vec();
                let n = encode_wire(&frame, &mut wire).expect("fits");
                let mut again: Box<StreamDecoder<FRAME_COBS_LEN_MAX>> = Box::default();
                let (_, ev2) = again.push(&wire[..n]);
                assert_eq!(ev2, Some(Ok(&frame[..])));
            }
        }
        for &b in piece {
            if let Some(Ok(f)) = small.feed(b) {
                assert!(f.len() <= 16);
            }
        }
    }
});
