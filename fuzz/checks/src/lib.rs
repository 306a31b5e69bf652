//! The checks of the fuzz targets, one function per target: every parser that reads data
//! from outside the program (link frames, global packets, the COBS byte stream, global
//! payloads, schedule images, MSH and VTK meshes, scene TOML). Each check feeds its input to
//! the parser and asserts what must hold for *any* input: no panic, no out-of-bounds read,
//! no unbounded allocation, and the property stated in its doc (an accepted frame re-emits
//! to the same bytes, a loaded mesh validates, ...). A failed assertion is a panic, which
//! libFuzzer and the replay test both report.
//!
//! The libFuzzer targets (`fuzz/fuzz_targets/*.rs`, `cargo fuzz run`) and the stable replay
//! test (`fuzz/checks/tests/replay.rs`, `cargo test`) call these same functions through
//! [`TARGETS`].
//!
//! Each check returns how many of its parsers accepted the input (and so had their
//! property checked): a target whose parsers refuse everything passes every "no panic"
//! check while proving nothing, so the replay test fails a target that accepts nothing.

use std::path::Path;

use link_proto::frame::crc32;
use link_proto::payload::{
    node_entry, surface_entry, BoxPayload, NodesHeader, SurfaceHeader, ToolForcePayload,
};
use link_proto::{
    cobs_len_max, encode_wire, Frame, FrameRepr, Packet, PacketRepr, StreamDecoder,
    FRAME_COBS_LEN_MAX, FRAME_LEN_MAX, PACKET_LEN_MAX,
};
use pe_firmware::image::{ImageReader, MAGIC};

/// A target's check: panics when the input breaks the target's property; returns how many
/// of the target's parsers accepted the input.
pub type Check = fn(&[u8]) -> u32;

/// Every target: its name (the directory of its seeds and regressions) and its check.
pub const TARGETS: &[(&str, Check)] = &[
    ("frame_parse", frame_parse),
    ("packet_parse", packet_parse),
    ("stream_decoder", stream_decoder),
    ("payload_parse", payload_parse),
    ("image_load", image_load),
    ("msh_parse", msh_parse),
    ("vtk_parse", vtk_parse),
    ("scene_toml", scene_toml),
];

/// `data` with its last four bytes replaced by the CRC-32 of the rest (link frames, packets
/// and images all end so), so a fuzzer's mutations get past the CRC check; `None` if it
/// is shorter than a CRC.
pub fn with_crc(data: &[u8]) -> Option<Vec<u8>> {
    let body_len = data.len().checked_sub(4)?;
    let mut fixed = data.to_vec();
    let crc = crc32(&fixed[..body_len]);
    fixed[body_len..].copy_from_slice(&crc.to_le_bytes());
    Some(fixed)
}

fn frame_once(data: &[u8]) -> u32 {
    let mut accepted = 0;
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
        assert_eq!(&out[..n], data, "a parsed frame re-emits to its own bytes");
        assert_eq!(repr.payload.iter().count(), repr.payload.len());
        for i in 0..repr.payload.len() {
            assert!(repr.payload.get(i).is_some());
        }
        accepted += 1;
    }
    accepted
}

/// Link frames: `Frame::new_checked`, its accessors and `FrameRepr::parse_bytes` never
/// panic; an accepted frame re-emits to the identical bytes. The input is also tried with a
/// correct CRC in its last four bytes, and must then never be refused for its CRC.
pub fn frame_parse(data: &[u8]) -> u32 {
    let mut accepted = frame_once(data);
    if let Some(fixed) = with_crc(data) {
        accepted += frame_once(&fixed);
        assert!(FrameRepr::parse_bytes(&fixed) != Err(link_proto::Error::BadCrc));
    }
    accepted
}

fn packet_once(data: &[u8]) -> u32 {
    let mut accepted = 0;
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
        assert_eq!(&out[..n], data, "a parsed packet re-emits to its own bytes");
        accepted += 1;
    }
    accepted
}

/// Global packets: as [`frame_parse`], for `Packet` / `PacketRepr`.
pub fn packet_parse(data: &[u8]) -> u32 {
    let mut accepted = packet_once(data);
    if let Some(fixed) = with_crc(data) {
        accepted += packet_once(&fixed);
        assert!(PacketRepr::parse_bytes(&fixed) != Err(link_proto::Error::BadCrc));
    }
    accepted
}

