//! The transport against a fake session (the test thread reads the Inbound channel and
//! fills the client's outbox) and a client written with this codec over a real socket.
//! The independent client (pyigtl) is `tests/igtl/client.py`.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::atomic::AtomicU32;
use std::sync::mpsc::{channel, Receiver};
use std::sync::Arc;
use std::time::Duration;

use super::*;
use crate::live::engine::Pose;
use crate::live::hub::Outbound;
use crate::live::igtl::body::{Framing, MetaEntry};
use crate::live::igtl::message::{decode, encode, encode_with, Content, Decoded};
use crate::live::igtl::point::FORCE_GROUP;
use crate::live::igtl::polydata::Cells;
use crate::live::igtl::position::PositionRepr;
use crate::live::igtl::transform::TransformRepr;

const WAIT: Duration = Duration::from_secs(10);

fn scene() -> Scene {
    Scene {
        tools: vec!["probe".into(), "grasper".into()],
        surface: SurfaceTopology {
            device: "builtin:coarse".into(),
            nodes: 4,
            triangles: vec![[0, 1, 2], [1, 3, 2]],
        },
    }
}

/// The session's side: the channel, and the outboxes of the clients it has seen.
struct Fake {
    rx: Receiver<Inbound>,
    outboxes: HashMap<ClientId, Outbox>,
}

impl Fake {
    fn next(&mut self) -> Inbound {
        let e = self.rx.recv_timeout(WAIT).expect("an event within 10 s");
        if let Inbound::Connected { client, outbox, .. } = &e {
            self.outboxes.insert(*client, outbox.clone());
        }
        e
    }

    /// The next event, which must be a refusal; the session's answer (an Error) is sent.
    fn bad(&mut self) -> String {
        match self.next() {
            Inbound::Bad { client, message } => {
                self.outboxes[&client].push(Outbound::Error(message.clone()));
                message
            }
            e => panic!("expected Bad, got {e:?}"),
        }
    }

    fn pose(&mut self) -> (String, Pose) {
        match self.next() {
            Inbound::Pose { tool, pose, .. } => (tool, pose),
            e => panic!("expected Pose, got {e:?}"),
        }
    }

    fn disconnected(&mut self) -> String {
        match self.next() {
            Inbound::Disconnected { reason, .. } => reason,
            e => panic!("expected Disconnected, got {e:?}"),
        }
    }
}

fn start() -> (IgtlServer, Fake) {
    let (tx, rx) = channel();
    let ids = Arc::new(AtomicU32::new(0));
    let addr = address_beside("127.0.0.1:8080", 0).unwrap();
    let server = IgtlServer::start(addr, scene(), tx, ids).unwrap();
    let fake = Fake {
        rx,
        outboxes: HashMap::new(),
    };
    (server, fake)
}

/// Connects a client; returns its stream and id.
fn connect(server: &IgtlServer, fake: &mut Fake) -> (TcpStream, ClientId) {
    let s = TcpStream::connect(server.addr()).unwrap();
    s.set_read_timeout(Some(WAIT)).unwrap();
    match fake.next() {
        Inbound::Connected {
            client, transport, ..
        } => {
            assert_eq!(transport, Transport::Igtl);
            (s, client)
        }
        e => panic!("expected Connected, got {e:?}"),
    }
}

fn send(s: &mut TcpStream, device: &str, content: &Content) {
    s.write_all(&encode(&Framing::V1, device, 0, content).unwrap())
        .unwrap();
}

fn receive(s: &mut TcpStream) -> Decoded {
    let mut head = [0u8; HEADER_LEN];
    s.read_exact(&mut head).unwrap();
    let h = HeaderRepr::parse_bytes(&head).unwrap();
    let mut msg = head.to_vec();
    msg.resize(HEADER_LEN + h.body_len as usize, 0);
    s.read_exact(&mut msg[HEADER_LEN..]).unwrap();
    decode(&msg).unwrap()
}

