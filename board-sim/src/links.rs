//! Emulated point-to-point links and global network between board threads, and the fault
//! injector that wraps a board's links.
//!
//! Each directed link is a bounded queue; a sender rings the receiving board's doorbell so a
//! waiting board can park instead of spinning. All randomness of the fault injector comes
//! from one seed (printed at the start of a run) mixed with the board and face, so a run
//! replays exactly.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use link_proto::{Face, Links, RecvError, SendError};
use pe_firmware::runtime::Environment;

/// Frames a link holds before the sender sees `WouldBlock`.
pub const LINK_QUEUE_FRAMES: usize = 16;

/// A board's doorbell: rung when a frame arrives for it.
#[derive(Default)]
pub struct Doorbell {
    /// Rung since the last wait, and how many threads are parked in [`Doorbell::wait`].
    state: Mutex<Bell>,
    cv: Condvar,
}

#[derive(Default)]
struct Bell {
    rung: bool,
    parked: u32,
}

impl Doorbell {
    /// Rings: a parked waiter wakes, a later wait returns at once. Wakes (a system call)
    /// only when a waiter is parked: most frames arrive while their board's worker is busy
    /// or spinning, and a ring per frame was a system call per frame.
    pub fn ring(&self) {
        let parked = match self.state.lock() {
            Ok(mut b) => {
                b.rung = true;
                b.parked > 0
            }
            Err(_) => true,
        };
        if parked {
            self.cv.notify_one();
        }
    }
    /// Waits until rung (or `timeout`), and clears it; whether a ring ended it (false when
    /// the timeout did). The count of parked waiters changes under the lock that `ring`
    /// reads it under, so no ring is missed.
    pub fn wait(&self, timeout: Duration) -> bool {
        let Ok(mut b) = self.state.lock() else {
            return false;
        };
        if !b.rung {
            b.parked += 1;
            match self.cv.wait_timeout(b, timeout) {
                Ok((g, waited)) => {
                    b = g;
                    b.parked -= 1;
                    if waited.timed_out() {
                        b.rung = false;
                        return false;
                    }
                }
                Err(_) => return false,
            }
        }
        std::mem::replace(&mut b.rung, false)
    }

    /// Threads parked in [`Doorbell::wait`] now.
    #[cfg(test)]
    fn parked(&self) -> u32 {
        self.state.lock().map(|b| b.parked).unwrap_or(0)
    }
}

/// A link's frames in flight, and the buffers of frames taken, kept for the next frames
/// (a link carries millions of frames in a run: no allocation each).
#[derive(Default)]
struct Queue {
    frames: VecDeque<Vec<u8>>,
    spare: Vec<Vec<u8>>,
}

impl Queue {
    fn len(&self) -> usize {
        self.frames.len()
    }
    fn push_back(&mut self, bytes: &[u8]) {
        let mut v = self.spare.pop().unwrap_or_default();
        v.clear();
        v.extend_from_slice(bytes);
        self.frames.push_back(v);
    }
}

/// One directed link: a bounded queue of frames plus the receiver's doorbell.
pub struct Channel {
    queue: Mutex<Queue>,
    /// Frames in `queue`, kept beside it so that a receiver polling an empty link does not
    /// take the lock (a board polls its links far more often than frames arrive).
    len: AtomicUsize,
    bell: Arc<Doorbell>,
}

/// The emulated global network: one inbox per board address, and the two sinks (the
/// graphics engine and the host) that keep what they receive for the run's outputs.
pub struct GlobalNet {
    /// Inbox per global address (`x + 4y + 16z`), with the board's doorbell.
    inboxes: Vec<Option<Arc<Channel>>>,
    /// The packets the graphics engine took (unwrapped, in order per board, once each).
    pub graphics: Mutex<Vec<Vec<u8>>>,
    /// The packets the host took.
    pub host: Mutex<Vec<Vec<u8>>>,
    /// The sinks run the receiving end of global recovery (`link_proto::reliable_global`):
    /// they take envelopes, acknowledge them into the sender's inbox, drop duplicates and
    /// deliver each board's flow in order.
    sink_recovery: bool,
    /// Per (sink, source) flow: the receiver's state.
    sink_flows: Mutex<std::collections::HashMap<(u8, u8), link_proto::reliable_global::FlowRx>>,
    /// What the sinks' recovery cost (acks and nacks sent, damaged, duplicates, gaps).
    pub sink_stats: Mutex<link_proto::reliable_global::GlobalRecovery>,
    /// Packets the sinks received damaged, without recovery (each stops the run).
    pub sink_faults: Mutex<Vec<SinkFault>>,
}

/// A damaged packet a sink received (without recovery): the sink, the source address the
/// packet names (perhaps damaged itself) and the step in its payload if readable.
#[derive(Clone, Debug, PartialEq)]
pub struct SinkFault {
    pub sink: u8,
    pub src: u8,
    pub step: Option<u32>,
    pub error: link_proto::Error,
}

/// Packets a board's inbox holds before senders see `WouldBlock`.
pub const GLOBAL_QUEUE_PACKETS: usize = 4096;