/// The COBS stream decoder never panics on any byte stream, pushed in chunks whose size the
/// first input byte sets, and fed byte by byte to a 16-byte decoder; every frame it yields
/// fits its buffer and re-encodes to a run that decodes back to the same frame.
pub fn stream_decoder(data: &[u8]) -> u32 {
    let Some((&chunk, data)) = data.split_first() else {
        return 0;
    };
    let mut accepted = 0;
    let chunk = usize::from(chunk).max(1);
    let mut dec: Box<StreamDecoder<FRAME_COBS_LEN_MAX>> = Box::default();
    let mut small: StreamDecoder<16> = StreamDecoder::new();
    let mut wire = vec![0u8; cobs_len_max(FRAME_COBS_LEN_MAX) + 2];
    for piece in data.chunks(chunk) {
        let mut rest = piece;
        while !rest.is_empty() {
            let (used, ev) = dec.push(rest);
            assert!(
                used >= 1 && used <= rest.len(),
                "push consumes 1..=len bytes"
            );
            rest = &rest[used..];
            if let Some(Ok(frame)) = ev {
                assert!(frame.len() <= FRAME_COBS_LEN_MAX);
                let _ = FrameRepr::parse_bytes(frame);
                let frame = frame.to_vec();
                let n = encode_wire(&frame, &mut wire).expect("a decoded frame re-encodes");
                let mut again: Box<StreamDecoder<FRAME_COBS_LEN_MAX>> = Box::default();
                let (_, ev2) = again.push(&wire[..n]);
                assert_eq!(
                    ev2,
                    Some(Ok(&frame[..])),
                    "re-encoded frame decodes to itself"
                );
                accepted += 1;
            }
        }
        for &b in piece {
            if let Some(Ok(f)) = small.feed(b) {
                assert!(f.len() <= 16);
            }
        }
    }
    accepted
}

/// Global-network payloads (link-proto's `payload`, what the runtime reads from collision,
/// bounding-box, tool-force and surface packets): every parser never panics on any bytes;
/// an accepted fixed-size payload re-emits to the same bytes; after a node or surface
/// header is accepted, every one of its `count` entries reads, and entry `count` does not.
pub fn payload_parse(data: &[u8]) -> u32 {
    let mut out = vec![0u8; data.len().max(64)];
    let mut accepted = 0;
    if let Ok(b) = BoxPayload::parse(data) {
        let n = b.emit(&mut out).expect("a parsed box re-emits");
        assert_eq!(
            &out[..n],
            data,
            "a parsed box payload re-emits to its bytes"
        );
        accepted += 1;
    }
    if let Ok(t) = ToolForcePayload::parse(data) {
        let n = t.emit(&mut out).expect("a parsed tool force re-emits");
        assert_eq!(&out[..n], data, "a parsed tool force re-emits to its bytes");
        accepted += 1;
    }
    if let Ok(p) = link_proto::tool_pose::ToolPoseRepr::parse_bytes(data) {
        let n = p.emit(&mut out).expect("a parsed tool pose re-emits");
        assert_eq!(&out[..n], data, "a parsed tool pose re-emits to its bytes");
        assert!(p.q.iter().chain(&p.p_m).all(|v| v.is_finite()));
        accepted += 1;
    }
    if let Ok(h) = NodesHeader::parse(data) {
        let count = usize::from(h.count);
        for k in 0..count {
            assert!(
                node_entry(data, h.precision, k).is_ok(),
                "node entry {k} of {count} reads"
            );
        }
        assert!(
            node_entry(data, h.precision, count).is_err(),
            "no entry past the count"
        );
        let n = h.emit(&mut out).expect("a parsed node header re-emits");
        assert_eq!(n, data.len());
        assert_eq!(&out[..8], &data[..8]);
        accepted += 1;
    }
    if let Ok(h) = SurfaceHeader::parse(data) {
        let count = usize::from(h.count);
        for k in 0..count {
            assert!(
                surface_entry(data, k).is_ok(),
                "surface entry {k} of {count} reads"
            );
        }
        assert!(
            surface_entry(data, count).is_err(),
            "no entry past the count"
        );
        let n = h.emit(&mut out).expect("a parsed surface header re-emits");
        assert_eq!(n, data.len());
        assert_eq!(&out[..12], &data[..12]);
        accepted += 1;
    }
    // Entries at any index of any bytes: an error, never a panic (the runtime reads them
    // only after the header parsed, but the functions are public).
    for k in [0, 1, usize::MAX / 64, usize::MAX] {
        let _ = node_entry(data, link_proto::Precision::F32, k);
        let _ = node_entry(data, link_proto::Precision::F64, k);
        let _ = surface_entry(data, k);
    }
    accepted
}

