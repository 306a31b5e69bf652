//! Face recovery ([`link_proto::recovery::face`]) between two boards over a scripted wire:
//! lost data frames, lost nacks, corrupted and duplicated frames, retries exhausted.

use std::cell::{Cell, RefCell};
use std::collections::VecDeque;
use std::rc::Rc;

use link_proto::recovery::face::{code, Reliable, ReliableConfig};
use link_proto::{
    Clock, Face, FrameKind, FrameRepr, Links, Payload, Peek, Precision, RecvError, SendError,
};

/// What the wire does to the n-th envelope it carries in one direction.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fate {
    Deliver,
    Drop,
    Corrupt,
    /// This bit of the envelope flipped (bit `i % 8` of byte `i / 8`).
    Flip(usize),
    Twice,
}

type Rule = Box<dyn FnMut(usize, &[u8]) -> Fate>;

struct Wire {
    queue: VecDeque<Vec<u8>>,
    carried: usize,
    rule: Rule,
    /// Envelope types carried, in order (after the rule).
    log: Vec<(u8, Fate)>,
}

impl Wire {
    fn new(rule: Rule) -> Rc<RefCell<Wire>> {
        Rc::new(RefCell::new(Wire {
            queue: VecDeque::new(),
            carried: 0,
            rule,
            log: Vec::new(),
        }))
    }
}

/// A face of a board with its outgoing and incoming wires.
type FaceWires = (Face, Rc<RefCell<Wire>>, Rc<RefCell<Wire>>);

/// One board's ends: on each face it has, sends into `out` and receives from `inp`;
/// with `peeks`, it tells the next envelope's type without taking it (as board-sim's
/// links do), else it cannot ([`Peek::Unknown`], as a byte stream).
struct End {
    faces: Vec<FaceWires>,
    peeks: bool,
}

impl End {
    fn one(face: Face, out: &Rc<RefCell<Wire>>, inp: &Rc<RefCell<Wire>>) -> End {
        End {
            faces: vec![(face, out.clone(), inp.clone())],
            peeks: true,
        }
    }
    fn wires(&self, face: Face) -> Option<&FaceWires> {
        self.faces.iter().find(|(f, _, _)| *f == face)
    }
}

impl Links for End {
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        let Some((_, out, _)) = self.wires(face) else {
            return Err(SendError::NoLink);
        };
        let mut w = out.borrow_mut();
        let n = w.carried;
        w.carried += 1;
        let fate = (w.rule)(n, frame);
        w.log.push((frame[0], fate));
        match fate {
            Fate::Deliver => w.queue.push_back(frame.to_vec()),
            Fate::Drop => {}
            Fate::Corrupt => {
                let mut b = frame.to_vec();
                let k = b.len() / 2;
                b[k] ^= 0x10;
                w.queue.push_back(b);
            }
            Fate::Flip(i) => {
                let mut b = frame.to_vec();
                b[i / 8] ^= 1 << (i % 8);
                w.queue.push_back(b);
            }
            Fate::Twice => {
                w.queue.push_back(frame.to_vec());
                w.queue.push_back(frame.to_vec());
            }
        }
        Ok(())
    }
    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        let Some((_, _, inp)) = self.wires(face) else {
            return Err(RecvError::NoLink);
        };
        match inp.borrow_mut().queue.pop_front() {
            None => Ok(None),
            Some(f) => {
                buf[..f.len()].copy_from_slice(&f);
                Ok(Some(f.len()))
            }
        }
    }
    fn peek(&mut self, face: Face) -> Peek {
        match self.wires(face) {
            Some((_, _, inp)) if self.peeks => match inp.borrow().queue.front() {
                None => Peek::Nothing,
                Some(e) => Peek::First(e[0]),
            },
            Some(_) => Peek::Unknown,
            None => Peek::Nothing,
        }
    }
    fn try_send_global(&mut self, _: &[u8]) -> Result<(), SendError> {
        Err(SendError::NoLink)
    }
    fn try_recv_global(&mut self, _: &mut [u8]) -> Result<Option<usize>, RecvError> {
        Ok(None)
    }
}

