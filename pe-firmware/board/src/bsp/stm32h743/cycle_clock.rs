//! Time from the core's cycle counter (DWT CYCCNT), extended to 64 bits.

use cortex_m::peripheral::DWT;

/// The runtime's clock and `Environment`: exact to a cycle, as long as it is read at least
/// once per wrap (8.9 s at 480 MHz; the runtime reads it at every wait and its link timeout
/// is shorter).
pub struct CycleClock {
    hz: u64,
    last: u32,
    high: u64,
}

/// The counter did not move after it was enabled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CounterStopped;

impl CycleClock {
    /// Enables and checks the counter; `hz` is the core clock.
    ///
    /// The M7's DWT ignores writes until its lock access register holds the CoreSight key
    /// (DWT_LAR at 0xE000_1FB0, key 0xC5AC_CE55: ARM CoreSight Architecture, "Lock Access
    /// Register"; cortex-m's `DWT::unlock`, "needed on some devices, e.g. the STM32F7").
    /// A debugger unlocks it, so without this a board on the bench would count only with a
    /// probe attached: `now_ns` would stand still and no link timeout would fire. TRCENA
    /// (DEMCR bit 24) powers the DWT (ARMv7-M ARM C1.6.5).
    pub fn start(cp: &mut cortex_m::Peripherals, hz: u32) -> Result<Self, CounterStopped> {
        cp.DCB.enable_trace();
        DWT::unlock();
        cp.DWT.enable_cycle_counter();
        let first = DWT::cycle_count();
        for _ in 0..16 {
            cortex_m::asm::nop();
        }
        let last = DWT::cycle_count();
        if last == first {
            return Err(CounterStopped);
        }
        Ok(CycleClock {
            hz: hz.max(1) as u64,
            last,
            high: 0,
        })
    }
}

impl link_proto::Clock for CycleClock {
    fn now_ns(&mut self) -> u64 {
        let c = DWT::cycle_count();
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
