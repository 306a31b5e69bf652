//! Link frame format: exact bytes, round trips, corruption and malformed input.

use link_proto::{
    emit_values, Error, Frame, FrameKind, FrameRepr, Payload, Precision, Values, FRAME_HEADER_LEN,
    FRAME_LEN_MAX, FRAME_LEN_MIN, VALUES_PER_FRAME_MAX,
};
use proptest::prelude::*;

mod common;

/// Forces, f32, step 0x01020304, values [1.0, -2.5]. The CRC was computed
/// independently (Python `zlib.crc32`, the same CRC-32/ISO-HDLC).
const F32_FRAME: [u8; 20] = [
    0x02, 0x04, 0x02, 0x00, 0x04, 0x03, 0x02, 0x01, // kind, precision, count, step
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x20, 0xc0, // 1.0f32, -2.5f32
    0x65, 0x8b, 0x42, 0xba, // CRC 0xba428b65
];

/// Displacements, f64, step 7, value [0.1]; CRC from `zlib.crc32`.
const F64_FRAME: [u8; 20] = [
    0x01, 0x08, 0x01, 0x00, 0x07, 0x00, 0x00, 0x00, //
    0x9a, 0x99, 0x99, 0x99, 0x99, 0x99, 0xb9, 0x3f, // 0.1f64
    0x1b, 0x92, 0x49, 0xf7,
];

/// Barrier, f64, step u32::MAX, no values; CRC from `zlib.crc32`.
const EMPTY_FRAME: [u8; 12] = [
    0x03, 0x08, 0x00, 0x00, 0xff, 0xff, 0xff, 0xff, 0x0e, 0xb6, 0xf9, 0x06,
];

// Property: emitting native values produces exactly the documented layout
// (field order, endianness, CRC polynomial). Exact comparison: any byte off
// is a wire incompatibility.
#[test]
fn emit_matches_byte_literals() {
    let mut buf = [0u8; 64];
    let n = emit_values(
        FrameKind::Forces,
        0x0102_0304,
        Values::F32(&[1.0, -2.5]),
        &mut buf,
    )
    .unwrap();
    assert_eq!(&buf[..n], &F32_FRAME);

    let n = emit_values(FrameKind::Displacements, 7, Values::F64(&[0.1]), &mut buf).unwrap();
    assert_eq!(&buf[..n], &F64_FRAME);

    let n = emit_values(FrameKind::Barrier, u32::MAX, Values::F64(&[]), &mut buf).unwrap();
    assert_eq!(&buf[..n], &EMPTY_FRAME);
}

// Property: FrameRepr::emit (from parsed bytes) writes the same bytes as the
// native emitter, so relaying a parsed frame is byte-exact.
#[test]
fn repr_emit_matches_byte_literals() {
    for lit in [&F32_FRAME[..], &F64_FRAME[..], &EMPTY_FRAME[..]] {
        let repr = FrameRepr::parse_bytes(lit).unwrap();
        let mut buf = [0u8; 64];
        let n = repr.emit(&mut buf).unwrap();
        assert_eq!(&buf[..n], lit);
        assert_eq!(repr.buffer_len(), lit.len());
    }
}

// Property: parsing the known bytes yields the known fields and values. The
// values compare exactly: f32 -> f64 widening is exact.
#[test]
fn parse_byte_literals() {
    let f = Frame::new_checked(&F32_FRAME[..]).unwrap();
    assert_eq!(f.kind(), FrameKind::Forces);
    assert_eq!(f.precision(), Ok(Precision::F32));
    assert_eq!(f.value_count(), 2);
    assert_eq!(f.step(), 0x0102_0304);
    assert_eq!(f.crc(), 0xba42_8b65);
    assert!(f.verify_crc());
    let repr = FrameRepr::parse(&f).unwrap();
    assert_eq!(repr.kind, FrameKind::Forces);
    assert_eq!(repr.step, 0x0102_0304);
    assert_eq!(repr.payload.len(), 2);
    assert_eq!(repr.payload.iter().collect::<Vec<_>>(), vec![1.0, -2.5]);
    let mut out = [0f32; 4];
    assert_eq!(repr.payload.copy_to_f32(&mut out), 2);
    assert_eq!(out[..2], [1.0, -2.5]);

    let repr = FrameRepr::parse_bytes(&F64_FRAME).unwrap();
    assert_eq!(repr.kind, FrameKind::Displacements);
    assert_eq!(repr.step, 7);
    assert_eq!(repr.payload.get(0), Some(0.1));
    assert_eq!(repr.payload.get(1), None);

    let repr = FrameRepr::parse_bytes(&EMPTY_FRAME).unwrap();
    assert_eq!(repr.kind, FrameKind::Barrier);
    assert!(repr.payload.is_empty());
}

