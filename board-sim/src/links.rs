//! Emulated point-to-point links and global network between board threads, and the fault
//! injector that wraps a board's links.
//!
//! Each directed link is a bounded queue; a sender rings the receiving board's doorbell so a
//! waiting board can park instead of spinning. All randomness of the fault injector comes
//! from one seed (printed at the start of a run) mixed with the board and face, so a run
//! replays exactly.

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use link_proto::{Face, Links, RecvError, SendError};
use pe_firmware::runtime::Environment;

/// Frames a link holds before the sender sees `WouldBlock`.
pub const LINK_QUEUE_FRAMES: usize = 16;

/// A board's doorbell: rung when a frame arrives for it.
#[derive(Default)]
pub struct Doorbell {
    rung: Mutex<bool>,
    cv: Condvar,
}

impl Doorbell {
    pub fn ring(&self) {
        if let Ok(mut r) = self.rung.lock() {
            *r = true;
        }
        self.cv.notify_one();
    }
    /// Waits until rung (or `timeout`), and clears it.
    pub fn wait(&self, timeout: Duration) {
        if let Ok(mut r) = self.rung.lock() {
            if !*r {
                if let Ok((g, _)) = self.cv.wait_timeout(r, timeout) {
                    r = g;
                } else {
                    return;
                }
            }
            *r = false;
        }
    }
}

/// One directed link: a bounded queue of frames plus the receiver's doorbell.
pub struct Channel {
    queue: Mutex<VecDeque<Vec<u8>>>,
    bell: Arc<Doorbell>,
}

/// The emulated global network: one inbox per board address, and the two sinks (the
/// graphics engine and the host) that keep what they receive for the run's outputs.
pub struct GlobalNet {
    /// Inbox per global address (`x + 4y + 16z`), with the board's doorbell.
    inboxes: Vec<Option<Arc<Channel>>>,
    pub graphics: Mutex<Vec<Vec<u8>>>,
    pub host: Mutex<Vec<Vec<u8>>>,
}

/// Packets a board's inbox holds before senders see `WouldBlock`.
pub const GLOBAL_QUEUE_PACKETS: usize = 4096;

impl GlobalNet {
    fn deliver(&self, dst: u8, src: u8, packet: &[u8]) -> Result<(), SendError> {
        use link_proto::packet::{ADDR_BROADCAST, ADDR_GRAPHICS, ADDR_HOST};
        let sink = |m: &Mutex<Vec<Vec<u8>>>| {
            m.lock()
                .map(|mut v| v.push(packet.to_vec()))
                .map_err(|_| SendError::NoLink)
        };
        match dst {
            ADDR_GRAPHICS => sink(&self.graphics),
            ADDR_HOST => sink(&self.host),
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

fn push(ch: &Channel, packet: &[u8], max: usize) -> Result<(), SendError> {
    let mut q = ch.queue.lock().map_err(|_| SendError::NoLink)?;
    if q.len() >= max {
        return Err(SendError::WouldBlock);
    }
    q.push_back(packet.to_vec());
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
        let mut q = ch.queue.lock().map_err(|_| SendError::NoLink)?;
        if q.len() >= LINK_QUEUE_FRAMES {
            return Err(SendError::WouldBlock);
        }
        q.push_back(frame.to_vec());
        drop(q);
        ch.bell.ring();
        Ok(())
    }

    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        let ch = self.rx[face.index()].as_ref().ok_or(RecvError::NoLink)?;
        pop_into(&ch.queue, buf)
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
        pop_into(&ch.queue, buf)
    }
}

/// Builds the links of a machine: `links[b]` for board `b` (x fastest); a frame for board
/// `b` rings `bells[b]` (boards sharing a worker thread share its doorbell).
pub fn build_links(dims: [usize; 3], bells: &[Arc<Doorbell>]) -> (Vec<EmuLinks>, Arc<GlobalNet>) {
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
        if let Some(a) = link_proto::link::board_at(c[0], c[1], c[2]) {
            inboxes[a as usize] = Some(Arc::new(Channel {
                queue: Mutex::new(VecDeque::new()),
                bell: bells[b].clone(),
            }));
            addresses[b] = a;
        }
    }
    let net = Arc::new(GlobalNet {
        inboxes,
        graphics: Mutex::new(Vec::new()),
        host: Mutex::new(Vec::new()),
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
                queue: Mutex::new(VecDeque::new()),
                bell: bells[nb].clone(),
            });
            links[b].tx[face.index()] = Some(ch.clone());
            links[nb].rx[face.opposite().index()] = Some(ch);
        }
    }
    (links, net)
}

