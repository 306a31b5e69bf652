//! The session's clients: where each one's messages go, and what it was sent.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::live::hub::{ClientId, Outbound, Outbox, Transport};

/// A client, connected or gone.
#[derive(Clone, Debug)]
struct Client {
    transport: Transport,
    peer: String,
    outbox: Outbox,
    surface_frames: u64,
    /// Why it left (None: still connected).
    gone: Option<String>,
    /// Surface frames dropped, read when it left.
    dropped_at_exit: u64,
}

/// What the summary says of a client.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ClientSummary {
    pub client: ClientId,
    pub transport: Transport,
    pub peer: String,
    /// Surface frames queued for it, and of those dropped because it read too slowly.
    pub surface_frames: u64,
    pub surface_frames_dropped: u64,
    /// Why it left (`None`: connected at the end).
    pub left: Option<String>,
}

#[derive(Debug, Default)]
pub struct Clients {
    all: BTreeMap<ClientId, Client>,
}

impl Clients {
    pub fn connect(&mut self, id: ClientId, transport: Transport, peer: String, outbox: Outbox) {
        self.all.insert(
            id,
            Client {
                transport,
                peer,
                outbox,
                surface_frames: 0,
                gone: None,
                dropped_at_exit: 0,
            },
        );
    }

    /// Client `id` left; its outbox is closed. Returns its peer (None: unknown or gone).
    pub fn disconnect(&mut self, id: ClientId, reason: &str) -> Option<String> {
        let c = self.all.get_mut(&id).filter(|c| c.gone.is_none())?;
        c.dropped_at_exit = c.outbox.dropped();
        c.outbox.close();
        c.gone = Some(reason.to_string());
        Some(c.peer.clone())
    }

    /// Connected clients.
    pub fn count(&self) -> usize {
        self.all.values().filter(|c| c.gone.is_none()).count()
    }

    pub fn peer(&self, id: ClientId) -> String {
        self.all
            .get(&id)
            .map_or_else(|| "?".to_string(), |c| c.peer.clone())
    }

    pub fn send(&self, id: ClientId, m: Outbound) {
        if let Some(c) = self.all.get(&id).filter(|c| c.gone.is_none()) {
            c.outbox.push(m);
        }
    }

    pub fn broadcast(&mut self, m: &Outbound) {
        for c in self.all.values_mut().filter(|c| c.gone.is_none()) {
            if matches!(m, Outbound::Surface { .. }) {
                c.surface_frames += 1;
            }
            c.outbox.push(m.clone());
        }
    }

    /// Each connected client's id and surface frames dropped so far.
    pub fn connected(&self) -> Vec<(ClientId, u64)> {
        self.all
            .iter()
            .filter(|(_, c)| c.gone.is_none())
            .map(|(&id, c)| (id, c.outbox.dropped()))
            .collect()
    }

    /// Closes every outbox (the session ended): each transport's writer ends.
    pub fn close_all(&mut self) {
        let ids: Vec<ClientId> = self.all.keys().copied().collect();
        for id in ids {
            self.disconnect(id, "the session ended");
        }
    }

    pub fn summaries(&self) -> Vec<ClientSummary> {
        self.all
            .iter()
            .map(|(&id, c)| ClientSummary {
                client: id,
                transport: c.transport,
                peer: c.peer.clone(),
                surface_frames: c.surface_frames,
                surface_frames_dropped: match c.gone {
                    Some(_) => c.dropped_at_exit,
                    None => c.outbox.dropped(),
                },
                left: c.gone.clone().filter(|r| r != "the session ended"),
            })
            .collect()
    }
}
