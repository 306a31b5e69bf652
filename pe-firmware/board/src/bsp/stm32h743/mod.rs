//! The prototype board (profile `stm32h743-uart`): an STM32H743 whose six faces and global
//! port are USART/UARTs moved by DMA, its caches on, and a cycle counter for time.
//!
//! What is hardware-specific stays here and small, one room per concern:
//! - [`chip`]: the silicon revision and the clocks it allows (480 MHz on revision V,
//!   400 MHz on Y), the link rates;
//! - [`memory`]: the caches and the MPU region that keeps DMA and RTT buffers out of them;
//! - [`ports`]: the seven ports' DMA streams, and [`DmaSerial`], a port as an `embedded-io`
//!   byte stream (`Read`, `ReadReady`, `Write`, `WriteReady`), which is all `link_proto`'s
//!   `StreamLinks` asks of a link: the same traits, framing and runtime as the QEMU build's
//!   CMSDK UARTs, which CI runs;
//! - [`cycle_clock`]: [`CycleClock`], the runtime's `Environment`.
//!
//! [`early`] runs first in `main` (revision, errata fix, caches); [`start`] once the image
//! is loaded (clocks, pins, ports).
//!
//! ## Pin map: NUCLEO-H743ZI2 (MB1364)
//!
//! | port | carries | peripheral | TX, RX pins (alternate function) | DMA RX, TX streams |
//! |---|---|---|---|---|
//! | 0 | face +x | USART1 | PB6, PB7 (AF7) | DMA1 0, 1 |
//! | 1 | face -x | USART2 | PD5, PD6 (AF7) | DMA1 2, 3 |
//! | 2 | face +y | UART4 | PD1, PD0 (AF8) | DMA1 4, 5 |
//! | 3 | face -y | UART5 | PC12, PD2 (AF8) | DMA1 6, 7 |
//! | 4 | face +z | USART6 | PC6, PC7 (AF7) | DMA2 0, 1 |
//! | 5 | face -z | UART7 | PE8, PE7 (AF7) | DMA2 2, 3 |
//! | 6 | global port | USART3 | PD8, PD9 (AF7) | DMA2 4, 5 |
//!
//! The pins' alternate functions are checked at compile time by stm32h7xx-hal's pin traits
//! (its table of DS12110's "Alternate functions"). On the NUCLEO-H743ZI2:
//! - USART3 on PD8/PD9 is the on-board STLINK-V3E's virtual COM port (UM2407, "USART
//!   virtual communication"): a host reads the global port over the probe's USB, at the
//!   global port's own rate ([`chip::GLOBAL_BAUD`]), not the faces'.
//! - The earlier map used PB14/PB15 for USART1 and PB13/PB12 for UART5: PB14 drives the red
//!   user LED LD3 (UM2407, "LEDs"; ST's demo firmware blinks it as "led3 red") and PB13 is
//!   the Ethernet PHY's RMII_TXD1 (stm32h7xx-hal's `ethernet-nucleo-h743zi2` example). USART1
//!   moved to PB6/PB7 (AF7) and UART5 to PC12/PD2 (AF8, the Zio connector's SDMMC pins).
//! - To check on the bench, against UM2407's solder-bridge tables and the MB1364
//!   schematic: that PB6, PB7, PC12, PD2, PD0, PD1, PD5, PD6, PE7 and PE8 reach the
//!   connectors with nothing else on them (an Ethernet, USB or SD solder bridge to open is
//!   to be listed in docs/boards.md).
//!
//! A cable crosses TX and RX between neighbours and shares ground. Not run here: the
//! prototype has not been built; docs/boards.md ("The prototype board") lists what needs
//! checking on it.

pub mod chip;
pub mod cycle_clock;
pub mod memory;
pub mod ports;

pub use cycle_clock::CycleClock;
pub use ports::{DmaError, DmaSerial, GLOBAL_PORT, PORTS, RX_RING, TX_BUF};

use chip::Revision;

/// Why the board could not start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartError {
    /// The device peripherals were taken before.
    Taken,
    /// A port's USART refused its configuration.
    Port(usize),
    /// PLL2's Q output (the U(S)ARTs' kernel clock) is not at [`chip::USART_KERNEL_HZ`].
    KernelClock { hz: u32 },
    /// The DMA and RTT buffers cannot be one MPU region.
    Mpu(memory::MpuError),
    /// The cycle counter did not move once enabled: the board would have no time.
    CycleCounter,
    /// DBGMCU_IDCODE names another device than the STM32H742/743/750/753.
    Device { dev_id: u16 },
}

impl core::fmt::Display for StartError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            StartError::Taken => write!(f, "STM32H743 peripherals taken twice"),
            StartError::Port(p) => write!(f, "port {p}: its USART refused its configuration"),
            StartError::KernelClock { hz } => write!(
                f,
                "the USARTs' kernel clock (PLL2 Q) is {hz} Hz, not {} Hz: the links would run at another rate",
                chip::USART_KERNEL_HZ
            ),
            StartError::Mpu(e) => write!(f, "{e}"),
            StartError::CycleCounter => write!(
                f,
                "the cycle counter (DWT CYCCNT) does not count: no time for the link timeouts"
            ),
            StartError::Device { dev_id } => write!(
                f,
                "DBGMCU_IDCODE names device {dev_id:#05x}, not the STM32H743 (0x450): wrong board support"
            ),
        }
    }
}