#[derive(Clone)]
struct Manual(Rc<Cell<u64>>);
impl Clock for Manual {
    fn now_ns(&mut self) -> u64 {
        self.0.get()
    }
}

type Board = Reliable<End, Manual, Vec<u8>>;

const CONFIG: ReliableConfig = ReliableConfig {
    window: 4,
    frame_len_max: 64,
    retries: 3,
    nack_after_ns: 1000,
    nack_backoff_max_ns: 4000,
};

/// Board A (sending on +x) and B (receiving on −x), the wires A→B and B→A, the clock.
/// The two boards, the wires A→B and B→A, and the clock.
type Pair = (
    Board,
    Board,
    Rc<RefCell<Wire>>,
    Rc<RefCell<Wire>>,
    Rc<Cell<u64>>,
);

fn pair(a_to_b: Rule, b_to_a: Rule) -> Pair {
    let (ab, ba) = (Wire::new(a_to_b), Wire::new(b_to_a));
    let t = Rc::new(Cell::new(0));
    let buf = || vec![0u8; Board::buffer_len(&CONFIG)];
    let a = Reliable::new(
        End::one(Face::PosX, &ab, &ba),
        Manual(t.clone()),
        CONFIG,
        buf(),
    )
    .unwrap();
    let b = Reliable::new(
        End::one(Face::NegX, &ba, &ab),
        Manual(t.clone()),
        CONFIG,
        buf(),
    )
    .unwrap();
    (a, b, ab, ba, t)
}

/// Link frame `k` (what recovery carries: it ends with its own CRC-32), 36 bytes.
fn frame(k: u8) -> Vec<u8> {
    let raw: Vec<u8> = (0..24)
        .map(|i| k.wrapping_mul(31).wrapping_add(i))
        .collect();
    let repr = FrameRepr {
        kind: FrameKind::Forces,
        step: u32::from(k),
        payload: Payload::new(Precision::F32, &raw).unwrap(),
    };
    let mut buf = vec![0u8; repr.buffer_len()];
    let n = repr.emit(&mut buf).unwrap();
    buf.truncate(n);
    buf
}

/// Receive buffers: one too short for an envelope (frames go through the receive slots)
/// and one that holds any (the next frame in order goes straight into it).
const SLOTTED: usize = 64;
const DIRECT: usize = 64 + link_proto::recovery::OVERHEAD;

/// Receives on B into a buffer of `len` bytes until a frame arrives, moving the clock
/// 500 ns per try and letting A answer (as its own loop would); at most `tries`.
fn recv_in(
    a: &mut Board,
    b: &mut Board,
    t: &Cell<u64>,
    len: usize,
    tries: usize,
) -> Result<Vec<u8>, RecvError> {
    let mut buf = vec![0u8; len];
    for _ in 0..tries {
        if let Some(n) = b.try_recv(Face::NegX, &mut buf)? {
            return Ok(buf[..n].to_vec());
        }
        a.poll();
        t.set(t.get() + 500);
    }
    panic!("nothing arrived in {tries} tries");
}

/// [`recv_in`] through the receive slots.
fn recv(a: &mut Board, b: &mut Board, t: &Cell<u64>, tries: usize) -> Result<Vec<u8>, RecvError> {
    recv_in(a, b, t, SLOTTED, tries)
}

fn fates(w: &Rc<RefCell<Wire>>, kind: u8) -> usize {
    w.borrow().log.iter().filter(|(k, _)| *k == kind).count()
}

/// A lost data frame is noticed at the next one (a gap), asked for and sent again: the
/// receiver gets every frame once, in order, with the same bytes.
#[test]
fn a_lost_data_frame_is_retransmitted() {
    let (mut a, mut b, ab, ba, t) = pair(
        Box::new(|n, _| if n == 1 { Fate::Drop } else { Fate::Deliver }),
        Box::new(|_, _| Fate::Deliver),
    );
    for k in 0..3 {
        a.try_send(Face::PosX, &frame(k)).unwrap();
    }
    for k in 0..3 {
        assert_eq!(recv(&mut a, &mut b, &t, 20).unwrap(), frame(k), "frame {k}");
    }
    // The nack went out at the gap (before any wait), and frames 1 and 2 again.
    assert!(fates(&ba, code::NACK) >= 1);
    assert_eq!(a.stats()[Face::PosX.index()].retransmitted_frames, 2);
    assert_eq!(b.stats()[Face::NegX.index()].gaps, 1);
    assert_eq!(fates(&ab, code::DATA), 5);
}