fn image_once(data: &[u8]) -> u32 {
    let Ok(reader) = ImageReader::new(data, None) else {
        return 0;
    };
    let board = reader.header.board;
    // The host's decoder (`pe inspect`, board-sim's timing model): vectors sized from the
    // header's counts.
    let decoded = host_tools::compile::decode_image(data, None);
    // The firmware's loader into a real board's fixed storage (what the board does at
    // start), and into storage sized exactly for the image (board-sim).
    let board_load = board_sim::load_check(
        data,
        board,
        board_sim::StorageSizing::Board(pe_firmware::profile::PE_BOARD),
    );
    let exact_load = board_sim::load_check(data, board, board_sim::StorageSizing::Exact);
    // An image the runtime loads is one whose records all decode and check out.
    if board_load.is_ok() || exact_load.is_ok() {
        assert!(
            decoded.is_ok(),
            "the runtime loaded an image the decoder refuses: {decoded:?}"
        );
    }
    u32::from(decoded.is_ok()) + u32::from(board_load.is_ok()) + u32::from(exact_load.is_ok())
}

/// Schedule images: the header reader (`ImageReader`), the host decoder (`decode_image`)
/// and the firmware's loader (`Runtime::load` through board-sim's `load_check`, with the
/// board's capacities and with exact ones) never panic and never allocate more than the
/// image can describe, on any bytes. Each input is tried as is, and with the image magic
/// written over its first bytes and a correct CRC in its last four, so mutations reach
/// the header and the records behind the CRC.
pub fn image_load(data: &[u8]) -> u32 {
    let mut accepted = image_once(data);
    if data.len() >= MAGIC.len() + 4 {
        let mut fixed = data.to_vec();
        fixed[..MAGIC.len()].copy_from_slice(&MAGIC);
        if let Some(fixed) = with_crc(&fixed) {
            // An input that already had the magic and its CRC was checked as it is.
            if fixed != data {
                accepted += image_once(&fixed);
            }
        }
    }
    accepted
}

/// Gmsh MSH (4.1 and 2.2, ASCII and binary): `parse_msh` never panics; a mesh it accepts
/// passes `Mesh::validate` (what `load_mesh` promises).
pub fn msh_parse(data: &[u8]) -> u32 {
    if let Ok(mesh) = host_tools::mesh::io::parse_msh(Path::new("fuzz.msh"), data) {
        let v = mesh.validate();
        assert!(v.is_ok(), "an accepted MSH mesh fails validation: {v:?}");
        return 1;
    }
    0
}

/// VTK, legacy (`parse_vtk`) and XML (`parse_vtu`): never panic on any bytes; a mesh either
/// accepts passes `Mesh::validate`.
pub fn vtk_parse(data: &[u8]) -> u32 {
    let mut accepted = 0;
    if let Ok(mesh) = host_tools::mesh::io::parse_vtk(Path::new("fuzz.vtk"), data) {
        let v = mesh.validate();
        assert!(v.is_ok(), "an accepted VTK mesh fails validation: {v:?}");
        accepted += 1;
    }
    if let Ok(mesh) = host_tools::mesh::io::parse_vtu(Path::new("fuzz.vtu"), data) {
        let v = mesh.validate();
        assert!(v.is_ok(), "an accepted VTU mesh fails validation: {v:?}");
        accepted += 1;
    }
    accepted
}

/// Scene TOML: `Scene::from_toml` never panics on any text; an accepted scene writes back
/// (`to_toml`) to TOML that parses again and writes the same text (nothing is lost or
/// changed on the way).
pub fn scene_toml(data: &[u8]) -> u32 {
    let Ok(text) = std::str::from_utf8(data) else {
        return 0;
    };
    let Ok(scene) = host_tools::scene::Scene::from_toml(text) else {
        return 0;
    };
    let written = scene
        .to_toml()
        .expect("an accepted scene writes back as TOML");
    let again = host_tools::scene::Scene::from_toml(&written)
        .unwrap_or_else(|e| panic!("a written scene parses again: {e}\n{written}"));
    let rewritten = again.to_toml().expect("the re-read scene writes back");
    assert_eq!(written, rewritten, "a scene survives write/read unchanged");
    1
}
