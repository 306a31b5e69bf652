//! Global recovery ([`link_proto::recovery::global`]) between several boards over a
//! scripted lossy network: lost, corrupted, duplicated and reordered envelopes, several
//! peers, retries exhausted, broadcast and a full peer table refused.

use std::cell::{Cell, RefCell};
use std::collections::{HashMap, VecDeque};
use std::rc::Rc;

use link_proto::recovery::global::{GlobalConfig, GlobalReliable};
use link_proto::{Clock, Face, Links, RecvError, SendError};

#[derive(Clone, Copy, Debug, PartialEq)]
enum Fate {
    Deliver,
    Drop,
    Corrupt,
    Twice,
    /// Held back and delivered after the next envelope to the same address.
    Late,
}

type Rule = Box<dyn FnMut(usize, &[u8]) -> Fate>;

struct Net {
    inboxes: HashMap<u8, VecDeque<Vec<u8>>>,
    late: HashMap<u8, Vec<u8>>,
    carried: usize,
    /// Bytes handed to the network: every envelope, ack and nack.
    carried_bytes: usize,
    rule: Rule,
    fates: HashMap<String, usize>,
}

impl Net {
    fn new(rule: Rule) -> Rc<RefCell<Net>> {
        Rc::new(RefCell::new(Net {
            inboxes: HashMap::new(),
            late: HashMap::new(),
            carried: 0,
            carried_bytes: 0,
            rule,
            fates: HashMap::new(),
        }))
    }

    fn route(&mut self, p: &[u8]) {
        let n = self.carried;
        self.carried += 1;
        self.carried_bytes += p.len();
        let fate = (self.rule)(n, p);
        *self.fates.entry(format!("{fate:?}")).or_default() += 1;
        let dst = p[0];
        let mut bytes = p.to_vec();
        match fate {
            Fate::Drop => return,
            Fate::Corrupt => {
                // Not the destination byte: a misrouted envelope is a loss, tested by Drop.
                let k = 8 + n % ((bytes.len() - 1) * 8);
                bytes[k / 8] ^= 1 << (k % 8);
            }
            Fate::Late => {
                if let Some(old) = self.late.insert(dst, bytes) {
                    self.inboxes.entry(dst).or_default().push_back(old);
                }
                return;
            }
            _ => {}
        }
        let q = self.inboxes.entry(dst).or_default();
        if fate == Fate::Twice {
            q.push_back(bytes.clone());
        }
        q.push_back(bytes);
        if let Some(old) = self.late.remove(&dst) {
            q.push_back(old);
        }
    }
}

struct Port {
    addr: u8,
    net: Rc<RefCell<Net>>,
}

impl Links for Port {
    fn try_send(&mut self, _: Face, _: &[u8]) -> Result<(), SendError> {
        Err(SendError::NoLink)
    }
    fn try_recv(&mut self, _: Face, _: &mut [u8]) -> Result<Option<usize>, RecvError> {
        Err(RecvError::NoLink)
    }
    fn try_send_global(&mut self, p: &[u8]) -> Result<(), SendError> {
        self.net.borrow_mut().route(p);
        Ok(())
    }
    fn try_recv_global(&mut self, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        let mut net = self.net.borrow_mut();
        let Some(p) = net.inboxes.get_mut(&self.addr).and_then(|q| q.pop_front()) else {
            return Ok(None);
        };
        buf[..p.len()].copy_from_slice(&p);
        Ok(Some(p.len()))
    }
}

struct TestClock(Rc<Cell<u64>>);

impl Clock for TestClock {
    fn now_ns(&mut self) -> u64 {
        self.0.get()
    }
}

const CONFIG: GlobalConfig = GlobalConfig {
    window: 4,
    peers_max: 4,
    tx_slots: 12,
    rx_slots: 8,
    packet_len_max: 64,
    retries: 6,
    retransmit_after_ns: 1_000_000,
    retransmit_backoff_max_ns: 8_000_000,
};

type Board = GlobalReliable<Port, TestClock, Vec<u8>>;

fn board(addr: u8, net: &Rc<RefCell<Net>>, time: &Rc<Cell<u64>>, config: GlobalConfig) -> Board {
    GlobalReliable::new(
        Port {
            addr,
            net: net.clone(),
        },
        TestClock(time.clone()),
        addr,
        config,
        vec![0u8; Board::buffer_len(&config)],
    )
    .unwrap()
}

