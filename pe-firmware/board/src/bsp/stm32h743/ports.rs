//! The seven ports (six faces, the global port) as byte streams over their U(S)ARTs' DMA
//! streams: the port table, the stream configuration words, [`DmaSerial`] and the start of
//! each port. See the module doc of [`super`] for the pins.
//!
//! Receive: a circular DMA stream fills a ring of [`RX_RING`] bytes, read behind the
//! stream's counter; the USART's overrun detection is off, so bytes lost to a full ring or a
//! slow stream damage a frame, which its CRC catches (the runtime names the link). Transmit:
//! one normal-mode DMA transfer of up to [`TX_BUF`] bytes at a time. The buffers are in
//! `.dma_buffers`, inside the uncached area at the start of SRAM1 ([`super::memory`]):
//! DMA1/DMA2 reach SRAM1-3, not the DTCM (RM0433, "Bus matrix", Figure 1 "System
//! architecture"). DMAMUX1 request numbers are RM0433's (table "DMAMUX1: assignment of
//! multiplexer inputs to resources", as in the PAC).
//!
//! Ordering: the core may reorder a Normal-memory access (the buffers) against a Device one
//! (the DMA registers), and a compiler fence emits no instruction; each hand-over between
//! the core and a stream is an `atomic::fence(SeqCst)`, a DMB on the M7 (ARMv7-M ARM
//! A3.7.3 "Memory barriers"), as stm32h7xx-hal does around its DMA transfers (`dma/mod.rs`).

use core::mem::MaybeUninit;
use core::sync::atomic::{fence, AtomicBool, Ordering};

use embedded_io::{ErrorKind, ErrorType, Read, ReadReady, Write, WriteReady};
use stm32h7xx_hal::pac;
use stm32h7xx_hal::pac::dma1::st::cr;

/// The ports: the six faces in `link_proto::Face::index` order, then the global port.
pub const PORTS: usize = 7;
/// The global port's index.
pub const GLOBAL_PORT: usize = 6;
/// Bytes of a port's receive ring: more than the largest frame's wire bytes would need a
/// reader that falls a whole frame behind; the runtime drains its links every poll.
pub const RX_RING: usize = 4096;
/// Bytes of a port's transmit buffer (one DMA transfer).
pub const TX_BUF: usize = 1024;

/// Where a port's hardware is.
struct PortHw {
    usart: *const pac::usart1::RegisterBlock,
    dma: *const pac::dma1::RegisterBlock,
    /// Streams of `dma` (0..8) and their DMAMUX1 channels (stream, plus 8 on DMA2).
    rx_stream: usize,
    tx_stream: usize,
    rx_mux: usize,
    tx_mux: usize,
    /// DMAMUX1 request inputs.
    rx_request: u8,
    tx_request: u8,
}

macro_rules! port {
    ($usart:ident, $dma:ident, $rx:expr, $tx:expr, $mux:expr, $req_rx:expr, $req_tx:expr) => {
        PortHw {
            usart: pac::$usart::ptr(),
            dma: pac::$dma::ptr() as *const pac::dma1::RegisterBlock,
            rx_stream: $rx,
            tx_stream: $tx,
            rx_mux: $mux + $rx,
            tx_mux: $mux + $tx,
            rx_request: $req_rx,
            tx_request: $req_tx,
        }
    };
}

/// The port table (see the module doc); DMAMUX1 requests from RM0433: USART1 41/42,
/// USART2 43/44, USART3 45/46, UART4 63/64, UART5 65/66, USART6 71/72, UART7 79/80.
const HW: [PortHw; PORTS] = [
    port!(USART1, DMA1, 0, 1, 0, 41, 42),
    port!(USART2, DMA1, 2, 3, 0, 43, 44),
    port!(UART4, DMA1, 4, 5, 0, 63, 64),
    port!(UART5, DMA1, 6, 7, 0, 65, 66),
    port!(USART6, DMA2, 0, 1, 8, 71, 72),
    port!(UART7, DMA2, 2, 3, 8, 79, 80),
    port!(USART3, DMA2, 4, 5, 8, 45, 46),
];

#[link_section = ".dma_buffers"]
static mut RX_RINGS: MaybeUninit<[[u8; RX_RING]; PORTS]> = MaybeUninit::uninit();
#[link_section = ".dma_buffers"]
static mut TX_BUFS: MaybeUninit<[[u8; TX_BUF]; PORTS]> = MaybeUninit::uninit();

/// Set once [`start`] has the ports running (before, no port may be touched: its clock is
/// off).
static STARTED: AtomicBool = AtomicBool::new(false);

/// A port's interrupt-flag bits in its DMA's LISR/HISR (FEIF, DMEIF, TEIF, HTIF, TCIF).
const FLAGS: u32 = 0b11_1101;
const TEIF: u32 = 1 << 3;

