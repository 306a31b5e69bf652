//! Time for the runtime's link timeouts: SysTick at 1 kHz from the core clock, counted in an
//! interrupt. Idle sleeps until a link moves (QEMU) or spins (the links are polled by the
//! runtime).

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::exception;
use link_proto::Clock;
use pe_firmware::runtime::Environment;

static MILLIS: AtomicU32 = AtomicU32::new(0);

#[exception]
fn SysTick() {
    MILLIS.fetch_add(1, Ordering::Relaxed);
}

/// The board's [`Environment`]: a millisecond clock extended to 64 bits.
pub struct BoardClock {
    last: u32,
    high: u64,
}

impl BoardClock {
    /// Starts SysTick: `clock_hz` is the core clock.
    pub fn start(cp: &mut cortex_m::Peripherals, clock_hz: u64) -> Self {
        let syst: &mut SYST = &mut cp.SYST;
        let reload = (clock_hz / 1000).clamp(2, 1 << 24) as u32 - 1;
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(reload);
        syst.clear_current();
        syst.enable_interrupt();
        syst.enable_counter();
        BoardClock { last: 0, high: 0 }
    }
}

impl Clock for BoardClock {
    fn now_ns(&mut self) -> u64 {
        let ms = MILLIS.load(Ordering::Relaxed);
        if ms < self.last {
            self.high += 1 << 32;
        }
        self.last = ms;
        (self.high + ms as u64) * 1_000_000
    }
}

impl Environment for BoardClock {
    /// QEMU: sleeps until a link moves ([`crate::links::wait_for_link_event`]); the board
    /// (no link drivers yet): spins.
    fn idle(&mut self) {
        if cfg!(feature = "qemu") {
            crate::links::wait_for_link_event();
        } else {
            core::hint::spin_loop();
        }
    }
}
