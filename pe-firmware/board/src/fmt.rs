//! Logging macros, crate-private in spirit: `defmt` over RTT on the board (feature `defmt`),
//! semihosting on QEMU (feature `qemu`), nothing otherwise. Messages are short and rare
//! (boot, end of run, faults); the main loop never logs.

#[cfg(feature = "defmt")]
#[macro_export]
macro_rules! log_info {
    ($($arg:tt)*) => { ::defmt::info!($($arg)*) };
}

#[cfg(all(not(feature = "defmt"), feature = "qemu"))]
#[macro_export]
macro_rules! log_info {
    ($($arg:tt)*) => { $crate::report::semihosting_line(format_args!($($arg)*)) };
}

#[cfg(all(not(feature = "defmt"), not(feature = "qemu")))]
#[macro_export]
macro_rules! log_info {
    ($($arg:tt)*) => {{
        let _ = format_args!($($arg)*);
    }};
}

/// Copies the RTT control block and buffer (`memory.x`'s `.rtt` section, in the uncached
/// area of SRAM1 where the debug probe and the core see the same bytes with the data cache
/// on) from their load image in flash, as the start-up code does for `.data`. First thing in
/// `main`, before the first log; empty without `defmt`.
#[cfg(all(not(feature = "qemu"), target_arch = "arm"))]
pub fn init_rtt_section() {
    extern "C" {
        static mut __srtt: u32;
        static mut __ertt: u32;
        static __sirtt: u32;
    }
    // SAFETY: the linker's symbols bound the section and its load image; nothing has used
    // the section yet (no log before this).
    unsafe {
        crate::section::copy_from_flash(
            core::ptr::addr_of_mut!(__srtt),
            core::ptr::addr_of_mut!(__ertt),
            core::ptr::addr_of!(__sirtt),
        )
    }
}
