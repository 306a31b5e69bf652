//! The prototype board (profile `stm32h743-uart`): an STM32H743 whose six faces and global
//! port are USART/UARTs moved by DMA, a core clock at 480 MHz and a cycle counter for time.
//!
//! What is hardware-specific stays here and small: [`start`] sets up clocks, pins, the seven
//! ports and their DMA streams once; [`DmaSerial`] is a port as an `embedded-io` byte
//! stream (`Read`, `ReadReady`, `Write`, `WriteReady`), which is all `link_proto`'s
//! `StreamLinks` asks of a link: the same traits, framing and runtime as the QEMU build's
//! CMSDK UARTs, which CI runs. [`CycleClock`] is the runtime's `Environment`.
//!
//! | port | carries | peripheral | TX, RX pins (alternate function) | DMA RX, TX streams |
//! |---|---|---|---|---|
//! | 0 | face +x | USART1 | PB14, PB15 (AF4) | DMA1 0, 1 |
//! | 1 | face -x | USART2 | PD5, PD6 (AF7) | DMA1 2, 3 |
//! | 2 | face +y | UART4 | PD1, PD0 (AF8) | DMA1 4, 5 |
//! | 3 | face -y | UART5 | PB13, PB12 (AF14) | DMA1 6, 7 |
//! | 4 | face +z | USART6 | PC6, PC7 (AF7) | DMA2 0, 1 |
//! | 5 | face -z | UART7 | PE8, PE7 (AF7) | DMA2 2, 3 |
//! | 6 | global port | USART3 | PD8, PD9 (AF7) | DMA2 4, 5 |
//!
//! All pins are on the LQFP144 package of the NUCLEO-H743ZI; USART3 on PD8/PD9 is that
//! board's ST-LINK virtual COM port, so a host on the prototype reads the global port over
//! the probe's USB. A cable crosses TX and RX between neighbours and shares ground.
//!
//! Each port runs at 7.5 Mbaud, 8N1 (the USART kernel clock, `rcc_pclk1` or `rcc_pclk2` at
//! 120 MHz, over 16: the rate `pe_firmware::profile::STM32H743_UART` is built on). Receive:
//! a circular DMA stream fills a ring of [`RX_RING`] bytes in SRAM1 (`.dma_buffers`, which
//! DMA1/DMA2 reach; the data cache stays off), read behind the stream's counter; the
//! USART's overrun detection is off, so bytes lost to a full ring or a slow stream damage a
//! frame, which its CRC catches (the runtime names the link). Transmit: one normal-mode DMA
//! transfer of up to [`TX_BUF`] bytes at a time. DMAMUX1 request numbers are RM0433's
//! (table "DMAMUX1: assignment of multiplexer inputs to resources", as in the PAC).
//!
//! Not run here: the prototype has not been built. What needs checking on it is listed in
//! docs/boards.md ("The prototype board").

use core::mem::MaybeUninit;
use core::sync::atomic::{compiler_fence, AtomicBool, Ordering};

use embedded_io::{ErrorKind, ErrorType, Read, ReadReady, Write, WriteReady};
use stm32h7xx_hal::pac;
use stm32h7xx_hal::prelude::*;

/// The ports: the six faces in `link_proto::Face::index` order, then the global port.
pub const PORTS: usize = 7;
/// The global port's index.
pub const GLOBAL_PORT: usize = 6;
/// Bytes of a port's receive ring: more than the largest frame's wire bytes would need a
/// reader that falls a whole frame behind; the runtime drains its links every poll.
pub const RX_RING: usize = 4096;
/// Bytes of a port's transmit buffer (one DMA transfer).
pub const TX_BUF: usize = 1024;
/// Each link's rate.
pub const BAUD: u32 = 7_500_000;

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
        // The DMA wrote the bytes before NDTR said so: no read below may move above it.
        compiler_fence(Ordering::Acquire);
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
        // The bytes are in memory before the stream starts reading them.
        compiler_fence(Ordering::Release);
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
unsafe fn start_port(p: usize) {
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
    rx.cr.write(|w| {
        w.dir()
            .peripheral_to_memory()
            .circ()
            .enabled()
            .minc()
            .incremented()
            .psize()
            .bits8()
            .msize()
            .bits8()
            .pl()
            .high()
    });
    rx.cr.modify(|_, w| w.en().enabled());
    let tx = &dma.st[hw.tx_stream];
    tx.par
        .write(|w| unsafe { w.bits(core::ptr::addr_of!(u.tdr) as u32) });
    tx.cr.write(|w| {
        w.dir()
            .memory_to_peripheral()
            .minc()
            .incremented()
            .psize()
            .bits8()
            .msize()
            .bits8()
            .pl()
            .high()
    });
}

/// Why the board could not start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartError {
    /// The device peripherals were taken before.
    Taken,
    /// A port's USART refused its configuration (its kernel clock cannot make [`BAUD`]).
    Port(usize),
}

