//! What travels between the session and its clients, whatever the transport (WebSocket,
//! OpenIGTLink): [`Inbound`] events into the session's one channel, [`Outbound`] messages
//! to each client's [`Outbox`]. A transport turns its wire messages into `Inbound` and
//! `Outbound` into its wire messages; the session never sees a byte of either protocol.

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex};

use super::engine::Pose;

/// A client of the session, numbered from 1 in the order they connected.
pub type ClientId = u32;

/// Which protocol a client speaks (reports, and what it is sent).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Transport {
    WebSocket,
    Igtl,
}

/// An event for the session.
#[derive(Debug)]
pub enum Inbound {
    /// A client connected: where to send its messages, and what to call it.
    Connected {
        client: ClientId,
        transport: Transport,
        /// The peer's address, for messages about it.
        peer: String,
        outbox: Outbox,
    },
    /// A client asks to move `tool` to `pose` (already checked for form: finite numbers,
    /// a unit quaternion within 1e-3, normalised; metres).
    Pose {
        client: ClientId,
        tool: String,
        pose: Pose,
        /// When the transport read it (for the pose-to-force latency).
        received: std::time::Instant,
    },
    /// A client stops driving `tool`.
    Release { client: ClientId, tool: String },
    /// A client sent something the transport could not take (said to the client already
    /// or not): the session logs it and answers with [`Outbound::Error`].
    Bad { client: ClientId, message: String },
    /// A client went away (closed, reset or broke its protocol mid-frame).
    Disconnected { client: ClientId, reason: String },
}

/// A message for one client.
#[derive(Clone, Debug)]
pub enum Outbound {
    /// On connecting: the scene, the model, the tools, the surface's size.
    Hello(Arc<serde_json::Value>),
    /// The surface's triangles and reference positions (once, after `Hello`).
    Topology(Arc<Vec<u8>>),
    /// The mean force of the tissue on `tool` over the millisecond of simulated time that
    /// ends at `time_s` (N).
    Force {
        time_s: f64,
        tool: Arc<str>,
        force_n: [f64; 3],
    },
    /// The surface nodes' positions (a binary frame, `docs/live.md`), at the graphics rate;
    /// `positions_m` as `3n` f32 for transports that encode their own frames.
    Surface {
        seq: u32,
        time_s: f64,
        frame: Arc<Vec<u8>>,
        positions_m: Arc<Vec<f32>>,
        /// The TOOLS frame of the same instant: each tool's applied pose.
        tools: Arc<Vec<u8>>,
    },
    /// Session status (JSON), about four times a second.
    Status(Arc<serde_json::Value>),
    /// Who drives `tool` now (None: nobody).
    Driver {
        tool: Arc<str>,
        client: Option<ClientId>,
    },
    /// Something the client sent was refused; the session goes on.
    Error(String),
    /// Something the client should know (a pose clamped, the session falling behind).
    Notice(String),
}

impl Outbound {
    /// Whether a slow client may lose it (only surface frames: a newer one follows).
    pub fn droppable(&self) -> bool {
        matches!(self, Outbound::Surface { .. })
    }
}

/// A client's queue of outbound messages, filled by the session and drained by the
/// transport's writer thread. Bounded: when full, the oldest droppable message (a surface
/// frame) is dropped and counted; other messages are never dropped (a client that lets
/// `limit` non-droppable messages pile up is disconnected by its writer, which sees
/// [`Outbox::overflowed`]).
#[derive(Clone, Debug)]
pub struct Outbox {
    inner: Arc<(Mutex<OutboxState>, Condvar)>,
}

#[derive(Debug, Default)]
struct OutboxState {
    queue: VecDeque<Outbound>,
    limit: usize,
    dropped: u64,
    overflowed: bool,
    closed: bool,
}

impl Outbox {
    /// An outbox holding at most `limit` messages.
    pub fn new(limit: usize) -> Outbox {
        Outbox {
            inner: Arc::new((
                Mutex::new(OutboxState {
                    limit: limit.max(1),
                    ..OutboxState::default()
                }),
                Condvar::new(),
            )),
        }
    }

    /// Queues `m` (the session's side; never blocks).
    pub fn push(&self, m: Outbound) {
        let (lock, bell) = &*self.inner;
        let Ok(mut s) = lock.lock() else { return };
        if s.closed {
            return;
        }
        if s.queue.len() >= s.limit {
            if let Some(i) = s.queue.iter().position(Outbound::droppable) {
                s.queue.remove(i);
                s.dropped += 1;
            } else if m.droppable() {
                s.dropped += 1;
                return;
            } else {
                s.overflowed = true;
            }
        }
        s.queue.push_back(m);
        bell.notify_one();
    }

    /// Takes the next message, waiting up to `timeout` (the writer's side); `None` on
    /// timeout or when closed and empty.
    pub fn pop(&self, timeout: std::time::Duration) -> Option<Outbound> {
        let (lock, bell) = &*self.inner;
        let mut s = lock.lock().ok()?;
        if s.queue.is_empty() && !s.closed {
            s = bell.wait_timeout(s, timeout).ok()?.0;
        }
        s.queue.pop_front()
    }

    /// Surface frames dropped for this client so far.
    pub fn dropped(&self) -> u64 {
        self.inner.0.lock().map_or(0, |s| s.dropped)
    }

    /// Whether non-droppable messages piled past the limit (the client does not read).
    pub fn overflowed(&self) -> bool {
        self.inner.0.lock().map_or(true, |s| s.overflowed)
    }

    /// No more messages will be taken (the client is gone); wakes the writer.
    pub fn close(&self) {
        let (lock, bell) = &*self.inner;
        if let Ok(mut s) = lock.lock() {
            s.closed = true;
            s.queue.clear();
        }
        bell.notify_all();
    }

    pub fn is_closed(&self) -> bool {
        self.inner.0.lock().map_or(true, |s| s.closed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn surface(seq: u32) -> Outbound {
        Outbound::Surface {
            seq,
            time_s: 0.0,
            frame: Arc::new(vec![]),
            positions_m: Arc::new(vec![]),
            tools: Arc::new(vec![]),
        }
    }

    #[test]
    fn a_full_outbox_drops_the_oldest_surface_frame_never_a_force() {
        let o = Outbox::new(3);
        o.push(surface(1));
        o.push(Outbound::Error("e".into()));
        o.push(surface(2));
        o.push(Outbound::Notice("n".into())); // drops surface 1
        o.push(surface(3)); // drops surface 2
        assert_eq!(o.dropped(), 2);
        assert!(!o.overflowed());
        let got: Vec<_> = std::iter::from_fn(|| o.pop(std::time::Duration::ZERO)).collect();
        assert_eq!(got.len(), 3);
        assert!(matches!(got[0], Outbound::Error(_)));
        assert!(matches!(got[1], Outbound::Notice(_)));
        assert!(matches!(got[2], Outbound::Surface { seq: 3, .. }));
        // Only non-droppable messages left: the next one overflows, and is still kept.
        for k in 0..4 {
            o.push(Outbound::Notice(format!("{k}")));
        }
        assert!(o.overflowed());
    }
}
