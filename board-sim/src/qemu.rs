//! `board-sim qemu DIR`: the board firmware itself on an emulated array. One QEMU
//! `mps2-an500` (Cortex-M7) per board runs the `pe image` ELF and schedule blob of its
//! position; this process wires their UARTs as the cables of the machine and plays the
//! global network, the host and the graphics engine.
//!
//! Wiring (one home for which UART carries what: `pe_firmware::profile::mps2_uarts`): QEMU's
//! `-serial` `i` is UART `i`; each UART a board uses is a TCP socket QEMU connects to this
//! process at start. A cable joins two face connectors (a board's face and its neighbour's
//! opposite face): the bytes are relayed both ways as they come, untouched (the frames
//! carry no address, the boards' Hello check finds a crossed cable). The global ports'
//! bytes are COBS-framed packets: each is routed on its destination like the global
//! network's switch: to a board's global UART, or to the host and graphics sinks, which
//! keep them as board-sim's do (tool forces, surface frames, each board's compilation id,
//! fault reports).
//!
//! Faults are the boards' own: a board that faults sends a fault packet and exits; its
//! neighbours time out on the dead link (the runtime's link timeout) and report in turn.
//! `kill` ends one board's QEMU mid-run (the harness's fault wrapper); `cross` swaps the
//! far ends of two cables. The run never hangs: a whole-run deadline and a watchdog on
//! progress (no byte on any link, global port or console for twice the boards' link
//! timeout) end every QEMU and say which boards were still running.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use host_tools::compile::read_manifest;
use link_proto::packet::{ADDR_BROADCAST, ADDR_GRAPHICS, ADDR_HOST};
use link_proto::{Face, PacketKind, PacketRepr};
use pe_firmware::image::ImageReader;
use pe_firmware::profile::mps2_uarts;
use pe_firmware::runtime::RuntimeConfig;

use crate::fabric::GlobalNet;

/// One end of a cable: a board's face connector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Connector {
    pub board: [usize; 3],
    pub face: usize,
}

impl std::fmt::Display for Connector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.board;
        let name = link_proto::link::FACE_NAMES[self.face];
        write!(f, "({x},{y},{z}) {name}")
    }
}

/// Board coordinates `X,Y,Z`.
pub fn parse_board(s: &str) -> Option<[usize; 3]> {
    let c: Vec<usize> = s
        .split(',')
        .map(|v| v.trim().parse().ok())
        .collect::<Option<_>>()?;
    c.try_into().ok()
}

impl Connector {
    /// `X,Y,Z:FACE`, e.g. `0,0,0:+x`.
    pub fn parse(s: &str) -> Result<Self> {
        let bad = || anyhow!("{s:?}: expected a connector X,Y,Z:FACE such as 0,0,0:+x");
        let (b, f) = s.split_once(':').ok_or_else(bad)?;
        let [x, y, z] = parse_board(b).ok_or_else(bad)?;
        let face = link_proto::link::FACE_NAMES
            .iter()
            .position(|n| *n == f.trim())
            .ok_or_else(bad)?;
        Ok(Connector {
            board: [x, y, z],
            face,
        })
    }
}

/// How to run the array.
#[derive(Clone, Debug)]
pub struct ArrayOptions {
    /// The emulator (`qemu-system-arm`).
    pub qemu: PathBuf,
    /// The firmware ELF `pe image` copies per board (default: built with cargo for the
    /// manifest's precision and integration).
    pub firmware: Option<PathBuf>,
    /// Where the per-board ELFs and schedule blobs go (default `DIR/qemu`).
    pub images: Option<PathBuf>,
    /// The whole run's bound.
    pub deadline: Duration,
    /// End this board's QEMU this long after every board began (told the host its
    /// compilation id, before its step 0): a board dying mid-run.
    pub kill: Option<([usize; 3], Duration)>,
    /// Swap the far ends of the cables at these two connectors.
    pub cross: Option<[Connector; 2]>,
    /// Print the boards' fault reports as they arrive.
    pub quiet: bool,
}

impl Default for ArrayOptions {
    fn default() -> Self {
        ArrayOptions {
            qemu: "qemu-system-arm".into(),
            firmware: None,
            images: None,
            deadline: Duration::from_secs(1800),
            kill: None,
            cross: None,
            quiet: true,
        }
    }
}