fn flag_shift(stream: usize) -> u32 {
    [0, 6, 16, 22][stream % 4]
}

/// Stream `s`'s flags (in FLAGS's layout).
fn stream_flags(dma: &pac::dma1::RegisterBlock, s: usize) -> u32 {
    let isr = if s < 4 {
        dma.lisr.read().bits()
    } else {
        dma.hisr.read().bits()
    };
    (isr >> flag_shift(s)) & FLAGS
}

fn clear_stream_flags(dma: &pac::dma1::RegisterBlock, s: usize) {
    let bits = FLAGS << flag_shift(s);
    // SAFETY: writing ones to the clear register only clears this stream's flags.
    if s < 4 {
        dma.lifcr.write(|w| unsafe { w.bits(bits) });
    } else {
        dma.hifcr.write(|w| unsafe { w.bits(bits) });
    }
}

/// Lets [`DmaSerial::port`] hand out ports: after every [`start_port`].
pub(super) fn mark_started() {
    STARTED.store(true, Ordering::Release);
}

/// A transfer error on a port's DMA stream (a bus error: a buffer outside DMA's reach).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DmaError;

impl embedded_io::Error for DmaError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// One port as a byte stream.
#[derive(Debug)]
pub struct DmaSerial {
    port: usize,
    /// Where the next byte to read is in the ring.
    read_at: usize,
}

impl DmaSerial {
    /// Port `port` (see the table), once [`start`] has run; `None` before or past the table.
    pub fn port(port: usize) -> Option<Self> {
        (port < PORTS && STARTED.load(Ordering::Acquire)).then(|| DmaSerial {
            port,
            read_at: Self::written(port),
        })
    }

    fn hw(&self) -> &'static PortHw {
        &HW[self.port % PORTS]
    }

    /// The ring position the receive stream writes next.
    fn written(port: usize) -> usize {
        let hw = &HW[port % PORTS];
        // SAFETY: a DMA register block of the table; reading NDTR has no side effect.
        let dma = unsafe { &*hw.dma };
        let left = dma.st[hw.rx_stream].ndtr.read().ndt().bits() as usize;
        // NDTR counts down from RX_RING and reloads (circular mode).
        (RX_RING - left.min(RX_RING)) % RX_RING
    }

    fn rx_error(&self) -> Result<(), DmaError> {
        let hw = self.hw();
        // SAFETY: as in `written`.
        let dma = unsafe { &*hw.dma };
        if stream_flags(dma, hw.rx_stream) & TEIF != 0 {
            return Err(DmaError);
        }
        Ok(())
    }

    fn tx_busy(&self) -> Result<bool, DmaError> {
        let hw = self.hw();
        // SAFETY: as in `written`.
        let dma = unsafe { &*hw.dma };
        if stream_flags(dma, hw.tx_stream) & TEIF != 0 {
            return Err(DmaError);
        }
        Ok(dma.st[hw.tx_stream].cr.read().en().bit_is_set())
    }
}

impl ErrorType for DmaSerial {
    type Error = DmaError;
}

impl ReadReady for DmaSerial {
    fn read_ready(&mut self) -> Result<bool, DmaError> {
        self.rx_error()?;
        Ok(Self::written(self.port) != self.read_at)
    }
}

impl Read for DmaSerial {
    /// Copies the bytes the ring holds beyond the last read (up to `buf`'s length).
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, DmaError> {
        self.rx_error()?;
        let end = Self::written(self.port);
        // The DMA wrote the bytes before NDTR said so: a DMB keeps the ring's reads below
        // behind the counter's read.
        fence(Ordering::SeqCst);
        let ring = core::ptr::addr_of!(RX_RINGS) as *const [u8; RX_RING];
        let mut n = 0;
        while self.read_at != end && n < buf.len() {
            // SAFETY: the ring of this port, inside RX_RINGS; only the DMA writes it, so
            // the byte is read volatile (the compiler cannot know it changed).
            let b = unsafe {
                core::ptr::read_volatile((*ring.add(self.port)).as_ptr().add(self.read_at))
            };
            buf[n] = b;
            n += 1;
            self.read_at = (self.read_at + 1) % RX_RING;
        }
        Ok(n)
    }
}

impl WriteReady for DmaSerial {
    fn write_ready(&mut self) -> Result<bool, DmaError> {
        Ok(!self.tx_busy()?)
    }
}

