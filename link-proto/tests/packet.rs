//! Global packet format: exact bytes, round trips, corruption and malformed input.

use link_proto::packet::{ADDR_BROADCAST, ADDR_GRAPHICS, ADDR_HOST, PACKET_VERSION};
use link_proto::{
    Control, Error, Packet, PacketKind, PacketRepr, PACKET_LEN_MAX, PACKET_PAYLOAD_LEN_MAX,
};
use proptest::prelude::*;

mod common;

/// Board 5 -> graphics engine (0x40), message 0x1234, graphics surface,
/// payload [0xaa, 0x00, 0x55]. CRC computed independently with Python `zlib.crc32`.
const SURFACE: [u8; 15] = [
    0x40, 0x05, 0x34, 0x12, 0x02, 0x01, 0x03, 0x00, // dst, src, msg id, kind, version, len
    0xaa, 0x00, 0x55, // payload
    0x5e, 0x01, 0x28, 0xc2, // CRC 0xc228015e
];

/// Host (0x41) -> broadcast, message 0, control start, no payload; CRC from `zlib.crc32`.
const START: [u8; 12] = [
    0xff, 0x41, 0x00, 0x00, 0x10, 0x01, 0x00, 0x00, 0xea, 0x9a, 0xce, 0xf0,
];

// Property: emit writes exactly the documented layout. Exact comparison:
// any difference is an incompatibility with the graphics engine and host.
#[test]
fn emit_matches_byte_literals() {
    let mut buf = [0u8; 64];
    let repr = PacketRepr {
        dst: ADDR_GRAPHICS,
        src: 5,
        msg_id: 0x1234,
        kind: PacketKind::GraphicsSurface,
        payload: &[0xaa, 0x00, 0x55],
    };
    let n = repr.emit(&mut buf).unwrap();
    assert_eq!(&buf[..n], &SURFACE);
    let repr = PacketRepr {
        dst: ADDR_BROADCAST,
        src: ADDR_HOST,
        msg_id: 0,
        kind: PacketKind::Control(Control::Start),
        payload: &[],
    };
    let n = repr.emit(&mut buf).unwrap();
    assert_eq!(&buf[..n], &START);
}

// Property: parsing the known bytes gives the known fields.
#[test]
fn parse_byte_literals() {
    let p = Packet::new_checked(&SURFACE[..]).unwrap();
    assert_eq!(p.dst(), 0x40);
    assert_eq!(p.src(), 5);
    assert_eq!(p.msg_id(), 0x1234);
    assert_eq!(p.kind(), PacketKind::GraphicsSurface);
    assert_eq!(p.version(), PACKET_VERSION);
    assert_eq!(p.payload(), &[0xaa, 0x00, 0x55]);
    assert_eq!(p.crc(), 0xc228_015e);
    let r = PacketRepr::parse(&p).unwrap();
    assert_eq!(r.payload, &[0xaa, 0x00, 0x55]);
    let r = PacketRepr::parse_bytes(&START).unwrap();
    assert_eq!(r.kind, PacketKind::Control(Control::Start));
    assert_eq!((r.dst, r.src, r.msg_id), (ADDR_BROADCAST, ADDR_HOST, 0));
}

// Property: each kind has a distinct code that maps back to it; every other
// code parses as Unknown(code) and re-emits unchanged.
#[test]
fn kind_codes() {
    let known = [
        (PacketKind::CollisionExchange, 0x01),
        (PacketKind::GraphicsSurface, 0x02),
        (PacketKind::BoundingBox, 0x03),
        (PacketKind::ToolForce, 0x04),
        (PacketKind::Hello, 0x05),
        (PacketKind::ToolPose, 0x06),
        (PacketKind::Control(Control::Start), 0x10),
        (PacketKind::Control(Control::Stop), 0x11),
        (PacketKind::Control(Control::StepDone), 0x12),
        (PacketKind::FaultReport, 0x20),
    ];
    for (k, c) in known {
        assert_eq!(k.code(), c);
        assert_eq!(PacketKind::from_code(c), k);
    }
    for code in 0..=255u8 {
        let k = PacketKind::from_code(code);
        assert_eq!(k.code(), code);
        if !known.iter().any(|&(_, c)| c == code) {
            assert_eq!(k, PacketKind::Unknown(code));
        }
    }
    let mut buf = [0u8; 32];
    let r = PacketRepr {
        dst: 1,
        src: 2,
        msg_id: 3,
        kind: PacketKind::Unknown(0x99),
        payload: &[1],
    };
    let n = r.emit(&mut buf).unwrap();
    assert_eq!(PacketRepr::parse_bytes(&buf[..n]), Ok(r));
}