fn string_of(d: &Decoded) -> &str {
    match &d.content {
        Content::String(s) => &s.text,
        c => panic!("expected a STRING, got {c:?}"),
    }
}

fn transform(q: [f64; 4], p_m: [f64; 3]) -> Content {
    Content::Transform(TransformRepr::of_pose(&Pose { q, p_m }))
}

#[test]
fn transforms_and_positions_become_poses_in_metres() {
    let (server, mut fake) = start();
    let (mut s, client) = connect(&server, &mut fake);
    assert_eq!(client, 1);
    let h = 0.5f64.sqrt();
    // +90° about x, 12.5 mm along z.
    send(
        &mut s,
        "probe",
        &transform([h, h, 0.0, 0.0], [0.0, 0.0, 0.0125]),
    );
    let (tool, pose) = fake.pose();
    assert_eq!(tool, "probe");
    for (g, w) in pose.q.iter().zip([h, h, 0.0, 0.0]) {
        assert!((g - w).abs() < 1e-7, "{:?}", pose.q);
    }
    assert!(
        (pose.p_m[2] - 0.0125).abs() < 1e-9 && pose.p_m[0] == 0.0,
        "{:?}",
        pose.p_m
    );

    // Version 2 with metadata: the same pose.
    let meta = [MetaEntry {
        key: "TransformStatus".into(),
        encoding: 3,
        value: b"OK".to_vec(),
    }];
    let v2 = Framing::V2 {
        message_id: 3,
        metadata: &meta,
    };
    let bytes = encode(
        &v2,
        "grasper",
        0,
        &transform([1.0, 0.0, 0.0, 0.0], [0.001, 0.0, 0.0]),
    )
    .unwrap();
    s.write_all(&bytes).unwrap();
    let (tool, pose) = fake.pose();
    assert_eq!((tool.as_str(), pose.q), ("grasper", [1.0, 0.0, 0.0, 0.0]));
    assert!((pose.p_m[0] - 0.001).abs() < 1e-9);

    // POSITION: quaternion (x, y, z, w) on the wire.
    let pos = Content::Position(PositionRepr {
        position_mm: [5.0, -5.0, 0.0],
        quaternion_xyzw: Some([0.0, 0.0, h as f32, h as f32]),
    });
    send(&mut s, "probe", &pos);
    let (_, pose) = fake.pose();
    assert!(
        (pose.q[0] - h).abs() < 1e-7 && (pose.q[3] - h).abs() < 1e-7,
        "{:?}",
        pose.q
    );
    assert!((pose.p_m[0] - 0.005).abs() < 1e-9 && (pose.p_m[1] + 0.005).abs() < 1e-9);
}