impl Write for DmaSerial {
    /// Starts one DMA transfer of up to [`TX_BUF`] bytes of `buf` when the last one is done;
    /// 0 while it is still going.
    fn write(&mut self, buf: &[u8]) -> Result<usize, DmaError> {
        if buf.is_empty() || self.tx_busy()? {
            return Ok(0);
        }
        let hw = self.hw();
        let n = buf.len().min(TX_BUF);
        let tx = core::ptr::addr_of_mut!(TX_BUFS) as *mut [u8; TX_BUF];
        // SAFETY: this port's buffer in TX_BUFS, which the DMA does not read while the
        // stream is off (tx_busy said so).
        let dst = unsafe { (*tx.add(self.port)).as_mut_ptr() };
        for (k, &b) in buf[..n].iter().enumerate() {
            // SAFETY: k < n <= TX_BUF.
            unsafe { core::ptr::write_volatile(dst.add(k), b) };
        }
        // The bytes are in memory before the stream starts reading them (a DMB between the
        // buffer's stores and the stream's enable).
        fence(Ordering::SeqCst);
        // SAFETY: the table's registers; the stream is off, so its address and count may
        // change.
        let dma = unsafe { &*hw.dma };
        let st = &dma.st[hw.tx_stream];
        clear_stream_flags(dma, hw.tx_stream);
        st.m0ar.write(|w| unsafe { w.bits(dst as u32) });
        st.ndtr.write(|w| unsafe { w.bits(n as u32) });
        st.cr.modify(|_, w| w.en().enabled());
        Ok(n)
    }

    fn flush(&mut self) -> Result<(), DmaError> {
        while self.tx_busy()? {}
        Ok(())
    }
}

/// Sets port `p`'s USART for DMA (receive and transmit requests, overrun detection off) and
/// starts its circular receive stream; the transmit stream is configured, not started.
///
/// # Safety
/// Once, at start, with the port's USART configured and enabled and DMA1/DMA2 clocked.
pub(super) unsafe fn start_port(p: usize) {
    let hw = &HW[p];
    // SAFETY: the caller's: the USART of the table, configured by the HAL.
    let u = unsafe { &*hw.usart };
    u.cr1.modify(|_, w| w.ue().disabled());
    u.cr3
        .modify(|_, w| w.ovrdis().set_bit().dmar().set_bit().dmat().set_bit());
    u.cr1.modify(|_, w| w.ue().enabled());
    // SAFETY: DMA1/DMA2 and DMAMUX1 register blocks.
    let (dma, mux) = unsafe { (&*hw.dma, &*pac::DMAMUX1::ptr()) };
    let ring = core::ptr::addr_of_mut!(RX_RINGS) as *mut [u8; RX_RING];
    for (stream, channel, request) in [
        (hw.rx_stream, hw.rx_mux, hw.rx_request),
        (hw.tx_stream, hw.tx_mux, hw.tx_request),
    ] {
        let st = &dma.st[stream];
        st.cr.modify(|_, w| w.en().disabled());
        while st.cr.read().en().bit_is_set() {}
        clear_stream_flags(dma, stream);
        // SAFETY: a request number of the table (RM0433's DMAMUX1 inputs).
        mux.ccr[channel].write(|w| unsafe { w.dmareq_id().bits(request) });
        st.fcr.reset(); // direct mode
    }
    let rx = &dma.st[hw.rx_stream];
    rx.par
        .write(|w| unsafe { w.bits(core::ptr::addr_of!(u.rdr) as u32) });
    // SAFETY: this port's ring, inside RX_RINGS (in SRAM1, reachable by DMA).
    rx.m0ar
        .write(|w| unsafe { w.bits((*ring.add(p)).as_mut_ptr() as u32) });
    rx.ndtr.write(|w| unsafe { w.bits(RX_RING as u32) });
    rx.cr.write(|w| rx_stream_cr(w));
    // The ring's address and count are set before the stream starts.
    fence(Ordering::SeqCst);
    rx.cr.modify(|_, w| w.en().enabled());
    let tx = &dma.st[hw.tx_stream];
    tx.par
        .write(|w| unsafe { w.bits(core::ptr::addr_of!(u.tdr) as u32) });
    tx.cr.write(|w| tx_stream_cr(w));
}

/// What every port's streams share in DMA_SxCR (RM0433, "DMA stream x configuration
/// register (DMA_SxCR)"): memory address incremented, bytes both sides, high priority,
/// TRBUFF set. TRBUFF (bit 20): RM0433 says it must be set when the stream serves a U(S)ART
/// (bufferable transfers); stm32h7xx-hal sets it for every serial target (`dma/mod.rs`,
/// `if PERIPHERAL::TRBUFF`), and NuttX found transfers unstable without it (apache/nuttx
/// PR 4331). Not yet enabled.
fn byte_stream_cr(w: &mut cr::W) -> &mut cr::W {
    w.minc()
        .incremented()
        .psize()
        .bits8()
        .msize()
        .bits8()
        .pl()
        .high()
        .trbuff()
        .enabled()
}

