//! One listening TCP address for a session: `GET /` and the page's files
//! ([`super::web::asset`]), `GET /session` upgraded to the WebSocket session
//! ([`super::ws`]). A thread accepts; each connection gets its own thread. Every request
//! that cannot be served is answered with its status and the reason, and the connection
//! closed: malformed HTTP (400), a head over [`HEAD_MAX`] bytes (431), a body (413), a
//! method other than GET (405), an unknown path (404), `/session` without a WebSocket
//! upgrade (426), a head not sent within [`HEAD_TIMEOUT`] (408).

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::mpsc::Sender;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{Context, Result};

use super::hub::{ClientId, Inbound};
use super::protocol::SESSION_PATH;
use super::{web, ws};

/// The largest request head read (bytes).
pub const HEAD_MAX: usize = 16 * 1024;
/// How long a client may take to send its request head.
pub const HEAD_TIMEOUT: Duration = Duration::from_secs(5);

/// What a transport needs of the session: where events go and the client numbering.
#[derive(Clone, Debug)]
pub struct Link {
    pub inbound: Sender<Inbound>,
    /// The one counter every transport numbers its clients from.
    pub ids: Arc<AtomicU32>,
}

impl Link {
    /// The next client id (from 1).
    pub fn new_client(&self) -> ClientId {
        self.ids.fetch_add(1, Ordering::SeqCst) + 1
    }
}

/// The listening server; stopped when dropped.
pub struct Server {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    accept: Option<JoinHandle<()>>,
}

impl Server {
    /// Listens on `listen` (`HOST:PORT`; port 0 picks a free one).
    pub fn start(listen: &str, link: Link, quiet: bool) -> Result<Server> {
        let listener = TcpListener::bind(listen)
            .with_context(|| format!("--listen {listen}: cannot listen"))?;
        let addr = listener.local_addr()?;
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let accept = std::thread::Builder::new()
            .name("pe-live-http".into())
            .spawn(move || {
                for conn in listener.incoming() {
                    if flag.load(Ordering::SeqCst) {
                        break;
                    }
                    let Ok(stream) = conn else { continue };
                    let link = link.clone();
                    let _ = std::thread::Builder::new()
                        .name("pe-live-conn".into())
                        .spawn(move || connection(stream, &link, quiet));
                }
            })?;
        Ok(Server {
            addr,
            stop,
            accept: Some(accept),
        })
    }

    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Stops accepting (connections already served go on until their session ends).
    pub fn stop(&mut self) {
        if let Some(t) = self.accept.take() {
            self.stop.store(true, Ordering::SeqCst);
            // Wake the accept loop.
            let _ = TcpStream::connect_timeout(&self.addr, Duration::from_secs(1));
            let _ = t.join();
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop();
    }
}

/// A request's head, as far as routing needs it.
#[derive(Debug, Default)]
struct Head {
    method: String,
    path: String,
    upgrade_websocket: bool,
    ws_key: Option<String>,
    ws_version: Option<String>,
    body_len: Option<u64>,
    chunked: bool,
}

/// A refusal: status, reason phrase, body.
type Refusal = (u16, &'static str, String);

fn connection(mut stream: TcpStream, link: &Link, quiet: bool) {
    let peer = stream
        .peer_addr()
        .map_or_else(|_| "?".to_string(), |a| a.to_string());
    let _ = stream.set_read_timeout(Some(HEAD_TIMEOUT));
    let (head, leftover) = match read_head(&mut stream) {
        Ok(Some(h)) => h,
        Ok(None) => return, // closed before a request (or the server's own wake-up)
        Err(r) => return refuse(&mut stream, &peer, &r, quiet),
    };
    match route(&head) {
        Ok(Route::Session(key)) => ws::serve(stream, leftover, &key, peer, link),
        Ok(Route::Asset(content_type, body)) => {
            respond(&mut stream, 200, "OK", content_type, body);
        }
        Err(r) => refuse(&mut stream, &peer, &r, quiet),
    }
}

/// Reads and parses the request head: Ok(None) when the peer closed before sending one.
fn read_head(stream: &mut TcpStream) -> Result<Option<(Head, Vec<u8>)>, Refusal> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        let n = match stream.read(&mut chunk) {
            Ok(0) if buf.is_empty() => return Ok(None),
            Ok(0) => {
                return Err((
                    400,
                    "Bad Request",
                    "the request ended before its head did".into(),
                ))
            }
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return Err((
                    408,
                    "Request Timeout",
                    format!(
                        "no complete request head within {} s",
                        HEAD_TIMEOUT.as_secs()
                    ),
                ));
            }
            Err(_) => return Ok(None),
        };
        buf.extend_from_slice(&chunk[..n]);
        let mut headers = [httparse::EMPTY_HEADER; 64];
        let mut req = httparse::Request::new(&mut headers);
        match req.parse(&buf) {
            Ok(httparse::Status::Complete(len)) => {
                let head = head_of(&req);
                return Ok(Some((head, buf[len..].to_vec())));
            }
            Ok(httparse::Status::Partial) if buf.len() > HEAD_MAX => {
                return Err(too_large());
            }
            Ok(httparse::Status::Partial) => {}
            Err(httparse::Error::TooManyHeaders) => return Err(too_large()),
            Err(e) => {
                return Err((400, "Bad Request", format!("malformed HTTP request: {e}")));
            }
        }
    }
}

