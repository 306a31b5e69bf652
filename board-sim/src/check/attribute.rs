//! Fault attribution: from every board's observation and what the injector recorded, the
//! first cause of a stopped run.

use link_proto::Machine;
use pe_firmware::runtime::FaultKind;

use super::observed::Observed;
use crate::fabric::global_face;
use crate::faults::Injected;

/// The first cause of a stopped run.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Cause {
    /// The board at fault: for an injected fault the board that sent the damaged frame; for
    /// an observed one the board that observed it.
    pub board: [usize; 3],
    /// Its link (`PosX` ...), if the cause is on one.
    pub face: Option<String>,
    pub step: u64,
    pub what: String,
    /// The cause is an injected fault (known ground truth) that explains `detected`.
    pub injected: bool,
    /// The observation that detected it (index into [`SimFault::observed`]).
    pub detected: usize,
}

impl std::fmt::Display for Cause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.board;
        write!(f, "board ({x},{y},{z})")?;
        if let Some(face) = &self.face {
            write!(f, " link {face}")?;
        }
        write!(f, " step {}: {}", self.step, self.what)
    }
}

/// A run that stopped on a fault: the first cause, every board's observation (ordered by
/// step, faults before waits, then by phase and board) and what was injected.
#[derive(Debug)]
pub struct SimFault {
    pub cause: Cause,
    pub observed: Vec<Observed>,
    pub injected: Vec<Injected>,
}

impl SimFault {
    /// The observations other than the one that detected the cause.
    pub fn consequences(&self) -> impl Iterator<Item = &Observed> {
        let d = self.cause.detected;
        self.observed
            .iter()
            .enumerate()
            .filter(move |(k, _)| *k != d)
            .map(|(_, o)| o)
    }
}

impl std::fmt::Display for SimFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "the run stopped on a fault:")?;
        writeln!(
            f,
            "  cause: {}{}",
            self.cause,
            if self.cause.injected {
                " (injected)"
            } else {
                ""
            }
        )?;
        if let Some(d) = self.observed.get(self.cause.detected) {
            writeln!(f, "  detected: {d}")?;
        }
        let rest: Vec<&Observed> = self.consequences().collect();
        if !rest.is_empty() {
            writeln!(f, "  consequences ({}):", rest.len())?;
        }
        for x in rest.iter().take(8) {
            writeln!(f, "    {x}")?;
        }
        if rest.len() > 8 {
            writeln!(f, "    ... and {} more", rest.len() - 8)?;
        }
        if !self.injected.is_empty() {
            writeln!(f, "injected faults ({}):", self.injected.len())?;
            for i in self.injected.iter().take(8) {
                writeln!(
                    f,
                    "  board ({},{},{}) link {} step {}: {}",
                    i.board[0], i.board[1], i.board[2], i.face, i.step, i.what
                )?;
            }
        }
        Ok(())
    }
}
impl std::error::Error for SimFault {}

