//! Starting the array: one QEMU per board, each UART a TCP socket QEMU connects to this
//! process at start, each console kept (and its fault lines printed unless quiet).

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use host_tools::firmware::ImageBoard;
use pe_firmware::profile::mps2_uarts;

use super::options::ArrayOptions;
use super::relay::Activity;
use super::wiring::{name, Uart};

/// One board's QEMU and what it said.
pub(crate) struct Emulated {
    pub board: [usize; 3],
    pub child: Child,
    pub console: Arc<Mutex<String>>,
    pub readers: Vec<JoinHandle<()>>,
    /// Exit status and the time of the exit (s from the start).
    pub exited: Option<(Option<i32>, f64)>,
    /// Why the harness ended it.
    pub killed: Option<String>,
}

impl Emulated {
    /// What the board's QEMU printed so far.
    pub fn console(&self) -> String {
        self.console.lock().map(|c| c.clone()).unwrap_or_default()
    }
}

/// A listening socket per UART in use; QEMU connects to it as it starts.
pub(crate) fn listen(uarts: impl Iterator<Item = Uart>) -> Result<BTreeMap<Uart, TcpListener>> {
    let mut listeners = BTreeMap::new();
    for u in uarts {
        listeners.insert(u, TcpListener::bind("127.0.0.1:0")?);
    }
    Ok(listeners)
}

/// Starts one QEMU per board of `boards` (its ELF and schedule blob in `images`), its
/// UARTs connecting to `listeners`.
pub(crate) fn start_boards(
    boards: &[ImageBoard],
    images: &Path,
    listeners: &BTreeMap<Uart, TcpListener>,
    opts: &ArrayOptions,
    act: &Arc<Activity>,
) -> Result<Vec<Emulated>> {
    let mut out = Vec::new();
    for b in boards {
        let mut cmd = qemu_command(b, images, listeners, opts)?;
        let mut child = cmd.spawn().with_context(|| {
            format!(
                "starting {} for board {}",
                opts.qemu.display(),
                name(b.board)
            )
        })?;
        let console = Arc::new(Mutex::new(String::new()));
        let readers = read_console(&mut child, b.board, &console, opts.quiet, act);
        out.push(Emulated {
            board: b.board,
            child,
            console,
            readers,
            exited: None,
            killed: None,
        });
    }
    Ok(out)
}

/// The QEMU command line of board `b`: an mps2-an500 with its firmware and schedule, each
/// UART in use a socket to this process, the others null.
fn qemu_command(
    b: &ImageBoard,
    images: &Path,
    listeners: &BTreeMap<Uart, TcpListener>,
    opts: &ArrayOptions,
) -> Result<Command> {
    let mut cmd = Command::new(&opts.qemu);
    cmd.current_dir(images)
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
    Ok(cmd)
}

/// Threads keeping `child`'s stdout and stderr in `console` (fault lines printed unless
/// `quiet`), each line counted as activity.
fn read_console(
    child: &mut Child,
    board: [usize; 3],
    console: &Arc<Mutex<String>>,
    quiet: bool,
    act: &Arc<Activity>,
) -> Vec<JoinHandle<()>> {
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
        let who = name(board);
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
    readers
}

/// Every UART's connection, each within the start-up time while its QEMU runs; on a
/// failure every QEMU is ended and the board's last console lines are in the error.
pub(crate) fn connect(
    listeners: &BTreeMap<Uart, TcpListener>,
    boards: &mut [Emulated],
) -> Result<BTreeMap<Uart, TcpStream>> {
    let startup = Instant::now() + Duration::from_secs(30);
    let mut sockets = BTreeMap::new();
    for (&(b, uart), l) in listeners {
        let k = boards.iter().position(|e| e.board == b).unwrap_or(0);
        let mut alive = || matches!(boards[k].child.try_wait(), Ok(None));
        match accept(l, startup, &mut alive) {
            Ok(s) => {
                sockets.insert((b, uart), s);
            }
            Err(e) => {
                let text = boards[k].console();
                for e in boards.iter_mut() {
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
    Ok(sockets)
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
