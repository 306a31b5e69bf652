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