impl GlobalNet {
    /// A network of only the graphics and host sinks (no board inboxes, no recovery): what
    /// an emulated array's host keeps; packets between boards are routed by the caller.
    pub fn sinks() -> Arc<GlobalNet> {
        build_links([0, 0, 0], &[], false).1
    }

    /// Routes a packet from `src` to `dst` (a board's inbox, a sink, or every other board).
    pub(crate) fn deliver(&self, dst: u8, src: u8, packet: &[u8]) -> Result<(), SendError> {
        use link_proto::packet::{ADDR_BROADCAST, ADDR_GRAPHICS, ADDR_HOST};
        match dst {
            ADDR_GRAPHICS => self.sink(ADDR_GRAPHICS, &self.graphics, packet),
            ADDR_HOST => self.sink(ADDR_HOST, &self.host, packet),
            ADDR_BROADCAST => {
                for (a, ch) in self.inboxes.iter().enumerate() {
                    if a != src as usize {
                        if let Some(ch) = ch {
                            push(ch, packet, GLOBAL_QUEUE_PACKETS)?;
                        }
                    }
                }
                Ok(())
            }
            d => match self.inboxes.get(d as usize) {
                Some(Some(ch)) => push(ch, packet, GLOBAL_QUEUE_PACKETS),
                _ => Err(SendError::NoLink),
            },
        }
    }
}

impl GlobalNet {
    /// A packet (or envelope, with recovery) arrives at sink `addr`, which keeps `m`.
    fn sink(&self, addr: u8, m: &Mutex<Vec<Vec<u8>>>, bytes: &[u8]) -> Result<(), SendError> {
        use link_proto::reliable_global::{code, control, parse, Envelope, Verdict, OVERHEAD};
        let keep = |p: &[u8]| {
            m.lock()
                .map(|mut v| v.push(p.to_vec()))
                .map_err(|_| SendError::NoLink)
        };
        if !self.sink_recovery {
            return match link_proto::PacketRepr::parse_bytes(bytes) {
                Ok(_) => keep(bytes),
                Err(error) => {
                    // Damaged: dropped, and reported (the run stops on it).
                    let src = bytes.get(1).copied().unwrap_or(u8::MAX);
                    if let Ok(mut f) = self.sink_faults.lock() {
                        f.push(SinkFault {
                            sink: addr,
                            src,
                            step: packet_step(bytes),
                            error,
                        });
                    }
                    Ok(())
                }
            };
        }
        let mut st = self.sink_stats.lock().map_err(|_| SendError::NoLink)?;
        let (src, seq, packet) = match parse(bytes) {
            Envelope::Data { src, seq, packet } => (src, seq, packet),
            // A sink sends no data: nothing to acknowledge.
            Envelope::Ack { .. } | Envelope::Nack { .. } => return Ok(()),
            Envelope::Damaged => {
                st.damaged += 1;
                return Ok(());
            }
        };
        let mut flows = self.sink_flows.lock().map_err(|_| SendError::NoLink)?;
        let flow = flows.entry((addr, src)).or_insert_with(|| {
            st.peers += 1;
            Default::default()
        });
        let kind = match flow.take(seq) {
            Verdict::Deliver => {
                keep(packet)?;
                code::ACK
            }
            Verdict::Duplicate => {
                st.duplicates += 1;
                code::ACK
            }
            Verdict::Gap { nack } => {
                st.gaps += 1;
                if !nack {
                    return Ok(());
                }
                code::NACK
            }
        };
        let reply = control(src, addr, kind, flow.expected());
        drop(flows);
        if let Some(Some(ch)) = self.inboxes.get(src as usize) {
            if push(ch, &reply, GLOBAL_QUEUE_PACKETS).is_ok() {
                st.control_bytes += OVERHEAD as u64;
                if kind == code::ACK {
                    st.acks_sent += 1;
                } else {
                    st.nacks_sent += 1;
                }
            }
        }
        Ok(())
    }
}

