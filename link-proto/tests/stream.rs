//! The link interface: faces, grid neighbours, and `StreamLinks` over an
//! in-memory byte pipe with limited capacity (like a UART FIFO).

use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

use embedded_io::{ErrorKind, ErrorType, Read, ReadReady, Write, WriteReady};
use link_proto::packet::ADDR_HOST;
use link_proto::Machine;
use link_proto::{
    emit_values, Axis, Error, Face, FrameKind, FrameRepr, Links, PacketKind, PacketRepr, RecvError,
    SendError, StreamLinks, Values, BOARD_COUNT, FRAME_LEN_MAX, PACKET_LEN_MAX,
};

/// One direction of a pipe: a bounded FIFO that accepts at most `burst`
/// bytes per write call.
struct Chan {
    q: VecDeque<u8>,
    cap: usize,
    burst: usize,
}

/// One end of a full-duplex in-memory pipe.
#[derive(Clone)]
struct End {
    rx: Rc<RefCell<Chan>>,
    tx: Rc<RefCell<Chan>>,
}

fn pipe(cap: usize, burst: usize) -> (End, End) {
    let a = Rc::new(RefCell::new(Chan {
        q: VecDeque::new(),
        cap,
        burst,
    }));
    let b = Rc::new(RefCell::new(Chan {
        q: VecDeque::new(),
        cap,
        burst,
    }));
    (
        End {
            rx: a.clone(),
            tx: b.clone(),
        },
        End { rx: b, tx: a },
    )
}

