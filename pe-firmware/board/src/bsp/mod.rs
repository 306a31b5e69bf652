//! Board support: what a physical board adds under the runtime's traits (`embedded-io`
//! streams for the links, `Environment` for time). One module per board; the QEMU build
//! needs none (its UARTs are `crate::uart`).

#[cfg(feature = "stm32h743")]
pub mod stm32h743;