/// Time and waiting for a board thread.
pub struct ThreadEnv {
    pub start: Instant,
    pub bell: Arc<Doorbell>,
    spins: u32,
}

impl ThreadEnv {
    pub fn new(bell: Arc<Doorbell>) -> Self {
        ThreadEnv {
            start: Instant::now(),
            bell,
            spins: 0,
        }
    }
}

impl Environment for ThreadEnv {
    fn now_ns(&mut self) -> u64 {
        self.start.elapsed().as_nanos() as u64
    }
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

/// What to inject (`--faults seed=S,drop=P,corrupt=P,delay=MS,stall=X.Y.Z@STEP`).
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
                    anyhow::bail!("--faults: unknown key {k:?} (seed, drop, corrupt, delay, stall)")
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
        }
    }
    fn record(&self, face: Face, step: u32, what: &str) {
        if let Ok(mut v) = self.injected.lock() {
            v.push(Injected {
                board: self.board,
                face: format!("{face:?}"),
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
    fn try_send_global(&mut self, p: &[u8]) -> Result<(), SendError> {
        self.inner.try_send_global(p)
    }
    fn try_recv_global(&mut self, b: &mut [u8]) -> Result<Option<usize>, RecvError> {
        self.inner.try_recv_global(b)
    }
}

/// Takes the oldest frame of `queue` into `buf`: its length, or None when the queue is empty.
fn pop_into(queue: &Mutex<VecDeque<Vec<u8>>>, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
    let mut q = queue.lock().map_err(|_| RecvError::NoLink)?;
    match q.pop_front() {
        None => Ok(None),
        Some(f) => {
            let dst = buf
                .get_mut(..f.len())
                .ok_or(RecvError::BufferTooSmall { needed: f.len() })?;
            dst.copy_from_slice(&f);
            Ok(Some(f.len()))
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
}

/// A board thread's clock for link recovery (its own start, passed in).
pub struct SimClock(Instant);

impl link_proto::reliable::Clock for SimClock {
    fn now_ns(&mut self) -> u64 {
        self.0.elapsed().as_nanos() as u64
    }
}

/// A board's links as its runtime sees them: with link recovery above the (possibly
/// faulty) emulated links, or without.
pub enum BoardLinks {
    Plain(Lower),
    Recovering(Box<link_proto::reliable::Reliable<Lower, SimClock, Vec<u8>>>),
}

impl BoardLinks {
    /// `lower` with recovery by `config`, or without (`None`). Fails on a configuration
    /// the wrapper refuses (window beyond `WINDOW_MAX`, frames too long).
    pub fn new(
        lower: Lower,
        config: Option<link_proto::reliable::ReliableConfig>,
    ) -> Result<Self, link_proto::Error> {
        use link_proto::reliable::Reliable;
        Ok(match config {
            None => BoardLinks::Plain(lower),
            Some(c) => {
                let buf = vec![0u8; Reliable::<Lower, SimClock, Vec<u8>>::buffer_len(&c)];
                BoardLinks::Recovering(Box::new(Reliable::new(
                    lower,
                    SimClock(Instant::now()),
                    c,
                    buf,
                )?))
            }
        })
    }

    /// What recovery cost, per face, if it is on.
    pub fn recovery(&self) -> Option<[link_proto::reliable::FaceRecovery; 6]> {
        match self {
            BoardLinks::Plain(_) => None,
            BoardLinks::Recovering(r) => Some(*r.stats()),
        }
    }
}

impl Links for BoardLinks {
    fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
        match self {
            BoardLinks::Plain(l) => l.try_send(face, frame),
            BoardLinks::Recovering(l) => l.try_send(face, frame),
        }
    }
    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        match self {
            BoardLinks::Plain(l) => l.try_recv(face, buf),
            BoardLinks::Recovering(l) => l.try_recv(face, buf),
        }
    }
    fn try_send_global(&mut self, p: &[u8]) -> Result<(), SendError> {
        match self {
            BoardLinks::Plain(l) => l.try_send_global(p),
            BoardLinks::Recovering(l) => l.try_send_global(p),
        }
    }
    fn try_recv_global(&mut self, b: &mut [u8]) -> Result<Option<usize>, RecvError> {
        match self {
            BoardLinks::Plain(l) => l.try_recv_global(b),
            BoardLinks::Recovering(l) => l.try_recv_global(b),
        }
    }
    fn poll(&mut self) {
        match self {
            BoardLinks::Plain(l) => l.poll(),
            BoardLinks::Recovering(l) => l.poll(),
        }
    }
}
