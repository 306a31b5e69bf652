//! A board's links as its runtime sees them: the emulated links, the fault injector when
//! faults are asked for, point-to-point recovery and global recovery above them, each
//! layer optional, their timers on the worker's clock.

use std::sync::Arc;

use link_proto::recovery::face::{Reliable, ReliableConfig};
use link_proto::recovery::global::{GlobalConfig, GlobalReliable};
use link_proto::recovery::FaceRecovery;
use link_proto::recovery::GlobalRecovery;
use link_proto::{Face, Links, RecvError, SendError};

use crate::clock::{SimClock, SweepClock};
use crate::fabric::EmuLinks;
use crate::faults::FaultyLinks;

/// A board's links below recovery: clean, or with faults injected.
pub enum Lower {
    Clean(EmuLinks),
    Faulty(Box<FaultyLinks<EmuLinks>>),
}

/// A board's links below global recovery: with point-to-point recovery, or without.
pub enum Faces {
    Plain(Lower),
    Recovering(Box<Reliable<Lower, SimClock, Vec<u8>>>),
}

/// A board's links as its runtime sees them: with global recovery above the faces (with or
/// without point-to-point recovery above the possibly faulty emulated links), or without.
pub enum BoardLinks {
    Plain(Faces),
    Recovering(Box<GlobalReliable<Faces, SimClock, Vec<u8>>>),
}

macro_rules! links_by_variant {
    ($t:ty, $($v:path),+) => {
        impl Links for $t {
            fn try_send(&mut self, face: Face, frame: &[u8]) -> Result<(), SendError> {
                match self { $($v(l) => l.try_send(face, frame),)+ }
            }
            fn try_recv(&mut self, face: Face, buf: &mut [u8]) -> Result<Option<usize>, RecvError> {
                match self { $($v(l) => l.try_recv(face, buf),)+ }
            }
            fn try_send_global(&mut self, p: &[u8]) -> Result<(), SendError> {
                match self { $($v(l) => l.try_send_global(p),)+ }
            }
            fn try_recv_global(&mut self, b: &mut [u8]) -> Result<Option<usize>, RecvError> {
                match self { $($v(l) => l.try_recv_global(b),)+ }
            }
            fn poll(&mut self) {
                match self { $($v(l) => l.poll(),)+ }
            }
            fn peek(&mut self, face: Face) -> link_proto::Peek {
                match self { $($v(l) => l.peek(face),)+ }
            }
        }
    };
}

links_by_variant!(Lower, Lower::Clean, Lower::Faulty);
links_by_variant!(Faces, Faces::Plain, Faces::Recovering);
links_by_variant!(BoardLinks, BoardLinks::Plain, BoardLinks::Recovering);

impl BoardLinks {
    /// `lower` with point-to-point recovery by `faces` and global recovery by `global`
    /// (each `None` for without), their timers on `clock`. Fails on a configuration a
    /// wrapper refuses.
    pub fn new(
        lower: Lower,
        clock: Arc<SweepClock>,
        faces: Option<ReliableConfig>,
        global: Option<GlobalConfig>,
    ) -> Result<Self, link_proto::Error> {
        let address = match &lower {
            Lower::Clean(l) => l.address,
            Lower::Faulty(l) => l.inner.address,
        };
        let mid = match faces {
            None => Faces::Plain(lower),
            Some(c) => {
                let buf = vec![0u8; Reliable::<Lower, SimClock, Vec<u8>>::buffer_len(&c)];
                Faces::Recovering(Box::new(Reliable::new(
                    lower,
                    SimClock(clock.clone()),
                    c,
                    buf,
                )?))
            }
        };
        Ok(match global {
            None => BoardLinks::Plain(mid),
            Some(c) => {
                let buf = vec![0u8; GlobalReliable::<Faces, SimClock, Vec<u8>>::buffer_len(&c)];
                BoardLinks::Recovering(Box::new(GlobalReliable::new(
                    mid,
                    SimClock(clock),
                    address,
                    c,
                    buf,
                )?))
            }
        })
    }

    fn faces(&self) -> &Faces {
        match self {
            BoardLinks::Plain(f) => f,
            BoardLinks::Recovering(g) => g.inner(),
        }
    }

    /// What point-to-point recovery cost, per face, if it is on.
    pub fn recovery(&self) -> Option<[FaceRecovery; 6]> {
        match self.faces() {
            Faces::Plain(_) => None,
            Faces::Recovering(r) => Some(*r.stats()),
        }
    }

    /// What global recovery cost, if it is on.
    pub fn global_recovery(&self) -> Option<GlobalRecovery> {
        match self {
            BoardLinks::Plain(_) => None,
            BoardLinks::Recovering(g) => Some(*g.stats()),
        }
    }

    /// The global flow recovery gave up, if any: (peer address, packet number, retransmissions).
    pub fn global_failure(&self) -> Option<(u8, u16, u8)> {
        match self {
            BoardLinks::Plain(_) => None,
            BoardLinks::Recovering(g) => g.failure(),
        }
    }

    /// Global packets sent and not yet acknowledged (0 without global recovery).
    pub fn global_unacknowledged(&self) -> usize {
        match self {
            BoardLinks::Plain(_) => 0,
            BoardLinks::Recovering(g) => g.unacknowledged(),
        }
    }
}
