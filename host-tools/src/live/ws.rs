//! WebSocket clients of a session (RFC 6455 through the `tungstenite` crate, sync, on std
//! threads). After [`super::http`] has read the upgrade request, [`serve`] answers it and
//! runs the client: this thread reads (text JSON -> [`Inbound`]), a writer thread sends
//! what the session queues in the client's [`Outbox`]. Either side that ends the
//! connection says why; the session goes on without the client.
//!
//! Bad input: a text message over [`CLIENT_MESSAGE_MAX`] bytes, malformed JSON, an unknown
//! message type, a malformed pose and any binary message are answered with an `error` and
//! the client stays; a message over [`MESSAGE_HARD_MAX`] bytes (which cannot be skipped
//! without reading it), invalid UTF-8 or a broken frame closes the connection with the
//! reason.

use std::io::{Read, Write};
use std::net::{Shutdown, TcpStream};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tungstenite::error::{CapacityError, Error as WsError};
use tungstenite::protocol::frame::coding::CloseCode;
use tungstenite::protocol::{CloseFrame, Role, WebSocketConfig};
use tungstenite::{Message, WebSocket};

use super::http::Link;
use super::hub::{ClientId, Inbound, Outbound, Outbox, Transport};
use super::pose;
use super::protocol::{ClientMessage, ServerMessage, CLIENT_MESSAGE_MAX};

/// The largest message read at all (bytes): longer closes the connection (1009).
pub const MESSAGE_HARD_MAX: usize = 1 << 20;
/// Messages a client's outbox holds (about 16 s of one tool's forces).
const OUTBOX_LIMIT: usize = 16384;
/// How long a write may block on a client that does not read.
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);

/// The `Sec-WebSocket-Accept` answer to a request's `Sec-WebSocket-Key`.
pub fn accept_key(key: &str) -> String {
    tungstenite::handshake::derive_accept_key(key.trim().as_bytes())
}

/// What the writer is told by the reader.
enum Control {
    Pong(tungstenite::Bytes),
    /// Send `error` (if any), close with `code` and `reason`, end.
    Close {
        code: CloseCode,
        reason: String,
        error: Option<String>,
    },
}

/// The reading side of the socket for `tungstenite` (what it would write, the replies to
/// pings and closes, is the writer's to send).
struct ReadSide(TcpStream);

impl Read for ReadSide {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.0.read(buf)
    }
}

impl Write for ReadSide {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The writing side: never read.
struct WriteSide(TcpStream);

impl Read for WriteSide {
    fn read(&mut self, _: &mut [u8]) -> std::io::Result<usize> {
        Err(std::io::ErrorKind::WouldBlock.into())
    }
}

impl Write for WriteSide {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.0.flush()
    }
}

fn config() -> WebSocketConfig {
    WebSocketConfig::default()
        .max_message_size(Some(MESSAGE_HARD_MAX))
        .max_frame_size(Some(MESSAGE_HARD_MAX))
        .write_buffer_size(64 * 1024)
}

/// Answers the upgrade of `stream` (its request read up to `leftover`, with `key`), joins
/// the session as a new client and serves it until either side ends.
pub fn serve(mut stream: TcpStream, leftover: Vec<u8>, key: &str, peer: String, link: &Link) {
    let answer = format!(
        "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: {}\r\n\r\n",
        accept_key(key)
    );
    let (Ok(()), Ok(reader), Ok(writer)) = (
        stream.write_all(answer.as_bytes()),
        stream.try_clone(),
        stream.try_clone(),
    ) else {
        return;
    };
    let _ = stream.set_read_timeout(None);
    let _ = stream.set_write_timeout(Some(WRITE_TIMEOUT));
    let _ = stream.set_nodelay(true);
    let client = link.new_client();
    let outbox = Outbox::new(OUTBOX_LIMIT);
    let connected = Inbound::Connected {
        client,
        transport: Transport::WebSocket,
        peer,
        outbox: outbox.clone(),
    };
    if link.inbound.send(connected).is_err() {
        return; // the session has ended
    }
    let reason = Arc::new(Mutex::new(None::<String>));
    let (control, controls) = mpsc::channel();
    let writer = {
        let reason = reason.clone();
        let ws = WebSocket::from_raw_socket(WriteSide(writer), Role::Server, Some(config()));
        std::thread::Builder::new()
            .name(format!("pe-live-ws-{client}-writer"))
            .spawn(move || write_loop(ws, &outbox, &controls, &reason))
    };
    let mut ws =
        WebSocket::from_partially_read(ReadSide(reader), leftover, Role::Server, Some(config()));
    let ended = read_loop(&mut ws, client, link, &control);
    let _ = control.send(ended.1);
    if let Ok(w) = writer {
        let _ = w.join();
    }
    let _ = stream.shutdown(Shutdown::Both);
    let why = reason
        .lock()
        .ok()
        .and_then(|mut r| r.take())
        .unwrap_or(ended.0);
    let _ = link.inbound.send(Inbound::Disconnected {
        client,
        reason: why,
    });
}

