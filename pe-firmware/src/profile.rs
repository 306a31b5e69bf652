//! Board profiles: the figures `memory.x`, the schedule compiler's fit check and the
//! capacity report share.

/// What the compiler needs to know about a board.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoardProfile {
    pub name: &'static str,
    /// Core clock (Hz).
    pub clock_hz: u64,
    /// RAM available to the firmware (bytes), as in `memory.x`.
    pub ram_bytes: u64,
    /// RAM kept for the stack, link buffers and firmware statics (bytes).
    pub ram_reserved_bytes: u64,
    /// Flash (bytes), as in `memory.x`.
    pub flash_bytes: u64,
    /// Flash region that holds the schedule image (bytes).
    pub image_flash_bytes: u64,
    /// Point-to-point link bandwidth, each direction (bytes/s).
    pub link_bytes_per_s: u64,
    /// One-way latency of a link frame (ns).
    pub link_latency_ns: u64,
    /// Global network bandwidth into one board (bytes/s).
    pub global_bytes_per_s: u64,
    /// Address of the schedule image region (`ORIGIN(IMAGE)` in the memory map), where
    /// `pe image` says to flash a board's schedule blob.
    pub image_origin: u64,
    /// probe-rs `--chip` of the board's MCU (empty for an emulation profile).
    pub probe_chip: &'static str,
}

/// The custom PE board: STM32H7-class Cortex-M7 at 480 MHz with a double-precision FPU,
/// 1 MiB RAM (TCM plus AXI SRAM), 2 MiB flash (the upper 1 MiB holds the schedule image),
/// six point-to-point links (LVDS, 200 Mbit/s each way) and a global network port.
pub const PE_BOARD: BoardProfile = BoardProfile {
    name: "pe-board",
    clock_hz: 480_000_000,
    ram_bytes: 1024 * 1024,
    ram_reserved_bytes: 128 * 1024,
    flash_bytes: 2 * 1024 * 1024,
    image_flash_bytes: 1024 * 1024,
    link_bytes_per_s: 25_000_000,
    link_latency_ns: 2_000,
    global_bytes_per_s: 12_500_000,
    image_origin: 0x0810_0000,
    probe_chip: "STM32H743ZITx",
};

/// QEMU's `mps2-an500` (Cortex-M7, FLASH at 0x0 and RAM at 0x20000000, 4 MiB each), the
/// emulation profile used in CI. The clock is nominal (QEMU does not model time).
pub const QEMU_MPS2_AN500: BoardProfile = BoardProfile {
    name: "qemu-mps2-an500",
    clock_hz: 25_000_000,
    ram_bytes: 4 * 1024 * 1024,
    ram_reserved_bytes: 256 * 1024,
    flash_bytes: 4 * 1024 * 1024,
    image_flash_bytes: 2 * 1024 * 1024,
    link_bytes_per_s: 25_000_000,
    link_latency_ns: 2_000,
    global_bytes_per_s: 12_500_000,
    image_origin: 0x0020_0000,
    probe_chip: "",
};

pub const PROFILES: [BoardProfile; 2] = [PE_BOARD, QEMU_MPS2_AN500];

/// Looks a profile up by name.
pub fn profile(name: &str) -> Option<BoardProfile> {
    PROFILES.iter().copied().find(|p| p.name == name)
}