/// How one board's QEMU ended.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BoardRun {
    pub board: [usize; 3],
    /// Exit status (`None`: ended by a signal, e.g. killed).
    pub status: Option<i32>,
    /// Ended by the harness (`--kill`, the deadline or the watchdog).
    pub killed_by_harness: Option<String>,
    /// Seconds from the start to its exit.
    pub exit_s: f64,
    /// Its fault, as its console and its fault packet said.
    pub fault: Option<String>,
    /// Bytes it sent on each face (Face::index order) and on its global port.
    pub face_bytes_sent: [u64; 6],
    pub global_bytes_sent: u64,
}

/// What an array run produced.
#[derive(Debug)]
pub struct ArrayOutput {
    pub machine: [usize; 3],
    pub steps: u64,
    /// From the first QEMU's start to the last one's exit.
    pub wall_s: f64,
    pub boards: Vec<BoardRun>,
    /// Every mesh node's final displacement (the boards' reports merged).
    pub displacements: Vec<[f64; 3]>,
    /// Global packets routed between boards, and taken by the host and graphics sinks.
    pub packets_between_boards: u64,
    pub packets_to_sinks: u64,
    /// Surface frames the graphics engine assembled, and the host's per-step tool force.
    pub graphics_frames: usize,
    pub tool_force: Vec<[f64; 3]>,
}

/// The boards' own account of a failed run: what the harness did (a kill, the deadline),
/// then every board's fault ordered by step.
#[derive(Debug)]
pub struct ArrayFault {
    pub boards: Vec<BoardRun>,
    pub lines: Vec<String>,
}

impl std::fmt::Display for ArrayFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "the emulated array did not finish:")?;
        for l in &self.lines {
            writeln!(f, "  {l}")?;
        }
        Ok(())
    }
}

impl std::error::Error for ArrayFault {}

/// The global address of a board.
fn address(c: [usize; 3]) -> u8 {
    link_proto::Machine::address(c).unwrap_or(u8::MAX)
}

fn name(c: [usize; 3]) -> String {
    format!("({},{},{})", c[0], c[1], c[2])
}

/// The step a fault message names (`board (x,y,z) step N: ...`), for ordering.
fn fault_step(text: &str) -> Option<u64> {
    let rest = text.split(" step ").nth(1)?;
    rest.split(|c: char| !c.is_ascii_digit())
        .next()?
        .parse()
        .ok()
}

/// The board across the link a fault message says timed out (`board (x,y,z) step N: link
/// FACE: no frame within the timeout`, FACE as the firmware prints it: `PosX`, `NegY`...).
fn timed_out_neighbour(text: &str) -> Option<[usize; 3]> {
    if !text.contains("no frame within the timeout") {
        return None;
    }
    let board = parse_board(text.strip_prefix("board (")?.split(')').next()?)?;
    let face = text.split(": link ").nth(1)?.split(':').next()?;
    let f = Face::ALL.into_iter().find(|f| format!("{f:?}") == face)?;
    link_proto::machine::across(board, f)
}

/// One board's QEMU and what it said.
struct Emulated {
    board: [usize; 3],
    child: Child,
    console: Arc<Mutex<String>>,
    readers: Vec<std::thread::JoinHandle<()>>,
    exited: Option<(Option<i32>, f64)>,
    killed: Option<String>,
}

/// Progress seen by the watchdog: bumped by every byte relayed or printed.
#[derive(Default)]
struct Activity(AtomicU64);

