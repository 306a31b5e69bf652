//! The board's links: `link_proto::StreamLinks` over [`LinkStream`]s.
//!
//! On QEMU's mps2-an500 the five CMSDK UARTs carry the global port and the faces, as
//! `pe_firmware::profile::mps2_uarts` assigns them (the harness that wires emulated boards
//! together reads the same table): UART 2 is the global port, and the faces this board
//! exchanges over take UARTs 0, 1, 3, 4 in face order. On the STM32H743 prototype (feature
//! `stm32h743`) each face and the global port is a USART/UART moved by DMA
//! ([`crate::bsp::stm32h743`]). [`take`] links them once the image has said where the board
//! sits; a board that needs more faces than there are drivers is refused before the first
//! step. The PE board's own build (SPI links, no board support yet) links no face and its
//! global port is [`LinkStream::Absent`]: an image that needs a face is refused.

use core::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use embedded_io::{ErrorType, Read, ReadReady, Write, WriteReady};
use link_proto::stream::{FacePort, GlobalPort};
use link_proto::{Face, StreamLinks};

use crate::uart::{CmsdkUart, UartError};

/// One link's byte stream.
#[derive(Debug)]
pub enum LinkStream {
    Cmsdk(CmsdkUart),
    #[cfg(feature = "stm32h743")]
    Stm(crate::bsp::stm32h743::DmaSerial),
    /// No driver: reads nothing, accepts and drops writes.
    Absent,
}

impl ErrorType for LinkStream {
    type Error = UartError;
}

#[cfg(feature = "stm32h743")]
impl From<crate::bsp::stm32h743::DmaError> for UartError {
    fn from(_: crate::bsp::stm32h743::DmaError) -> Self {
        UartError
    }
}

impl Read for LinkStream {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, UartError> {
        match self {
            LinkStream::Cmsdk(u) => u.read(buf),
            #[cfg(feature = "stm32h743")]
            LinkStream::Stm(p) => Ok(p.read(buf)?),
            LinkStream::Absent => Ok(0),
        }
    }
}

impl ReadReady for LinkStream {
    fn read_ready(&mut self) -> Result<bool, UartError> {
        match self {
            LinkStream::Cmsdk(u) => u.read_ready(),
            #[cfg(feature = "stm32h743")]
            LinkStream::Stm(p) => Ok(p.read_ready()?),
            LinkStream::Absent => Ok(false),
        }
    }
}

