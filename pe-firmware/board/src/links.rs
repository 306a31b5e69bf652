//! The board's links: `link_proto::StreamLinks` over [`LinkStream`]s.
//!
//! On QEMU's mps2-an500 the global port is CMSDK UART 2 (no host backend: bytes go into the
//! void, which exercises the fault-packet path without disturbing the semihosting output)
//! and no face is linked: the emulation runs one board (a 1x1x1 machine exchanges nothing).
//! On the PE board the six LVDS links and the global port are the MCU's UARTs; their
//! pin/clock set-up belongs to the board support package, which is not written yet, so the
//! board build links no face and the global port is [`LinkStream::Absent`]. An image that
//! needs a face without a driver is refused before the first step.

use core::sync::atomic::{AtomicBool, Ordering};

use embedded_io::{ErrorType, Read, ReadReady, Write, WriteReady};
use link_proto::{Face, StreamLinks};

use crate::uart::{CmsdkUart, UartError};

/// One link's byte stream.
#[derive(Debug)]
pub enum LinkStream {
    Cmsdk(CmsdkUart),
    /// No driver: reads nothing, accepts and drops writes.
    Absent,
}

impl ErrorType for LinkStream {
    type Error = UartError;
}

impl Read for LinkStream {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, UartError> {
        match self {
            LinkStream::Cmsdk(u) => u.read(buf),
            LinkStream::Absent => Ok(0),
        }
    }
}

impl ReadReady for LinkStream {
    fn read_ready(&mut self) -> Result<bool, UartError> {
        match self {
            LinkStream::Cmsdk(u) => u.read_ready(),
            LinkStream::Absent => Ok(false),
        }
    }
}

impl Write for LinkStream {
    fn write(&mut self, buf: &[u8]) -> Result<usize, UartError> {
        match self {
            LinkStream::Cmsdk(u) => u.write(buf),
            LinkStream::Absent => Ok(buf.len()),
        }
    }

    fn flush(&mut self) -> Result<(), UartError> {
        Ok(())
    }
}

impl WriteReady for LinkStream {
    fn write_ready(&mut self) -> Result<bool, UartError> {
        match self {
            LinkStream::Cmsdk(u) => u.write_ready(),
            LinkStream::Absent => Ok(true),
        }
    }
}

pub type BoardLinks = StreamLinks<LinkStream, LinkStream>;

/// The global port's stream (also used, freshly taken, by the fault reporter).
///
/// # Safety
/// Nothing else may be driving the global port's UART at the same time.
pub unsafe fn global_stream() -> LinkStream {
    if cfg!(feature = "qemu") {
        // SAFETY: UART 2 of mps2-an500 is a CMSDK UART; exclusivity is the caller's.
        LinkStream::Cmsdk(unsafe { CmsdkUart::new(crate::uart::MPS2_UART_BASES[2]) })
    } else {
        LinkStream::Absent
    }
}

/// Which faces this firmware has drivers for.
pub fn face_linked(_face: Face) -> bool {
    false
}

static mut LINKS: BoardLinks = StreamLinks::unlinked(LinkStream::Absent);
static TAKEN: AtomicBool = AtomicBool::new(false);

/// The links: a static built at compile time (about 170 KB of frame buffers: never on
/// the stack), given the global port's stream once.
pub fn take() -> Option<&'static mut BoardLinks> {
    if TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    // SAFETY: TAKEN makes this the only reference to LINKS, created once; the global port
    // is not yet driven by anyone else (the fault reporter only takes it after the links
    // are dropped from use, at the end of a run).
    let links: &'static mut BoardLinks = unsafe { &mut *core::ptr::addr_of_mut!(LINKS) };
    links
        .global_port()
        .replace_stream(unsafe { global_stream() });
    Some(links)
}