/// The step a global packet belongs to, read from its payload (boxes, contact nodes and
/// tool forces carry it first, surface chunks after their frame number); None for other
/// kinds or too short a packet. Unchecked: for observers.
pub fn packet_step(packet: &[u8]) -> Option<u32> {
    use link_proto::PacketKind as K;
    let at = match K::from_code(*packet.get(4)?) {
        K::BoundingBox | K::CollisionExchange | K::ToolForce => 0,
        K::GraphicsSurface => 4,
        _ => return None,
    };
    let b =
        packet.get(link_proto::PACKET_HEADER_LEN + at..link_proto::PACKET_HEADER_LEN + at + 4)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// How a global address is named in reports: `(x,y,z)`, `host`, `graphics`, `broadcast`.
pub fn address_name(addr: u8) -> String {
    use link_proto::packet::{ADDR_BROADCAST, ADDR_GRAPHICS, ADDR_HOST};
    match addr {
        ADDR_GRAPHICS => "graphics".into(),
        ADDR_HOST => "host".into(),
        ADDR_BROADCAST => "broadcast".into(),
        a => match link_proto::Machine::from_address(a) {
            Some([x, y, z]) => format!("({x},{y},{z})"),
            None => format!("address {a}"),
        },
    }
}

/// The "face" an injected global fault is recorded on: `global to (x,y,z)`, `global to host`...
pub fn global_face(dst: u8) -> String {
    format!("global to {}", address_name(dst))
}

fn push(ch: &Channel, packet: &[u8], max: usize) -> Result<(), SendError> {
    let mut q = ch.queue.lock().map_err(|_| SendError::NoLink)?;
    if q.len() >= max {
        return Err(SendError::WouldBlock);
    }
    q.push_back(packet);
    ch.len.store(q.len(), Ordering::Release);
    drop(q);
    ch.bell.ring();
    Ok(())
}

/// A board's view of its links.
pub struct EmuLinks {
    /// Outgoing channel per face (None at the machine's edge).
    pub tx: [Option<Arc<Channel>>; 6],
    pub rx: [Option<Arc<Channel>>; 6],
    /// The global network, this board's address and inbox.
    pub net: Option<Arc<GlobalNet>>,
    pub address: u8,
}

impl Links for EmuLinks {
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        let ch = self.tx[face.index()].as_ref().ok_or(SendError::NoLink)?;
        push(ch, frame, LINK_QUEUE_FRAMES)
    }

    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        let ch = self.rx[face.index()].as_ref().ok_or(RecvError::NoLink)?;
        pop_into(ch, buf)
    }

    fn peek(&mut self, face: Face) -> link_proto::Peek {
        use link_proto::Peek;
        let Some(ch) = self.rx[face.index()].as_ref() else {
            return Peek::Nothing;
        };
        if ch.len.load(Ordering::Acquire) == 0 {
            return Peek::Nothing;
        }
        let Ok(q) = ch.queue.lock() else {
            return Peek::Unknown;
        };
        match q.frames.front() {
            None => Peek::Nothing,
            Some(f) => f.first().map_or(Peek::Unknown, |&b| Peek::First(b)),
        }
    }

    fn try_send_global(&mut self, packet: &[u8]) -> Result<(), SendError> {
        let net = self.net.as_ref().ok_or(SendError::NoLink)?;
        // The network routes on the header's destination, as a switch would.
        let dst = *packet.first().ok_or(SendError::TooLong)?;
        net.deliver(dst, self.address, packet)
    }

    fn try_recv_global(&mut self, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        let Some(net) = self.net.as_ref() else {
            return Ok(None);
        };
        let Some(Some(ch)) = net.inboxes.get(self.address as usize) else {
            return Ok(None);
        };
        pop_into(ch, buf)
    }
}

/// Builds the links of a machine: `links[b]` for board `b` (x fastest); a frame for board
/// `b` rings `bells[b]` (boards sharing a worker thread share its doorbell).
/// With `sink_recovery` the graphics and host sinks run the receiving end of global recovery.
pub fn build_links(
    dims: [usize; 3],
    bells: &[Arc<Doorbell>],
    sink_recovery: bool,
) -> (Vec<EmuLinks>, Arc<GlobalNet>) {
    let count = dims.iter().product::<usize>();
    let index = |c: [usize; 3]| c[0] + dims[0] * (c[1] + dims[1] * c[2]);
    let coords = |b: usize| {
        [
            b % dims[0],
            (b / dims[0]) % dims[1],
            b / (dims[0] * dims[1]),
        ]
    };
    let mut inboxes: Vec<Option<Arc<Channel>>> = vec![None; link_proto::BOARD_COUNT];
    let mut addresses = vec![u8::MAX; count];
    for b in 0..count {
        let c = coords(b);
        if let Some(a) = link_proto::Machine::address(c) {
            inboxes[a as usize] = Some(Arc::new(Channel {
                queue: Mutex::new(Queue::default()),
                len: AtomicUsize::new(0),
                bell: bells[b].clone(),
            }));
            addresses[b] = a;
        }
    }
    let net = Arc::new(GlobalNet {
        inboxes,
        graphics: Mutex::new(Vec::new()),
        host: Mutex::new(Vec::new()),
        sink_recovery,
        sink_flows: Mutex::new(Default::default()),
        sink_stats: Mutex::new(Default::default()),
        sink_faults: Mutex::new(Vec::new()),
    });
    let mut links: Vec<EmuLinks> = (0..count)
        .map(|b| EmuLinks {
            tx: Default::default(),
            rx: Default::default(),
            net: Some(net.clone()),
            address: addresses[b],
        })
        .collect();
    for b in 0..count {
        let c = [
            b % dims[0],
            (b / dims[0]) % dims[1],
            b / (dims[0] * dims[1]),
        ];
        for face in Face::ALL {
            let axis = face.index() / 2;
            let plus = face.index() % 2 == 0;
            let mut d = c;
            if plus {
                if c[axis] + 1 >= dims[axis] {
                    continue;
                }
                d[axis] += 1;
            } else {
                if c[axis] == 0 {
                    continue;
                }
                d[axis] -= 1;
            }
            let nb = index(d);
            let ch = Arc::new(Channel {
                queue: Mutex::new(Queue::default()),
                len: AtomicUsize::new(0),
                bell: bells[nb].clone(),
            });
            links[b].tx[face.index()] = Some(ch.clone());
            links[nb].rx[face.opposite().index()] = Some(ch);
        }
    }
    (links, net)
}

