//! Wire lengths: the `const fn`s that say a frame's, a packet's, a payload's, an
//! envelope's and a byte stream's length without building one agree with the documented
//! layouts (numbers worked out by hand from the tables in the module docs) and with the
//! bytes the emitters and recovery actually write.

use link_proto::frame::frame_len;
use link_proto::packet::packet_len;
use link_proto::payload::{
    emit_node_entry, emit_surface_entry, BoxPayload, HelloPayload, NodesHeader, SurfaceHeader,
    ToolForcePayload, NODES_HEADER_LEN, SURFACE_NODES_PER_PACKET_MAX,
};
use link_proto::recovery::face::{Reliable, ReliableConfig};
use link_proto::recovery::global::emit_data;
use link_proto::recovery::{enveloped_len, OVERHEAD};
use link_proto::{
    emit_values, encode_wire, Clock, Error, Face, FrameKind, FrameRepr, Links, PacketKind,
    PacketRepr, Precision, RecvError, SendError, Values, FRAME_LEN_MAX, FRAME_RX_LEN,
    FRAME_WIRE_LEN_MAX, PACKET_LEN_MAX, PACKET_PAYLOAD_LEN_MAX, PACKET_WIRE_LEN_MAX,
    VALUES_PER_FRAME_MAX,
};

/// The layout's numbers: header 8 bytes, values of 4 or 8 bytes, CRC 4; the largest frame
/// 12 300 bytes (the crate doc). Each emitted frame is exactly `frame_len` long and parses.
#[test]
fn frame_len_is_the_layout_and_what_is_emitted() {
    assert_eq!(frame_len(0, Precision::F32), 12);
    assert_eq!(frame_len(2, Precision::F32), 20);
    assert_eq!(frame_len(1, Precision::F64), 20);
    assert_eq!(frame_len(512, Precision::F64), 8 + 4096 + 4);
    assert_eq!(frame_len(VALUES_PER_FRAME_MAX, Precision::F64), 12_300);
    assert_eq!(FRAME_LEN_MAX, 12_300);
    let mut buf = vec![0u8; FRAME_LEN_MAX];
    for n in [0, 1, 2, 7, 255, 512, VALUES_PER_FRAME_MAX] {
        let v32 = vec![1.5f32; n];
        let v64 = vec![-2.25f64; n];
        for (values, precision) in [
            (Values::F32(&v32), Precision::F32),
            (Values::F64(&v64), Precision::F64),
        ] {
            let len = emit_values(FrameKind::Forces, 3, values, &mut buf).unwrap();
            assert_eq!(len, frame_len(n, precision), "{n} values, {precision:?}");
            let repr = FrameRepr::parse_bytes(&buf[..len]).unwrap();
            assert_eq!(repr.payload.len(), n);
            assert_eq!(repr.buffer_len(), len);
            assert_eq!(repr.enveloped_len(), len + 10);
            // One byte less is not a frame.
            assert_eq!(
                FrameRepr::parse_bytes(&buf[..len - 1]),
                Err(Error::Truncated)
            );
        }
    }
}

/// Header 8, CRC 4: a packet of `n` payload bytes is `n + 12`, the largest 12 300.
#[test]
fn packet_len_is_the_layout_and_what_is_emitted() {
    assert_eq!(packet_len(0), 12);
    assert_eq!(packet_len(BoxPayload::LEN), 64);
    assert_eq!(packet_len(PACKET_PAYLOAD_LEN_MAX), PACKET_LEN_MAX);
    assert_eq!(PACKET_LEN_MAX, 12_300);
    let payload = vec![0x5Au8; PACKET_PAYLOAD_LEN_MAX];
    let mut buf = vec![0u8; PACKET_LEN_MAX];
    for n in [0, 1, 29, 52, 1000, PACKET_PAYLOAD_LEN_MAX] {
        let repr = PacketRepr {
            dst: 1,
            src: 2,
            msg_id: 3,
            kind: PacketKind::GraphicsSurface,
            payload: &payload[..n],
        };
        let len = repr.emit(&mut buf).unwrap();
        assert_eq!(len, packet_len(n), "payload of {n}");
        assert_eq!(repr.buffer_len(), len);
        assert_eq!(repr.enveloped_len(), len + 10);
        // Global recovery's envelope around it is enveloped_len bytes.
        let mut env = vec![0u8; enveloped_len(len)];
        assert_eq!(emit_data(&buf[..len], 0, &mut env), Some(len + OVERHEAD));
        assert_eq!(emit_data(&buf[..len], 0, &mut env[..len + 9]), None);
    }
}