// Property: an unknown kind code is not an error; it parses as Unknown(code)
// and re-emits unchanged, so newer firmware can add kinds.
#[test]
fn unknown_kind_parses_as_unknown() {
    let mut buf = [0u8; 32];
    let n = emit_values(FrameKind::Unknown(0x7e), 1, Values::F32(&[3.0]), &mut buf).unwrap();
    assert_eq!(buf[0], 0x7e);
    let repr = FrameRepr::parse_bytes(&buf[..n]).unwrap();
    assert_eq!(repr.kind, FrameKind::Unknown(0x7e));
    for code in 0..=255u8 {
        assert_eq!(FrameKind::from_code(code).code(), code);
    }
}

// Property: lengths shorter than announced are Truncated, longer are
// BadLength, counts over the maximum are Oversized, bad precision codes are
// UnknownPrecision, a wrong CRC is BadCrc. Exact error values: the firmware's
// fault counters depend on them.
#[test]
fn malformed_frames_are_rejected_with_the_right_error() {
    // Every proper prefix of a valid frame is truncated.
    for cut in 0..F32_FRAME.len() {
        assert_eq!(
            FrameRepr::parse_bytes(&F32_FRAME[..cut]),
            Err(Error::Truncated),
            "cut {cut}"
        );
    }
    // A trailing byte.
    let mut long = F32_FRAME.to_vec();
    long.push(0);
    assert_eq!(FrameRepr::parse_bytes(&long), Err(Error::BadLength));
    // Count one past the maximum (header alone decides).
    let mut hdr = F32_FRAME.to_vec();
    hdr[2..4].copy_from_slice(&((VALUES_PER_FRAME_MAX + 1) as u16).to_le_bytes());
    assert_eq!(FrameRepr::parse_bytes(&hdr), Err(Error::Oversized));
    // A buffer larger than any frame.
    let huge = vec![0u8; FRAME_LEN_MAX + 1];
    assert_eq!(FrameRepr::parse_bytes(&huge), Err(Error::Oversized));
    // Unknown precision.
    let mut p = F32_FRAME.to_vec();
    p[1] = 2;
    assert_eq!(FrameRepr::parse_bytes(&p), Err(Error::UnknownPrecision(2)));
    // Bad CRC.
    let mut c = F32_FRAME.to_vec();
    c[19] ^= 0x80;
    assert_eq!(FrameRepr::parse_bytes(&c), Err(Error::BadCrc));
    // Empty input.
    assert_eq!(FrameRepr::parse_bytes(&[]), Err(Error::Truncated));
}

// Property: emitting refuses what cannot be represented or does not fit,
// without panicking: too many values -> Oversized, short buffer -> BufferTooSmall.
#[test]
fn emit_rejects_oversized_and_short_buffers() {
    let too_many = vec![0f32; VALUES_PER_FRAME_MAX + 1];
    let mut buf = vec![0u8; FRAME_LEN_MAX * 2];
    assert_eq!(
        emit_values(FrameKind::Forces, 0, Values::F32(&too_many), &mut buf),
        Err(Error::Oversized)
    );
    let max = vec![1.5f64; VALUES_PER_FRAME_MAX];
    let n = emit_values(FrameKind::Forces, 0, Values::F64(&max), &mut buf).unwrap();
    assert_eq!(
        n, FRAME_LEN_MAX,
        "the largest frame is exactly FRAME_LEN_MAX"
    );
    assert!(FrameRepr::parse_bytes(&buf[..n]).is_ok());
    let mut short = [0u8; FRAME_LEN_MIN + 3];
    assert_eq!(
        emit_values(FrameKind::Forces, 0, Values::F32(&[1.0]), &mut short),
        Err(Error::BufferTooSmall)
    );
    let repr = FrameRepr::parse_bytes(&F32_FRAME).unwrap();
    assert_eq!(repr.emit(&mut [0u8; 19]), Err(Error::BufferTooSmall));
    assert_eq!(
        Payload::new(Precision::F64, &[0u8; 12]),
        Err(Error::BadLength),
        "payload bytes must be whole values"
    );
}