#[test]
fn refused_messages_get_an_error_string_and_the_connection_goes_on() {
    let (server, mut fake) = start();
    let (mut s, _) = connect(&server, &mut fake);
    let identity = transform([1.0, 0.0, 0.0, 0.0], [0.0; 3]);

    // An unknown device name.
    send(&mut s, "forceps", &identity);
    let m = fake.bad();
    assert!(
        m.contains("\"forceps\"") && m.contains("[\"probe\", \"grasper\"]"),
        "{m}"
    );
    let d = receive(&mut s);
    assert_eq!(d.header.device, "error");
    assert_eq!(string_of(&d), m);

    // A bad CRC.
    let mut bytes = encode(&Framing::V1, "probe", 0, &identity).unwrap();
    bytes[HEADER_LEN] ^= 1;
    s.write_all(&bytes).unwrap();
    let m = fake.bad();
    assert!(m.contains("CRC-64"), "{m}");

    // An unknown type (with a body, skipped whole).
    let other = encode_with(&Framing::V1, "SENSOR", "probe", 0, 6, |b| {
        b.copy_from_slice(&[1, 2, 3, 4, 5, 6]);
        Ok(())
    })
    .unwrap();
    s.write_all(&other).unwrap();
    let m = fake.bad();
    assert!(m.contains("\"SENSOR\" is not taken"), "{m}");

    // A type this server knows but does not take from a client.
    send(
        &mut s,
        "probe",
        &Content::String(super::super::string::StringRepr::new("hi")),
    );
    assert!(fake.bad().contains("\"STRING\" is not taken"));

    // A non-rigid matrix (scaled by 2) and a non-finite one.
    let mut scaled = TransformRepr::of_pose(&Pose::IDENTITY);
    scaled.r[1][1] = 2.0;
    send(&mut s, "probe", &Content::Transform(scaled));
    assert!(fake.bad().contains("not rigid"));
    let mut nan = TransformRepr::of_pose(&Pose::IDENTITY);
    nan.t_mm[0] = f32::INFINITY;
    send(&mut s, "probe", &Content::Transform(nan));
    assert!(fake.bad().contains("non-finite"));

    // A TRANSFORM of the wrong length.
    let short = encode_with(&Framing::V1, "TRANSFORM", "probe", 0, 44, |_| Ok(())).unwrap();
    s.write_all(&short).unwrap();
    assert!(fake.bad().contains("44 bytes, expected 48"));

    // A bad version-2 extended header (sizes past the body).
    let mut ext = encode_with(&Framing::V1, "TRANSFORM", "probe", 0, 12, |b| {
        b.copy_from_slice(&[0, 12, 0, 2, 0, 0, 0, 99, 0, 0, 0, 0]);
        Ok(())
    })
    .unwrap();
    ext[1] = 2; // header version 2 (the CRC covers the body only)
    s.write_all(&ext).unwrap();
    assert!(fake.bad().contains("extended header"));

    // And the connection still takes a good pose.
    send(&mut s, "probe", &identity);
    assert_eq!(fake.pose().1, Pose::IDENTITY);
    // Every refusal above was answered in order: 7 more STRINGs on device "error".
    for _ in 0..7 {
        assert_eq!(receive(&mut s).header.device, "error");
    }
}

#[test]
fn a_header_that_is_not_one_closes_the_connection_with_a_reason() {
    let (server, mut fake) = start();
    for (patch, want) in [
        ((0usize, [0u8, 7]), "header version 7"),
        ((42usize, [0x01, 0x00]), "more than the 16777216"),
    ] {
        let (mut s, _) = connect(&server, &mut fake);
        let mut bytes = encode(
            &Framing::V1,
            "probe",
            0,
            &transform([1.0, 0.0, 0.0, 0.0], [0.0; 3]),
        )
        .unwrap();
        bytes[patch.0..patch.0 + 2].copy_from_slice(&patch.1);
        s.write_all(&bytes).unwrap();
        let m = fake.bad();
        assert!(m.contains(want) && m.contains("closing"), "{m}");
        let reason = fake.disconnected();
        assert!(reason.contains("broke the framing"), "{reason}");
        // The server closed: the error STRING may or may not have gone out first, then EOF.
        let mut rest = Vec::new();
        let _ = s.read_to_end(&mut rest);
    }
    // A client that goes away mid-message.
    let (mut s, _) = connect(&server, &mut fake);
    let bytes = encode(
        &Framing::V1,
        "probe",
        0,
        &transform([1.0, 0.0, 0.0, 0.0], [0.0; 3]),
    )
    .unwrap();
    s.write_all(&bytes[..HEADER_LEN + 10]).unwrap();
    drop(s);
    let reason = fake.disconnected();
    assert!(
        reason.contains("closed mid-message") && reason.contains("10 of 48"),
        "{reason}"
    );
    let (s, _) = connect(&server, &mut fake);
    drop(s);
    assert_eq!(fake.disconnected(), "closed by the client");
}

