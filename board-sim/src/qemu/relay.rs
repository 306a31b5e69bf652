//! The array's cables and global network in this process: each cable's bytes relayed both
//! ways as they come, untouched; each global port's COBS-framed packets routed on their
//! destination like the global network's switch, to a board's global UART or to the host
//! and graphics sinks.

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use anyhow::{Context, Result};
use link_proto::packet::{ADDR_BROADCAST, ADDR_GRAPHICS, ADDR_HOST};
use link_proto::{Control, PacketKind, PacketRepr};
use pe_firmware::profile::mps2_uarts;

use super::replay::GateWaits;
use super::wiring::{address, Connector, Uart, Wiring};
use crate::fabric::{packet_header, GlobalNet};

/// Progress seen by the watchdog: bumped by every byte relayed or printed.
#[derive(Default)]
pub(crate) struct Activity(AtomicU64);

impl Activity {
    pub fn bump(&self, n: usize) {
        self.0.fetch_add(n as u64, Ordering::Relaxed);
    }
    pub fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// Reads `from` until it ends, counting the bytes, handing each chunk to `take`.
fn pump(mut from: TcpStream, sent: &AtomicU64, act: &Activity, mut take: impl FnMut(&[u8])) {
    let mut buf = [0u8; 4096];
    loop {
        let n = match from.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        sent.fetch_add(n as u64, Ordering::Relaxed);
        act.bump(n);
        take(&buf[..n]);
    }
}

/// Copies `from` to `to` until `from` ends, counting bytes; once `to` fails the bytes are
/// read and dropped (a dead board's cable: the sender must not stall on it).
fn relay(from: TcpStream, mut to: TcpStream, sent: Arc<AtomicU64>, act: Arc<Activity>) {
    let mut open = true;
    pump(from, &sent, &act, |bytes| {
        if open && to.write_all(bytes).is_err() {
            open = false;
        }
    });
}

/// The global network: packets from board `src`'s global port, routed on their destination.
pub(crate) struct GlobalSwitch {
    /// Each board's global socket (for packets to it), by global address.
    ports: BTreeMap<u8, Mutex<TcpStream>>,
    pub sinks: Arc<GlobalNet>,
    /// Fault reports the host received: (source address, text).
    pub faults: Mutex<Vec<(u8, String)>>,
    /// Damaged packets (a decode or CRC failure): (source board, error).
    pub damaged: Mutex<Vec<(u8, String)>>,
    pub between_boards: AtomicU64,
    pub to_sinks: AtomicU64,
    /// The steps the gated boards wait at (a replay: [`super::replay`]).
    pub gate: GateWaits,
}

impl GlobalSwitch {
    /// Sends `packet` (unframed) to board `dst`'s global port.
    pub fn forward(&self, dst: u8, packet: &[u8]) {
        let mut wire = vec![0u8; link_proto::PACKET_WIRE_LEN_MAX];
        let Ok(n) = link_proto::encode_wire(packet, &mut wire) else {
            return;
        };
        if let Some(port) = self.ports.get(&dst) {
            if let Ok(mut s) = port.lock() {
                // A dead board's port fails: its packets are lost, as on a real network.
                let _ = s.write_all(&wire[..n]);
            }
        }
    }

    fn route(&self, src: u8, packet: &[u8]) {
        let repr = match PacketRepr::parse_bytes(packet) {
            Ok(r) => r,
            Err(e) => {
                if let Ok(mut d) = self.damaged.lock() {
                    d.push((src, e.to_string()));
                }
                return;
            }
        };
        match repr.dst {
            ADDR_HOST if repr.kind == PacketKind::Control(Control::StepDone) => {
                if let Err(e) = self.gate.report(repr.src, repr.payload) {
                    if let Ok(mut d) = self.damaged.lock() {
                        d.push((src, format!("step gate report: {e}")));
                    }
                }
            }
            ADDR_HOST if repr.kind == PacketKind::FaultReport => {
                let text = String::from_utf8_lossy(repr.payload).into_owned();
                if let Ok(mut f) = self.faults.lock() {
                    f.push((repr.src, text));
                }
            }
            ADDR_HOST | ADDR_GRAPHICS => {
                self.to_sinks.fetch_add(1, Ordering::Relaxed);
                let _ = self.sinks.deliver(repr.dst, repr.src, packet);
            }
            ADDR_BROADCAST => {
                for &a in self.ports.keys().filter(|&&a| a != src) {
                    self.between_boards.fetch_add(1, Ordering::Relaxed);
                    self.forward(a, packet);
                }
            }
            d => {
                self.between_boards.fetch_add(1, Ordering::Relaxed);
                self.forward(d, packet);
            }
        }
    }