impl core::fmt::Display for StartError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            StartError::Taken => write!(f, "STM32H743 peripherals taken twice"),
            StartError::Port(p) => write!(f, "port {p}: its USART cannot run at {BAUD} baud"),
        }
    }
}

/// Clocks (480 MHz core, 240 MHz AHB, 120 MHz APB, voltage scale 0), the seven ports and
/// their DMA streams, and the cycle counter. Once, at start.
pub fn start(cp: &mut cortex_m::Peripherals) -> Result<CycleClock, StartError> {
    let dp = pac::Peripherals::take().ok_or(StartError::Taken)?;
    let pwr = dp.PWR.constrain().vos0(&dp.SYSCFG).freeze();
    let ccdr = dp
        .RCC
        .constrain()
        .sys_ck(480.MHz())
        .hclk(240.MHz())
        .pclk1(120.MHz())
        .pclk2(120.MHz())
        .freeze(pwr, &dp.SYSCFG);
    // SRAM1-3 (the DMA buffers) clocked.
    // SAFETY: setting enable bits of the D2 SRAMs only.
    unsafe {
        (*pac::RCC::ptr()).ahb2enr.modify(|_, w| {
            w.sram1en()
                .set_bit()
                .sram2en()
                .set_bit()
                .sram3en()
                .set_bit()
        });
    }
    let b = dp.GPIOB.split(ccdr.peripheral.GPIOB);
    let c = dp.GPIOC.split(ccdr.peripheral.GPIOC);
    let d = dp.GPIOD.split(ccdr.peripheral.GPIOD);
    let e = dp.GPIOE.split(ccdr.peripheral.GPIOE);
    let clocks = &ccdr.clocks;
    // Each port's USART at BAUD, 8N1 (the HAL enables its clock and checks the pins).
    macro_rules! serial {
        ($port:expr, $usart:ident, $tx:expr, $rx:expr) => {
            dp.$usart
                .serial(($tx, $rx), BAUD.bps(), ccdr.peripheral.$usart, clocks)
                .map_err(|_| StartError::Port($port))?
        };
    }
    serial!(
        0,
        USART1,
        b.pb14.into_alternate::<4>(),
        b.pb15.into_alternate::<4>()
    );
    serial!(
        1,
        USART2,
        d.pd5.into_alternate::<7>(),
        d.pd6.into_alternate::<7>()
    );
    serial!(
        2,
        UART4,
        d.pd1.into_alternate::<8>(),
        d.pd0.into_alternate::<8>()
    );
    serial!(
        3,
        UART5,
        b.pb13.into_alternate::<14>(),
        b.pb12.into_alternate::<14>()
    );
    serial!(
        4,
        USART6,
        c.pc6.into_alternate::<7>(),
        c.pc7.into_alternate::<7>()
    );
    serial!(
        5,
        UART7,
        e.pe8.into_alternate::<7>(),
        e.pe7.into_alternate::<7>()
    );
    serial!(
        GLOBAL_PORT,
        USART3,
        d.pd8.into_alternate::<7>(),
        d.pd9.into_alternate::<7>()
    );
    use stm32h7xx_hal::rcc::ResetEnable;
    ccdr.peripheral.DMA1.enable();
    ccdr.peripheral.DMA2.enable();
    for p in 0..PORTS {
        // SAFETY: once, each port's USART configured above, DMA1/DMA2 clocked.
        unsafe { start_port(p) };
    }
    STARTED.store(true, Ordering::Release);
    Ok(CycleClock::start(cp, clocks.c_ck().raw()))
}

/// Time from the core's cycle counter (DWT CYCCNT), extended to 64 bits: exact to a cycle,
/// as long as it is read at least once per wrap (8.9 s at 480 MHz; the runtime reads it at
/// every wait and its link timeout is shorter).
pub struct CycleClock {
    hz: u64,
    last: u32,
    high: u64,
}

impl CycleClock {
    fn start(cp: &mut cortex_m::Peripherals, hz: u32) -> Self {
        cp.DCB.enable_trace();
        cp.DWT.enable_cycle_counter();
        CycleClock {
            hz: hz.max(1) as u64,
            last: cortex_m::peripheral::DWT::cycle_count(),
            high: 0,
        }
    }
}

impl link_proto::Clock for CycleClock {
    fn now_ns(&mut self) -> u64 {
        let c = cortex_m::peripheral::DWT::cycle_count();
        if c < self.last {
            self.high += 1 << 32;
        }
        self.last = c;
        let cycles = self.high + c as u64;
        // cycles * 1e9 / hz without overflow for any run shorter than centuries.
        (cycles / self.hz) * 1_000_000_000 + (cycles % self.hz) * 1_000_000_000 / self.hz
    }
}

impl pe_firmware::runtime::Environment for CycleClock {
    /// The ports move by DMA: nothing to wait for but the next poll.
    fn idle(&mut self) {
        core::hint::spin_loop();
    }
}