/// Reads the client's messages until it leaves or breaks the protocol: why, and what the
/// writer is to send last.
fn read_loop(
    ws: &mut WebSocket<ReadSide>,
    client: ClientId,
    link: &Link,
    control: &Sender<Control>,
) -> (String, Control) {
    let close = |code, reason: &str, error: Option<String>| Control::Close {
        code,
        reason: reason.to_string(),
        error,
    };
    loop {
        let event = match ws.read() {
            Ok(Message::Text(text)) => parse(client, text.as_str(), Instant::now()),
            Ok(Message::Binary(b)) => Inbound::Bad {
                client,
                message: format!(
                    "a binary message of {} bytes: a client sends text (JSON) messages only",
                    b.len()
                ),
            },
            Ok(Message::Ping(p)) => {
                let _ = control.send(Control::Pong(p));
                continue;
            }
            Ok(Message::Pong(_)) | Ok(Message::Frame(_)) => continue,
            Ok(Message::Close(_)) => {
                return (
                    "closed by the client".into(),
                    close(CloseCode::Normal, "", None),
                )
            }
            Err(WsError::Capacity(e)) => {
                let m = match e {
                    CapacityError::MessageTooLong { size, .. } => format!(
                        "a message of {size} bytes, over the {MESSAGE_HARD_MAX}-byte limit of what is read at all (and the {CLIENT_MESSAGE_MAX}-byte limit of a message): disconnected"
                    ),
                    other => format!("{other}: disconnected"),
                };
                return (
                    m.clone(),
                    close(CloseCode::Size, "message too big", Some(m)),
                );
            }
            Err(WsError::Utf8(e)) => {
                let m = format!("a text message that is not UTF-8 ({e}): disconnected");
                return (m.clone(), close(CloseCode::Invalid, "not UTF-8", Some(m)));
            }
            Err(WsError::Protocol(e)) => {
                let m = format!("broke the WebSocket protocol ({e}): disconnected");
                return (
                    m.clone(),
                    close(CloseCode::Protocol, "protocol error", Some(m)),
                );
            }
            Err(WsError::ConnectionClosed) | Err(WsError::AlreadyClosed) => {
                return ("closed".into(), close(CloseCode::Normal, "", None))
            }
            Err(e) => {
                return (
                    format!("connection lost: {e}"),
                    close(CloseCode::Away, "", None),
                )
            }
        };
        if link.inbound.send(event).is_err() {
            return (
                "the session ended".into(),
                close(CloseCode::Away, "the session ended", None),
            );
        }
    }
}

/// A client's text message as a session event.
pub fn parse(client: ClientId, text: &str, received: Instant) -> Inbound {
    if text.len() > CLIENT_MESSAGE_MAX {
        return Inbound::Bad {
            client,
            message: format!(
                "a message of {} bytes, over the {CLIENT_MESSAGE_MAX}-byte limit: refused",
                text.len()
            ),
        };
    }
    match serde_json::from_str::<ClientMessage>(text) {
        Ok(ClientMessage::Pose {
            tool,
            position_m,
            orientation,
        }) => match pose::from_wire(position_m, orientation) {
            Ok(pose) => Inbound::Pose {
                client,
                tool,
                pose,
                received,
            },
            Err(e) => Inbound::Bad {
                client,
                message: format!("pose for tool {tool:?} refused: {e}"),
            },
        },
        Ok(ClientMessage::Release { tool }) => Inbound::Release { client, tool },
        Err(e) => Inbound::Bad {
            client,
            message: format!(
                "malformed message ({e}): expected {{\"type\":\"pose\",\"tool\":NAME,\"position_m\":[x,y,z],\"orientation\":[w,x,y,z]}} or {{\"type\":\"release\",\"tool\":NAME}}"
            ),
        },
    }
}