    /// Reads board `src`'s global port until it closes.
    fn serve(&self, src: u8, from: TcpStream, sent: Arc<AtomicU64>, act: Arc<Activity>) {
        let mut decoder = link_proto::framing::StreamDecoder::<
            { link_proto::limits::PACKET_COBS_LEN_MAX },
        >::new();
        pump(from, &sent, &act, |mut rest| {
            while !rest.is_empty() {
                let (used, event) = decoder.push(rest);
                rest = &rest[used..];
                match event {
                    Some(Ok(packet)) => {
                        let packet = packet.to_vec();
                        self.route(src, &packet);
                    }
                    Some(Err(e)) => {
                        if let Ok(mut d) = self.damaged.lock() {
                            d.push((src, e.to_string()));
                        }
                    }
                    None => {}
                }
            }
        });
    }

    /// Hello packets the host has taken (each board sends one before its step 0).
    pub fn hellos(&self) -> usize {
        self.sinks.host.lock().map_or(0, |h| {
            h.iter()
                .filter(|p| packet_header(p).is_some_and(|h| h.kind() == PacketKind::Hello))
                .count()
        })
    }
}

/// The array's network as it runs: the relay threads, the switch, and the bytes each
/// connector and global port sent.
pub(crate) struct Network {
    pub threads: Vec<JoinHandle<()>>,
    pub switch: Arc<GlobalSwitch>,
    pub face_sent: BTreeMap<Connector, Arc<AtomicU64>>,
    pub global_sent: BTreeMap<[usize; 3], Arc<AtomicU64>>,
}

impl Network {
    /// Wires the connected UARTs: every cable relayed both ways, every global port served
    /// by the switch.
    pub fn wire(
        w: &Wiring,
        sockets: BTreeMap<Uart, TcpStream>,
        act: &Arc<Activity>,
    ) -> Result<Network> {
        let face_sent: BTreeMap<Connector, Arc<AtomicU64>> = w
            .linked
            .iter()
            .flat_map(|(&b, l)| {
                (0..6)
                    .filter(|&f| l[f])
                    .map(move |face| (Connector { board: b, face }, Arc::new(AtomicU64::new(0))))
            })
            .collect();
        let socket = |c: Connector| -> Result<TcpStream> {
            let uart = w.uarts[&c.board][c.face].context("face without a UART")?;
            Ok(sockets[&(c.board, uart)].try_clone()?)
        };
        let mut threads = Vec::new();
        for &(a, b) in &w.cables {
            for (from, to) in [(a, b), (b, a)] {
                let (src, dst) = (socket(from)?, socket(to)?);
                let (sent, act) = (face_sent[&from].clone(), act.clone());
                threads.push(std::thread::spawn(move || relay(src, dst, sent, act)));
            }
        }
        // The global network.
        let global_uart = mps2_uarts::GLOBAL_UART;
        let mut ports = BTreeMap::new();
        for &b in w.linked.keys() {
            ports.insert(
                address(b),
                Mutex::new(sockets[&(b, global_uart)].try_clone()?),
            );
        }
        let switch = Arc::new(GlobalSwitch {
            ports,
            sinks: GlobalNet::sinks(),
            faults: Mutex::new(Vec::new()),
            damaged: Mutex::new(Vec::new()),
            between_boards: AtomicU64::new(0),
            to_sinks: AtomicU64::new(0),
            gate: GateWaits::default(),
        });
        let global_sent: BTreeMap<[usize; 3], Arc<AtomicU64>> = w
            .linked
            .keys()
            .map(|&b| (b, Arc::new(AtomicU64::new(0))))
            .collect();
        for &b in w.linked.keys() {
            let from = sockets[&(b, global_uart)].try_clone()?;
            let (sw, sent, act) = (switch.clone(), global_sent[&b].clone(), act.clone());
            threads.push(std::thread::spawn(move || {
                sw.serve(address(b), from, sent, act)
            }));
        }
        drop(sockets);
        Ok(Network {
            threads,
            switch,
            face_sent,
            global_sent,
        })
    }
}
