//! COBS byte-stream framing: exact bytes, resynchronisation, damage reporting.

use link_proto::{
    emit_values, encode_wire, Error, FrameKind, FrameRepr, StreamDecoder, Values,
    FRAME_COBS_LEN_MAX, FRAME_LEN_MAX, FRAME_WIRE_LEN_MAX, VALUES_PER_FRAME_MAX,
};
use proptest::prelude::*;

type Decoder = StreamDecoder<FRAME_COBS_LEN_MAX>;

/// A link frame whose payload contains zero bytes (0.0 values), so COBS has
/// work to do; `step` identifies it.
fn frame(step: u32, n: usize) -> Vec<u8> {
    let vals: Vec<f32> = (0..n)
        .map(|i| {
            if i % 3 == 0 {
                0.0
            } else {
                step as f32 + i as f32 * 0.5
            }
        })
        .collect();
    let mut buf = vec![0u8; FRAME_LEN_MAX];
    let len = emit_values(FrameKind::Forces, step, Values::F32(&vals), &mut buf).unwrap();
    buf.truncate(len);
    buf
}

fn wire(frame: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8; FRAME_WIRE_LEN_MAX];
    let n = encode_wire(frame, &mut out).unwrap();
    out.truncate(n);
    out
}

/// Feeds a stream through a decoder the way firmware does (chunks via
/// `push`); returns the step numbers of the frames that parse, and the number
/// of damaged runs the decoder or the parser reported.
fn receive(dec: &mut Decoder, mut stream: &[u8]) -> (Vec<u32>, usize) {
    let mut steps = Vec::new();
    let mut damaged = 0;
    while !stream.is_empty() {
        let (used, event) = dec.push(stream);
        stream = &stream[used..];
        match event {
            None => {}
            Some(Ok(bytes)) => match FrameRepr::parse_bytes(bytes) {
                Ok(r) => steps.push(r.step),
                Err(_) => damaged += 1,
            },
            Some(Err(_)) => damaged += 1,
        }
    }
    (steps, damaged)
}

// Property: the wire form is exactly 0x00, COBS(frame), 0x00 (COBS example
// checked by hand: 11 00 22 -> 02 11 02 22).
#[test]
fn wire_byte_literal() {
    let mut out = [0u8; 16];
    let n = encode_wire(&[0x11, 0x00, 0x22], &mut out).unwrap();
    assert_eq!(&out[..n], &[0x00, 0x02, 0x11, 0x02, 0x22, 0x00]);
    let n = encode_wire(&[], &mut out).unwrap();
    assert_eq!(&out[..n], &[0x00, 0x01, 0x00]);
    assert_eq!(
        encode_wire(&[1, 2, 3], &mut out[..4]),
        Err(Error::BufferTooSmall)
    );
    let mut dec: StreamDecoder<16> = StreamDecoder::new();
    let (used, ev) = dec.push(&[0x00, 0x02, 0x11, 0x02, 0x22, 0x00, 0x00]);
    assert_eq!(used, 6, "push stops right after the frame's delimiter");
    assert_eq!(ev, Some(Ok(&[0x11, 0x00, 0x22][..])));
}

// Property: the compile-time bounds hold for the worst case (a maximal frame
// with no zero bytes, which has the largest COBS overhead): it encodes within
// FRAME_WIRE_LEN_MAX and decodes within a FRAME_COBS_LEN_MAX decoder.
#[test]
fn largest_frame_fits_the_bounds() {
    let vals = vec![f64::from_bits(0x0101_0101_0101_0101); VALUES_PER_FRAME_MAX];
    let mut buf = vec![0u8; FRAME_LEN_MAX];
    let n = emit_values(
        FrameKind::Displacements,
        0x0101_0101,
        Values::F64(&vals),
        &mut buf,
    )
    .unwrap();
    assert_eq!(n, FRAME_LEN_MAX);
    let w = wire(&buf);
    assert!(w.len() <= FRAME_WIRE_LEN_MAX);
    let mut dec = Box::new(Decoder::new());
    let (steps, damaged) = receive(&mut dec, &w);
    assert_eq!((steps, damaged), (vec![0x0101_0101], 0));
}

// Property: a clean stream of frames, idle delimiters between them, comes
// through complete and in order, whatever the chunking.
#[test]
fn clean_stream_in_any_chunking() {
    let mut stream = vec![0u8, 0, 0];
    for s in 0..5 {
        stream.extend(wire(&frame(s, 40)));
        stream.extend([0u8, 0]);
    }
    let mut dec = Box::new(Decoder::new());
    assert_eq!(receive(&mut dec, &stream), (vec![0, 1, 2, 3, 4], 0));
    for chunk in [1, 2, 7, 64] {
        let mut dec = Box::new(Decoder::new());
        let mut got = Vec::new();
        for c in stream.chunks(chunk) {
            let (s, d) = receive(&mut dec, c);
            assert_eq!(d, 0);
            got.extend(s);
        }
        assert_eq!(got, vec![0, 1, 2, 3, 4], "chunk size {chunk}");
    }
}