fn assert_every_bit_flip_detected(frame: &[u8]) {
    let mut buf = frame.to_vec();
    for bit in 0..frame.len() * 8 {
        buf[bit / 8] ^= 1 << (bit % 8);
        assert!(
            FrameRepr::parse_bytes(&buf).is_err(),
            "flip of bit {bit} not detected"
        );
        buf[bit / 8] ^= 1 << (bit % 8);
    }
    assert!(FrameRepr::parse_bytes(&buf).is_ok());
}

// Property: every single-bit error anywhere (header, payload, CRC) is
// rejected. Exhaustive over all bits; CRC-32 detects all single-bit errors by
// construction, and header flips are caught by the length checks or the CRC,
// so zero tolerance.
#[test]
fn every_single_bit_flip_is_detected() {
    assert_every_bit_flip_detected(&F32_FRAME);
    assert_every_bit_flip_detected(&F64_FRAME);
    assert_every_bit_flip_detected(&EMPTY_FRAME);
    let mut buf = vec![0u8; FRAME_LEN_MAX];
    let vals: Vec<f64> = (0..300).map(|i| i as f64 * 0.37 - 20.0).collect();
    let n = emit_values(
        FrameKind::Displacements,
        123_456,
        Values::F64(&vals),
        &mut buf,
    )
    .unwrap();
    assert_every_bit_flip_detected(&buf[..n]);
    let vals: Vec<f32> = (0..VALUES_PER_FRAME_MAX)
        .map(|i| i as f32 * -1.25)
        .collect();
    let n = emit_values(FrameKind::Forces, 9, Values::F32(&vals), &mut buf).unwrap();
    assert_every_bit_flip_detected(&buf[..n]);
}

fn kind_strategy() -> impl Strategy<Value = FrameKind> {
    any::<u8>().prop_map(FrameKind::from_code)
}

