//! The host's check of what the boards say they run: each board's hello (its compilation
//! id, before its step 0) against the manifest's.

use anyhow::{anyhow, bail, Result};
use link_proto::payload::HelloPayload;
use link_proto::{Machine, PacketKind, PacketRepr};

use crate::fabric::GlobalNet;

/// The host's check of what the boards say they run: each board's [`PacketKind::Hello`]
/// packet (before its step 0) must carry the manifest's compilation id; every board must
/// have said it by the end. Catches a board that runs another image than the host loaded
/// (flashed from another compile), a board with no neighbour to compare with included.
pub struct HostCheck {
    expected: String,
    machine: Machine,
    /// Host packets already looked at.
    seen: usize,
    /// Boards (by index) that have said hello.
    said: Vec<bool>,
}

impl HostCheck {
    pub fn new(expected: &str, machine: Machine) -> Self {
        HostCheck {
            expected: expected.to_ascii_lowercase(),
            machine,
            seen: 0,
            said: vec![false; machine.count()],
        }
    }

    /// The board (coordinates) at a global address, if it is one of this machine's.
    fn coords(&self, address: u8) -> Option<[usize; 3]> {
        Machine::from_address(address).filter(|&c| self.machine.contains(c))
    }

    /// Looks at the host packets that arrived since the last call.
    pub fn poll(&mut self, net: &GlobalNet) -> Result<()> {
        let new: Vec<Vec<u8>> = match net.host.lock() {
            Ok(v) => v.get(self.seen..).map(<[_]>::to_vec).unwrap_or_default(),
            Err(_) => bail!("host: the packet sink was poisoned"),
        };
        self.seen += new.len();
        for p in new {
            let Ok(r) = PacketRepr::parse_bytes(&p) else {
                continue; // named by `collect_sinks`
            };
            if r.kind != PacketKind::Hello {
                continue;
            }
            let Some(c) = self.coords(r.src) else {
                bail!(
                    "host: a hello from address {}, which is no board of this {} machine",
                    r.src,
                    self.machine
                );
            };
            let [x, y, z] = c;
            let h = HelloPayload::parse(r.payload)
                .map_err(|e| anyhow!("host: bad hello from board ({x},{y},{z}): {e}"))?;
            let id = pe_firmware::image::CompilationId(h.compilation).to_string();
            if id != self.expected {
                bail!(
                    "board ({x},{y},{z}) runs an image of compilation {id}, but the host loaded compilation {} (the manifest's): the board was flashed from another compile",
                    self.expected
                );
            }
            if let Some(s) = self.said.get_mut(self.machine.index(c)) {
                *s = true;
            }
        }
        Ok(())
    }

    /// At the end of a run: every board has said hello.
    pub fn finish(&mut self, net: &GlobalNet) -> Result<()> {
        self.poll(net)?;
        let silent: Vec<String> = (0..self.said.len())
            .filter(|&b| !self.said[b])
            .map(|b| {
                let [x, y, z] = self.machine.coords(b);
                format!("({x},{y},{z})")
            })
            .collect();
        if !silent.is_empty() {
            bail!(
                "host: {} board(s) never reported their compilation id: {}",
                silent.len(),
                silent.join(" ")
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fabric::{build_links, Doorbell};
    use std::sync::Arc;

    fn hello(src: u8, id: [u8; 8]) -> Vec<u8> {
        let mut payload = [0u8; HelloPayload::LEN];
        HelloPayload { compilation: id }
            .emit(&mut payload)
            .expect("payload");
        let r = PacketRepr {
            dst: link_proto::packet::ADDR_HOST,
            src,
            msg_id: 0,
            kind: PacketKind::Hello,
            payload: &payload,
        };
        let mut buf = vec![0u8; r.buffer_len()];
        r.emit(&mut buf).expect("packet");
        buf
    }

    /// The host names a board whose hello carries another compilation's id, and the boards
    /// that never said hello; a set whose every board said the manifest's id passes.
    #[test]
    fn the_host_checks_what_every_board_says_it_runs() {
        let dims = Machine::new([2, 2, 1]).expect("machine");
        let bells: Vec<Arc<Doorbell>> = (0..4).map(|_| Default::default()).collect();
        let (_, net) = build_links(dims, &bells, false);
        let ours = [0x57, 0xdc, 1, 2, 3, 4, 5, 6];
        let expected = pe_firmware::image::CompilationId(ours).to_string();
        assert_eq!(expected.len(), 16, "16 hex digits: {expected}");
        let mut check = HostCheck::new(&expected, dims);
        let push = |p: Vec<u8>| net.host.lock().expect("sink").push(p);
        // Boards (0,0,0), (1,0,0) and (0,1,0) (addresses 0, 1, 4) say the right id.
        for a in [0u8, 1, 4] {
            push(hello(a, ours));
        }
        check.poll(&net).expect("right ids pass");
        let e = check
            .finish(&net)
            .expect_err("board (1,1,0) never said hello");
        let m = format!("{e:#}");
        assert!(m.contains("1 board(s)") && m.contains("(1,1,0)"), "{m}");
        // Board (1,1,0) (address 5) says another compilation's id.
        let mut theirs = ours;
        theirs[7] ^= 0x80;
        push(hello(5, theirs));
        let e = check
            .poll(&net)
            .expect_err("another compilation's id is refused");
        let m = format!("{e:#}");
        let theirs_hex = pe_firmware::image::CompilationId(theirs).to_string();
        assert!(
            m.contains("board (1,1,0)") && m.contains(&theirs_hex) && m.contains(&expected),
            "names the board and both ids: {m}"
        );
        // A hello from an address outside the machine.
        let (_, net) = build_links(dims, &bells, false);
        let mut check = HostCheck::new(&expected, dims);
        net.host.lock().expect("sink").push(hello(16, ours));
        let e = check
            .poll(&net)
            .expect_err("address 16 is board (0,0,1): not on 2x2x1");
        assert!(format!("{e:#}").contains("address 16"), "{e:#}");
    }
}