impl Activity {
    fn bump(&self, n: usize) {
        self.0.fetch_add(n as u64, Ordering::Relaxed);
    }
    fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// Reads `from` until it ends, counting the bytes, handing each chunk to `take`.
fn pump(mut from: TcpStream, sent: &AtomicU64, act: &Activity, mut take: impl FnMut(&[u8])) {
    let mut buf = [0u8; 4096];
    loop {
        let n = match from.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        sent.fetch_add(n as u64, Ordering::Relaxed);
        act.bump(n);
        take(&buf[..n]);
    }
}

/// Copies `from` to `to` until `from` ends, counting bytes; once `to` fails the bytes are
/// read and dropped (a dead board's cable: the sender must not stall on it).
fn relay(from: TcpStream, mut to: TcpStream, sent: Arc<AtomicU64>, act: Arc<Activity>) {
    let mut open = true;
    pump(from, &sent, &act, |bytes| {
        if open && to.write_all(bytes).is_err() {
            open = false;
        }
    });
}

/// The global network: packets from board `src`'s global port, routed on their destination.
struct GlobalSwitch {
    /// Each board's global socket (for packets to it), by global address.
    ports: BTreeMap<u8, Mutex<TcpStream>>,
    sinks: Arc<GlobalNet>,
    /// Fault reports the host received: (source address, text).
    faults: Mutex<Vec<(u8, String)>>,
    /// Damaged packets (a decode or CRC failure): (source board, error).
    damaged: Mutex<Vec<(u8, String)>>,
    between_boards: AtomicU64,
    to_sinks: AtomicU64,
}

impl GlobalSwitch {
    fn forward(&self, dst: u8, packet: &[u8]) {
        let mut wire = vec![0u8; link_proto::PACKET_WIRE_LEN_MAX];
        let Ok(n) = link_proto::encode_wire(packet, &mut wire) else {
            return;
        };
        if let Some(port) = self.ports.get(&dst) {
            if let Ok(mut s) = port.lock() {
                // A dead board's port fails: its packets are lost, as on a real network.
                let _ = s.write_all(&wire[..n]);
            }
        }
    }

    fn route(&self, src: u8, packet: &[u8]) {
        let repr = match PacketRepr::parse_bytes(packet) {
            Ok(r) => r,
            Err(e) => {
                if let Ok(mut d) = self.damaged.lock() {
                    d.push((src, e.to_string()));
                }
                return;
            }
        };
        match repr.dst {
            ADDR_HOST if repr.kind == PacketKind::FaultReport => {
                let text = String::from_utf8_lossy(repr.payload).into_owned();
                if let Ok(mut f) = self.faults.lock() {
                    f.push((repr.src, text));
                }
            }
            ADDR_HOST | ADDR_GRAPHICS => {
                self.to_sinks.fetch_add(1, Ordering::Relaxed);
                let _ = self.sinks.deliver(repr.dst, repr.src, packet);
            }
            ADDR_BROADCAST => {
                for &a in self.ports.keys().filter(|&&a| a != src) {
                    self.between_boards.fetch_add(1, Ordering::Relaxed);
                    self.forward(a, packet);
                }
            }
            d => {
                self.between_boards.fetch_add(1, Ordering::Relaxed);
                self.forward(d, packet);
            }
        }
    }