/// Packet `k` from `src` to `dst` (a global packet, ending with its own CRC, as recovery
/// carries): the number as its message id, and a payload that depends on all three.
fn packet(src: u8, dst: u8, k: u16) -> Vec<u8> {
    let payload: Vec<u8> = (0..20u8).map(|i| i ^ src ^ dst ^ k as u8).collect();
    let repr = link_proto::PacketRepr {
        dst,
        src,
        msg_id: k,
        kind: link_proto::PacketKind::CollisionExchange,
        payload: &payload,
    };
    let mut p = vec![0u8; repr.buffer_len()];
    repr.emit(&mut p).expect("packet");
    p
}

/// Per board, per source, the packets received in order.
type Received = Vec<HashMap<u8, Vec<Vec<u8>>>>;

/// Every board sends `per_flow` packets to every other; returns what each received, per
/// source, in order, and the time it took (ns).
fn exchange(boards: &mut [Board], time: &Rc<Cell<u64>>, per_flow: u16) -> (Received, u64) {
    let addrs: Vec<u8> = (0..boards.len() as u8).collect();
    let mut next: Vec<HashMap<u8, u16>> = vec![HashMap::new(); boards.len()];
    let mut got: Received = vec![HashMap::new(); boards.len()];
    let want = per_flow as usize * (boards.len() - 1);
    let mut buf = [0u8; 128];
    for _round in 0..200_000 {
        for (b, board) in boards.iter_mut().enumerate() {
            for &d in &addrs {
                if d as usize == b {
                    continue;
                }
                let k = next[b].entry(d).or_default();
                if *k < per_flow && board.try_send_global(&packet(b as u8, d, *k)).is_ok() {
                    *k += 1;
                }
            }
            while let Some(n) = board.try_recv_global(&mut buf).unwrap() {
                got[b].entry(buf[1]).or_default().push(buf[..n].to_vec());
            }
            board.poll();
        }
        let done = got
            .iter()
            .all(|g| g.values().map(Vec::len).sum::<usize>() == want)
            && boards.iter().all(|b| b.unacknowledged() == 0);
        if done {
            return (got, time.get());
        }
        time.set(time.get() + 200_000);
    }
    panic!("the exchange did not finish");
}

fn check_in_order(got: &[HashMap<u8, Vec<Vec<u8>>>], per_flow: u16) {
    for (b, g) in got.iter().enumerate() {
        assert_eq!(g.len(), got.len() - 1, "board {b}: a flow from every other");
        for (&src, ps) in g {
            let expect: Vec<Vec<u8>> = (0..per_flow).map(|k| packet(src, b as u8, k)).collect();
            assert_eq!(ps.len(), expect.len(), "{src} -> {b}");
            assert!(*ps == expect, "{src} -> {b}: every packet once, in order");
        }
    }
}

/// A clean network: every packet once, in order, nothing sent again (the clock moves
/// slower than the acks).
#[test]
fn clean_network_delivers_in_order_without_retransmission() {
    let time = Rc::new(Cell::new(0));
    let net = Net::new(Box::new(|_, _| Fate::Deliver));
    let mut boards: Vec<Board> = (0..4).map(|a| board(a, &net, &time, CONFIG)).collect();
    let (got, _) = exchange(&mut boards, &time, 50);
    check_in_order(&got, 50);
    for b in &boards {
        let s = b.stats();
        assert_eq!(s.data_packets, 150);
        assert_eq!(s.retransmitted_packets, 0);
        assert_eq!(s.peers, 3);
        assert!(s.acks_sent > 0);
    }
}

/// Drops, corruption, duplicates and reordering on every flow between four boards: every
/// packet still arrives once and in order, and the statistics show each was met; also with
/// 5 send slots shared by the 3 peers of a board (fewer than their windows: the shared
/// pool's flow control).
#[test]
fn lossy_network_delivers_every_flow_in_order() {
    for tx_slots in [12, 5] {
        lossy_exchange(GlobalConfig { tx_slots, ..CONFIG });
    }
}