/// What face recovery says it added (`FaceRecovery::overhead_bytes`) is every byte the
/// sender put on the wire beyond its frames: envelopes, retransmissions, its acks.
#[test]
fn the_overhead_is_what_was_sent_beyond_the_frames() {
    let on_wire = Rc::new(Cell::new(0usize));
    let counted = on_wire.clone();
    let (mut a, mut b, _ab, _ba, t) = pair(
        Box::new(move |n, e| {
            counted.set(counted.get() + e.len());
            if n == 1 {
                Fate::Drop
            } else {
                Fate::Deliver
            }
        }),
        Box::new(|_, _| Fate::Deliver),
    );
    let frames: usize = (0..3).map(|k| frame(k).len()).sum();
    for k in 0..3 {
        a.try_send(Face::PosX, &frame(k)).unwrap();
    }
    for k in 0..3 {
        assert_eq!(recv(&mut a, &mut b, &t, 20).unwrap(), frame(k), "frame {k}");
    }
    let s = a.stats()[Face::PosX.index()];
    assert_eq!(s.retransmitted_frames, 2, "frames 1 and 2 sent again");
    assert!(s.overhead_bytes() >= 3 * 10 + 2 * 46, "{s:?}");
    assert_eq!(s.overhead_bytes(), (on_wire.get() - frames) as u64);
}

/// The last frame of a burst lost: nothing follows to reveal it, so the receiver's wait
/// asks for it.
#[test]
fn a_lost_last_frame_is_asked_for_after_a_wait() {
    let (mut a, mut b, _ab, _ba, t) = pair(
        Box::new(|n, _| if n == 0 { Fate::Drop } else { Fate::Deliver }),
        Box::new(|_, _| Fate::Deliver),
    );
    a.try_send(Face::PosX, &frame(7)).unwrap();
    assert_eq!(recv(&mut a, &mut b, &t, 20).unwrap(), frame(7));
    assert!(t.get() >= CONFIG.nack_after_ns, "after one wait");
    assert_eq!(b.stats()[Face::NegX.index()].nacks_sent, 1);
}

/// The nack itself lost: the receiver asks again after a longer wait.
#[test]
fn a_lost_nack_is_sent_again() {
    let (mut a, mut b, _ab, ba, t) = pair(
        Box::new(|n, _| if n == 0 { Fate::Drop } else { Fate::Deliver }),
        Box::new(|n, _| if n == 0 { Fate::Drop } else { Fate::Deliver }),
    );
    a.try_send(Face::PosX, &frame(3)).unwrap();
    assert_eq!(recv(&mut a, &mut b, &t, 40).unwrap(), frame(3));
    let log = ba.borrow().log.clone();
    assert_eq!(log[0], (code::NACK, Fate::Drop), "{log:?}");
    assert!(b.stats()[Face::NegX.index()].nacks_sent >= 2);
}

/// A corrupted frame fails its CRC: asked for at once, the copy sent again is delivered
/// intact.
#[test]
fn a_corrupted_frame_is_replaced() {
    let (mut a, mut b, _ab, _ba, t) = pair(
        Box::new(|n, _| if n == 0 { Fate::Corrupt } else { Fate::Deliver }),
        Box::new(|_, _| Fate::Deliver),
    );
    a.try_send(Face::PosX, &frame(9)).unwrap();
    a.try_send(Face::PosX, &frame(10)).unwrap();
    assert_eq!(recv(&mut a, &mut b, &t, 20).unwrap(), frame(9));
    assert_eq!(recv(&mut a, &mut b, &t, 20).unwrap(), frame(10));
    let s = b.stats()[Face::NegX.index()];
    assert_eq!(s.damaged, 1);
    assert!(s.nacks_sent >= 1);
}

