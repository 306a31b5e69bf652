//! Caches on, and one memory region they leave alone: what another bus master reads or
//! writes behind the core (the ports' DMA buffers, and the RTT control block and buffer that
//! the debug probe reads and writes), which `memory.x` gathers at the start of SRAM1
//! (`__suncached` .. `__euncached`).
//!
//! With the data cache on, the default memory map makes SRAM1-3 Normal write-back
//! cacheable (ARMv7-M Architecture Reference Manual, DDI 0403E, B3.1 "The system address
//! map": 0x2000_0000-0x3FFF_FFFF "SRAM", WBWA): the DMA's bytes would hide behind stale
//! lines and the core's writes would stay in the cache. One MPU region marks the area Normal,
//! non-cacheable (ST AN4839, "Level 1 cache on STM32F7 Series and STM32H7 Series", and
//! AN4838, "Managing memory protection unit in STM32 MCUs", recommend exactly this for DMA
//! buffers); every other address keeps the default map (PRIVDEFENA).

/// An MPU region's two words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MpuRegion {
    /// MPU_RBAR: base address, VALID, REGION.
    pub rbar: u32,
    /// MPU_RASR: attributes, size, enable.
    pub rasr: u32,
}

/// Why the uncached area cannot be one region.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MpuError {
    /// A region of `size` bytes (a power of two) must start at a multiple of `size`.
    Misaligned { start: u32, size: u32 },
}

impl core::fmt::Display for MpuError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            MpuError::Misaligned { start, size } => write!(
                f,
                "uncached area at {start:#010x} needs an MPU region of {size} bytes, which must start at a multiple of its size (memory.x: put .uncached first in SRAM_D2)"
            ),
        }
    }
}

// DDI 0403E, B3.5.8 "MPU Region Base Address Register, MPU_RBAR": ADDR [31:5], VALID [4]
// (the region number comes from REGION [3:0]).
const RBAR_VALID: u32 = 1 << 4;
// B3.5.9 "MPU Region Attribute and Size Register, MPU_RASR": XN [28], AP [26:24], TEX
// [21:19], S [18], C [17], B [16], SRD [15:8], SIZE [5:1] (2^(SIZE+1) bytes), ENABLE [0].
const RASR_XN: u32 = 1 << 28;
/// AP 0b011: read/write at every privilege (Table B3-15 "Access permissions field encoding").
const RASR_AP_FULL: u32 = 0b011 << 24;
/// TEX 0b001, C 0, B 0: Normal memory, non-cacheable (Table B3-13 "TEX, C, B, and S
/// encoding").
const RASR_NORMAL_UNCACHED: u32 = 0b001 << 19;
/// Shareable: another master uses it.
const RASR_S: u32 = 1 << 18;
const RASR_ENABLE: u32 = 1;
/// The smallest region (B3.5.9: SIZE >= 4, 32 bytes).
const REGION_MIN: u32 = 32;

/// MPU_CTRL (B3.5.6): ENABLE [0], PRIVDEFENA [2] (the default map for every address no
/// region covers, in privileged code: the firmware's only mode).
pub const MPU_CTRL_ENABLE_PRIVDEFENA: u32 = 0b101;

/// The region that makes `[start, end)` Normal, non-cacheable, shareable, never executed:
/// the smallest power of two (at least 32 bytes) that holds it, from `start`, which must be
/// aligned to that size.
pub fn uncached_region(number: u8, start: u32, end: u32) -> Result<MpuRegion, MpuError> {
    let len = end.saturating_sub(start).max(REGION_MIN);
    let size = len.checked_next_power_of_two().unwrap_or(1 << 31);
    if !start.is_multiple_of(size) {
        return Err(MpuError::Misaligned { start, size });
    }
    let size_field = size.trailing_zeros() - 1;
    Ok(MpuRegion {
        rbar: start | RBAR_VALID | (number as u32 & 0xF),
        rasr: RASR_XN
            | RASR_AP_FULL
            | RASR_NORMAL_UNCACHED
            | RASR_S
            | (size_field << 1)
            | RASR_ENABLE,
    })
}

/// The linker's bounds of the uncached area (`memory.x`).
#[cfg(target_arch = "arm")]
pub fn uncached_area() -> (u32, u32) {
    extern "C" {
        static __suncached: u8;
        static __euncached: u8;
    }
    // Only the symbols' addresses are taken.
    (
        core::ptr::addr_of!(__suncached) as u32,
        core::ptr::addr_of!(__euncached) as u32,
    )
}