fn too_large() -> Refusal {
    (
        431,
        "Request Header Fields Too Large",
        format!("the request head is over {HEAD_MAX} bytes or 64 headers"),
    )
}

fn head_of(req: &httparse::Request) -> Head {
    let mut h = Head {
        method: req.method.unwrap_or("").to_string(),
        path: req.path.unwrap_or("/").to_string(),
        ..Head::default()
    };
    for hd in req.headers.iter() {
        let value = String::from_utf8_lossy(hd.value).trim().to_string();
        let lower = value.to_ascii_lowercase();
        match hd.name.to_ascii_lowercase().as_str() {
            "upgrade" => h.upgrade_websocket |= lower.split(',').any(|v| v.trim() == "websocket"),
            "sec-websocket-key" => h.ws_key = Some(value),
            "sec-websocket-version" => h.ws_version = Some(value),
            "content-length" => h.body_len = Some(value.parse().unwrap_or(u64::MAX)),
            "transfer-encoding" => h.chunked = true,
            _ => {}
        }
    }
    h
}

enum Route {
    /// Upgrade to the WebSocket session with this key.
    Session(String),
    Asset(&'static str, &'static [u8]),
}

fn route(h: &Head) -> Result<Route, Refusal> {
    if h.method != "GET" {
        return Err((
            405,
            "Method Not Allowed",
            format!(
                "{} is not served: only GET (the page at /, the session at {SESSION_PATH})",
                h.method
            ),
        ));
    }
    if h.chunked || h.body_len.is_some_and(|n| n > 0) {
        return Err((
            413,
            "Payload Too Large",
            "a GET with a body: no request here takes one".into(),
        ));
    }
    let path = h.path.split(['?', '#']).next().unwrap_or("/");
    if path == SESSION_PATH {
        if !h.upgrade_websocket {
            return Err((
                426,
                "Upgrade Required",
                format!("{SESSION_PATH} is the WebSocket session: connect with a WebSocket client (the page at / does)"),
            ));
        }
        if h.ws_version.as_deref() != Some("13") {
            return Err((
                400,
                "Bad Request",
                format!(
                    "Sec-WebSocket-Version {:?}: only 13 (RFC 6455) is served",
                    h.ws_version
                ),
            ));
        }
        return match &h.ws_key {
            Some(k) if !k.is_empty() => Ok(Route::Session(k.clone())),
            _ => Err((
                400,
                "Bad Request",
                "a WebSocket upgrade without Sec-WebSocket-Key".into(),
            )),
        };
    }
    match web::asset(path) {
        Some((t, body)) => Ok(Route::Asset(t, body)),
        None => Err((
            404,
            "Not Found",
            format!("nothing at {path}: the trainer page is at /, the session at {SESSION_PATH}"),
        )),
    }
}

fn refuse(stream: &mut TcpStream, peer: &str, r: &Refusal, quiet: bool) {
    if !quiet {
        eprintln!("pe live: http {peer}: {} {}: {}", r.0, r.1, r.2);
    }
    let body = format!("{} {}: {}\n", r.0, r.1, r.2);
    respond(
        stream,
        r.0,
        r.1,
        "text/plain; charset=utf-8",
        body.as_bytes(),
    );
}

fn respond(stream: &mut TcpStream, code: u16, reason: &str, content_type: &str, body: &[u8]) {
    let head = format!(
        "HTTP/1.1 {code} {reason}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    );
    let _ = stream
        .write_all(head.as_bytes())
        .and_then(|_| stream.write_all(body))
        .and_then(|_| stream.flush());
    let _ = stream.shutdown(std::net::Shutdown::Write);
    // Let the peer read the answer before the socket goes (a close with unread input
    // would reset it): drain what it still sends, briefly.
    let _ = stream.set_read_timeout(Some(Duration::from_millis(200)));
    let mut sink = [0u8; 1024];
    while matches!(stream.read(&mut sink), Ok(n) if n > 0) {}
}