/// A frame delivered twice is taken once.
#[test]
fn a_duplicate_is_taken_once() {
    let (mut a, mut b, _ab, _ba, t) = pair(
        Box::new(|n, _| if n == 0 { Fate::Twice } else { Fate::Deliver }),
        Box::new(|_, _| Fate::Deliver),
    );
    a.try_send(Face::PosX, &frame(1)).unwrap();
    a.try_send(Face::PosX, &frame(2)).unwrap();
    assert_eq!(recv(&mut a, &mut b, &t, 20).unwrap(), frame(1));
    assert_eq!(recv(&mut a, &mut b, &t, 20).unwrap(), frame(2));
    assert_eq!(b.stats()[Face::NegX.index()].duplicates, 1);
    let mut buf = [0u8; 64];
    assert_eq!(b.try_recv(Face::NegX, &mut buf), Ok(None), "nothing more");
}

/// Every copy lost: after `retries` requests the receiver gives up with an error naming
/// the frame.
#[test]
fn retries_exhausted_is_an_error() {
    let (mut a, mut b, ab, _ba, t) =
        pair(Box::new(|_, _| Fate::Drop), Box::new(|_, _| Fate::Deliver));
    a.try_send(Face::PosX, &frame(5)).unwrap();
    let e = recv(&mut a, &mut b, &t, 1000).unwrap_err();
    assert_eq!(
        e,
        RecvError::RetriesExhausted {
            seq: 0,
            requests: CONFIG.retries
        }
    );
    // One first transmission and one retransmission per request.
    assert_eq!(fates(&ab, code::DATA), 1 + CONFIG.retries as usize);
    assert!(e.to_string().contains("frame 0"), "{e}");
}

/// A slow sender is not a lost frame: it answers "not sent yet" and the count starts again.
#[test]
fn a_slow_sender_is_not_given_up() {
    let (mut a, mut b, _ab, ba, t) = pair(
        Box::new(|_, _| Fate::Deliver),
        Box::new(|_, _| Fate::Deliver),
    );
    let mut buf = [0u8; 64];
    for _ in 0..200 {
        assert_eq!(b.try_recv(Face::NegX, &mut buf), Ok(None));
        a.poll();
        t.set(t.get() + 500);
    }
    assert!(
        fates(&ba, code::NACK) > CONFIG.retries as usize,
        "asked many times"
    );
    a.try_send(Face::PosX, &frame(4)).unwrap();
    assert_eq!(recv(&mut a, &mut b, &t, 20).unwrap(), frame(4));
}

/// The window bounds what is kept: a sender that is not acknowledged blocks, and an ack
/// frees it.
#[test]
fn the_window_blocks_until_acknowledged() {
    let (mut a, mut b, _ab, _ba, t) = pair(
        Box::new(|_, _| Fate::Deliver),
        Box::new(|_, _| Fate::Deliver),
    );
    for k in 0..CONFIG.window as u8 {
        a.try_send(Face::PosX, &frame(k)).unwrap();
    }
    assert_eq!(
        a.try_send(Face::PosX, &frame(99)),
        Err(SendError::WouldBlock)
    );
    for k in 0..CONFIG.window as u8 {
        assert_eq!(recv(&mut a, &mut b, &t, 20).unwrap(), frame(k));
    }
    a.try_send(Face::PosX, &frame(99)).unwrap();
    assert_eq!(recv(&mut a, &mut b, &t, 20).unwrap(), frame(99));
}

