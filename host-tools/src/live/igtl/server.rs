//! The OpenIGTLink transport: a TCP server (default port [`DEFAULT_PORT`], OpenIGTLink's
//! registered port) that talks to the session only through [`crate::live::hub`]. Threads:
//! one accepts; per client a reader (messages -> [`Inbound`], see [`super::inbound`]) and a
//! writer ([`Outbox::pop`] -> messages, see [`super::outbound`]), both ending when the peer
//! closes.
//!
//! - A message refused on its own (bad CRC, unknown type, unknown device name, a bad
//!   TRANSFORM) gives [`Inbound::Bad`] and the connection goes on: its body was read whole,
//!   so the next header is where the stream is.
//! - A header that is not one (version other than 1 or 2, a type or device name that is
//!   not text, a body over [`BODY_LEN_MAX`]) gives [`Inbound::Bad`], then the connection
//!   closes: nothing says where the next message starts.
//! - A client that closes mid-message, or whose outbox overflows (it does not read), or
//!   whose socket does not take a message within [`WRITE_TIMEOUT`], is disconnected with
//!   the reason in [`Inbound::Disconnected`]; the session goes on.

use std::collections::HashMap;
use std::io::{ErrorKind, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use super::header::{device_name_of, timestamp_now, HeaderRepr, BODY_LEN_MAX, HEADER_LEN};
use super::inbound::inbound_of;
use super::outbound::{Encoder, SurfaceTopology};
use crate::live::engine::EngineInfo;
use crate::live::hub::{ClientId, Inbound, Outbox, Transport};

/// OpenIGTLink's port (IANA-registered, the default of Slicer's OpenIGTLinkIF).
pub const DEFAULT_PORT: u16 = 18944;
/// Messages queued for one client: 2 s of one tool's 1 kHz forces. Surface frames beyond
/// it are dropped for the client (a newer one follows); forces and messages piling past it
/// mean the client does not read, and it is disconnected.
pub const OUTBOX_LIMIT: usize = 2048;
/// How long a write may block before the client is taken as gone.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// How often a writer with nothing to send looks whether its client is gone.
const POLL: Duration = Duration::from_millis(100);

/// What the transport knows of the scene: the tools a TRANSFORM may name, the surface a
/// POLYDATA carries.
#[derive(Clone, Debug)]
pub struct Scene {
    pub tools: Vec<String>,
    pub surface: SurfaceTopology,
}

impl Scene {
    /// The scene of an engine (its name is the POLYDATA's device name).
    pub fn of(info: &EngineInfo) -> Scene {
        Scene {
            tools: info.tools.iter().map(|t| t.name.clone()).collect(),
            surface: SurfaceTopology {
                device: info.scene.clone(),
                nodes: info.surface.reference_m.len(),
                triangles: info.surface.triangles.clone(),
            },
        }
    }
}

/// `listen`'s host with port `port` (OpenIGTLink listens where the page does).
pub fn address_beside(listen: &str, port: u16) -> Result<SocketAddr> {
    let mut a = listen
        .to_socket_addrs()
        .with_context(|| format!("--listen {listen}: not HOST:PORT"))?
        .next()
        .with_context(|| format!("--listen {listen}: no address"))?;
    a.set_port(port);
    Ok(a)
}

/// A session's OpenIGTLink server on `listen`'s host at `port` (0: none) for the engine
/// described by `info`; stopped when dropped.
pub fn start(
    listen: &str,
    port: u16,
    info: &EngineInfo,
    inbound: Sender<Inbound>,
    ids: Arc<AtomicU32>,
    quiet: bool,
) -> Result<Option<IgtlServer>> {
    if port == 0 {
        return Ok(None);
    }
    let server = IgtlServer::start(address_beside(listen, port)?, Scene::of(info), inbound, ids)?;
    if !quiet {
        eprintln!(
            "pe live: OpenIGTLink on {} (TRANSFORM per tool in; POINT forces, POLYDATA surface \"{}\" out)",
            server.addr(),
            device_name_of(&info.scene)
        );
    }
    Ok(Some(server))
}

/// The listening server; stopped (every client disconnected) when dropped.
pub struct IgtlServer {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    clients: Arc<Mutex<HashMap<ClientId, TcpStream>>>,
    accept: Option<JoinHandle<()>>,
}

/// What every client thread shares.
struct Shared {
    scene: Scene,
    inbound: Sender<Inbound>,
    ids: Arc<AtomicU32>,
    clients: Arc<Mutex<HashMap<ClientId, TcpStream>>>,
}

impl IgtlServer {
    /// Listens on `addr` (port 0: a free one); clients are numbered from `ids` (the
    /// session's one counter: `fetch_add(1) + 1`, from 1) and their events go to `inbound`.
    pub fn start(
        addr: SocketAddr,
        scene: Scene,
        inbound: Sender<Inbound>,
        ids: Arc<AtomicU32>,
    ) -> Result<IgtlServer> {
        // Refuse a topology the encoder cannot send now, not at the first client.
        Encoder::new(&scene.surface).context("OpenIGTLink: the scene's surface")?;
        let listener = TcpListener::bind(addr)
            .with_context(|| format!("--igtl-port: cannot listen on {addr}"))?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let clients = Arc::new(Mutex::new(HashMap::new()));
        let shared = Arc::new(Shared {
            scene,
            inbound,
            ids,
            clients: clients.clone(),
        });
        let flag = stop.clone();
        let accept = std::thread::Builder::new()
            .name("pe-live-igtl".into())
            .spawn(move || accept_loop(&listener, &flag, &shared))?;
        Ok(IgtlServer {
            addr,
            stop,
            clients,
            accept: Some(accept),
        })
    }

    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops accepting and disconnects every client.
    pub fn stop(&mut self) {
        if self.stop.swap(true, Ordering::SeqCst) {
            return;
        }
        // Wake the accept thread with a connection of our own.
        let _ = TcpStream::connect_timeout(&self.addr, Duration::from_secs(1));
        if let Some(t) = self.accept.take() {
            let _ = t.join();
        }
        if let Ok(mut c) = self.clients.lock() {
            for (_, s) in c.drain() {
                let _ = s.shutdown(Shutdown::Both);
            }
        }
    }
}

impl Drop for IgtlServer {
    fn drop(&mut self) {
        self.stop();
    }
}

fn accept_loop(listener: &TcpListener, stop: &AtomicBool, shared: &Arc<Shared>) {
    for conn in listener.incoming() {
        if stop.load(Ordering::SeqCst) {
            return;
        }
        let Ok(stream) = conn else { continue };
        let shared = shared.clone();
        let spawned = std::thread::Builder::new()
            .name("pe-live-igtl-read".into())
            .spawn(move || serve_client(stream, &shared));
        if spawned.is_err() {
            // No thread for it: the stream was dropped with the closure (closed).
            continue;
        }
    }
}

/// The reader thread of one client: announces it, starts its writer, reads until it goes.
fn serve_client(stream: TcpStream, shared: &Shared) {
    let client: ClientId = shared.ids.fetch_add(1, Ordering::SeqCst) + 1;
    let peer = stream
        .peer_addr()
        .map_or_else(|_| "unknown peer".to_string(), |a| a.to_string());
    let _ = stream.set_nodelay(true);
    let _ = stream.set_write_timeout(Some(WRITE_TIMEOUT));
    let (Ok(writer_stream), Ok(registry)) = (stream.try_clone(), stream.try_clone()) else {
        return;
    };
    if let Ok(mut c) = shared.clients.lock() {
        c.insert(client, registry);
    }
    let outbox = Outbox::new(OUTBOX_LIMIT);
    let gone = Arc::new(Mutex::new(None::<String>));
    let connected = Inbound::Connected {
        client,
        transport: Transport::Igtl,
        peer,
        outbox: outbox.clone(),
    };
    if shared.inbound.send(connected).is_err() {
        return; // the session has ended
    }
    let writer = {
        let (outbox, gone) = (outbox.clone(), gone.clone());
        let surface = shared.scene.surface.clone();
        std::thread::Builder::new()
            .name("pe-live-igtl-write".into())
            .spawn(move || write_loop(writer_stream, &outbox, &surface, &gone))
    };
    let reason = match writer {
        Ok(_) => read_loop(&stream, client, shared),
        Err(e) => format!("no writer thread: {e}"),
    };
    let reason = gone
        .lock()
        .ok()
        .and_then(|mut g| g.take())
        .unwrap_or(reason);
    let _ = stream.shutdown(Shutdown::Both);
    if let Ok(mut c) = shared.clients.lock() {
        c.remove(&client);
    }
    outbox.close();
    let _ = shared
        .inbound
        .send(Inbound::Disconnected { client, reason });
}

/// Reads messages until the client goes; returns why it went.
fn read_loop(mut stream: &TcpStream, client: ClientId, shared: &Shared) -> String {
    let mut head = [0u8; HEADER_LEN];
    loop {
        match read_full(&mut stream, &mut head) {
            Ok(()) => {}
            Err(Some(0)) => return "closed by the client".into(),
            Err(Some(n)) => return format!("closed mid-header ({n} of {HEADER_LEN} bytes)"),
            Err(None) => return "connection reset".into(),
        }
        let header = match HeaderRepr::parse_bytes(&head) {
            Ok(h) => h,
            Err(e) => {
                let message = format!(
                    "OpenIGTLink header refused, closing (the stream is not at a message \
                     boundary): {e}"
                );
                let _ = shared.inbound.send(Inbound::Bad { client, message });
                return format!("broke the framing: {e}");
            }
        };
        // At most BODY_LEN_MAX (16 MiB), checked by parse.
        let mut body = vec![0u8; usize::try_from(header.body_len.min(BODY_LEN_MAX)).unwrap_or(0)];
        match read_full(&mut stream, &mut body) {
            Ok(()) => {}
            Err(Some(n)) => {
                return format!(
                    "closed mid-message ({} {:?}: {n} of {} body bytes)",
                    header.type_name,
                    header.device,
                    body.len()
                )
            }
            Err(None) => return "connection reset".into(),
        }
        let event = inbound_of(client, &header, &body, &shared.scene.tools, Instant::now());
        if shared.inbound.send(event).is_err() {
            return "the session ended".into();
        }
    }
}

/// Fills `buf`; on failure the bytes read before the peer closed (`Some`), or `None` for
/// an error other than a clean close.
fn read_full(stream: &mut impl Read, buf: &mut [u8]) -> Result<(), Option<usize>> {
    let mut at = 0;
    while at < buf.len() {
        match stream.read(&mut buf[at..]) {
            Ok(0) => return Err(Some(at)),
            Ok(n) => at += n,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(_) => return Err(if at == 0 { None } else { Some(at) }),
        }
    }
    Ok(())
}

/// The writer thread of one client: sends its outbox until it closes or a write fails.
fn write_loop(
    mut stream: TcpStream,
    outbox: &Outbox,
    surface: &SurfaceTopology,
    gone: &Mutex<Option<String>>,
) {
    let why = match Encoder::new(surface) {
        Ok(mut encoder) => send_all(&mut stream, outbox, &mut encoder),
        Err(e) => Some(format!("the surface cannot be sent: {e}")),
    };
    if let Some(why) = why {
        if let Ok(mut g) = gone.lock() {
            g.get_or_insert(why);
        }
        // Ends the reader's read too.
        let _ = stream.shutdown(Shutdown::Both);
    }
}

/// Sends until the outbox is closed (`None`) or the client must go (`Some(why)`).
fn send_all(stream: &mut TcpStream, outbox: &Outbox, encoder: &mut Encoder) -> Option<String> {
    loop {
        if outbox.overflowed() {
            return Some(format!(
                "does not read: more than {OUTBOX_LIMIT} messages waited for it"
            ));
        }
        let Some(m) = outbox.pop(POLL) else {
            if outbox.is_closed() {
                return None;
            }
            continue;
        };
        let bytes = match encoder.encode(&m, timestamp_now()) {
            Ok(Some(b)) => b,
            Ok(None) => continue,
            Err(e) => return Some(format!("a message could not be encoded: {e}")),
        };
        if let Err(e) = stream.write_all(&bytes) {
            return Some(format!("write failed: {e}"));
        }
    }
}

#[cfg(test)]
#[path = "server_tests.rs"]
mod tests;