/// A worker's clock: read once per sweep over its boards ([`SweepClock::tick`]) and seen by
/// all of them (their runtimes and their link recovery) until the next. A board that waits
/// is polled again only at a later sweep, so it sees every wait's end at the time the
/// worker saw it; and a clock read per link poll was 3-4% of the run.
pub struct SweepClock {
    start: Instant,
    now_ns: AtomicU64,
}

impl SweepClock {
    pub fn new() -> Arc<SweepClock> {
        Arc::new(SweepClock {
            start: Instant::now(),
            now_ns: AtomicU64::new(0),
        })
    }
    /// Reads the time (ns since the clock's start) for the sweep about to begin.
    pub fn tick(&self) {
        let t = self.start.elapsed().as_nanos() as u64;
        self.now_ns.store(t, Ordering::Relaxed);
    }
    /// The time of the current sweep.
    pub fn now_ns(&self) -> u64 {
        self.now_ns.load(Ordering::Relaxed)
    }
}

/// Time and waiting for a board thread.
pub struct ThreadEnv {
    pub clock: Arc<SweepClock>,
    pub bell: Arc<Doorbell>,
    spins: u32,
}

impl ThreadEnv {
    pub fn new(bell: Arc<Doorbell>, clock: Arc<SweepClock>) -> Self {
        ThreadEnv {
            clock,
            bell,
            spins: 0,
        }
    }
}

impl link_proto::Clock for ThreadEnv {
    fn now_ns(&mut self) -> u64 {
        self.clock.now_ns()
    }
}

impl Environment for ThreadEnv {
    fn idle(&mut self) {
        // Spin briefly (a frame is often about to arrive), then park on the doorbell.
        self.spins += 1;
        if !self.spins.is_multiple_of(64) {
            std::hint::spin_loop();
            std::thread::yield_now();
        } else {
            self.bell.wait(Duration::from_millis(2));
        }
    }
}

/// Which traffic drop and corrupt apply to (`on=all|links|global`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FaultScope {
    /// Point-to-point frames and global packets (the default).
    #[default]
    All,
    /// Point-to-point frames only.
    Links,
    /// Global packets only.
    Global,
}

/// What to inject (`--faults seed=S,drop=P,corrupt=P,delay=MS,stall=X.Y.Z@STEP,on=all`).
///
/// `drop` and `corrupt` apply to every point-to-point frame and every global packet a board
/// sends (`on=links` or `on=global` for one kind only; global packets draw from their own
/// random stream, so adding them leaves the frames' faults of a seed as they were); `delay`
/// to the point-to-point frames; a stalled board sends nothing more, frames or packets.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FaultSpec {
    pub seed: u64,
    /// Probability that a frame is lost.
    pub drop: f64,
    /// Probability that one bit of a frame is flipped.
    pub corrupt: f64,
    /// Every frame is held this long before delivery (ms; the link holds it, the sender
    /// goes on).
    pub delay_ms: u64,
    /// This board stops sending at this step.
    pub stall: Option<([usize; 3], u64)>,
    /// Which traffic `drop` and `corrupt` apply to.
    pub on: FaultScope,
}

impl FaultSpec {
    pub fn parse(s: &str) -> anyhow::Result<FaultSpec> {
        let mut f = FaultSpec {
            seed: 1,
            ..Default::default()
        };
        for part in s.split(',').filter(|p| !p.is_empty()) {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| anyhow::anyhow!("--faults: {part:?} is not key=value"))?;
            let num = |v: &str| {
                v.parse::<f64>()
                    .map_err(|_| anyhow::anyhow!("--faults {k}: {v:?} is not a number"))
            };
            match k {
                "seed" => {
                    f.seed = v
                        .parse()
                        .map_err(|_| anyhow::anyhow!("--faults seed: {v:?}"))?
                }
                "drop" => f.drop = num(v)?,
                "corrupt" => f.corrupt = num(v)?,
                "delay" => {
                    f.delay_ms = v
                        .parse()
                        .map_err(|_| anyhow::anyhow!("--faults delay: {v:?} (ms)"))?
                }
                "on" => {
                    f.on = match v {
                        "all" => FaultScope::All,
                        "links" => FaultScope::Links,
                        "global" => FaultScope::Global,
                        _ => anyhow::bail!("--faults on: {v:?} (all, links, global)"),
                    }
                }
                "stall" => {
                    let (b, st) = v
                        .split_once('@')
                        .ok_or_else(|| anyhow::anyhow!("--faults stall=X.Y.Z@STEP"))?;
                    let c: Vec<usize> =
                        b.split(['.', ':']).filter_map(|x| x.parse().ok()).collect();
                    let step = st
                        .parse()
                        .map_err(|_| anyhow::anyhow!("--faults stall step: {st:?}"))?;
                    if c.len() != 3 {
                        anyhow::bail!("--faults stall=X.Y.Z@STEP: board {b:?}");
                    }
                    f.stall = Some(([c[0], c[1], c[2]], step));
                }
                _ => {
                    anyhow::bail!(
                        "--faults: unknown key {k:?} (seed, drop, corrupt, delay, stall, on)"
                    )
                }
            }
        }
        if !(0.0..=1.0).contains(&f.drop) || !(0.0..=1.0).contains(&f.corrupt) {
            anyhow::bail!("--faults: probabilities must lie in [0, 1]");
        }
        Ok(f)
    }
}