/// The same faults give the same frames, in order, whether frames go straight into the caller's buffer (one large enough for an envelope) or through the
/// receive slots; and straight in, frames not yet asked for stay on the link (they are
/// not read ahead into slots).
#[test]
fn a_buffer_that_holds_an_envelope_takes_frames_straight_from_the_link() {
    let mut counts = Vec::new();
    for len in [SLOTTED, DIRECT] {
        let (mut a, mut b, ab, _ba, t) = pair(
            Box::new(|n, _| match n {
                1 => Fate::Drop,
                4 => Fate::Corrupt,
                6 => Fate::Twice,
                _ => Fate::Deliver,
            }),
            Box::new(|_, _| Fate::Deliver),
        );
        for k in 0..3 {
            a.try_send(Face::PosX, &frame(k)).unwrap();
        }
        assert_eq!(recv_in(&mut a, &mut b, &t, len, 20).unwrap(), frame(0));
        let left = ab.borrow().queue.len();
        assert_eq!(
            left,
            if len == DIRECT { 1 } else { 0 },
            "envelopes left on the link after the first delivery, buffer of {len} bytes"
        );
        let mut got = vec![frame(0)];
        for k in 3..CONFIG.window as u8 {
            a.try_send(Face::PosX, &frame(k)).unwrap();
        }
        for _ in 1..CONFIG.window {
            got.push(recv_in(&mut a, &mut b, &t, len, 40).unwrap());
        }
        let sent: Vec<Vec<u8>> = (0..CONFIG.window as u8).map(frame).collect();
        assert_eq!(got.len(), sent.len());
        assert!(sent
            .iter()
            .all(|f| f.len() == 36 && f.iter().any(|&x| x != 0)));
        assert_eq!(got, sent, "buffer of {len} bytes");
        let s = b.stats()[Face::NegX.index()];
        counts.push((s.damaged, s.gaps, s.duplicates));
    }
    // Both saw the corrupted envelope and the gap the lost one left (how many later
    // envelopes also arrived beyond a gap depends on when each reads its link).
    assert!(
        counts
            .iter()
            .all(|&(damaged, gaps, _)| damaged == 1 && gaps >= 1),
        "(damaged, gaps, duplicates): {counts:?}"
    );
}

/// Every single-bit change to a data envelope is caught (header, frame, the frame's CRC,
/// the envelope's CRC), and the frame is sent again and delivered intact: the envelope's
/// CRC covers ten bytes, the frame's own CRC the rest.
#[test]
fn every_bit_of_a_data_envelope_is_checked() {
    let bits = (frame(7).len() + link_proto::recovery::OVERHEAD) * 8;
    assert_eq!(bits, 46 * 8);
    assert!(
        frame(7).iter().filter(|&&b| b != 0).count() > 20,
        "a frame far from zeros"
    );
    for bit in 0..bits {
        for len in [SLOTTED, DIRECT] {
            let (mut a, mut b, _ab, _ba, t) = pair(
                Box::new(move |n, _| {
                    if n == 0 {
                        Fate::Flip(bit)
                    } else {
                        Fate::Deliver
                    }
                }),
                Box::new(|_, _| Fate::Deliver),
            );
            a.try_send(Face::PosX, &frame(7)).unwrap();
            assert_eq!(
                recv_in(&mut a, &mut b, &t, len, 40).unwrap(),
                frame(7),
                "bit {bit}, buffer of {len} bytes"
            );
            let s = b.stats()[Face::NegX.index()];
            assert_eq!((s.damaged, s.gaps), (1, 0), "bit {bit}");
        }
    }
}

/// Recovery carries link frames: bytes that do not end with their own CRC-32 are damaged
/// to every receiver, and after its requests the receiver gives up; bytes shorter than a
/// CRC are refused at the sender.
#[test]
fn bytes_that_are_not_a_frame_are_not_delivered() {
    let (mut a, mut b, ab, _ba, t) = pair(
        Box::new(|_, _| Fate::Deliver),
        Box::new(|_, _| Fate::Deliver),
    );
    let mut not_a_frame = frame(3);
    let last = not_a_frame.len() - 1;
    not_a_frame[last] ^= 0xff;
    a.try_send(Face::PosX, &not_a_frame).unwrap();
    let e = recv_in(&mut a, &mut b, &t, DIRECT, 1000).unwrap_err();
    assert!(
        matches!(e, RecvError::RetriesExhausted { seq: 0, .. }),
        "{e:?}"
    );
    assert!(b.stats()[Face::NegX.index()].damaged > CONFIG.retries as u64);
    assert_eq!(fates(&ab, code::DATA), 1 + CONFIG.retries as usize);
    assert_eq!(
        a.try_send(Face::PosX, &[1, 2, 3]),
        Err(SendError::NotAFrame)
    );
}