fn lossy_exchange(config: GlobalConfig) {
    let time = Rc::new(Cell::new(0));
    let net = Net::new(Box::new(|n, _| match n % 23 {
        3 | 17 => Fate::Drop,
        5 | 11 => Fate::Corrupt,
        7 => Fate::Twice,
        13 => Fate::Late,
        _ => Fate::Deliver,
    }));
    let mut boards: Vec<Board> = (0..4).map(|a| board(a, &net, &time, config)).collect();
    let (got, _) = exchange(&mut boards, &time, 200);
    check_in_order(&got, 200);
    let sum = |f: fn(&link_proto::recovery::GlobalRecovery) -> u64| {
        boards.iter().map(|b| f(b.stats())).sum::<u64>()
    };
    let fates = &net.borrow().fates;
    assert!(fates["Drop"] > 100 && fates["Corrupt"] > 100 && fates["Twice"] > 50);
    assert!(sum(|s| s.retransmitted_packets) > 0);
    assert!(sum(|s| s.damaged) > 0);
    assert!(sum(|s| s.duplicates) > 0);
    assert!(sum(|s| s.gaps) > 0);
    assert!(sum(|s| s.nacks_sent) > 0);
    assert_eq!(sum(|s| s.data_packets), 4 * 3 * 200);
    assert!(boards.iter().all(|b| b.failure().is_none()));
    // The overhead the reports give is what the network carried beyond the payloads,
    // counted at the network: envelopes, retransmissions, acks and nacks.
    let payload_bytes = 4 * 3 * 200 * packet(0, 1, 0).len() as u64;
    let carried = net.borrow().carried_bytes as u64;
    let overhead = sum(|s| s.overhead_bytes());
    assert!(
        overhead > payload_bytes / 2,
        "a lossy run's overhead: {overhead}"
    );
    assert_eq!(overhead, carried - payload_bytes, "bytes carried {carried}");
}

/// Everything from board 0 to board 1 lost: board 0 gives up the flow after `retries`
/// retransmissions with the backoff's bounded wait, names the peer and the packet, and
/// refuses later sends; the other flows are not affected.
#[test]
fn retries_exhausted_gives_up_the_flow_naming_the_peer() {
    let time = Rc::new(Cell::new(0));
    let net = Net::new(Box::new(|_, p| {
        if p[0] == 1 && p[1] == 0 {
            Fate::Drop
        } else {
            Fate::Deliver
        }
    }));
    let mut boards: Vec<Board> = (0..3).map(|a| board(a, &net, &time, CONFIG)).collect();
    boards[0].try_send_global(&packet(0, 1, 0)).unwrap();
    boards[0].try_send_global(&packet(0, 2, 0)).unwrap();
    let mut buf = [0u8; 128];
    let mut error = None;
    for _ in 0..10_000 {
        for b in boards.iter_mut().skip(1) {
            while let Some(_n) = b.try_recv_global(&mut buf).unwrap() {}
        }
        match boards[0].try_recv_global(&mut buf) {
            Ok(_) => {}
            Err(e) => {
                error = Some(e);
                break;
            }
        }
        time.set(time.get() + 100_000);
    }
    assert_eq!(
        error,
        Some(RecvError::GlobalRetriesExhausted {
            peer: 1,
            seq: 0,
            requests: CONFIG.retries
        })
    );
    assert_eq!(boards[0].failure(), Some((1, 0, CONFIG.retries)));
    // 1 + 2 + 4 + 8 ms, then 8 ms each: bounded.
    let bound = 1 + 2 + 4 + 8 + 8 * (CONFIG.retries as u64 - 3) + 1;
    assert!(
        time.get() <= bound * 1_000_000,
        "gave up after {} ns",
        time.get()
    );
    assert_eq!(
        boards[0].stats().retransmitted_packets,
        CONFIG.retries as u64
    );
    // The flow to board 2 was acknowledged.
    assert_eq!(boards[0].unacknowledged(), 1);
    assert_eq!(
        boards[0].try_send_global(&packet(0, 2, 1)),
        Err(SendError::NoLink)
    );
}

/// Broadcast is refused (no flow to acknowledge it), and so is a new peer beyond the table.
#[test]
fn broadcast_and_a_full_peer_table_are_refused() {
    let time = Rc::new(Cell::new(0));
    let net = Net::new(Box::new(|_, _| Fate::Deliver));
    let config = GlobalConfig {
        peers_max: 2,
        ..CONFIG
    };
    let mut a = board(0, &net, &time, config);
    assert_eq!(
        a.try_send_global(&packet(0, link_proto::packet::ADDR_BROADCAST, 0)),
        Err(SendError::NoLink)
    );
    a.try_send_global(&packet(0, 1, 0)).unwrap();
    a.try_send_global(&packet(0, 2, 0)).unwrap();
    assert_eq!(a.try_send_global(&packet(0, 3, 0)), Err(SendError::NoLink));
    assert_eq!(a.stats().peers, 2);
    assert!(net.borrow().inboxes.get(&3).is_none_or(|q| q.is_empty()));
    // A window's worth to one peer, then flow control.
    for k in 1..CONFIG.window as u16 {
        a.try_send_global(&packet(0, 1, k)).unwrap();
    }
    assert_eq!(
        a.try_send_global(&packet(0, 1, 9)),
        Err(SendError::WouldBlock)
    );
}