/// A receive stream's DMA_SxCR: peripheral to memory, circular, as [`byte_stream_cr`].
pub fn rx_stream_cr(w: &mut cr::W) -> &mut cr::W {
    byte_stream_cr(w.dir().peripheral_to_memory().circ().enabled())
}

/// A transmit stream's DMA_SxCR: memory to peripheral, normal mode, as [`byte_stream_cr`].
pub fn tx_stream_cr(w: &mut cr::W) -> &mut cr::W {
    byte_stream_cr(w.dir().memory_to_peripheral().circ().disabled())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The word `f` writes into a DMA_SxCR, through the PAC, in a register block in
    /// ordinary memory (the PAC's accessors are volatile reads and writes of its fields).
    fn stream_cr(f: fn(&mut cr::W) -> &mut cr::W) -> u32 {
        // SAFETY: a register block is plain u32 cells; all-zero is every register's value.
        let block: pac::dma1::RegisterBlock = unsafe { core::mem::zeroed() };
        block.st[3].cr.write(|w| f(w));
        block.st[3].cr.read().bits()
    }

    // DMA_SxCR fields (RM0433, "DMA stream x configuration register"), written out here:
    // EN [0], DIR [7:6] (00 peripheral to memory, 01 memory to peripheral), CIRC [8],
    // PINC [9], MINC [10], PSIZE [12:11], MSIZE [14:13], PL [17:16], TRBUFF [20].
    const EN: u32 = 1;
    const CIRC: u32 = 1 << 8;
    const PINC: u32 = 1 << 9;
    const MINC: u32 = 1 << 10;
    const TRBUFF: u32 = 1 << 20;
    const fn dir(w: u32) -> u32 {
        (w >> 6) & 0b11
    }
    const fn sizes(w: u32) -> (u32, u32) {
        ((w >> 11) & 0b11, (w >> 13) & 0b11)
    }
    const fn priority(w: u32) -> u32 {
        (w >> 16) & 0b11
    }

    #[test]
    fn receive_streams_are_circular_bufferable_byte_streams_into_memory() {
        let w = stream_cr(rx_stream_cr);
        assert_ne!(w, 0, "the word sets something");
        assert_eq!(
            w & TRBUFF,
            TRBUFF,
            "TRBUFF: RM0433 requires it for a U(S)ART"
        );
        assert_eq!(dir(w), 0b00, "peripheral to memory");
        assert_eq!(w & CIRC, CIRC, "circular: the ring refills itself");
        assert_eq!(
            (w & MINC, w & PINC),
            (MINC, 0),
            "memory address moves, RDR stays"
        );
        assert_eq!(sizes(w), (0, 0), "bytes on both sides");
        assert_eq!(priority(w), 0b10, "high priority");
        assert_eq!(w & EN, 0, "configured, started later");
        assert_eq!(w, TRBUFF | (0b10 << 16) | MINC | CIRC, "no other bit");
    }

    #[test]
    fn transmit_streams_are_one_shot_bufferable_byte_streams_to_the_peripheral() {
        let w = stream_cr(tx_stream_cr);
        assert_eq!(
            w & TRBUFF,
            TRBUFF,
            "TRBUFF: RM0433 requires it for a U(S)ART"
        );
        assert_eq!(dir(w), 0b01, "memory to peripheral");
        assert_eq!(w & CIRC, 0, "one transfer per write");
        assert_eq!(
            (w & MINC, w & PINC),
            (MINC, 0),
            "memory address moves, TDR stays"
        );
        assert_eq!(sizes(w), (0, 0), "bytes on both sides");
        assert_eq!(priority(w), 0b10, "high priority");
        assert_eq!(w & EN, 0, "started by each write");
        assert_eq!(
            w,
            TRBUFF | (0b10 << 16) | MINC | (0b01 << 6),
            "no other bit"
        );
    }

    #[test]
    fn every_port_has_its_own_streams_and_multiplexer_channels() {
        // Two ports on one stream (or one DMAMUX1 channel) would steal each other's bytes.
        let mut seen = [[false; 8]; 2];
        let mut mux = [false; 16];
        for hw in &HW {
            let dma = usize::from(!core::ptr::eq(hw.dma, pac::DMA1::ptr()));
            for (s, m) in [(hw.rx_stream, hw.rx_mux), (hw.tx_stream, hw.tx_mux)] {
                assert!(!seen[dma][s], "DMA{} stream {s} used twice", dma + 1);
                seen[dma][s] = true;
                assert_eq!(
                    m,
                    s + 8 * dma,
                    "DMAMUX1 channel of DMA{} stream {s}",
                    dma + 1
                );
                assert!(!mux[m]);
                mux[m] = true;
            }
        }
        assert_eq!(HW.len(), PORTS);
    }
}
