//! Analyses built on the serial solver: the element-kernel benchmark, the stability
//! checks, the precision/integration trade-off study and the hourglass calibration.

pub mod bench;
pub mod hourglass;
pub mod plan;
pub mod stability;
pub mod tradeoff;