proptest! {
    // Property: parse(emit(native values)) gives back kind, step and every
    // value bit for bit (NaN payloads and signed zeros included, compared via
    // to_bits): the link must not alter a single value.
    #[test]
    fn roundtrip_native_f32(kind in kind_strategy(), step: u32,
                            bits in prop::collection::vec(any::<u32>(), 0..200)) {
        let vals: Vec<f32> = bits.iter().map(|&b| f32::from_bits(b)).collect();
        let mut buf = vec![0u8; FRAME_LEN_MAX];
        let n = emit_values(kind, step, Values::F32(&vals), &mut buf).unwrap();
        prop_assert_eq!(n, FRAME_HEADER_LEN + 4 * vals.len() + 4);
        let repr = FrameRepr::parse_bytes(&buf[..n]).unwrap();
        prop_assert_eq!(repr.kind, kind);
        prop_assert_eq!(repr.step, step);
        prop_assert_eq!(repr.payload.precision(), Precision::F32);
        let back: Vec<u32> = repr.payload.as_bytes().chunks(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect();
        prop_assert_eq!(back, bits);
    }

    // Same for f64, and through the typed accessor (get) as well.
    #[test]
    fn roundtrip_native_f64(kind in kind_strategy(), step: u32,
                            bits in prop::collection::vec(any::<u64>(), 0..200)) {
        let vals: Vec<f64> = bits.iter().map(|&b| f64::from_bits(b)).collect();
        let mut buf = vec![0u8; FRAME_LEN_MAX];
        let n = emit_values(kind, step, Values::F64(&vals), &mut buf).unwrap();
        let repr = FrameRepr::parse_bytes(&buf[..n]).unwrap();
        prop_assert_eq!(repr.kind, kind);
        prop_assert_eq!(repr.step, step);
        for (i, b) in bits.iter().enumerate() {
            prop_assert_eq!(repr.payload.get(i).unwrap().to_bits(), *b);
        }
    }

    // Property: parse(emit(repr)) == repr for any representable repr
    // (equality is bitwise on the payload).
    #[test]
    fn roundtrip_repr(kind in kind_strategy(), step: u32, f64p: bool,
                      raw in prop::collection::vec(any::<u8>(), 0..800)) {
        let precision = if f64p { Precision::F64 } else { Precision::F32 };
        let whole = raw.len() / precision.width() * precision.width();
        let repr = FrameRepr { kind, step, payload: Payload::new(precision, &raw[..whole]).unwrap() };
        let mut buf = vec![0u8; FRAME_LEN_MAX];
        let n = repr.emit(&mut buf).unwrap();
        prop_assert_eq!(FrameRepr::parse_bytes(&buf[..n]), Ok(repr));
    }

    // Property: arbitrary bytes never panic the parser and are (almost
    // surely) rejected; if accepted, re-emitting reproduces them exactly,
    // so nothing is silently reinterpreted. Random bytes never pass the CRC,
    // so `garbage_with_its_crc_reaches_the_re_emit` below also runs them with a
    // correct CRC and counts what is accepted.
    #[test]
    fn garbage_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        if let Ok(repr) = FrameRepr::parse_bytes(&bytes) {
            let mut buf = vec![0u8; FRAME_LEN_MAX];
            let n = repr.emit(&mut buf).unwrap();
            prop_assert_eq!(&buf[..n], &bytes[..]);
        }
    }
}

/// Mutated frames with a correct CRC (bit flips and truncations of the three documented
/// frames, the CRC recomputed): every one the parser accepts re-emits to its own bytes,
/// and both outcomes occur, so the re-emit check runs (on random bytes alone it never
/// did: none passes the CRC).
#[test]
fn garbage_with_its_crc_reaches_the_re_emit() {
    let (accepted, refused) = common::mutations_with_crc(
        &[&F32_FRAME, &F64_FRAME, &EMPTY_FRAME],
        0x9E37_79B9_7F4A_7C15,
        3000,
        |bytes| {
            let repr = FrameRepr::parse_bytes(bytes)?;
            let mut buf = vec![0u8; FRAME_LEN_MAX];
            let n = repr.emit(&mut buf)?;
            buf.truncate(n);
            Ok(buf)
        },
    );
    assert!(
        accepted > 100 && refused > 100,
        "{accepted} accepted, {refused} refused"
    );
}

/// CRC-32/ISO-HDLC bit by bit, straight from its definition (reflected polynomial
/// 0xEDB88320, init and xor-out 0xFFFFFFFF): an independent reference.
fn crc32_bitwise(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// The host's CRC (`crc32fast`, carry-less multiplication in 16- and 64-byte blocks) and the
/// board's table CRC are the CRC: the catalogue's check value, and the bitwise definition
/// on every length from 0 to 300 bytes (whole blocks and every tail) of pseudo-random data,
/// and on a largest frame.
#[test]
fn table_crc_is_the_bitwise_crc_on_every_length() {
    assert_eq!(link_proto::frame::crc32(b"123456789"), 0xCBF4_3926);
    let mut x = 0x9E37_79B9u32;
    let data: Vec<u8> = (0..FRAME_LEN_MAX.max(300))
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x >> 24) as u8
        })
        .collect();
    assert!(data.iter().any(|&b| b != 0), "the data is not all zeros");
    for n in (0..=300).chain([FRAME_LEN_MAX]) {
        let bitwise = crc32_bitwise(&data[..n]);
        assert_eq!(link_proto::frame::crc32(&data[..n]), bitwise, "length {n}");
        assert_eq!(
            link_proto::frame::CRC32.checksum(&data[..n]),
            bitwise,
            "board table, length {n}"
        );
    }
}