// Property: after each kind of damage the decoder resynchronises at the next
// delimiter and exactly the damaged frames are lost; none is altered.
// Exact expected set (not "at least"): the two-delimiter scheme makes the
// outcome deterministic for each damage placed here.
#[test]
fn damaged_stream_resynchronises_and_loses_only_damaged_frames() {
    let frames: Vec<Vec<u8>> = (0..11).map(|s| wire(&frame(s, 30 + s as usize))).collect();
    let mut stream = Vec::new();
    for (s, w) in frames.iter().enumerate() {
        let mut w = w.clone();
        let mid = w.len() / 2;
        match s {
            // Receiver joins late: the first 5 bytes of frame 0 are never seen.
            0 => {
                w.drain(..5);
            }
            // A body byte lost.
            2 => {
                w.remove(mid);
            }
            // The trailing delimiter lost: costs nothing, frame 4's leading one ends it.
            3 => {
                w.pop();
            }
            // A body byte turned into 0x00: the frame splits into two damaged runs.
            4 => w[mid] = 0,
            // Line noise between frames 4 and 5: a garbage run, reported, nothing lost.
            5 => {
                stream.extend([0x13, 0x37]);
            }
            // A body byte corrupted (kept non-zero).
            6 => {
                w[mid] = if w[mid] ^ 0x40 == 0 {
                    0x41
                } else {
                    w[mid] ^ 0x40
                }
            }
            // The leading delimiter corrupted: frame 7 lost, frame 6 unaffected.
            7 => w[0] = 0x05,
            // Frame 9's trailing delimiter is missing; frame 10's leading one delivers it.
            9 => {
                w.pop();
            }
            _ => {}
        }
        stream.extend(w);
    }
    let mut dec = Box::new(Decoder::new());
    let (steps, damaged) = receive(&mut dec, &stream);
    assert_eq!(steps, vec![1, 3, 5, 8, 9, 10]);
    // Damage reports: frame 0's tail, 2, both halves of 4, the noise run, 6, 7.
    assert_eq!(damaged, 7);
}

// Property: a run longer than the decoder's buffer (e.g. a lost-delimiter
// storm or babble) is reported as Oversized without panicking, and the next
// frame is received.
#[test]
fn oversized_run_is_reported_and_skipped() {
    let mut stream = vec![0u8];
    stream.extend(std::iter::repeat_n(0x42u8, FRAME_COBS_LEN_MAX + 100));
    stream.extend(wire(&frame(77, 10)));
    let mut dec = Box::new(Decoder::new());
    let (used, ev) = dec.push(&stream);
    assert_eq!(ev, Some(Err(Error::Oversized)));
    assert_eq!(receive(&mut dec, &stream[used..]), (vec![77], 0));
}

// Property: invalid COBS (a code byte pointing past the delimiter) is
// reported as BadEncoding.
#[test]
fn invalid_cobs_is_bad_encoding() {
    let mut dec: StreamDecoder<32> = StreamDecoder::new();
    assert_eq!(
        dec.push(&[0x00, 0x05, 0x01, 0x00]).1,
        Some(Err(Error::BadEncoding))
    );
    assert_eq!(dec.pending(), 0);
}

#[derive(Debug, Clone)]
enum Damage {
    Drop(usize),
    Corrupt(usize, u8),
    Insert(usize, u8),
}

fn damage_strategy() -> impl Strategy<Value = Damage> {
    prop_oneof![
        any::<usize>().prop_map(Damage::Drop),
        (any::<usize>(), 1..=255u8).prop_map(|(p, x)| Damage::Corrupt(p, x)),
        (any::<usize>(), any::<u8>()).prop_map(|(p, b)| Damage::Insert(p, b)),
    ]
}

proptest! {
    // Property: one random damage (drop, corrupt, insert) anywhere in a
    // stream of frames loses at most the one frame whose wire span (its two
    // delimiters included) holds the damage, and never delivers an altered
    // frame. Tolerance: a damaged frame may still survive (e.g. a dropped
    // delimiter), so the check is "all others survive, in order", not
    // "the damaged one is lost". CRC collisions (2^-32) are ignored.
    #[test]
    fn single_damage_loses_at_most_one_frame(sizes in prop::collection::vec(0usize..120, 2..8),
                                             damage in damage_strategy()) {
        let wires: Vec<Vec<u8>> = sizes.iter().enumerate()
            .map(|(s, &n)| wire(&frame(s as u32, n))).collect();
        let mut stream: Vec<u8> = wires.concat();
        let owner = |pos: usize| {
            let mut start = 0;
            for (i, w) in wires.iter().enumerate() {
                if pos < start + w.len() { return i; }
                start += w.len();
            }
            wires.len() - 1
        };
        let hit = match damage {
            Damage::Drop(p) => { let p = p % stream.len(); stream.remove(p); owner(p) }
            Damage::Corrupt(p, x) => { let p = p % stream.len(); stream[p] ^= x; owner(p) }
            Damage::Insert(p, b) => { let p = p % stream.len(); stream.insert(p, b); owner(p) }
        };
        let mut dec = Box::new(Decoder::new());
        let (steps, _) = receive(&mut dec, &stream);
        let mut expected: Vec<u32> = (0..wires.len() as u32).collect();
        if !steps.contains(&(hit as u32)) {
            expected.retain(|&s| s != hit as u32);
        }
        prop_assert_eq!(steps, expected);
    }

    // Property: arbitrary bytes never panic the decoder, and whatever it
    // yields is at most the decoder's capacity.
    #[test]
    fn garbage_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..2000)) {
        let mut dec: StreamDecoder<64> = StreamDecoder::new();
        let mut rest = &bytes[..];
        while !rest.is_empty() {
            let (used, ev) = dec.push(rest);
            prop_assert!(used >= 1);
            if let Some(Ok(f)) = ev { prop_assert!(f.len() <= 64); }
            rest = &rest[used..];
        }
    }
}

// Property: an empty frame survives the wire as an empty frame (not as idle).
#[test]
fn empty_frame_is_delivered() {
    let mut out = [0u8; 4];
    let n = encode_wire(&[], &mut out).unwrap();
    let mut dec: StreamDecoder<8> = StreamDecoder::new();
    assert_eq!(dec.push(&out[..n]).1, Some(Ok(&[][..])));
}