impl FaultSpec {
    /// Refuses a spec that names a board a `dims` machine does not have (before the run).
    pub fn check(&self, dims: [usize; 3]) -> anyhow::Result<()> {
        if let Some((b, step)) = self.stall {
            if (0..3).any(|a| b[a] >= dims[a]) {
                anyhow::bail!(
                    "--faults stall={}.{}.{}@{step}: no board ({},{},{}) on this {}x{}x{} machine (boards 0..{} x 0..{} x 0..{})",
                    b[0], b[1], b[2], b[0], b[1], b[2], dims[0], dims[1], dims[2],
                    dims[0], dims[1], dims[2]
                );
            }
        }
        Ok(())
    }
}

/// Steps behind the latest that the fault injector keeps its per-step packet counts for.
const GLOBAL_COUNT_STEPS: u32 = 256;

/// SplitMix64: small, fast and good enough for fault injection.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// An injected fault, as recorded by the injector.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Injected {
    pub board: [usize; 3],
    pub face: String,
    pub step: u32,
    pub what: String,
}

/// Wraps a board's links and injects faults into what it sends.
pub struct FaultyLinks<L> {
    pub inner: L,
    pub board: [usize; 3],
    spec: FaultSpec,
    rng: Rng,
    pub injected: Arc<Mutex<Vec<Injected>>>,
    /// Faces whose delay is recorded (at their first delayed frame).
    delayed: [bool; 6],
    /// Faces whose stall is recorded.
    stalled: [bool; 6],
    /// Frames held by the delay: (due, face, bytes), in sending order.
    held: VecDeque<(Instant, Face, Vec<u8>)>,
    /// Step of the last data frame sent per face.
    last_step: [u32; 6],
    /// The seed of the global packets' draws (the frames' stream stays as without them).
    global_seed: u64,
    /// Per (destination, kind, step): how many packets were sent (retransmissions
    /// included); a packet's draws come from (seed, board, destination, kind, step, that
    /// count), so that they do not depend on the order packets to different destinations
    /// go out in (which depends on thread timing). Steps far behind are forgotten.
    global_counts: std::collections::HashMap<(u8, u8, u32), u32>,
    /// The global packets sent through here are recovery envelopes
    /// (`link_proto::reliable_global`), not bare packets.
    pub global_envelopes: bool,
    /// The global stall is recorded.
    global_stalled: bool,
    /// Step of the last global packet whose step was readable.
    global_step: u32,
}

impl<L> FaultyLinks<L> {
    pub fn new(
        inner: L,
        board: [usize; 3],
        board_index: usize,
        spec: FaultSpec,
        injected: Arc<Mutex<Vec<Injected>>>,
    ) -> Self {
        let rng = Rng::new(spec.seed ^ (board_index as u64).wrapping_mul(0xA24B_AED4_963E_E407));
        let global_seed = spec.seed
            ^ 0x6C6F_6261_6C00_0000
            ^ (board_index as u64).wrapping_mul(0xD6E8_FEB8_6659_FD93);
        FaultyLinks {
            inner,
            board,
            spec,
            rng,
            injected,
            delayed: [false; 6],
            stalled: [false; 6],
            held: VecDeque::new(),
            last_step: [0; 6],
            global_seed,
            global_counts: Default::default(),
            global_envelopes: false,
            global_stalled: false,
            global_step: 0,
        }
    }
    fn record(&self, face: Face, step: u32, what: &str) {
        self.record_on(format!("{face:?}"), step, what);
    }
    fn record_on(&self, face: String, step: u32, what: &str) {
        if let Ok(mut v) = self.injected.lock() {
            v.push(Injected {
                board: self.board,
                face,
                step,
                what: what.into(),
            });
        }
    }
}