    /// Reads board `src`'s global port until it closes.
    fn serve(&self, src: u8, from: TcpStream, sent: Arc<AtomicU64>, act: Arc<Activity>) {
        let mut decoder = link_proto::framing::StreamDecoder::<
            { link_proto::limits::PACKET_COBS_LEN_MAX },
        >::new();
        pump(from, &sent, &act, |mut rest| {
            while !rest.is_empty() {
                let (used, event) = decoder.push(rest);
                rest = &rest[used..];
                match event {
                    Some(Ok(packet)) => {
                        let packet = packet.to_vec();
                        self.route(src, &packet);
                    }
                    Some(Err(e)) => {
                        if let Ok(mut d) = self.damaged.lock() {
                            d.push((src, e.to_string()));
                        }
                    }
                    None => {}
                }
            }
        });
    }
}

/// Hello packets the host has taken (each board sends one before its step 0).
fn hellos(net: &GlobalNet) -> usize {
    net.host.lock().map_or(0, |h| {
        h.iter()
            .filter(|p| p.get(4) == Some(&PacketKind::Hello.code()))
            .count()
    })
}

/// Accepts one connection on `l` within `deadline`, while `alive` says the QEMU that
/// should connect still runs.
fn accept(
    l: &TcpListener,
    deadline: Instant,
    alive: &mut dyn FnMut() -> bool,
) -> Result<TcpStream> {
    l.set_nonblocking(true)?;
    loop {
        match l.accept() {
            Ok((s, _)) => {
                s.set_nonblocking(false)?;
                let _ = s.set_nodelay(true);
                return Ok(s);
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                if Instant::now() > deadline {
                    bail!("no connection within the start-up time");
                }
                if !alive() {
                    bail!("QEMU exited before connecting its UART");
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(e) => return Err(e.into()),
        }
    }
}

/// The cables of a machine: each linked face connector with the one across it (each cable
/// once, lower board first), `cross` applied.
pub fn cables(
    linked: &BTreeMap<[usize; 3], [bool; 6]>,
    cross: Option<[Connector; 2]>,
) -> Result<Vec<(Connector, Connector)>> {
    let mut out = Vec::new();
    for (&b, l) in linked {
        for face in Face::ALL.into_iter().filter(|f| f.sign() > 0) {
            if !l[face.index()] {
                continue;
            }
            let mut n = b;
            n[face.index() / 2] += 1;
            if !linked.get(&n).is_some_and(|nl| nl[face.opposite().index()]) {
                bail!(
                    "board {} exchanges over {} but board {} does not over {}: the images disagree on the machine",
                    name(b),
                    link_proto::link::FACE_NAMES[face.index()],
                    name(n),
                    link_proto::link::FACE_NAMES[face.opposite().index()]
                );
            }
            out.push((
                Connector {
                    board: b,
                    face: face.index(),
                },
                Connector {
                    board: n,
                    face: face.opposite().index(),
                },
            ));
        }
    }
    if let Some([a, b]) = cross {
        let find = |c: Connector| {
            out.iter()
                .position(|&(p, q)| p == c || q == c)
                .ok_or_else(|| anyhow!("--cross: connector {c} carries no cable in this machine"))
        };
        let (i, j) = (find(a)?, find(b)?);
        if i == j {
            bail!(
                "--cross: {a} and {b} are the two ends of one cable: crossing it changes nothing"
            );
        }
        // Each cable as (the named connector, its far end); the far ends swap.
        let split = |k: usize, c: Connector| {
            let (p, q) = out[k];
            if p == c {
                (p, q)
            } else {
                (q, p)
            }
        };
        let ((a, fa), (b, fb)) = (split(i, a), split(j, b));
        out[i] = (a, fb);
        out[j] = (b, fa);
    }
    Ok(out)
}

/// Runs the images of `dir` (`pe compile --profile qemu-mps2-an500`) on one QEMU per board.
pub fn run_array(dir: &Path, opts: &ArrayOptions) -> Result<ArrayOutput> {
    let m = read_manifest(dir)?;
    let qemu_profile = pe_firmware::profile::QEMU_MPS2_AN500;
    if m.profile != qemu_profile.name {
        bail!(
            "{}: compiled for the {} profile; the emulated array runs images of the {} profile (pe compile ... --profile {})",
            dir.display(),
            m.profile,
            qemu_profile.name,
            qemu_profile.name
        );
    }
    let version = Command::new(&opts.qemu).arg("--version").output();
    if !version.is_ok_and(|o| o.status.success()) {
        bail!(
            "{} not found or not working: install QEMU's Arm system emulator (apt-get install qemu-system-arm)",
            opts.qemu.display()
        );
    }
    let images = opts.images.clone().unwrap_or_else(|| dir.join("qemu"));
    let im = host_tools::firmware::image_dir(dir, &images, opts.firmware.as_deref())?;

    // Which faces each board exchanges over, and the UART each goes on.
    let mut linked = BTreeMap::new();
    let mut uarts = BTreeMap::new();
    let mut tools = 0;
    for b in &m.boards {
        let p = dir.join(&b.file);
        let bytes = std::fs::read(&p).with_context(|| format!("reading {}", p.display()))?;
        let h = ImageReader::new(&bytes, Some(b.board.map(|v| v as u8)))
            .map_err(|e| anyhow!("board {}: {}: {e}", name(b.board), p.display()))?
            .header;
        // The scene's tools: the most any image holds (a board that owns no contact
        // node carries no contact tables).
        tools = tools.max(h.counts.tools as usize);
        let l = h.linked_faces();
        let u = mps2_uarts::face_uarts(l).map_err(|n| {
            anyhow!(
                "board {} exchanges over {n} faces; QEMU's mps2-an500 has {} UARTs for faces (the fifth is the global port)",
                name(b.board),
                mps2_uarts::FACE_UARTS.len()
            )
        })?;
        linked.insert(b.board, l);
        uarts.insert(b.board, u);
    }
    let cables = cables(&linked, opts.cross)?;

    // A listening socket per UART in use; QEMU connects to it as it starts.
    let mut listeners: BTreeMap<([usize; 3], usize), TcpListener> = BTreeMap::new();
    for (&b, u) in &uarts {
        for uart in u.iter().flatten().copied().chain([mps2_uarts::GLOBAL_UART]) {
            listeners.insert((b, uart), TcpListener::bind("127.0.0.1:0")?);
        }
    }
    let act = Arc::new(Activity::default());
    let start = Instant::now();
    let mut boards: Vec<Emulated> = Vec::new();
    for b in &im.boards {
        let mut cmd = Command::new(&opts.qemu);
        cmd.current_dir(&images)
            .args(["-cpu", "cortex-m7", "-machine", "mps2-an500"])
            .args(["-display", "none", "-monitor", "none"])
            .args(["-semihosting-config", "enable=on,target=native"])
            .arg("-kernel")
            .arg(&b.elf)
            .arg("-device")
            .arg(format!(
                "loader,file={},addr={}",
                b.schedule, b.schedule_address
            ));
        for uart in 0..mps2_uarts::UART_BASES.len() {
            match listeners.get(&(b.board, uart)) {
                Some(l) => {
                    let port = l.local_addr()?.port();
                    cmd.arg("-chardev").arg(format!(
                        "socket,id=u{uart},host=127.0.0.1,port={port},server=off,nodelay=on"
                    ));
                    cmd.arg("-serial").arg(format!("chardev:u{uart}"));
                }
                None => {
                    cmd.args(["-serial", "null"]);
                }
            }
        }
        cmd.stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().with_context(|| {
            format!(
                "starting {} for board {}",
                opts.qemu.display(),
                name(b.board)
            )
        })?;
        let console = Arc::new(Mutex::new(String::new()));
        let mut readers = Vec::new();
        let out = child
            .stdout
            .take()
            .map(|s| Box::new(s) as Box<dyn Read + Send>);
        let err = child
            .stderr
            .take()
            .map(|s| Box::new(s) as Box<dyn Read + Send>);
        for stream in [out, err].into_iter().flatten() {
            let (console, act) = (console.clone(), act.clone());
            let (quiet, who) = (opts.quiet, name(b.board));
            readers.push(std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    act.bump(line.len() + 1);
                    if !quiet && line.contains("FAULT") {
                        eprintln!("board {who}: {line}");
                    }
                    if let Ok(mut c) = console.lock() {
                        c.push_str(&line);
                        c.push('\n');
                    }
                }
            }));
        }
        boards.push(Emulated {
            board: b.board,
            child,
            console,
            readers,
            exited: None,
            killed: None,
        });
    }

