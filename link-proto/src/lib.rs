//! Link frames (point-to-point, address-free) and global-network packets.
#![no_std]
