//! What recovery cost: [`FaceRecovery`] per face, [`GlobalRecovery`] on the global port
//! (each on this board's side). With the crate's `serde` feature both serialise as they
//! are (the host's reports).

use super::envelope::OVERHEAD;

/// What recovery cost on one face (this board's side).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FaceRecovery {
    /// Data envelopes sent the first time.
    pub data_frames: u64,
    /// Their bytes (envelope included).
    pub data_bytes: u64,
    /// Data envelopes sent again.
    pub retransmitted_frames: u64,
    /// Their bytes.
    pub retransmitted_bytes: u64,
    /// Acks sent.
    pub acks_sent: u64,
    /// Nacks sent.
    pub nacks_sent: u64,
    /// Statuses sent.
    pub statuses_sent: u64,
    /// Bytes of the acks, nacks and statuses.
    pub control_bytes: u64,
    /// Nacks received from the neighbour.
    pub nacks_received: u64,
    /// Envelopes received that failed their CRC or length.
    pub damaged: u64,
    /// Data envelopes received beyond the next expected (one before was lost).
    pub gaps: u64,
    /// Data envelopes received twice.
    pub duplicates: u64,
}

impl FaceRecovery {
    /// Bytes recovery added on the face: an [`OVERHEAD`]-byte envelope per data frame, the
    /// retransmissions, the acks, nacks and statuses.
    pub fn overhead_bytes(&self) -> u64 {
        self.data_frames * OVERHEAD as u64 + self.retransmitted_bytes + self.control_bytes
    }
}

/// What recovery cost on the global port (this board's side).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct GlobalRecovery {
    /// Data envelopes sent the first time.
    pub data_packets: u64,
    /// Their bytes (envelope included).
    pub data_bytes: u64,
    /// Data envelopes sent again.
    pub retransmitted_packets: u64,
    /// Their bytes.
    pub retransmitted_bytes: u64,
    /// Retransmissions started by a timeout (not a nack).
    pub timeouts: u64,
    /// Acks sent.
    pub acks_sent: u64,
    /// Nacks sent.
    pub nacks_sent: u64,
    /// Bytes of the acks and nacks.
    pub control_bytes: u64,
    /// Nacks received.
    pub nacks_received: u64,
    /// Envelopes received that failed their CRC, length or type.
    pub damaged: u64,
    /// Data envelopes received beyond the next expected.
    pub gaps: u64,
    /// Data envelopes received twice.
    pub duplicates: u64,
    /// Packets from a new address dropped because every peer slot was taken, or in-order
    /// packets dropped because the receive slots were full (the sender's timer recovers
    /// the latter).
    pub refused: u64,
    /// Peer slots taken.
    pub peers: u32,
}

impl GlobalRecovery {
    /// Bytes recovery added: an [`OVERHEAD`]-byte envelope per data packet, the
    /// retransmissions, the acks and nacks.
    pub fn overhead_bytes(&self) -> u64 {
        self.data_packets * OVERHEAD as u64 + self.retransmitted_bytes + self.control_bytes
    }
}