// Property: malformed packets are rejected with the exact error: short ->
// Truncated, trailing bytes -> BadLength, announced or actual length past the
// maximum -> Oversized, wrong CRC -> BadCrc, valid CRC but other version ->
// UnsupportedVersion.
#[test]
fn malformed_packets_are_rejected_with_the_right_error() {
    for cut in 0..SURFACE.len() {
        assert_eq!(
            PacketRepr::parse_bytes(&SURFACE[..cut]),
            Err(Error::Truncated),
            "cut {cut}"
        );
    }
    let mut long = SURFACE.to_vec();
    long.push(0);
    assert_eq!(PacketRepr::parse_bytes(&long), Err(Error::BadLength));
    let mut big = SURFACE.to_vec();
    big[6..8].copy_from_slice(&((PACKET_PAYLOAD_LEN_MAX + 1) as u16).to_le_bytes());
    assert_eq!(PacketRepr::parse_bytes(&big), Err(Error::Oversized));
    assert_eq!(
        PacketRepr::parse_bytes(&vec![0u8; PACKET_LEN_MAX + 1]),
        Err(Error::Oversized)
    );
    let mut crc = SURFACE.to_vec();
    crc[9] ^= 1;
    assert_eq!(PacketRepr::parse_bytes(&crc), Err(Error::BadCrc));
    // Version 2 with a correct CRC.
    let mut v2 = SURFACE.to_vec();
    v2[5] = 2;
    let mut p = Packet::new_unchecked(&mut v2[..]);
    p.fill_crc();
    assert_eq!(
        PacketRepr::parse_bytes(&v2),
        Err(Error::UnsupportedVersion(2))
    );
}

// Property: emit refuses payloads past the maximum and short buffers, no panic.
#[test]
fn emit_rejects_oversized_and_short_buffers() {
    let payload = vec![7u8; PACKET_PAYLOAD_LEN_MAX + 1];
    let mut buf = vec![0u8; PACKET_LEN_MAX * 2];
    let r = PacketRepr {
        dst: 0,
        src: 1,
        msg_id: 0,
        kind: PacketKind::FaultReport,
        payload: &payload,
    };
    assert_eq!(r.emit(&mut buf), Err(Error::Oversized));
    let r = PacketRepr {
        payload: &payload[..PACKET_PAYLOAD_LEN_MAX],
        ..r
    };
    assert_eq!(r.emit(&mut buf), Ok(PACKET_LEN_MAX));
    assert_eq!(
        r.emit(&mut buf[..PACKET_LEN_MAX - 1]),
        Err(Error::BufferTooSmall)
    );
}

fn assert_every_bit_flip_detected(packet: &[u8]) {
    let mut buf = packet.to_vec();
    for bit in 0..packet.len() * 8 {
        buf[bit / 8] ^= 1 << (bit % 8);
        assert!(
            PacketRepr::parse_bytes(&buf).is_err(),
            "flip of bit {bit} not detected"
        );
        buf[bit / 8] ^= 1 << (bit % 8);
    }
    assert!(PacketRepr::parse_bytes(&buf).is_ok());
}

// Property: every single-bit error is rejected. Exhaustive over all bits of
// several packets up to the largest; CRC-32 detects every single-bit error,
// so zero tolerance.
#[test]
fn every_single_bit_flip_is_detected() {
    assert_every_bit_flip_detected(&SURFACE);
    assert_every_bit_flip_detected(&START);
    let payload: Vec<u8> = (0..PACKET_PAYLOAD_LEN_MAX)
        .map(|i| (i * 31 % 251) as u8)
        .collect();
    let mut buf = vec![0u8; PACKET_LEN_MAX];
    for len in [1, 100, PACKET_PAYLOAD_LEN_MAX] {
        let r = PacketRepr {
            dst: 9,
            src: 10,
            msg_id: 0xbeef,
            kind: PacketKind::CollisionExchange,
            payload: &payload[..len],
        };
        let n = r.emit(&mut buf).unwrap();
        assert_every_bit_flip_detected(&buf[..n]);
    }
}

proptest! {
    // Property: parse(emit(repr)) == repr for every representable repr.
    #[test]
    fn roundtrip(dst: u8, src: u8, msg_id: u16, kind in any::<u8>().prop_map(PacketKind::from_code),
                 payload in prop::collection::vec(any::<u8>(), 0..1000)) {
        let r = PacketRepr { dst, src, msg_id, kind, payload: &payload };
        let mut buf = vec![0u8; PACKET_LEN_MAX];
        let n = r.emit(&mut buf).unwrap();
        prop_assert_eq!(n, r.buffer_len());
        prop_assert_eq!(PacketRepr::parse_bytes(&buf[..n]), Ok(r));
    }

    // Property: arbitrary bytes never panic the parser; anything accepted
    // re-emits to the identical bytes. Random bytes never pass the CRC, so
    // `garbage_with_its_crc_reaches_the_re_emit` below runs them with a correct one.
    #[test]
    fn garbage_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        if let Ok(r) = PacketRepr::parse_bytes(&bytes) {
            let mut buf = vec![0u8; PACKET_LEN_MAX];
            let n = r.emit(&mut buf).unwrap();
            prop_assert_eq!(&buf[..n], &bytes[..]);
        }
    }
}

/// Mutated packets with a correct CRC (bit flips and truncations of the two documented
/// packets, the CRC recomputed): every one the parser accepts re-emits to its own bytes,
/// and both outcomes occur, so the re-emit check runs.
#[test]
fn garbage_with_its_crc_reaches_the_re_emit() {
    let (accepted, refused) =
        common::mutations_with_crc(&[&SURFACE, &START], 0x2545_F491_4F6C_DD1D, 3000, |bytes| {
            let repr = PacketRepr::parse_bytes(bytes)?;
            let mut buf = vec![0u8; PACKET_LEN_MAX];
            let n = repr.emit(&mut buf)?;
            buf.truncate(n);
            Ok(buf)
        });
    assert!(
        accepted > 100 && refused > 100,
        "{accepted} accepted, {refused} refused"
    );
}