/// The injected global fault that explains an observation on the global network: for a
/// sink's observation one on the board's packets to that sink; for a board's wait for
/// board `src` one on `src`'s packets to it (or a stall of `src`); for a damaged packet one
/// corrupting a packet to the observing board (else any corrupted global packet: its
/// destination may have been hit); for recovery giving up a flow one on the packets
/// between the board and that peer, either way. The latest such at the observed step or
/// the one after (a partner runs at most a step ahead).
fn explains_global<'a>(o: &Observed, injected: &'a [Injected]) -> Option<&'a Injected> {
    use FaultKind as K;
    let to_usize = |b: [u8; 3]| b.map(|v| v as usize);
    let me = o.fault.board;
    let me_addr = Machine::address(me.map(usize::from));
    let coords = Machine::from_address;
    let in_time = |i: &&Injected| i.step as u64 <= o.fault.step + 1 && i.face.starts_with("global");
    let latest = |f: &dyn Fn(&Injected) -> bool| {
        injected
            .iter()
            .filter(in_time)
            .filter(|i| f(i))
            .max_by_key(|i| i.step)
    };
    let corrupt = |i: &Injected| i.what.starts_with("corrupt");
    if let Some(sink) = o.sink {
        let face = global_face(sink);
        let from = to_usize(me);
        return match o.fault.kind {
            K::BadPacket { .. } => latest(&|i| i.board == from && i.face == face && corrupt(i))
                .or_else(|| latest(&|i| i.face == face && corrupt(i)))
                .or_else(|| latest(&|i| corrupt(i))),
            _ => latest(&|i| i.board == from && i.face == face),
        };
    }
    let me_face = global_face(me_addr?);
    // This board's packets to `peer` first, else `peer`'s to it (its acks).
    let between = |peer: u8| {
        let pf = global_face(peer);
        latest(&|i| i.board == to_usize(me) && i.face == pf).or_else(|| {
            let pc = coords(peer);
            latest(&|i| Some(i.board) == pc && (i.face == me_face || i.what == "stall"))
        })
    };
    match o.fault.kind {
        K::GlobalTimeout { src } => match coords(src) {
            Some(from) => latest(&|i| i.board == from && (i.face == me_face || i.what == "stall")),
            // Not waiting for a board's packet (its own sends blocked: with recovery,
            // unacknowledged packets fill its window): a fault on its own packets.
            None => latest(&|i| i.board == to_usize(me)),
        },
        K::BadPacket { .. } => {
            latest(&|i| i.face == me_face && corrupt(i)).or_else(|| latest(&|i| corrupt(i)))
        }
        K::GlobalError {
            error: link_proto::RecvError::GlobalRetriesExhausted { peer, .. },
        } => between(peer),
        K::GlobalSendFailed { dst, .. } => between(dst),
        _ => None,
    }
}

/// The injected fault that explains an observation: one on the frames the observing board
/// receives on that link (sent by the neighbour across it), at the observed step or the
/// one before (a lost or damaged frame is noticed in its step, a lost last frame of a step
/// perhaps only once the next one arrives), or at any earlier step for a stall or delay
/// (which go on); the latest such.
fn explains<'a>(machine: Machine, o: &Observed, injected: &'a [Injected]) -> Option<&'a Injected> {
    if let Some(i) = explains_global(o, injected) {
        return Some(i);
    }
    let face = o.face()?;
    let from = machine.neighbour(o.fault.board.map(usize::from), face)?;
    let link = format!("{:?}", face.opposite());
    injected
        .iter()
        .filter(|i| i.board == from && i.face == link && i.step as u64 <= o.fault.step)
        .filter(|i| {
            i.what == "stall" || i.what.starts_with("delay") || i.step as u64 + 1 >= o.fault.step
        })
        .max_by_key(|i| i.step)
}

/// Orders the observations and names the first cause: the first observation when an
/// injected fault explains it or it is not a wait; otherwise (the first is a wait, a
/// consequence) the first observation an injected fault explains; otherwise the first.
pub fn attribute(
    machine: Machine,
    mut observed: Vec<Observed>,
    injected: Vec<Injected>,
) -> SimFault {
    observed.sort_by_key(Observed::key);
    let explained = |o: &Observed| explains(machine, o, &injected).is_some();
    let pick = match observed.first() {
        Some(first) if explained(first) || !first.is_wait() => 0,
        _ => observed.iter().position(explained).unwrap_or(0),
    };
    let cause = match observed.get(pick) {
        Some(o) => match explains(machine, o, &injected) {
            Some(i) => Cause {
                board: i.board,
                face: Some(i.face.clone()),
                step: i.step as u64,
                what: format!("injected {}", i.what),
                injected: true,
                detected: pick,
            },
            None => Cause {
                board: o.fault.board.map(|v| v as usize),
                face: o.face().map(|f| format!("{f:?}")),
                step: o.fault.step,
                what: o.to_string(),
                injected: false,
                detected: pick,
            },
        },
        None => Cause {
            board: [0; 3],
            face: None,
            step: 0,
            what: "no board reported a fault".into(),
            injected: false,
            detected: 0,
        },
    };
    SimFault {
        cause,
        observed,
        injected,
    }
}
