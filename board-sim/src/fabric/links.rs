//! A board's emulated links: one [`Channel`] per linked face each way, and its port on the
//! global network; [`build_links`] wires a whole machine.

use std::sync::Arc;

use link_proto::{Face, Links, Machine, RecvError, SendError};

use super::channel::{Channel, Doorbell};
use super::global::GlobalNet;

/// Frames a link holds before the sender sees `WouldBlock`.
pub const LINK_QUEUE_FRAMES: usize = 16;

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
        ch.push(frame, LINK_QUEUE_FRAMES)
    }

    fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        let ch = self.rx[face.index()].as_ref().ok_or(RecvError::NoLink)?;
        ch.pop_into(buf)
    }

    fn peek(&mut self, face: Face) -> link_proto::Peek {
        match self.rx[face.index()].as_ref() {
            None => link_proto::Peek::Nothing,
            Some(ch) => ch.peek(),
        }
    }

    fn try_send_global(&mut self, packet: &[u8]) -> Result<(), SendError> {
        let net = self.net.as_ref().ok_or(SendError::NoLink)?;
        net.send(self.address, packet)
    }

    fn try_recv_global(&mut self, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
        let Some(net) = self.net.as_ref() else {
            return Ok(None);
        };
        let Some(ch) = net.inbox(self.address) else {
            return Ok(None);
        };
        ch.pop_into(buf)
    }
}

/// Builds the links of a machine: `links[b]` for board `b` (its [`Machine::index`]); a
/// frame for board `b` rings `bells[b]` (boards sharing a worker thread share its doorbell).
/// With `sink_recovery` the graphics and host sinks run the receiving end of global recovery.
pub fn build_links(
    machine: Machine,
    bells: &[Arc<Doorbell>],
    sink_recovery: bool,
) -> (Vec<EmuLinks>, Arc<GlobalNet>) {
    let mut inboxes: Vec<Option<Arc<Channel>>> = vec![None; link_proto::BOARD_COUNT];
    let mut addresses = vec![u8::MAX; machine.count()];
    for (b, c) in machine.boards().enumerate() {
        if let Some(a) = Machine::address(c) {
            inboxes[a as usize] = Some(Channel::new(bells[b].clone()));
            addresses[b] = a;
        }
    }
    let net = Arc::new(GlobalNet::new(inboxes, sink_recovery));
    let mut links: Vec<EmuLinks> = addresses
        .iter()
        .map(|&address| EmuLinks {
            tx: Default::default(),
            rx: Default::default(),
            net: Some(net.clone()),
            address,
        })
        .collect();
    for (b, c) in machine.boards().enumerate() {
        for face in machine.linked_faces(c) {
            let Some(nb) = machine.neighbour(c, face).map(|n| machine.index(n)) else {
                continue;
            };
            let ch = Channel::new(bells[nb].clone());
            links[b].tx[face.index()] = Some(ch.clone());
            links[nb].rx[face.opposite().index()] = Some(ch);
        }
    }
    (links, net)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A peek tells the first byte of the frame at the head of a link without taking it:
    /// the receive that follows gets that frame, whole; an empty link and a face at the
    /// machine's edge have nothing.
    #[test]
    fn a_peek_sees_the_head_of_a_link_and_leaves_it() {
        use link_proto::Peek;
        let bells: Vec<Arc<Doorbell>> = (0..2).map(|_| Default::default()).collect();
        let machine = Machine::new([2, 1, 1]).expect("machine");
        let (mut links, _) = build_links(machine, &bells, false);
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