/// Each payload's length by the layout table (surface: 12-byte header, 16-byte entries;
/// nodes: 8-byte header, entries of 16 (f32) or 28 (f64) bytes; box 52; tool force 29;
/// hello 8), and entries written up to exactly that length, not a byte more.
#[test]
fn payload_lengths_are_the_layout_and_what_is_emitted() {
    assert_eq!(SurfaceHeader::payload_len(0), 12);
    assert_eq!(SurfaceHeader::payload_len(3), 12 + 48);
    assert_eq!(NodesHeader::payload_len(2, Precision::F32), 8 + 32);
    assert_eq!(NodesHeader::payload_len(2, Precision::F64), 8 + 56);
    assert_eq!(NODES_HEADER_LEN, 8);
    assert_eq!(
        (BoxPayload::LEN, ToolForcePayload::LEN, HelloPayload::LEN),
        (52, 29, 8)
    );
    assert!(packet_len(SurfaceHeader::payload_len(SURFACE_NODES_PER_PACKET_MAX)) <= PACKET_LEN_MAX);
    assert!(
        packet_len(SurfaceHeader::payload_len(SURFACE_NODES_PER_PACKET_MAX + 1)) > PACKET_LEN_MAX
    );

    let mut buf = vec![0u8; 1024];
    for count in [0usize, 1, 5] {
        let h = SurfaceHeader {
            frame: 1,
            step: 2,
            chunk: 0,
            chunks: 1,
            count: count as u16,
        };
        let len = SurfaceHeader::payload_len(count);
        assert_eq!(h.encoded_len(), len);
        assert_eq!(h.emit(&mut buf).unwrap(), len);
        if count > 0 {
            let k = count - 1;
            assert!(emit_surface_entry(&mut buf[..len], k, 9, [1.0; 3]).is_ok());
            assert_eq!(
                emit_surface_entry(&mut buf[..len - 1], k, 9, [1.0; 3]),
                Err(Error::BufferTooSmall)
            );
        }
        assert_eq!(SurfaceHeader::parse(&buf[..len]), Ok(h));
        for precision in [Precision::F32, Precision::F64] {
            let h = NodesHeader {
                step: 4,
                last: true,
                precision,
                count: count as u16,
            };
            let len = NodesHeader::payload_len(count, precision);
            assert_eq!(h.encoded_len(), len);
            assert_eq!(h.emit(&mut buf).unwrap(), len);
            if count > 0 {
                let k = count - 1;
                assert!(emit_node_entry(&mut buf[..len], precision, k, 9, [1.0; 3]).is_ok());
                assert_eq!(
                    emit_node_entry(&mut buf[..len - 1], precision, k, 9, [1.0; 3]),
                    Err(Error::BufferTooSmall)
                );
            }
            assert_eq!(NodesHeader::parse(&buf[..len]), Ok(h));
        }
    }
    let b = BoxPayload {
        step: 1,
        min: [0.0; 3],
        max: [1.0; 3],
    };
    assert_eq!(b.emit(&mut buf), Ok(b.encoded_len()));
    assert_eq!(b.emit(&mut buf[..51]), Err(Error::BufferTooSmall));
    let t = ToolForcePayload {
        step: 1,
        tool: 0,
        force: [1.0; 3],
    };
    assert_eq!(t.emit(&mut buf), Ok(t.encoded_len()));
    assert_eq!(t.emit(&mut buf[..28]), Err(Error::BufferTooSmall));
    let h = HelloPayload {
        compilation: [7; 8],
    };
    assert_eq!(h.emit(&mut buf), Ok(h.encoded_len()));
}