impl ErrorType for End {
    type Error = ErrorKind;
}
impl Read for End {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, ErrorKind> {
        let mut c = self.rx.borrow_mut();
        let n = buf.len().min(c.q.len());
        for b in buf.iter_mut().take(n) {
            *b = c.q.pop_front().unwrap();
        }
        Ok(n)
    }
}
impl ReadReady for End {
    fn read_ready(&mut self) -> Result<bool, ErrorKind> {
        Ok(!self.rx.borrow().q.is_empty())
    }
}
impl Write for End {
    fn write(&mut self, buf: &[u8]) -> Result<usize, ErrorKind> {
        let mut c = self.tx.borrow_mut();
        let n = buf.len().min(c.cap - c.q.len()).min(c.burst);
        c.q.extend(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> Result<(), ErrorKind> {
        Ok(())
    }
}
impl WriteReady for End {
    fn write_ready(&mut self) -> Result<bool, ErrorKind> {
        let c = self.tx.borrow();
        Ok(c.q.len() < c.cap)
    }
}

type Board = StreamLinks<End, End>;

/// Two boards linked A.PosX <-> B.NegX, each with a global port to a host end.
fn two_boards(cap: usize, burst: usize) -> (Box<Board>, Box<Board>, End, End) {
    let (ax, bx) = pipe(cap, burst);
    let (ag, host_a) = pipe(1 << 16, 1 << 16);
    let (bg, host_b) = pipe(1 << 16, 1 << 16);
    let mut fa: [Option<End>; 6] = Default::default();
    fa[Face::PosX.index()] = Some(ax);
    let mut fb: [Option<End>; 6] = Default::default();
    fb[Face::NegX.index()] = Some(bx);
    (
        Box::new(StreamLinks::new(fa, ag)),
        Box::new(StreamLinks::new(fb, bg)),
        host_a,
        host_b,
    )
}

fn forces_frame(step: u32, n: usize) -> Vec<u8> {
    let vals: Vec<f32> = (0..n).map(|i| (i as f32 - 3.0) * step as f32).collect();
    let mut buf = vec![0u8; FRAME_LEN_MAX];
    let len = emit_values(FrameKind::Forces, step, Values::F32(&vals), &mut buf).unwrap();
    buf.truncate(len);
    buf
}

// Property: faces index 0..6 in ALL order, opposite is an involution that
// keeps the axis and flips the sign.
#[test]
fn face_geometry() {
    for (i, f) in Face::ALL.iter().enumerate() {
        assert_eq!(f.index(), i);
        assert_eq!(Face::from_index(i), Some(*f));
        assert_eq!(f.opposite().opposite(), *f);
        assert_ne!(f.opposite(), *f);
        assert_eq!(f.opposite().axis(), f.axis());
        assert_eq!(f.opposite().sign(), -f.sign());
    }
    assert_eq!(Face::from_index(6), None);
    assert_eq!(Face::PosY.axis(), Axis::Y);
}

// Property: the 4x4x4 grid has 3*3*16 = 144 links, each seen from both
// ends through opposite faces; ids outside the grid have no neighbours.
#[test]
fn grid_neighbours() {
    // The address space is the 4x4x4 machine: addresses and neighbours through it.
    let m = Machine::ADDRESSES;
    let neighbour = |b: u8, f: Face| {
        Machine::from_address(b)
            .and_then(|c| m.neighbour(c, f))
            .and_then(Machine::address)
    };
    let mut directed = 0;
    for b in 0..BOARD_COUNT as u8 {
        let c = Machine::from_address(b).unwrap();
        assert_eq!(Machine::address(c), Some(b));
        for f in Face::ALL {
            if let Some(n) = neighbour(b, f) {
                directed += 1;
                assert_eq!(neighbour(n, f.opposite()), Some(b));
            }
        }
    }
    assert_eq!(directed, 2 * 144);
    assert_eq!(neighbour(0, Face::NegX), None);
    assert_eq!(neighbour(0, Face::PosX), Some(1));
    assert_eq!(neighbour(0, Face::PosY), Some(4));
    assert_eq!(neighbour(0, Face::PosZ), Some(16));
    assert_eq!(neighbour(BOARD_COUNT as u8, Face::PosX), None);
}

// Property: a frame sent on A's +x arrives whole and unchanged on B's -x,
// and a packet sent on the global port arrives at the host end.
#[test]
fn frame_and_packet_cross_the_links() {
    let (mut a, mut b, mut host_a, _) = two_boards(4096, 4096);
    let f = forces_frame(42, 100);
    a.try_send(Face::PosX, &f).unwrap();
    let mut buf = vec![0u8; FRAME_LEN_MAX];
    let n = b.try_recv(Face::NegX, &mut buf).unwrap().unwrap();
    assert_eq!(&buf[..n], &f[..]);
    assert_eq!(FrameRepr::parse_bytes(&buf[..n]).unwrap().step, 42);
    assert_eq!(b.try_recv(Face::NegX, &mut buf), Ok(None), "nothing more");

    let mut pkt = vec![0u8; PACKET_LEN_MAX];
    let r = PacketRepr {
        dst: ADDR_HOST,
        src: 0,
        msg_id: 1,
        kind: PacketKind::FaultReport,
        payload: &[0, 1, 0],
    };
    let len = r.emit(&mut pkt).unwrap();
    a.try_send_global(&pkt[..len]).unwrap();
    let mut wire = vec![0u8; 64];
    let got = host_a.read(&mut wire).unwrap();
    let mut dec: link_proto::StreamDecoder<64> = link_proto::StreamDecoder::new();
    let (_, ev) = dec.push(&wire[..got]);
    let bytes = ev.unwrap().unwrap();
    assert_eq!(PacketRepr::parse_bytes(bytes), Ok(r));
}

// Property: with a small FIFO (64 bytes, 16 per write), a second send while
// the first is still draining returns WouldBlock and sends nothing; frames
// flow as the receiver drains and poll() pushes, arriving intact and in order.
// This is the interleaving the schedule relies on.
#[test]
fn full_queue_says_would_block_and_frames_stay_in_order() {
    let (mut a, mut b, _, _) = two_boards(64, 16);
    let frames: Vec<Vec<u8>> = (0..6)
        .map(|s| forces_frame(s, 50 + 10 * s as usize))
        .collect();
    let mut next = 0;
    let mut got = Vec::new();
    let mut would_block = 0;
    let mut buf = vec![0u8; FRAME_LEN_MAX];
    for _ in 0..100_000 {
        if next < frames.len() {
            match a.try_send(Face::PosX, &frames[next]) {
                Ok(()) => next += 1,
                Err(SendError::WouldBlock) => would_block += 1,
                Err(e) => panic!("{e}"),
            }
        }
        a.poll();
        if let Some(n) = b.try_recv(Face::NegX, &mut buf).unwrap() {
            got.push(buf[..n].to_vec());
        }
        if got.len() == frames.len() {
            break;
        }
    }
    assert_eq!(got, frames);
    assert!(would_block > 0, "the small FIFO must have pushed back");
}

// Property: faces without a link say NoLink; an oversized frame is refused
// with TooLong; a receive buffer too small reports BufferTooSmall and the
// link keeps working.
#[test]
fn no_link_too_long_and_small_buffer() {
    let (mut a, mut b, _, _) = two_boards(1 << 16, 1 << 16);
    let mut buf = vec![0u8; FRAME_LEN_MAX];
    assert_eq!(a.try_send(Face::NegZ, &[1, 2, 3]), Err(SendError::NoLink));
    assert_eq!(a.try_recv(Face::PosY, &mut buf), Err(RecvError::NoLink));
    assert_eq!(
        a.try_send(Face::PosX, &vec![1u8; FRAME_LEN_MAX + 1]),
        Err(SendError::TooLong)
    );

    let f = forces_frame(1, 10);
    a.try_send(Face::PosX, &f).unwrap();
    a.try_send(Face::PosX, &forces_frame(2, 10)).unwrap();
    assert_eq!(
        b.try_recv(Face::NegX, &mut buf[..10]),
        Err(RecvError::BufferTooSmall { needed: f.len() })
    );
    let n = b.try_recv(Face::NegX, &mut buf).unwrap().unwrap();
    assert_eq!(FrameRepr::parse_bytes(&buf[..n]).unwrap().step, 2);
}

// Property: bytes corrupted on the wire make try_recv report the damaged
// frame (Damaged, or a frame that fails its CRC), and the next frame is
// received intact: the link resynchronises by itself.
#[test]
fn corrupted_bytes_on_the_wire_cost_one_frame() {
    let (mut a, mut b, _, _) = two_boards(1 << 16, 1 << 16);
    a.try_send(Face::PosX, &forces_frame(1, 40)).unwrap();
    // Drop a byte in the middle of frame 1 while it sits in the FIFO.
    {
        let mut c = b
            .face_port(Face::NegX)
            .unwrap()
            .stream_mut()
            .rx
            .borrow_mut();
        let mid = c.q.len() / 2;
        c.q.remove(mid);
    }
    a.try_send(Face::PosX, &forces_frame(2, 40)).unwrap();
    let mut buf = vec![0u8; FRAME_LEN_MAX];
    let mut steps = Vec::new();
    let mut damaged = 0;
    for _ in 0..10 {
        match b.try_recv(Face::NegX, &mut buf) {
            Ok(Some(n)) => match FrameRepr::parse_bytes(&buf[..n]) {
                Ok(r) => steps.push(r.step),
                Err(_) => damaged += 1,
            },
            Ok(None) => break,
            Err(RecvError::Damaged(e)) => {
                assert!(matches!(e, Error::BadEncoding | Error::Oversized));
                damaged += 1
            }
            Err(e) => panic!("{e}"),
        }
    }
    assert_eq!(steps, vec![2]);
    assert_eq!(damaged, 1);
}

/// Firmware-style code written against the trait only (as a trait object, so
/// board-sim's emulated links can be swapped in).
fn exchange_step(links: &mut dyn Links, face: Face, step: u32, buf: &mut [u8]) -> Option<u32> {
    let f = forces_frame(step, 9);
    links.try_send(face, &f).ok()?;
    links.poll();
    let n = links.try_recv(face, buf).ok()??;
    FrameRepr::parse_bytes(&buf[..n]).ok().map(|r| r.step)
}

// Property: the trait is object-safe and `&mut L` forwards to `L`; a
// lockstep exchange through `dyn Links` delivers each side's frame to the
// other.
#[test]
fn lockstep_exchange_through_dyn_links() {
    let (mut a, mut b, _, _) = two_boards(1 << 16, 1 << 16);
    let mut buf = vec![0u8; FRAME_LEN_MAX];
    // A sends first (nothing to receive yet), B then sends and receives A's.
    assert_eq!(exchange_step(&mut *a, Face::PosX, 10, &mut buf), None);
    assert_eq!(
        exchange_step(&mut &mut *b, Face::NegX, 20, &mut buf),
        Some(10)
    );
    let n = a.try_recv(Face::PosX, &mut buf).unwrap().unwrap();
    assert_eq!(FrameRepr::parse_bytes(&buf[..n]).unwrap().step, 20);
}
