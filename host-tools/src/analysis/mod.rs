//! Analyses built on the serial solver: the element-kernel benchmark, the stability
//! checks and the precision/integration trade-off study.

pub mod bench;
pub mod stability;
pub mod tradeoff;