/// A board waiting on one face still answers the others, once its wait has lasted half
/// `nack_after_ns`: B waits on −x for A (who sends nothing) while its frame to C on +y was
/// lost; C's nack is read and the frame sent again, before C's requests run out.
#[test]
fn a_waiting_board_answers_the_nacks_of_its_other_faces() {
    let (ab, ba) = (
        Wire::new(Box::new(|_, _| Fate::Deliver)),
        Wire::new(Box::new(|_, _| Fate::Deliver)),
    );
    let (bc, cb) = (
        Wire::new(Box::new(
            |n, _| if n == 0 { Fate::Drop } else { Fate::Deliver },
        )),
        Wire::new(Box::new(|_, _| Fate::Deliver)),
    );
    let t = Rc::new(Cell::new(0));
    let buf = || vec![0u8; Board::buffer_len(&CONFIG)];
    let board = |end: End| Reliable::new(end, Manual(t.clone()), CONFIG, buf()).unwrap();
    let _a = board(End::one(Face::PosX, &ab, &ba));
    let mut b = board(End {
        faces: vec![
            (Face::NegX, ba.clone(), ab.clone()),
            (Face::PosY, bc.clone(), cb.clone()),
        ],
        peeks: true,
    });
    let mut c = board(End::one(Face::NegY, &cb, &bc));
    b.try_send(Face::PosY, &frame(6)).unwrap();
    let (mut got, mut rx) = (None, vec![0u8; DIRECT]);
    for _ in 0..2000 {
        // B's loop: waiting on −x (nothing comes), polling its links as the runtime does.
        assert_eq!(b.try_recv(Face::NegX, &mut rx), Ok(None));
        b.poll();
        // C's loop: waiting for B's frame.
        let mut buf = vec![0u8; DIRECT];
        if let Some(n) = c.try_recv(Face::NegY, &mut buf).unwrap() {
            got = Some(buf[..n].to_vec());
            break;
        }
        t.set(t.get() + 100);
    }
    assert_eq!(got, Some(frame(6)), "C got B's frame");
    let s = b.stats()[Face::PosY.index()];
    assert_eq!(s.retransmitted_frames, 1, "{s:?}");
    assert!(s.nacks_received >= 1);
    assert!(c.stats()[Face::NegY.index()].nacks_sent < CONFIG.retries as u64);
}

/// A nack for a frame not sent yet (the receiver's wait ran out first) is read before the
/// frame goes out, and answered "not yet": the frame is sent once, not again for a request
/// that crossed it. With a link that can look ahead, the sender reads only the nack at the
/// head (a data envelope behind it stays on the link); with one that cannot, all of it.
#[test]
fn a_nack_that_crosses_its_frame_is_answered_not_yet() {
    for peeks in [true, false] {
        let (mut a, mut b, ab, ba, t) = pair(
            Box::new(|_, _| Fate::Deliver),
            Box::new(|_, _| Fate::Deliver),
        );
        a.inner_mut().peeks = peeks;
        // B waits past nack_after_ns for frame 0 of A's, which A has not sent.
        let mut buf = vec![0u8; DIRECT];
        while fates(&ba, code::NACK) == 0 {
            assert_eq!(b.try_recv(Face::NegX, &mut buf), Ok(None));
            t.set(t.get() + 100);
        }
        // B sends A a frame behind its nack; then A sends its frame 0.
        b.try_send(Face::NegX, &frame(1)).unwrap();
        assert_eq!(ba.borrow().queue.len(), 2, "the nack, then B's frame");
        a.try_send(Face::PosX, &frame(0)).unwrap();
        assert_eq!(
            ba.borrow().queue.len(),
            if peeks { 1 } else { 0 },
            "what A left on its link (peeks: {peeks})"
        );
        assert_eq!(recv_in(&mut a, &mut b, &t, DIRECT, 20).unwrap(), frame(0));
        let sa = a.stats()[Face::PosX.index()];
        assert_eq!(sa.nacks_received, 1, "peeks: {peeks}");
        assert_eq!(sa.statuses_sent, 1, "answered not yet (peeks: {peeks})");
        assert_eq!(sa.retransmitted_frames, 0, "peeks: {peeks}");
        assert_eq!(fates(&ab, code::DATA), 1);
        let mut got = vec![0u8; DIRECT];
        let n = a
            .try_recv(Face::PosX, &mut got)
            .unwrap()
            .expect("B's frame");
        assert_eq!(got[..n], frame(1)[..]);
    }
}