/// Links that only record what is sent on +x.
struct Recorder(Vec<Vec<u8>>);

impl Links for Recorder {
    fn try_send(&mut self, _: Face, frame: &[u8]) -> Result<(), SendError> {
        self.0.push(frame.to_vec());
        Ok(())
    }
    fn try_recv(&mut self, _: Face, _: &mut [u8]) -> Result<Option<usize>, RecvError> {
        Ok(None)
    }
    fn try_send_global(&mut self, _: &[u8]) -> Result<(), SendError> {
        Err(SendError::NoLink)
    }
    fn try_recv_global(&mut self, _: &mut [u8]) -> Result<Option<usize>, RecvError> {
        Ok(None)
    }
}

struct Still;
impl Clock for Still {
    fn now_ns(&mut self) -> u64 {
        0
    }
}

/// Face recovery puts a frame of `frame_len(n, p)` bytes on the link as an envelope of
/// `enveloped_len` of that, and a receive buffer of FRAME_RX_LEN holds the largest.
#[test]
fn face_recovery_sends_enveloped_len() {
    assert_eq!(OVERHEAD, 10);
    assert_eq!(FRAME_RX_LEN, enveloped_len(FRAME_LEN_MAX));
    let config = ReliableConfig::default();
    let buf = vec![0u8; Reliable::<Recorder, Still, Vec<u8>>::buffer_len(&config)];
    let mut r = Reliable::new(Recorder(Vec::new()), Still, config, buf).unwrap();
    let mut frame = vec![0u8; FRAME_LEN_MAX];
    let values = vec![0.5f64; VALUES_PER_FRAME_MAX];
    for (k, n) in [1usize, 100, VALUES_PER_FRAME_MAX].into_iter().enumerate() {
        let len = emit_values(FrameKind::Forces, 0, Values::F64(&values[..n]), &mut frame).unwrap();
        r.try_send(Face::PosX, &frame[..len]).unwrap();
        let sent = &r.inner().0[k];
        assert_eq!(sent.len(), enveloped_len(frame_len(n, Precision::F64)));
        assert_eq!(
            &sent[6..6 + len],
            &frame[..len],
            "the frame inside, unchanged"
        );
    }
    assert_eq!(r.inner().0[2].len(), FRAME_RX_LEN);
}

/// On a byte stream a frame or packet takes at most `wire_len_max` of its length: reached
/// by the worst case (no zero byte, so every 254 bytes cost a code byte), and the crate's
/// buffer sizes are that bound of the largest.
#[test]
fn wire_len_max_bounds_the_stream() {
    assert_eq!(FRAME_WIRE_LEN_MAX, link_proto::wire_len_max(FRAME_LEN_MAX));
    assert_eq!(
        PACKET_WIRE_LEN_MAX,
        link_proto::wire_len_max(PACKET_LEN_MAX)
    );
    let mut out = vec![0u8; link_proto::wire_len_max(FRAME_RX_LEN)];
    for n in [
        0usize,
        1,
        253,
        254,
        255,
        508,
        1000,
        FRAME_LEN_MAX,
        FRAME_RX_LEN,
    ] {
        let worst = vec![0x01u8; n];
        let w = encode_wire(&worst, &mut out).unwrap();
        assert!(w <= link_proto::wire_len_max(n), "{n} bytes: {w}");
        // COBS adds a code byte per started run of 254 non-zero bytes (one for none).
        assert_eq!(w, n + n.div_ceil(254).max(1) + 2, "{n} bytes");
    }
}