    // Every UART's connection.
    let startup = Instant::now() + Duration::from_secs(30);
    let mut sockets: BTreeMap<([usize; 3], usize), TcpStream> = BTreeMap::new();
    for (&(b, uart), l) in &listeners {
        let k = boards.iter().position(|e| e.board == b).unwrap_or(0);
        let mut alive = || matches!(boards[k].child.try_wait(), Ok(None));
        match accept(l, startup, &mut alive) {
            Ok(s) => {
                sockets.insert((b, uart), s);
            }
            Err(e) => {
                let text = boards[k]
                    .console
                    .lock()
                    .map(|c| c.clone())
                    .unwrap_or_default();
                for e in &mut boards {
                    let _ = e.child.kill();
                    let _ = e.child.wait();
                }
                bail!(
                    "board {}: UART {uart}: {e}; QEMU said:\n{}",
                    name(b),
                    text.lines().rev().take(5).collect::<Vec<_>>().join("\n")
                );
            }
        }
    }

    // Cables, relayed both ways.
    let face_sent: BTreeMap<Connector, Arc<AtomicU64>> = linked
        .iter()
        .flat_map(|(&b, l)| {
            (0..6)
                .filter(|&f| l[f])
                .map(move |face| (Connector { board: b, face }, Arc::new(AtomicU64::new(0))))
        })
        .collect();
    let socket = |c: Connector| -> Result<TcpStream> {
        let uart = uarts[&c.board][c.face].context("face without a UART")?;
        Ok(sockets[&(c.board, uart)].try_clone()?)
    };
    let mut threads = Vec::new();
    for &(a, b) in &cables {
        for (from, to) in [(a, b), (b, a)] {
            let (src, dst) = (socket(from)?, socket(to)?);
            let (sent, act) = (face_sent[&from].clone(), act.clone());
            threads.push(std::thread::spawn(move || relay(src, dst, sent, act)));
        }
    }
    // The global network.
    let global_uart = mps2_uarts::GLOBAL_UART;
    let mut ports = BTreeMap::new();
    for &b in linked.keys() {
        ports.insert(
            address(b),
            Mutex::new(sockets[&(b, global_uart)].try_clone()?),
        );
    }
    let switch = Arc::new(GlobalSwitch {
        ports,
        sinks: GlobalNet::sinks(),
        faults: Mutex::new(Vec::new()),
        damaged: Mutex::new(Vec::new()),
        between_boards: AtomicU64::new(0),
        to_sinks: AtomicU64::new(0),
    });
    let global_sent: BTreeMap<[usize; 3], Arc<AtomicU64>> = linked
        .keys()
        .map(|&b| (b, Arc::new(AtomicU64::new(0))))
        .collect();
    for &b in linked.keys() {
        let from = sockets[&(b, global_uart)].try_clone()?;
        let (sw, sent, act) = (switch.clone(), global_sent[&b].clone(), act.clone());
        threads.push(std::thread::spawn(move || {
            sw.serve(address(b), from, sent, act)
        }));
    }
    drop(sockets);