/// The step of a frame, or of the frame in a recovery envelope; None for a recovery
/// control envelope (ack, nack, status).
fn frame_step(frame: &[u8]) -> Option<u32> {
    let f = match frame.first() {
        Some(&link_proto::reliable::code::DATA) => link_proto::reliable::data_frame(frame)?,
        Some(c) if *c >= link_proto::reliable::code::ACK => return None,
        _ => frame,
    };
    f.get(4..8)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

impl<L: Links> FaultyLinks<L> {
    /// Delivers the held frames that are due, in order (a frame the link refuses now waits
    /// with those behind it).
    fn release(&mut self) {
        let now = Instant::now();
        while let Some((due, face, bytes)) = self.held.front() {
            if *due > now || self.inner.try_send(*face, bytes).is_err() {
                break;
            }
            self.held.pop_front();
        }
    }

    /// Sends after the held frames (none are held without a delay).
    fn flush_then(&mut self, face: Face, bytes: &[u8]) -> Result<(), SendError> {
        self.release();
        if !self.held.is_empty() {
            return Err(SendError::WouldBlock);
        }
        self.inner.try_send(face, bytes)
    }
}

impl<L: Links> Links for FaultyLinks<L> {
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        // A control envelope belongs to the step of the last data frame on its link.
        let step = match frame_step(frame) {
            Some(s) => {
                self.last_step[face.index()] = s;
                s
            }
            None => self.last_step[face.index()],
        };
        if let Some((b, s)) = self.spec.stall {
            if b == self.board && step as u64 >= s {
                // A stalled board sends nothing more (and says it did); each link's stall is
                // recorded at its first frame not sent.
                if !self.stalled[face.index()] {
                    self.stalled[face.index()] = true;
                    self.record(face, step, "stall");
                }
                return Ok(());
            }
        }
        let (u_drop, u_corrupt, bit) = (self.rng.unit(), self.rng.unit(), self.rng.next_u64());
        let (u_drop, u_corrupt) = if self.spec.on == FaultScope::Global {
            (1.0, 1.0)
        } else {
            (u_drop, u_corrupt)
        };
        if u_drop < self.spec.drop {
            self.record(face, step, "drop");
            return Ok(());
        }
        if u_corrupt >= self.spec.corrupt && self.spec.delay_ms == 0 {
            return self.inner.try_send(face, frame);
        }
        let mut bytes = frame.to_vec();
        if u_corrupt < self.spec.corrupt {
            let k = (bit % (bytes.len() as u64 * 8)) as usize;
            bytes[k / 8] ^= 1 << (k % 8);
            self.record(face, step, &format!("corrupt bit {k}"));
        }
        if self.spec.delay_ms > 0 {
            if !self.delayed[face.index()] {
                self.delayed[face.index()] = true;
                self.record(face, step, &format!("delay {} ms", self.spec.delay_ms));
            }
            let due = Instant::now() + Duration::from_millis(self.spec.delay_ms);
            self.held.push_back((due, face, bytes));
            self.release();
            return Ok(());
        }
        self.flush_then(face, &bytes)
    }
    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.release();
        self.inner.try_recv(face, buf)
    }
    fn poll(&mut self) {
        self.release();
        self.inner.poll();
    }
    /// Faults hit frames as they are sent: the head of a link is what a receive would take.
    fn peek(&mut self, face: Face) -> link_proto::Peek {
        self.release();
        self.inner.peek(face)
    }
    /// The same drop and corrupt as frames (from the global stream), and the stall; recorded
    /// on `global to <destination>` at the packet's step (a recovery control envelope at
    /// the last packet's step).
    fn try_send_global(&mut self, p: &[u8]) -> Result<(), SendError> {
        let dst = p.first().copied().unwrap_or(u8::MAX);
        let (packet, is_control) = if self.global_envelopes {
            match link_proto::reliable_global::data_packet(p) {
                Some(packet) => (packet, false),
                None => (p, true),
            }
        } else {
            (p, false)
        };
        if !is_control {
            if let Some(s) = packet_step(packet) {
                self.global_step = s;
            }
        }
        let step = self.global_step;
        if let Some((b, s)) = self.spec.stall {
            if b == self.board && step as u64 >= s {
                if !self.global_stalled {
                    self.global_stalled = true;
                    self.record_on(global_face(dst), step, "stall");
                }
                return Ok(());
            }
        }
        let kind = if is_control {
            p.get(2).copied().unwrap_or(0)
        } else {
            packet.get(4).copied().unwrap_or(0)
        };
        if self.global_counts.len() > 4096 {
            self.global_counts
                .retain(|k, _| k.2.saturating_add(GLOBAL_COUNT_STEPS) >= step);
        }
        let c = self.global_counts.entry((dst, kind, step)).or_insert(0);
        *c += 1;
        let key = [
            u64::from(dst),
            u64::from(kind),
            u64::from(step),
            u64::from(*c),
        ]
        .iter()
        .fold(self.global_seed, |h, v| {
            Rng::new(h ^ v.wrapping_mul(0x9E37_79B9_7F4A_7C15)).next_u64()
        });
        let mut rng = Rng::new(key);
        let (u_drop, u_corrupt, bit) = (rng.unit(), rng.unit(), rng.next_u64());
        if self.spec.on == FaultScope::Links {
            return self.inner.try_send_global(p);
        }
        if u_drop < self.spec.drop {
            self.record_on(global_face(dst), step, "drop");
            return Ok(());
        }
        if u_corrupt >= self.spec.corrupt || p.is_empty() {
            return self.inner.try_send_global(p);
        }
        let mut bytes = p.to_vec();
        let k = (bit % (bytes.len() as u64 * 8)) as usize;
        bytes[k / 8] ^= 1 << (k % 8);
        self.record_on(global_face(dst), step, &format!("corrupt bit {k}"));
        match self.inner.try_send_global(&bytes) {
            // A destination corrupted into no address: the network loses the packet.
            Err(SendError::NoLink) => Ok(()),
            r => r,
        }
    }
    fn try_recv_global(&mut self, b: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.inner.try_recv_global(b)
    }
}