#[test]
fn forces_go_out_as_decimated_points_and_the_surface_as_polydata() {
    let (server, mut fake) = start();
    let (mut s, client) = connect(&server, &mut fake);
    let outbox = fake.outboxes[&client].clone();
    let probe: Arc<str> = Arc::from("probe");
    // 20 one-millisecond means: x = 1..20 N, y = −2 N, z = 0.5·x.
    for k in 1..=20 {
        let x = f64::from(k);
        outbox.push(Outbound::Force {
            time_s: x * 1e-3,
            tool: probe.clone(),
            force_n: [x, -2.0, 0.5 * x],
        });
    }
    for want_x in [5.5f32, 15.5] {
        let d = receive(&mut s);
        assert_eq!(
            (d.header.type_name.as_str(), d.header.device.as_str()),
            ("POINT", "probe")
        );
        let Content::Point(p) = &d.content else {
            panic!()
        };
        assert_eq!(p.len(), 1);
        assert_eq!(
            (p[0].name.as_str(), p[0].group.as_str()),
            ("probe", FORCE_GROUP)
        );
        assert_eq!(
            p[0].xyz,
            [want_x, -2.0, 0.5 * want_x],
            "mean of ten 1 ms means"
        );
    }
    // A surface frame: positions in m -> points in mm, triangles as polygons.
    let positions_m = vec![
        0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.01, 0.01, 0.0025,
    ];
    outbox.push(Outbound::Surface {
        seq: 1,
        time_s: 0.02,
        frame: Arc::new(vec![]),
        positions_m: Arc::new(positions_m.clone()),
        tools: Arc::new(vec![]),
    });
    let d = receive(&mut s);
    assert_eq!(
        (d.header.type_name.as_str(), d.header.device.as_str()),
        ("POLYDATA", "builtin:coarse")
    );
    let Content::PolyData(p) = &d.content else {
        panic!()
    };
    assert_eq!(p.points.len(), 4);
    for (got, m) in p.points.iter().flatten().zip(&positions_m) {
        assert!((got - m * 1000.0).abs() < 1e-4, "{:?}", p.points);
    }
    assert_eq!(
        p.cells[Cells::Polygons as usize],
        vec![vec![0, 1, 2], vec![1, 3, 2]]
    );
    assert!(p.cells[Cells::Lines as usize].is_empty());
    // Notices, drivers, hello and status as STRINGs; the topology frame sends nothing.
    outbox.push(Outbound::Topology(Arc::new(vec![1, 2, 3])));
    outbox.push(Outbound::Notice("pose clamped".into()));
    outbox.push(Outbound::Driver {
        tool: probe.clone(),
        client: Some(client),
    });
    outbox.push(Outbound::Hello(Arc::new(
        serde_json::json!({"type": "hello"}),
    )));
    for (device, text) in [
        ("notice", "pose clamped".to_string()),
        ("driver", format!("probe: client {client}")),
        ("hello", "{\"type\":\"hello\"}".to_string()),
    ] {
        let d = receive(&mut s);
        assert_eq!(
            (d.header.device.as_str(), string_of(&d)),
            (device, text.as_str())
        );
    }
}

#[test]
fn a_client_that_does_not_read_is_disconnected_and_stop_ends_the_rest() {
    let (mut server, mut fake) = start();
    let (_quiet, client) = connect(&server, &mut fake);
    let outbox = fake.outboxes[&client].clone();
    // 40 MB of notices against a client that reads nothing: the socket's buffers fill, the
    // write times out (or the outbox overflows first).
    let text = "x".repeat(16 * 1024);
    for _ in 0..2 * OUTBOX_LIMIT + 100 {
        outbox.push(Outbound::Notice(text.clone()));
    }
    let reason = fake.disconnected();
    assert!(
        reason.contains("does not read") || reason.contains("write failed"),
        "{reason}"
    );
    assert!(outbox.is_closed());

    let (_other, _) = connect(&server, &mut fake);
    server.stop();
    assert!(!fake.disconnected().is_empty());
}