/// What [`early`] found.
#[derive(Clone, Copy, Debug)]
pub struct Chip {
    pub revision: Revision,
    pub clocks: chip::ClockPlan,
}

/// First thing at reset, before the storage fills: reads the revision (refusing another
/// device), applies revision Y's AXI SRAM fix, and turns the caches on with the uncached
/// region in place.
#[cfg(target_arch = "arm")]
pub fn early(cp: &mut cortex_m::Peripherals) -> Result<Chip, StartError> {
    let (revision, dev_id) = chip::read_idcode();
    // DEV_ID 0 with REV_ID 0: an IDCODE the CPU could not read; the cautious plan covers it.
    if dev_id != chip::DEV_ID_H743 && (dev_id, revision.0) != (0, 0) {
        return Err(StartError::Device { dev_id });
    }
    chip::fix_axi_sram_reads(revision);
    let (start, end) = memory::uncached_area();
    let region = memory::uncached_region(0, start, end).map_err(StartError::Mpu)?;
    memory::caches_on(cp, region);
    Ok(Chip {
        revision,
        clocks: chip::ClockPlan::for_revision(revision),
    })
}

/// Clocks (the revision's plan; the U(S)ARTs on PLL2 Q at 120 MHz), the seven ports and
/// their DMA streams, and the cycle counter. Once, after [`early`].
pub fn start(cp: &mut cortex_m::Peripherals, chip: &Chip) -> Result<CycleClock, StartError> {
    use stm32h7xx_hal::pac;
    use stm32h7xx_hal::prelude::*;
    use stm32h7xx_hal::rcc::rec::{Usart16ClkSel, Usart234578ClkSel};
    use stm32h7xx_hal::rcc::ResetEnable;

    let dp = pac::Peripherals::take().ok_or(StartError::Taken)?;
    let plan = chip.clocks;
    let pwr = dp.PWR.constrain();
    let pwr = if plan.vos0 { pwr.vos0(&dp.SYSCFG) } else { pwr };
    let ccdr = dp
        .RCC
        .constrain()
        .sys_ck(plan.core_hz.Hz())
        .hclk(plan.hclk_hz.Hz())
        .pclk1(plan.pclk_hz.Hz())
        .pclk2(plan.pclk_hz.Hz())
        .pll2_p_ck(chip::USART_KERNEL_HZ.Hz())
        .pll2_q_ck(chip::USART_KERNEL_HZ.Hz())
        .freeze(pwr.freeze(), &dp.SYSCFG);
    let q = ccdr.clocks.pll2_q_ck().map(|f| f.raw()).unwrap_or(0);
    if q != chip::USART_KERNEL_HZ {
        return Err(StartError::KernelClock { hz: q });
    }
    let mut peripheral = ccdr.peripheral;
    peripheral.kernel_usart16_clk_mux(Usart16ClkSel::Pll2Q);
    peripheral.kernel_usart234578_clk_mux(Usart234578ClkSel::Pll2Q);
    // SRAM1-3 (the DMA buffers) allocated to the core's domain (RM0433, RCC_AHB2ENR
    // SRAMxEN: keeps D2 running while the core runs).
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
    let b = dp.GPIOB.split(peripheral.GPIOB);
    let c = dp.GPIOC.split(peripheral.GPIOC);
    let d = dp.GPIOD.split(peripheral.GPIOD);
    let e = dp.GPIOE.split(peripheral.GPIOE);
    let clocks = &ccdr.clocks;
    // Each port's USART, 8N1 (the HAL enables its clock, checks the pins' alternate
    // functions at compile time, and sets BRR from the kernel clock chosen above).
    macro_rules! serial {
        ($port:expr, $usart:ident, $baud:expr, $tx:expr, $rx:expr) => {
            dp.$usart
                .serial(($tx, $rx), $baud.bps(), peripheral.$usart, clocks)
                .map_err(|_| StartError::Port($port))?
        };
    }
    let link = chip::LINK_BAUD;
    let pb6 = b.pb6.into_alternate::<7>();
    serial!(0, USART1, link, pb6, b.pb7.into_alternate::<7>());
    let pd5 = d.pd5.into_alternate::<7>();
    serial!(1, USART2, link, pd5, d.pd6.into_alternate::<7>());
    let pd1 = d.pd1.into_alternate::<8>();
    serial!(2, UART4, link, pd1, d.pd0.into_alternate::<8>());
    let pc12 = c.pc12.into_alternate::<8>();
    serial!(3, UART5, link, pc12, d.pd2.into_alternate::<8>());
    let pc6 = c.pc6.into_alternate::<7>();
    serial!(4, USART6, link, pc6, c.pc7.into_alternate::<7>());
    let pe8 = e.pe8.into_alternate::<7>();
    serial!(5, UART7, link, pe8, e.pe7.into_alternate::<7>());
    let pd8 = d.pd8.into_alternate::<7>();
    serial!(
        GLOBAL_PORT,
        USART3,
        chip::GLOBAL_BAUD,
        pd8,
        d.pd9.into_alternate::<7>()
    );
    peripheral.DMA1.enable();
    peripheral.DMA2.enable();
    for p in 0..PORTS {
        // SAFETY: once, each port's USART configured above, DMA1/DMA2 clocked.
        unsafe { ports::start_port(p) };
    }
    ports::mark_started();
    CycleClock::start(cp, clocks.c_ck().raw()).map_err(|_| StartError::CycleCounter)
}