impl Write for LinkStream {
    fn write(&mut self, buf: &[u8]) -> Result<usize, UartError> {
        match self {
            LinkStream::Cmsdk(u) => u.write(buf),
            #[cfg(feature = "stm32h743")]
            LinkStream::Stm(p) => Ok(p.write(buf)?),
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
            #[cfg(feature = "stm32h743")]
            LinkStream::Stm(p) => Ok(p.write_ready()?),
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
    #[cfg(feature = "stm32h743")]
    if let Some(p) = crate::bsp::stm32h743::DmaSerial::port(crate::bsp::stm32h743::GLOBAL_PORT) {
        return LinkStream::Stm(p);
    }
    if cfg!(feature = "qemu") {
        // SAFETY: UART 2 of mps2-an500 is a CMSDK UART; exclusivity is the caller's.
        LinkStream::Cmsdk(unsafe {
            CmsdkUart::new(
                pe_firmware::profile::mps2_uarts::UART_BASES
                    [pe_firmware::profile::mps2_uarts::GLOBAL_UART],
            )
        })
    } else {
        LinkStream::Absent
    }
}

/// The driver of each face for a board whose linked faces are `linked`
/// ([`pe_firmware::image::linked_faces`]): QEMU, the UART number; the STM32H743 prototype,
/// its port (one per face). `Err(n)`: it needs `n` face links, more than this firmware
/// drives.
pub fn face_drivers(linked: [bool; 6]) -> Result<[Option<usize>; 6], usize> {
    if cfg!(feature = "qemu") {
        pe_firmware::profile::mps2_uarts::face_uarts(linked)
    } else if cfg!(feature = "stm32h743") {
        let mut d = [None; 6];
        for (f, slot) in d.iter_mut().enumerate() {
            *slot = linked[f].then_some(f);
        }
        Ok(d)
    } else {
        match linked.iter().filter(|&&l| l).count() {
            0 => Ok([None; 6]),
            n => Err(n),
        }
    }
}

/// The stream of face driver `d` (from [`face_drivers`]).
fn face_stream(d: usize) -> Option<LinkStream> {
    #[cfg(feature = "stm32h743")]
    {
        crate::bsp::stm32h743::DmaSerial::port(d).map(LinkStream::Stm)
    }
    #[cfg(not(feature = "stm32h743"))]
    {
        let base = *pe_firmware::profile::mps2_uarts::UART_BASES.get(d)?;
        // SAFETY: a CMSDK UART of mps2-an500 that the plan gives one face alone (never the
        // global port's).
        let u = unsafe { CmsdkUart::new(base) };
        register(d);
        Some(LinkStream::Cmsdk(u))
    }
}

const fn absent_port() -> Option<FacePort<LinkStream>> {
    Some(FacePort::new(LinkStream::Absent))
}

/// A port for every face (built at compile time: the buffers are never a stack temporary);
/// [`take`] links the faces the image needs and takes the others off. On the board it sits
/// in the `.links` section of SRAM1-3 (the AXI SRAM holds the storage), which the start-up
/// code does not initialise: [`take`] copies it from flash first.
#[cfg_attr(not(feature = "qemu"), link_section = ".links")]
static mut LINKS: BoardLinks = StreamLinks::from_ports(
    [
        absent_port(),
        absent_port(),
        absent_port(),
        absent_port(),
        absent_port(),
        absent_port(),
    ],
    GlobalPort::new(LinkStream::Absent),
);
static TAKEN: AtomicBool = AtomicBool::new(false);

/// Copies the `.links` section (LINKS's initial value) from its load address in flash to
/// SRAM1-3, as the start-up code does for `.data` (`memory.x` defines the symbols).
///
/// # Safety
/// Once, before anything reads or references LINKS.
#[cfg(not(feature = "qemu"))]
unsafe fn init_link_section() {
    extern "C" {
        static mut __slinks: u32;
        static mut __elinks: u32;
        static __silinks: u32;
    }
    // SAFETY: the linker's symbols bound the section and its load image; the caller's
    // "once, before anything reads LINKS".
    unsafe {
        crate::section::copy_from_flash(
            core::ptr::addr_of_mut!(__slinks),
            core::ptr::addr_of_mut!(__elinks),
            core::ptr::addr_of!(__silinks),
        )
    }
}

/// The UARTs the links use (base addresses; 0: none), for [`wait_for_link_event`] and the
/// interrupt handler.
static WAKE_UARTS: [AtomicUsize; 5] = [const { AtomicUsize::new(0) }; 5];

/// A UART interrupt as the NVIC numbers it.
#[derive(Clone, Copy)]
struct Irq(u16);

// SAFETY: the numbers are mps2-an500's UART interrupts (profile::mps2_uarts::RX_IRQS and
// the next), all below the NVIC's interrupt count.
unsafe impl cortex_m::interrupt::InterruptNumber for Irq {
    fn number(self) -> u16 {
        self.0
    }
}

/// Records UART `uart` as one the links use ([`wake_on_links`] lets it wake the core).
fn register(uart: usize) {
    use pe_firmware::profile::mps2_uarts::UART_BASES;
    if let (Some(&base), Some(slot)) = (UART_BASES.get(uart), WAKE_UARTS.get(uart)) {
        slot.store(base, Ordering::Release);
    }
}

/// Lets the links' UARTs wake the core: their receive and transmit interrupts enabled in
/// the UARTs and unmasked in the NVIC. Only for a binary whose `DefaultHandler` calls
/// [`on_uart_interrupt`] (the firmware's does; cortex-m-rt's default handler would hang).
pub fn wake_on_links() {
    use pe_firmware::profile::mps2_uarts::{RX_IRQS, UART_BASES};
    for (uart, slot) in WAKE_UARTS.iter().enumerate() {
        let base = slot.load(Ordering::Acquire);
        let (Some(&b), Some(&rx)) = (UART_BASES.get(uart), RX_IRQS.get(uart)) else {
            continue;
        };
        if base == 0 || base != b {
            continue;
        }
        // SAFETY: a UART the links registered; only CTRL's interrupt enables change.
        unsafe { CmsdkUart::alias(base) }.enable_wake_interrupts();
        // SAFETY: unmasking only lets these interrupts run the handler that clears them; no
        // critical section relies on them being masked.
        unsafe {
            cortex_m::peripheral::NVIC::unmask(Irq(rx));
            cortex_m::peripheral::NVIC::unmask(Irq(rx + 1));
        }
    }
}

fn wake_uarts() -> impl Iterator<Item = CmsdkUart> {
    WAKE_UARTS
        .iter()
        .filter_map(|a| match a.load(Ordering::Acquire) {
            0 => None,
            // SAFETY: a UART the links registered; only its status registers are touched here
            // (never DATA, which the link's own driver reads).
            base => Some(unsafe { CmsdkUart::alias(base) }),
        })
}

/// Sleeps until a link moves: a byte arrives or one has gone on any UART the links use (or
/// the millisecond tick), instead of spinning. The emulated array runs many cores on few
/// host CPUs; a sleeping core leaves them to the others and to the emulator's I/O. With
/// interrupts masked, a byte that is already waiting skips the sleep, and one that arrives
/// between the check and the `wfi` leaves its interrupt pending, which ends the `wfi` at
/// once: no wake-up is lost.
pub fn wait_for_link_event() {
    cortex_m::interrupt::free(|_| {
        if !wake_uarts().any(|u| u.rx_waiting()) {
            cortex_m::asm::wfi();
        }
    });
}

/// What a UART interrupt does: clears the links' UARTs' interrupt status (its only purpose
/// was to end a `wfi`; the bytes stay for the links to read).
pub fn on_uart_interrupt() {
    for u in wake_uarts() {
        u.clear_interrupts();
    }
}

/// The links (about 170 KB of frame buffers, in a static), taken once: the global port and
/// every face of `drivers` (from [`face_drivers`]) on its driver; the other faces say
/// `NoLink`.
pub fn take(drivers: [Option<usize>; 6]) -> Option<&'static mut BoardLinks> {
    if TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    #[cfg(not(feature = "qemu"))]
    // SAFETY: before any reference to LINKS exists (TAKEN), once.
    unsafe {
        init_link_section()
    };
    // SAFETY: TAKEN makes this the only reference to LINKS, created once; the global port
    // is not yet driven by anyone else (the fault reporter only takes it after the links
    // are dropped from use, at the end of a run).
    let links: &'static mut BoardLinks = unsafe { &mut *core::ptr::addr_of_mut!(LINKS) };
    let global = unsafe { global_stream() };
    if let LinkStream::Cmsdk(_) = global {
        register(pe_firmware::profile::mps2_uarts::GLOBAL_UART);
    }
    links.global_port().replace_stream(global);
    for face in Face::ALL {
        let stream = drivers[face.index()].and_then(face_stream);
        links.relink(face, stream);
    }
    Some(links)
}