    // Supervise: exits, the kill, the deadline, the watchdog.
    let timeout = Duration::from_nanos(RuntimeConfig::default().link_timeout_ns);
    let quiet_limit = 2 * timeout + Duration::from_secs(5);
    let (mut last_activity, mut last_seen) = (act.get(), Instant::now());
    // When every board had told the host its compilation id (before its step 0): the run
    // has begun, and `--kill` counts from there.
    let mut begun: Option<Instant> = None;
    loop {
        let now = Instant::now();
        let t = now.duration_since(start);
        if begun.is_none() && hellos(&switch.sinks) >= boards.len() {
            begun = Some(now);
        }
        let mut running = 0;
        for e in &mut boards {
            if e.exited.is_none() {
                match e.child.try_wait() {
                    Ok(Some(st)) => e.exited = Some((st.code(), t.as_secs_f64())),
                    Ok(None) => running += 1,
                    Err(_) => e.exited = Some((None, t.as_secs_f64())),
                }
            }
        }
        if running == 0 {
            break;
        }
        if act.get() != last_activity {
            (last_activity, last_seen) = (act.get(), now);
        }
        let mut end_all = None;
        if t > opts.deadline {
            end_all = Some(format!(
                "still running at the run's deadline ({:.0} s): ended by the harness",
                opts.deadline.as_secs_f64()
            ));
        } else if now.duration_since(last_seen) > quiet_limit {
            end_all = Some(format!(
                "no byte on any link, global port or console for {:.0} s (twice the boards' link timeout and more): ended by the harness",
                quiet_limit.as_secs_f64()
            ));
        }
        for e in &mut boards {
            if e.exited.is_some() || e.killed.is_some() {
                continue;
            }
            let why = match (&end_all, opts.kill) {
                (Some(w), _) => Some(w.clone()),
                (None, Some((b, after))) if b == e.board && begun.is_some_and(|s| now >= s + after) => {
                    Some(format!(
                        "killed by the harness at {:.2} s, {:.2} s after every board began (--kill)",
                        t.as_secs_f64(),
                        begun.map_or(0.0, |s| now.duration_since(s).as_secs_f64())
                    ))
                }
                _ => None,
            };
            if let Some(w) = why {
                let _ = e.child.kill();
                e.killed = Some(w);
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let wall_s = start.elapsed().as_secs_f64();
    for e in &mut boards {
        let _ = e.child.wait();
        for r in e.readers.drain(..) {
            let _ = r.join();
        }
    }
    for t in threads {
        let _ = t.join();
    }

    // The boards' account.
    let faults = switch.faults.lock().map(|f| f.clone()).unwrap_or_default();
    let runs: Vec<BoardRun> = boards
        .iter()
        .map(|e| {
            let console = e.console.lock().map(|c| c.clone()).unwrap_or_default();
            let fault = console
                .lines()
                .find_map(|l| l.split_once("pe-board: FAULT ").map(|(_, f)| f.to_string()))
                .or_else(|| {
                    faults
                        .iter()
                        .find(|(src, _)| *src == address(e.board))
                        .map(|(_, t)| t.clone())
                });
            let mut face_bytes_sent = [0; 6];
            for (f, sent) in face_bytes_sent.iter_mut().enumerate() {
                if let Some(s) = face_sent.get(&Connector {
                    board: e.board,
                    face: f,
                }) {
                    *sent = s.load(Ordering::Relaxed);
                }
            }
            BoardRun {
                board: e.board,
                status: e.exited.and_then(|x| x.0),
                killed_by_harness: e.killed.clone(),
                exit_s: e.exited.map_or(wall_s, |x| x.1),
                fault,
                face_bytes_sent,
                global_bytes_sent: global_sent[&e.board].load(Ordering::Relaxed),
            }
        })
        .collect();
    let failed = runs
        .iter()
        .any(|r| r.status != Some(0) || r.killed_by_harness.is_some() || r.fault.is_some());
    let damaged = switch.damaged.lock().map(|d| d.clone()).unwrap_or_default();
    if failed || !damaged.is_empty() {
        let mut lines: Vec<String> = runs
            .iter()
            .filter_map(|r| {
                r.killed_by_harness
                    .as_ref()
                    .map(|w| format!("board {}: {w}", name(r.board)))
            })
            .collect();
        let mut said: Vec<(u64, f64, String)> = runs
            .iter()
            .filter_map(|r| {
                let f = r.fault.as_ref()?;
                Some((fault_step(f).unwrap_or(u64::MAX), r.exit_s, f.clone()))
            })
            .collect();
        said.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
        let stopped = |c: [usize; 3]| runs.iter().find(|r| r.board == c);
        lines.extend(said.into_iter().map(|(_, t, f)| {
            let mut l = format!("{f} (reported over the global port; exited at {t:.2} s)");
            // A wait on a link whose far board had already gone: say so (the cause is
            // that board, the wait its consequence).
            if let Some(far) = timed_out_neighbour(&f) {
                match stopped(far) {
                    Some(r) if r.killed_by_harness.is_some() => l.push_str(&format!(
                        "; across that link: board {}, dead ({})",
                        name(far),
                        r.killed_by_harness.as_deref().unwrap_or_default()
                    )),
                    // Gone before this board's wait began (one link timeout before its
                    // report): that board's stop is what it waited on.
                    Some(r) if r.fault.is_some() && r.exit_s < t - 0.9 * timeout.as_secs_f64() => l
                        .push_str(&format!(
                            "; across that link: board {}, stopped by its own fault at {:.2} s",
                            name(far),
                            r.exit_s
                        )),
                    _ => {}
                }
            }
            l
        }));
        for r in &runs {
            if r.fault.is_none() && r.killed_by_harness.is_none() && r.status != Some(0) {
                lines.push(format!(
                    "board {}: QEMU exited with {:?} without a fault report",
                    name(r.board),
                    r.status
                ));
            }
        }
        lines.extend(damaged.iter().map(|(src, e)| {
            format!(
                "global network: a damaged packet from {}: {e}",
                crate::fabric::address_name(*src)
            )
        }));
        return Err(ArrayFault {
            boards: runs,
            lines,
        }
        .into());
    }

    // The final state: every board's owned nodes.
    let mut merged: Vec<Option<[f64; 3]>> = Vec::new();
    for e in &boards {
        let console = e.console.lock().map(|c| c.clone()).unwrap_or_default();
        let own = host_tools::firmware::parse_displacements(
            &console,
            &format!("board {}", name(e.board)),
        )?;
        if merged.len() < own.len() {
            merged.resize(own.len(), None);
        }
        for (n, u) in own.into_iter().enumerate() {
            if let Some(u) = u {
                if merged[n].replace(u).is_some() {
                    bail!(
                        "node {n} reported by two boards (board {} the second)",
                        name(e.board)
                    );
                }
            }
        }
    }
    let missing: Vec<usize> = (0..merged.len()).filter(|&n| merged[n].is_none()).collect();
    if !missing.is_empty() {
        bail!(
            "{} nodes reported by no board (first: {:?})",
            missing.len(),
            &missing[..missing.len().min(10)]
        );
    }
    let displacements: Vec<[f64; 3]> = merged.into_iter().flatten().collect();
    let mut check =
        crate::check::HostCheck::new(&m.compilation, crate::runner::manifest_machine(dir, &m)?);
    check.finish(&switch.sinks)?;
    let (frames, tool_force) = crate::check::collect_sinks(&switch.sinks, m.steps, tools)?;
    Ok(ArrayOutput {
        machine: m.machine,
        steps: m.steps,
        wall_s,
        boards: runs,
        displacements,
        packets_between_boards: switch.between_boards.load(Ordering::Relaxed),
        packets_to_sinks: switch.to_sinks.load(Ordering::Relaxed),
        graphics_frames: frames.len(),
        tool_force,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn machine(m: [usize; 3]) -> BTreeMap<[usize; 3], [bool; 6]> {
        let mut out = BTreeMap::new();
        for z in 0..m[2] {
            for y in 0..m[1] {
                for x in 0..m[0] {
                    let b = [x as u8, y as u8, z as u8];
                    let l = pe_firmware::image::linked_faces(b, m.map(|v| v as u8), [1, 1, 1]);
                    out.insert([x, y, z], l);
                }
            }
        }
        out
    }

    fn c(b: [usize; 3], face: Face) -> Connector {
        Connector {
            board: b,
            face: face.index(),
        }
    }

    /// Every link of a 2x2x2 machine once (12 cables), each joining a face to its
    /// neighbour's opposite face; crossing two swaps their far ends and nothing else.
    #[test]
    fn cables_join_opposite_faces_and_cross_swaps_far_ends() {
        let plain = cables(&machine([2, 2, 2]), None).unwrap();
        assert_eq!(plain.len(), 12);
        for &(a, b) in &plain {
            assert_eq!(b.face, Face::ALL[a.face].opposite().index());
            let mut n = a.board;
            n[a.face / 2] += 1;
            assert_eq!(b.board, n);
        }
        let (x, y) = (c([0, 0, 0], Face::PosX), c([0, 0, 0], Face::PosY));
        let crossed = cables(&machine([2, 2, 2]), Some([x, y])).unwrap();
        assert_eq!(crossed.len(), plain.len());
        let far = |cs: &[(Connector, Connector)], k: Connector| {
            cs.iter()
                .find_map(|&(p, q)| (p == k).then_some(q).or((q == k).then_some(p)))
                .unwrap()
        };
        assert_eq!(far(&crossed, x), c([0, 1, 0], Face::NegY));
        assert_eq!(far(&crossed, y), c([1, 0, 0], Face::NegX));
        let unchanged = plain.iter().zip(&crossed).filter(|(p, q)| p == q).count();
        assert_eq!(unchanged, 10);
    }

    /// A connector without a cable, or both ends of one cable, cannot be crossed.
    #[test]
    fn crossing_needs_two_cables() {
        let m = machine([2, 1, 1]);
        let e = cables(
            &m,
            Some([c([0, 0, 0], Face::PosX), c([0, 0, 0], Face::PosY)]),
        );
        assert!(e
            .unwrap_err()
            .to_string()
            .contains("(0,0,0) +y carries no cable"));
        let e = cables(
            &m,
            Some([c([0, 0, 0], Face::PosX), c([1, 0, 0], Face::NegX)]),
        );
        assert!(e.unwrap_err().to_string().contains("two ends of one cable"));
    }

    /// Fault messages of the firmware name the board across a timed-out link.
    #[test]
    fn a_timed_out_link_names_the_board_across_it() {
        let t = "board (1,1,0) step 19: link NegY: no frame within the timeout";
        assert_eq!(timed_out_neighbour(t), Some([1, 0, 0]));
        assert_eq!(fault_step(t), Some(19));
        let other = "board (1,1,0) step 19: link NegY: bad frame: CRC mismatch";
        assert_eq!(timed_out_neighbour(other), None);
    }

    #[test]
    fn connectors_parse_as_written() {
        assert_eq!(
            Connector::parse("1,0,2:-z").unwrap(),
            c([1, 0, 2], Face::NegZ)
        );
        assert!(Connector::parse("1,0:+x").is_err());
        assert!(Connector::parse("1,0,0:x").is_err());
        assert_eq!(c([1, 0, 2], Face::NegZ).to_string(), "(1,0,2) -z");
    }
}
