//! Link recovery ([`link_proto::reliable`]) between two boards over a scripted wire:
//! lost data frames, lost nacks, corrupted and duplicated frames, retries exhausted.

use std::cell::{Cell, RefCell};
use std::collections::VecDeque;
use std::rc::Rc;

use link_proto::reliable::{code, Clock, Reliable, ReliableConfig};
use link_proto::{Face, Links, RecvError, SendError};

/// What the wire does to the n-th envelope it carries in one direction.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fate {
    Deliver,
    Drop,
    Corrupt,
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

/// One board's end: sends on `face` into `out`, receives from `inp`.
struct End {
    face: Face,
    out: Rc<RefCell<Wire>>,
    inp: Rc<RefCell<Wire>>,
}

impl Links for End {
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        if face != self.face {
            return Err(SendError::NoLink);
        }
        let mut w = self.out.borrow_mut();
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
            Fate::Twice => {
                w.queue.push_back(frame.to_vec());
                w.queue.push_back(frame.to_vec());
            }
        }
        Ok(())
    }
    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        if face != self.face {
            return Err(RecvError::NoLink);
        }
        match self.inp.borrow_mut().queue.pop_front() {
            None => Ok(None),
            Some(f) => {
                buf[..f.len()].copy_from_slice(&f);
                Ok(Some(f.len()))
            }
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
        End {
            face: Face::PosX,
            out: ab.clone(),
            inp: ba.clone(),
        },
        Manual(t.clone()),
        CONFIG,
        buf(),
    )
    .unwrap();
    let b = Reliable::new(
        End {
            face: Face::NegX,
            out: ba.clone(),
            inp: ab.clone(),
        },
        Manual(t.clone()),
        CONFIG,
        buf(),
    )
    .unwrap();
    (a, b, ab, ba, t)
}

fn frame(k: u8) -> Vec<u8> {
    (0..20)
        .map(|i| k.wrapping_mul(31).wrapping_add(i))
        .collect()
}

/// Receives on B until a frame arrives, moving the clock 500 ns per try and letting A
/// answer (as its own loop would); at most `tries`.
fn recv(a: &mut Board, b: &mut Board, t: &Cell<u64>, tries: usize) -> Result<Vec<u8>, RecvError> {
    let mut buf = [0u8; 64];
    for _ in 0..tries {
        if let Some(n) = b.try_recv(Face::NegX, &mut buf)? {
            return Ok(buf[..n].to_vec());
        }
        a.poll();
        t.set(t.get() + 500);
    }
    panic!("nothing arrived in {tries} tries");
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
