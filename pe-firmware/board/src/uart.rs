//! Link drivers: byte streams for `link_proto::StreamLinks` through `embedded-io`.
//!
//! [`CmsdkUart`] drives the ARM CMSDK APB UART of the MPS2 FPGA images (and of QEMU's
//! `mps2-an500`): DATA at +0x0, STATE at +0x4 (bit 0 TX full, bit 1 RX full), CTRL at +0x8
//! (bit 0 TX enable, bit 1 RX enable, bits 2 and 3 their interrupts), INTSTATUS/INTCLEAR at
//! +0xC, BAUDDIV at +0x10. Nothing blocks: `write_ready` and `read_ready` say whether a byte
//! can move, as `StreamPort` expects. The prototype board's USARTs
//! ([`crate::bsp::stm32h743`]) implement the same `embedded-io` traits and plug into
//! `StreamLinks` unchanged.

use embedded_io::{ErrorKind, ErrorType, Read, ReadReady, Write, WriteReady};

const DATA: usize = 0x0;
const STATE: usize = 0x4;
const CTRL: usize = 0x8;
/// Read: interrupt status; write ones: clear them.
const INTSTATUS: usize = 0xC;
const BAUDDIV: usize = 0x10;
const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const CTRL_TX_EN: u32 = 1 << 0;
const CTRL_RX_EN: u32 = 1 << 1;
const CTRL_TX_INT_EN: u32 = 1 << 2;
const CTRL_RX_INT_EN: u32 = 1 << 3;
/// TX, RX, TX overrun, RX overrun.
const INT_ALL: u32 = 0xF;

/// One CMSDK APB UART.
#[derive(Debug)]
pub struct CmsdkUart {
    base: usize,
}

/// The UART never reports errors (overruns lose bytes, which the framing's CRC catches).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UartError;

impl embedded_io::Error for UartError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

impl CmsdkUart {
    /// Takes the UART at `base` (one of `pe_firmware::profile::mps2_uarts::UART_BASES`) and enables TX and RX.
    ///
    /// # Safety
    /// `base` must be a CMSDK UART's register block that nothing else drives.
    pub unsafe fn new(base: usize) -> Self {
        let u = CmsdkUart { base };
        u.write_reg(BAUDDIV, 16);
        u.write_reg(CTRL, CTRL_TX_EN | CTRL_RX_EN);
        u
    }

    /// Raises the UART's interrupts when a byte arrives or one has gone (for a core that
    /// sleeps until its links move: [`crate::links::wait_for_link_event`]).
    pub fn enable_wake_interrupts(&self) {
        self.write_reg(
            CTRL,
            CTRL_TX_EN | CTRL_RX_EN | CTRL_TX_INT_EN | CTRL_RX_INT_EN,
        );
    }

    /// Whether a received byte waits to be read.
    pub fn rx_waiting(&self) -> bool {
        self.read_reg(STATE) & STATE_RX_FULL != 0
    }

    /// Clears the interrupt status (the received byte stays in DATA).
    pub fn clear_interrupts(&self) {
        self.write_reg(INTSTATUS, INT_ALL);
    }

    /// A second handle on the UART at `base`, for its status registers only.
    ///
    /// # Safety
    /// `base` must be a CMSDK UART's register block; the handle must not touch DATA, and
    /// may change CTRL only to enable interrupts.
    pub unsafe fn alias(base: usize) -> Self {
        CmsdkUart { base }
    }

    fn read_reg(&self, offset: usize) -> u32 {
        // SAFETY: `new`'s contract: `base + offset` is a register of this UART.
        unsafe { core::ptr::read_volatile((self.base + offset) as *const u32) }
    }

    fn write_reg(&self, offset: usize, value: u32) {
        // SAFETY: as in `read_reg`.
        unsafe { core::ptr::write_volatile((self.base + offset) as *mut u32, value) }
    }
}

impl ErrorType for CmsdkUart {
    type Error = UartError;
}

impl Read for CmsdkUart {
    /// Reads the bytes waiting (at most one: the UART has a one-byte buffer); 0 if none.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, UartError> {
        match buf.first_mut() {
            Some(b) if self.read_reg(STATE) & STATE_RX_FULL != 0 => {
                *b = self.read_reg(DATA) as u8;
                Ok(1)
            }
            _ => Ok(0),
        }
    }
}

impl ReadReady for CmsdkUart {
    fn read_ready(&mut self) -> Result<bool, UartError> {
        Ok(self.read_reg(STATE) & STATE_RX_FULL != 0)
    }
}

impl Write for CmsdkUart {
    /// Writes at most one byte (when the transmitter has room); 0 otherwise.
    fn write(&mut self, buf: &[u8]) -> Result<usize, UartError> {
        match buf.first() {
            Some(&b) if self.read_reg(STATE) & STATE_TX_FULL == 0 => {
                self.write_reg(DATA, b as u32);
                Ok(1)
            }
            Some(_) => Ok(0),
            None => Ok(0),
        }
    }

    fn flush(&mut self) -> Result<(), UartError> {
        Ok(())
    }
}

impl WriteReady for CmsdkUart {
    fn write_ready(&mut self) -> Result<bool, UartError> {
        Ok(self.read_reg(STATE) & STATE_TX_FULL == 0)
    }
}