/// Sets MPU region 0 to `region`, turns the MPU on (default map elsewhere), then the
/// instruction and data caches. Once, at start, before any DMA stream runs.
#[cfg(target_arch = "arm")]
pub fn caches_on(cp: &mut cortex_m::Peripherals, region: MpuRegion) {
    // DDI 0403E B3.5.6-B3.5.9: MPU_CTRL 0xE000_ED94, MPU_RBAR 0xE000_ED9C, MPU_RASR
    // 0xE000_EDA0; the MPU is off while a region changes, and a DSB and ISB make the new map
    // hold for the next access and instruction (ARM's "MPU configuration" sequence, as in
    // CMSIS's ARM_MPU_Enable).
    cortex_m::asm::dmb();
    // SAFETY: the MPU's architected registers; nothing runs from or into the area while
    // the map changes (no DMA stream is on yet).
    unsafe {
        cp.MPU.ctrl.write(0);
        cp.MPU.rbar.write(region.rbar);
        cp.MPU.rasr.write(region.rasr);
        cp.MPU.ctrl.write(MPU_CTRL_ENABLE_PRIVDEFENA);
    }
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
    // Cortex-M7: the caches are invalidated, then enabled (cortex-m's `enable_icache` and
    // `enable_dcache` do both, with the barriers; Cortex-M7 TRM DDI 0489, "Enabling the L1
    // caches").
    cp.SCB.enable_icache();
    cp.SCB.enable_dcache(&mut cp.CPUID);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dma_area_is_normal_uncached_in_one_aligned_region() {
        // 7 ports x (4096 + 1024) bytes of DMA buffers and ~1.1 KiB of RTT from SRAM1's
        // start: 36 KiB, so a 64 KiB region at 0x3000_0000.
        let r = uncached_region(0, 0x3000_0000, 0x3000_0000 + 36 * 1024).expect("aligned");
        // RBAR: the base, VALID (bit 4), region 0.
        assert_eq!(r.rbar, 0x3000_0010);
        // RASR by field, from DDI 0403E's layout written out here: SIZE = log2(64 Ki) - 1 = 15.
        assert_eq!((r.rasr >> 1) & 0x1F, 15, "SIZE");
        assert_eq!(r.rasr & 1, 1, "ENABLE");
        assert_eq!((r.rasr >> 19) & 0b111, 0b001, "TEX: Normal");
        assert_eq!((r.rasr >> 16) & 0b11, 0, "C and B clear: non-cacheable");
        assert_eq!((r.rasr >> 24) & 0b111, 0b011, "AP: full access");
        assert_eq!((r.rasr >> 28) & 1, 1, "XN: never executed");
        assert_eq!((r.rasr >> 8) & 0xFF, 0, "no subregion disabled");
        assert_eq!(
            (r.rasr >> 18) & 1,
            1,
            "S: shared with the DMA and the probe"
        );
        // The whole word, summed by hand from those fields: 0x1000_0000 (XN) + 0x0300_0000
        // (AP) + 0x0008_0000 (TEX) + 0x0004_0000 (S) + 0x1E (SIZE) + 1.
        assert_eq!(r.rasr, 0x130C_001F);
    }

    #[test]
    fn sizes_round_up_to_a_power_of_two_and_misalignment_is_refused() {
        // Exactly 32 KiB: SIZE 14; one byte more: 64 KiB.
        let exact = uncached_region(1, 0x3000_0000, 0x3000_8000).expect("aligned");
        assert_eq!((exact.rasr >> 1) & 0x1F, 14);
        assert_eq!(exact.rbar & 0xF, 1, "region number");
        let more = uncached_region(1, 0x3000_0000, 0x3000_8001).expect("aligned");
        assert_eq!((more.rasr >> 1) & 0x1F, 15);
        // An empty area still gets the smallest region (32 bytes, SIZE 4).
        let empty = uncached_region(0, 0x3000_0000, 0x3000_0000).expect("aligned");
        assert_eq!((empty.rasr >> 1) & 0x1F, 4);
        // 36 KiB starting 4 KiB into SRAM1 cannot be one 64 KiB region.
        assert_eq!(
            uncached_region(0, 0x3000_1000, 0x3000_A000),
            Err(MpuError::Misaligned {
                start: 0x3000_1000,
                size: 64 * 1024
            })
        );
    }
}