/// One packet corrupted on every transmission while later ones get through (each one beyond
/// the gap answered with a nack): the sender retransmits a bounded number of times (nacks
/// for the same packet do not each start a retransmission of the window) and gives up.
#[test]
fn a_packet_always_corrupted_is_given_up_without_a_retransmission_storm() {
    use link_proto::recovery::global::code;
    let time = Rc::new(Cell::new(0));
    let net = Net::new(Box::new(|_, p| {
        if p[1] == 0 && p[2] == code::DATA && p[4] == 0 && p[5] == 0 {
            Fate::Corrupt
        } else {
            Fate::Deliver
        }
    }));
    let mut boards: Vec<Board> = (0..2).map(|a| board(a, &net, &time, CONFIG)).collect();
    let mut buf = [0u8; 128];
    let mut sent = 0u16;
    let mut error = None;
    for _ in 0..10_000 {
        if sent < 4 && boards[0].try_send_global(&packet(0, 1, sent)).is_ok() {
            sent += 1;
        }
        while let Some(_n) = boards[1].try_recv_global(&mut buf).unwrap() {}
        if let Err(e) = boards[0].try_recv_global(&mut buf) {
            error = Some(e);
            break;
        }
        time.set(time.get() + 100_000);
    }
    assert!(matches!(
        error,
        Some(RecvError::GlobalRetriesExhausted {
            peer: 1,
            seq: 0,
            ..
        })
    ));
    let s = *boards[0].stats();
    assert!(s.nacks_received > 0);
    // Per timeout at most the window again, and once more per distinct nack.
    let bound = (CONFIG.retries as u64 + 1) * 2 * CONFIG.window as u64;
    assert!(
        s.retransmitted_packets <= bound,
        "{} retransmissions",
        s.retransmitted_packets
    );
    assert!(
        net.borrow().carried < 200,
        "{} envelopes",
        net.borrow().carried
    );
}

/// Every single-bit change to a data envelope is refused (`Damaged`): header, packet, the
/// packet's own CRC, the envelope's CRC. The envelope's CRC covers ten bytes, the packet's
/// CRC the rest; the intact envelope gives the packet back. Bytes without their own CRC
/// are refused however the envelope was made.
#[test]
fn every_bit_of_a_global_data_envelope_is_checked() {
    use link_proto::recovery::global::{emit_data, parse, Envelope};
    use link_proto::recovery::OVERHEAD;
    let p = packet(3, 9, 41);
    let mut e = vec![0u8; p.len() + OVERHEAD];
    assert_eq!(emit_data(&p, 7, &mut e), Some(e.len()));
    assert_eq!(
        parse(&e),
        Envelope::Data {
            src: 3,
            seq: 7,
            packet: &p
        }
    );
    assert!(p.len() > 20 && p.iter().any(|&b| b != 0));
    for bit in 0..e.len() * 8 {
        let mut d = e.clone();
        d[bit / 8] ^= 1 << (bit % 8);
        assert_eq!(parse(&d), Envelope::Damaged, "bit {bit}");
    }
    let mut not_a_packet = p.clone();
    let last = not_a_packet.len() - 1;
    not_a_packet[last] ^= 0x40;
    assert_eq!(emit_data(&not_a_packet, 8, &mut e), Some(e.len()));
    assert_eq!(parse(&e), Envelope::Damaged);
    assert_eq!(
        emit_data(&[9, 3, 0], 8, &mut e),
        None,
        "shorter than its CRC"
    );
}

/// What an observer reads of a global envelope without checking it: the destination of a
/// packet and of the data envelope carrying it is the packet's, a control envelope names
/// its own destination and type, the carried packet comes back whole, and bytes too short
/// for a field give none.
#[test]
fn an_observer_reads_destination_and_type_of_an_envelope() {
    use link_proto::recovery::global::{
        code, control, data_packet, destination, emit_data, envelope_type,
    };
    let p = packet(3, 9, 7);
    assert!(
        p.len() > link_proto::PACKET_HEADER_LEN,
        "a packet with a payload"
    );
    assert_eq!(destination(&p), Some(9));
    let mut e = vec![0u8; link_proto::enveloped_len(p.len())];
    let n = emit_data(&p, 41, &mut e).expect("an envelope");
    assert_eq!(n, e.len());
    assert_eq!(destination(&e), Some(9));
    assert_eq!(envelope_type(&e), Some(code::DATA));
    assert_eq!(data_packet(&e), Some(&p[..]));
    let ack = control(5, 9, code::ACK, 42);
    assert_eq!(
        (destination(&ack), envelope_type(&ack)),
        (Some(5), Some(code::ACK))
    );
    assert_eq!(data_packet(&ack), None);
    assert_eq!((destination(&[]), envelope_type(&[9, 3])), (None, None));
}