/// Sends the session's messages and the reader's controls until the connection ends.
fn write_loop(
    mut ws: WebSocket<WriteSide>,
    outbox: &Outbox,
    controls: &Receiver<Control>,
    reason: &Mutex<Option<String>>,
) {
    let set_reason = |r: String| {
        if let Ok(mut g) = reason.lock() {
            g.get_or_insert(r);
        }
    };
    let end = |ws: &mut WebSocket<WriteSide>| {
        let _ = ws.get_mut().0.shutdown(Shutdown::Both);
    };
    loop {
        while let Ok(c) = controls.try_recv() {
            match c {
                Control::Pong(p) => {
                    let _ = ws.send(Message::Pong(p));
                }
                Control::Close {
                    code,
                    reason,
                    error,
                } => {
                    if let Some(e) = error {
                        let _ =
                            ws.write(Message::text(ServerMessage::Error { message: e }.to_json()));
                    }
                    let _ = ws.close(Some(CloseFrame {
                        code,
                        reason: reason.into(),
                    }));
                    let _ = ws.flush();
                    end(&mut ws);
                    return;
                }
            }
        }
        if outbox.overflowed() {
            let m = format!("did not read its messages ({OUTBOX_LIMIT} waiting): disconnected");
            set_reason(m.clone());
            let _ = ws.write(Message::text(ServerMessage::Error { message: m }.to_json()));
            let _ = ws.close(Some(CloseFrame {
                code: CloseCode::Policy,
                reason: "too slow".into(),
            }));
            let _ = ws.flush();
            end(&mut ws);
            return;
        }
        let sent = match outbox.pop(Duration::from_millis(50)) {
            Some(m) => send_all(&mut ws, m, outbox),
            None if outbox.is_closed() => {
                let _ = ws.close(Some(CloseFrame {
                    code: CloseCode::Away,
                    reason: "the session ended".into(),
                }));
                let _ = ws.flush();
                end(&mut ws);
                return;
            }
            None => Ok(()),
        };
        if let Err(e) = sent {
            set_reason(format!("connection lost while sending: {e}"));
            end(&mut ws);
            return;
        }
    }
}

/// Writes `first` and whatever else is queued, then flushes.
fn send_all(
    ws: &mut WebSocket<WriteSide>,
    first: Outbound,
    outbox: &Outbox,
) -> Result<(), WsError> {
    let mut next = Some(first);
    while let Some(m) = next {
        for msg in wire(m) {
            ws.write(msg)?;
        }
        next = outbox.pop(Duration::ZERO);
    }
    ws.flush()
}

/// A session message as WebSocket messages.
fn wire(m: Outbound) -> Vec<Message> {
    let text = |s: ServerMessage| vec![Message::text(s.to_json())];
    match m {
        Outbound::Hello(v) | Outbound::Status(v) => vec![Message::text(v.to_string())],
        Outbound::Topology(b) => vec![Message::binary(b.to_vec())],
        Outbound::Force {
            time_s,
            tool,
            force_n,
        } => text(ServerMessage::Force {
            time_s,
            tool: tool.to_string(),
            force_n,
        }),
        Outbound::Surface { frame, tools, .. } => {
            let mut v = vec![Message::binary(frame.to_vec())];
            if !tools.is_empty() {
                v.push(Message::binary(tools.to_vec()));
            }
            v
        }
        Outbound::Driver { tool, client } => text(ServerMessage::Driver {
            tool: tool.to_string(),
            client,
        }),
        Outbound::Error(message) => text(ServerMessage::Error { message }),
        Outbound::Notice(message) => text(ServerMessage::Notice { message }),
    }
}
