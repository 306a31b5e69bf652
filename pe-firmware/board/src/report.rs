//! Results and faults leave the board here.
//!
//! * Final state (QEMU): one semihosting line per owned node, `u,GLOBAL,UX,UY,UZ` with the
//!   displacement components as the 16 hex digits of their `f64` bits (an `f32` run widens
//!   exactly), between `pe-board: begin nodes` and `pe-board: end nodes`.
//! * Faults (numerical, image, link, panic, hard fault): the message (the runtime's `Fault`
//!   display) goes as a global-network fault packet (`PacketKind::FaultReport`, to the host,
//!   COBS-framed on the global port), to semihosting (`pe-board: FAULT ...`) on QEMU and to
//!   defmt on the board; then [`exit`]. Nothing here blocks without bound.

use core::fmt::Write as _;

use embedded_io::{Write, WriteReady};
use link_proto::packet::ADDR_HOST;
use link_proto::{PacketKind, PacketRepr};

/// Longest fault message sent (longer ones are cut).
pub const FAULT_MESSAGE_MAX: usize = 240;

/// One line to the host's stdout through semihosting (QEMU), formatted first so the line
/// is written in one call.
#[cfg(feature = "qemu")]
pub fn semihosting_line(args: core::fmt::Arguments) {
    let mut s: heapless::String<320> = heapless::String::new();
    let _ = s.write_fmt(args);
    let _ = s.push('\n');
    cortex_m_semihosting::export::hstdout_str(&s);
}

/// One node of the final state: `u,GLOBAL,UX,UY,UZ` (hex bits of the f64 values).
pub fn node(global: u32, u: [f64; 3]) {
    let [x, y, z] = u.map(f64::to_bits);
    #[cfg(feature = "defmt")]
    defmt::info!("u,{=u32},{=u64:x},{=u64:x},{=u64:x}", global, x, y, z);
    #[cfg(all(not(feature = "defmt"), feature = "qemu"))]
    semihosting_line(format_args!("u,{global},{x:016x},{y:016x},{z:016x}"));
    let _ = (global, x, y, z);
}

/// A fixed-capacity string that cuts instead of failing.
pub struct Message(pub heapless::String<FAULT_MESSAGE_MAX>);

impl core::fmt::Write for Message {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        for c in s.chars() {
            if self.0.push(c).is_err() {
                break;
            }
        }
        Ok(())
    }
}

/// Formats a message.
pub fn message(args: core::fmt::Arguments) -> Message {
    let mut m = Message(heapless::String::new());
    let _ = m.write_fmt(args);
    m
}

/// Sends `text` as a fault packet from `board` on the global port, spinning at most a
/// bounded number of times per byte.
fn send_fault_packet(board: [u8; 3], text: &str) {
    let src = link_proto::Machine::address(board.map(usize::from)).unwrap_or(0xFE);
    let repr = PacketRepr {
        dst: ADDR_HOST,
        src,
        msg_id: 0,
        kind: PacketKind::FaultReport,
        payload: text.as_bytes(),
    };
    let mut packet = [0u8; link_proto::packet::packet_len(FAULT_MESSAGE_MAX)];
    let Ok(len) = repr.emit(&mut packet) else {
        return;
    };
    let mut wire =
        [0u8; link_proto::wire_len_max(link_proto::packet::packet_len(FAULT_MESSAGE_MAX))];
    let Ok(n) = link_proto::encode_wire(packet.get(..len).unwrap_or(&[]), &mut wire) else {
        return;
    };
    // SAFETY: called once, at the end of a run, after the runtime stopped using the links.
    let mut port = unsafe { crate::links::global_stream() };
    for &b in wire.get(..n).unwrap_or(&[]) {
        let mut spins = 0u32;
        while !matches!(port.write_ready(), Ok(true)) && spins < 100_000 {
            spins += 1;
            core::hint::spin_loop();
        }
        let _ = port.write(&[b]);
    }
}

/// Reports a fault everywhere it can go, then exits (QEMU) or parks the core for the host
/// to reset it (board).
pub fn fault(board: [u8; 3], args: core::fmt::Arguments) -> ! {
    let m = message(args);
    #[cfg(feature = "qemu")]
    semihosting_line(format_args!("pe-board: FAULT {}", m.0.as_str()));
    #[cfg(feature = "defmt")]
    defmt::error!("FAULT {=str}", m.0.as_str());
    send_fault_packet(board, &m.0);
    exit(false)
}

/// Ends the run: QEMU exits with the status (semihosting); the board waits for interrupts
/// (the host resets it for the next scene).
pub fn exit(success: bool) -> ! {
    #[cfg(feature = "qemu")]
    cortex_m_semihosting::debug::exit(if success {
        cortex_m_semihosting::debug::EXIT_SUCCESS
    } else {
        cortex_m_semihosting::debug::EXIT_FAILURE
    });
    let _ = success;
    loop {
        cortex_m::asm::wfi();
    }
}