/// Takes the oldest frame of `ch` into `buf`: its length, or None when the queue is empty
/// (seen without the lock; a frame pushed meanwhile is taken at the next poll, which its
/// doorbell brings).
fn pop_into(ch: &Channel, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
    if ch.len.load(Ordering::Acquire) == 0 {
        return Ok(None);
    }
    let mut q = ch.queue.lock().map_err(|_| RecvError::NoLink)?;
    let front = q.frames.pop_front();
    ch.len.store(q.len(), Ordering::Release);
    match front {
        None => Ok(None),
        Some(f) => {
            let n = f.len();
            let copied = buf.get_mut(..n).map(|dst| dst.copy_from_slice(&f));
            q.spare.push(f);
            copied.ok_or(RecvError::BufferTooSmall { needed: n })?;
            Ok(Some(n))
        }
    }
}

/// A board's links below recovery: clean, or with faults injected.
pub enum Lower {
    Clean(EmuLinks),
    Faulty(Box<FaultyLinks<EmuLinks>>),
}

impl Links for Lower {
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        match self {
            Lower::Clean(l) => l.try_send(face, frame),
            Lower::Faulty(l) => l.try_send(face, frame),
        }
    }
    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        match self {
            Lower::Clean(l) => l.try_recv(face, buf),
            Lower::Faulty(l) => l.try_recv(face, buf),
        }
    }
    fn try_send_global(&mut self, p: &[u8]) -> Result<(), SendError> {
        match self {
            Lower::Clean(l) => l.try_send_global(p),
            Lower::Faulty(l) => l.try_send_global(p),
        }
    }
    fn try_recv_global(&mut self, b: &mut [u8]) -> Result<Option<usize>, RecvError> {
        match self {
            Lower::Clean(l) => l.try_recv_global(b),
            Lower::Faulty(l) => l.try_recv_global(b),
        }
    }
    fn poll(&mut self) {
        match self {
            Lower::Clean(l) => l.poll(),
            Lower::Faulty(l) => l.poll(),
        }
    }
    fn peek(&mut self, face: Face) -> link_proto::Peek {
        match self {
            Lower::Clean(l) => l.peek(face),
            Lower::Faulty(l) => l.peek(face),
        }
    }
}

/// A board's clock for link recovery: its worker's [`SweepClock`], passed in.
pub struct SimClock(Arc<SweepClock>);

impl link_proto::Clock for SimClock {
    fn now_ns(&mut self) -> u64 {
        self.0.now_ns()
    }
}

/// A board's links below global recovery: with point-to-point recovery, or without.
pub enum Faces {
    Plain(Lower),
    Recovering(Box<link_proto::reliable::Reliable<Lower, SimClock, Vec<u8>>>),
}

macro_rules! links_by_variant {
    ($t:ty, $($v:path),+) => {
        impl Links for $t {
            fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
                match self { $($v(l) => l.try_send(face, frame),)+ }
            }
            fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
                match self { $($v(l) => l.try_recv(face, buf),)+ }
            }
            fn try_send_global(&mut self, p: &[u8]) -> Result<(), SendError> {
                match self { $($v(l) => l.try_send_global(p),)+ }
            }
            fn try_recv_global(&mut self, b: &mut [u8]) -> Result<Option<usize>, RecvError> {
                match self { $($v(l) => l.try_recv_global(b),)+ }
            }
            fn poll(&mut self) {
                match self { $($v(l) => l.poll(),)+ }
            }
            fn peek(&mut self, face: Face) -> link_proto::Peek {
                match self { $($v(l) => l.peek(face),)+ }
            }
        }
    };
}

links_by_variant!(Faces, Faces::Plain, Faces::Recovering);
links_by_variant!(BoardLinks, BoardLinks::Plain, BoardLinks::Recovering);

/// A board's links as its runtime sees them: with global recovery above the faces (with or
/// without point-to-point recovery above the possibly faulty emulated links), or without.
pub enum BoardLinks {
    Plain(Faces),
    Recovering(Box<link_proto::reliable_global::GlobalReliable<Faces, SimClock, Vec<u8>>>),
}

