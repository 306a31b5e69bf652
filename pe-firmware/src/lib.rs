//! Board firmware library: physics, schedule image and runtime. `no_std`, allocation-free.
#![no_std]