impl BoardLinks {
    /// `lower` with point-to-point recovery by `faces` and global recovery by `global`
    /// (each `None` for without), their timers on `clock`. Fails on a configuration a
    /// wrapper refuses.
    pub fn new(
        lower: Lower,
        clock: Arc<SweepClock>,
        faces: Option<link_proto::reliable::ReliableConfig>,
        global: Option<link_proto::reliable_global::GlobalConfig>,
    ) -> Result<Self, link_proto::Error> {
        use link_proto::reliable::Reliable;
        use link_proto::reliable_global::GlobalReliable;
        let address = match &lower {
            Lower::Clean(l) => l.address,
            Lower::Faulty(l) => l.inner.address,
        };
        let mid = match faces {
            None => Faces::Plain(lower),
            Some(c) => {
                let buf = vec![0u8; Reliable::<Lower, SimClock, Vec<u8>>::buffer_len(&c)];
                Faces::Recovering(Box::new(Reliable::new(
                    lower,
                    SimClock(clock.clone()),
                    c,
                    buf,
                )?))
            }
        };
        Ok(match global {
            None => BoardLinks::Plain(mid),
            Some(c) => {
                let buf = vec![0u8; GlobalReliable::<Faces, SimClock, Vec<u8>>::buffer_len(&c)];
                BoardLinks::Recovering(Box::new(GlobalReliable::new(
                    mid,
                    SimClock(clock),
                    address,
                    c,
                    buf,
                )?))
            }
        })
    }

    fn faces(&self) -> &Faces {
        match self {
            BoardLinks::Plain(f) => f,
            BoardLinks::Recovering(g) => g.inner(),
        }
    }

    /// What point-to-point recovery cost, per face, if it is on.
    pub fn recovery(&self) -> Option<[link_proto::reliable::FaceRecovery; 6]> {
        match self.faces() {
            Faces::Plain(_) => None,
            Faces::Recovering(r) => Some(*r.stats()),
        }
    }

    /// What global recovery cost, if it is on.
    pub fn global_recovery(&self) -> Option<link_proto::reliable_global::GlobalRecovery> {
        match self {
            BoardLinks::Plain(_) => None,
            BoardLinks::Recovering(g) => Some(*g.stats()),
        }
    }

    /// The global flow recovery gave up, if any: (peer address, packet number, retransmissions).
    pub fn global_failure(&self) -> Option<(u8, u16, u8)> {
        match self {
            BoardLinks::Plain(_) => None,
            BoardLinks::Recovering(g) => g.failure(),
        }
    }

    /// Global packets sent and not yet acknowledged (0 without global recovery).
    pub fn global_unacknowledged(&self) -> usize {
        match self {
            BoardLinks::Plain(_) => 0,
            BoardLinks::Recovering(g) => g.unacknowledged(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ring with no one parked is kept for the next wait, and a ring while a thread is
    /// parked wakes it: its wait reports the ring, not the end of its 20 s timeout (which
    /// is what a ring that skipped the wake-up would leave it to). The waiter waits again
    /// after a spurious wake-up (the ring then finds it unparked and is kept for it).
    #[test]
    fn a_ring_wakes_a_parked_waiter_and_is_kept_when_none_is_parked() {
        let bell = Arc::new(Doorbell::default());
        bell.ring();
        assert!(
            bell.wait(Duration::from_secs(60)),
            "the ring before the wait is kept"
        );
        assert_eq!(bell.parked(), 0);
        let b = bell.clone();
        let waiter = std::thread::spawn(move || (0..3).any(|_| b.wait(Duration::from_secs(20))));
        while bell.parked() == 0 {
            std::thread::yield_now();
        }
        bell.ring();
        assert!(
            waiter.join().unwrap_or(false),
            "the parked waiter saw the ring"
        );
        assert_eq!(bell.parked(), 0);
    }

    /// A peek tells the first byte of the frame at the head of a link without taking it:
    /// the receive that follows gets that frame, whole; an empty link and a face at the
    /// machine's edge have nothing.
    #[test]
    fn a_peek_sees_the_head_of_a_link_and_leaves_it() {
        use link_proto::Peek;
        let bells: Vec<Arc<Doorbell>> = (0..2).map(|_| Default::default()).collect();
        let (mut links, _) = build_links([2, 1, 1], &bells, false);
        let (a, b) = links.split_at_mut(1);
        let (a, b) = (&mut a[0], &mut b[0]);
        assert_eq!(b.peek(Face::NegX), Peek::Nothing);
        assert_eq!(b.peek(Face::PosX), Peek::Nothing, "the machine's edge");
        a.try_send(Face::PosX, &[0xA3, 1, 2, 3]).expect("sent");
        a.try_send(Face::PosX, &[0xA1, 9]).expect("sent");
        assert_eq!(b.peek(Face::NegX), Peek::First(0xA3));
        assert_eq!(b.peek(Face::NegX), Peek::First(0xA3), "not taken");
        let mut buf = [0u8; 8];
        assert_eq!(b.try_recv(Face::NegX, &mut buf), Ok(Some(4)));
        assert_eq!(buf[..4], [0xA3, 1, 2, 3]);
        assert_eq!(b.peek(Face::NegX), Peek::First(0xA1));
        assert_eq!(b.try_recv(Face::NegX, &mut buf), Ok(Some(2)));
        assert_eq!(b.peek(Face::NegX), Peek::Nothing);
    }
}
