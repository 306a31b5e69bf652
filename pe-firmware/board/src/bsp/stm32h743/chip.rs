//! Which STM32H743 this is, and the clocks it may run: the silicon revision from
//! DBGMCU_IDCODE decides the core clock; the links' kernel clock is the same on every
//! revision, so boards of two revisions in one array still agree on the link rate.
//!
//! Sources (ST): RM0433 rev 8, the STM32H742/743/750/753 reference manual; DS12110, the
//! STM32H742xI/G and STM32H743xI/G datasheet; ES0392, their errata sheet; ST's CMSIS
//! `system_stm32h7xx.c` (`SystemInit`).

use pe_firmware::profile::STM32H743_UART;

/// DBGMCU_IDCODE: RM0433, "DBGMCU identity code register (DBGMCU_IDCODE)", address
/// 0x5C00_1000: REV_ID in bits 31:16, DEV_ID in bits 11:0 (0x450 for the STM32H742/743/750/
/// 753). The CPU reads it without a debugger: ST's `SystemInit` does at every reset.
pub const DBGMCU_IDCODE: usize = 0x5C00_1000;

/// AXI_TARG7_FN_MOD: the AXI interconnect's issuing-capability register for target 7, the
/// AXI SRAM (RM0433, "AXI interconnect matrix (AXIM)": AXI_TARGx_FN_MOD at offset
/// 0x1108 + 0x1000 * (x - 1) from 0x5100_0000). Bit 0, READ_ISS_OVERRIDE, limits the
/// target's read issuing capability to one.
pub const AXI_TARG7_FN_MOD: usize = 0x5100_8108;

/// The device identifier of the STM32H742/743/750/753 in DBGMCU_IDCODE's DEV_ID.
pub const DEV_ID_H743: u16 = 0x450;

/// The silicon revision (DBGMCU_IDCODE's REV_ID).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Revision(pub u16);

impl Revision {
    /// Revision Y (RM0433, DBGMCU_IDCODE: REV_ID 0x1003).
    pub const Y: Revision = Revision(0x1003);
    /// Revision V (REV_ID 0x2003).
    pub const V: Revision = Revision(0x2003);

    /// The revision and device identifier in an IDCODE word.
    pub fn from_idcode(idcode: u32) -> (Revision, u16) {
        (Revision((idcode >> 16) as u16), (idcode & 0xFFF) as u16)
    }

    /// Revision Y or earlier: what ST's `SystemInit` tests (`REV_ID < 0x2000`). An IDCODE
    /// that reads 0 counts as such (the cautious side: the lower clock, the errata fix).
    pub fn is_y_or_earlier(self) -> bool {
        self.0 < 0x2000
    }

    /// Its name for logs: "Y", "V", or what another REV_ID is treated as.
    pub fn name(self) -> &'static str {
        match self {
            Revision::Y => "Y",
            Revision::V => "V",
            r if r.is_y_or_earlier() => "unknown, clocked as Y",
            _ => "unknown, clocked as V",
        }
    }
}

/// The clock tree a revision runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClockPlan {
    /// Core clock (sys_ck = c_ck, D1CPRE 1), Hz.
    pub core_hz: u32,
    /// AHB (hclk), Hz.
    pub hclk_hz: u32,
    /// APB1..4 (pclk), Hz.
    pub pclk_hz: u32,
    /// Voltage scale 0 (only revision V has it).
    pub vos0: bool,
}

impl ClockPlan {
    /// The fastest clocks the revision allows. DS12110, "General operating conditions":
    /// revision V reaches 480 MHz at voltage scale 0 (hclk 240, pclk 120 MHz); revision Y has
    /// no VOS0 and tops out at 400 MHz at scale 1 (hclk 200, pclk 100 MHz). stm32h7xx-hal
    /// 0.16 checks only revision V's limits (`rcc/mod.rs`: "We do not assert checks for
    /// earlier revisions"), so the choice is made here.
    pub fn for_revision(rev: Revision) -> ClockPlan {
        if rev.is_y_or_earlier() {
            ClockPlan {
                core_hz: 400_000_000,
                hclk_hz: 200_000_000,
                pclk_hz: 100_000_000,
                vos0: false,
            }
        } else {
            ClockPlan {
                core_hz: 480_000_000,
                hclk_hz: 240_000_000,
                pclk_hz: 120_000_000,
                vos0: true,
            }
        }
    }
}

/// The U(S)ARTs' kernel clock (Hz), on every revision: PLL2's Q output, selected for USART1/6
/// (RCC_D2CCIP2R.USART16SEL) and USART2/3/4/5/7/8 (USART234578SEL) (RM0433, "RCC domain 2
/// kernel clock configuration register"). PLL2 from HSI (64 MHz) / 32 = 2 MHz, VCO 360 MHz
/// in the medium range (150-420 MHz, on every revision), P and Q divided by 3.
/// stm32h7xx-hal turns PLL2 on only when its P output is asked for (`rcc/mod.rs`:
/// `if pll2_p_ck.is_some()`), so P is asked for too (120 MHz, unused).
pub const USART_KERNEL_HZ: u32 = 120_000_000;

/// Each face link's rate (baud): ten bits a byte (start, 8 data, stop) at the profile's
/// `link_bytes_per_s` (the compile report's figure; one home).
pub const LINK_BAUD: u32 = (STM32H743_UART.link_bytes_per_s * 10) as u32;

/// The global port's rate (baud), its own: on the NUCLEO-H743ZI2 USART3 is the on-board
/// probe's virtual COM port, whose USB bridge cannot take the links' rate (an ST-LINK/V2-1,
/// on the older NUCLEO-H743ZI, tops out near 2.25 Mbaud). From the profile's
/// `global_bytes_per_s` (one home).
pub const GLOBAL_BAUD: u32 = (STM32H743_UART.global_bytes_per_s * 10) as u32;

// The HAL sets BRR = kernel clock / baud, truncated, at 16x oversampling (stm32h7xx-hal
// 0.16, `serial.rs`, `configure`): exact divisors keep both ends of a cable on one rate, and
// BRR >= 16 is what 16x oversampling needs (RM0433, "USART baud rate generation").
const _: () =
    assert!(USART_KERNEL_HZ.is_multiple_of(LINK_BAUD) && USART_KERNEL_HZ / LINK_BAUD >= 16);
const _: () =
    assert!(USART_KERNEL_HZ.is_multiple_of(GLOBAL_BAUD) && USART_KERNEL_HZ / GLOBAL_BAUD >= 16);

/// Reads the revision and device identifier.
#[cfg(target_arch = "arm")]
pub fn read_idcode() -> (Revision, u16) {
    // SAFETY: a read-only identity register at its RM0433 address; reading has no effect.
    let idcode = unsafe { core::ptr::read_volatile(DBGMCU_IDCODE as *const u32) };
    Revision::from_idcode(idcode)
}

/// The fix for revision Y's AXI SRAM read corruption (ES0392, "Reading from AXI SRAM may
/// lead to data read corruption"; workaround: set READ_ISS_OVERRIDE in AXI_TARG7_FN_MOD, as
/// ST's `SystemInit` does when REV_ID < 0x2000). The runtime's storage is in the AXI SRAM.
#[cfg(target_arch = "arm")]
pub fn fix_axi_sram_reads(rev: Revision) {
    if rev.is_y_or_earlier() {
        // SAFETY: the AXI interconnect register at its RM0433 address; the value is ST's.
        unsafe { core::ptr::write_volatile(AXI_TARG7_FN_MOD as *mut u32, 1) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn revisions_from_idcode_words_as_rm0433_lists_them() {
        // RM0433's DBGMCU_IDCODE: REV_ID 0x1003 = Y, 0x2003 = V, DEV_ID 0x450.
        assert_eq!(Revision::from_idcode(0x1003_6450), (Revision::Y, 0x450));
        assert_eq!(
            Revision::from_idcode(0x2003_6450),
            (Revision::V, DEV_ID_H743)
        );
        assert!(Revision::Y.is_y_or_earlier());
        assert!(!Revision::V.is_y_or_earlier());
        // An IDCODE read as 0 takes the cautious side.
        assert!(Revision::from_idcode(0).0.is_y_or_earlier());
        assert_eq!(Revision::from_idcode(0).0.name(), "unknown, clocked as Y");
    }

    #[test]
    fn revision_y_is_never_clocked_past_400_mhz() {
        // DS12110: revision Y 400 MHz (VOS1, hclk 200, pclk 100); V 480 MHz (VOS0).
        let y = ClockPlan::for_revision(Revision::Y);
        assert_eq!(
            (y.core_hz, y.hclk_hz, y.pclk_hz, y.vos0),
            (400_000_000, 200_000_000, 100_000_000, false)
        );
        let v = ClockPlan::for_revision(Revision::V);
        assert_eq!(
            (v.core_hz, v.hclk_hz, v.pclk_hz, v.vos0),
            (480_000_000, 240_000_000, 120_000_000, true)
        );
        assert_eq!(ClockPlan::for_revision(Revision(0)), y);
    }

    #[test]
    fn link_rates_are_exact_divisors_of_the_kernel_clock() {
        // 7.5 Mbaud on the faces (BRR 16), the global port well under the probe bridge's
        // 2.25 Mbaud; both exact at 120 MHz whatever the core runs.
        assert_eq!(LINK_BAUD, 7_500_000);
        assert_eq!(USART_KERNEL_HZ / LINK_BAUD, 16);
        assert_eq!(
            GLOBAL_BAUD, 2_000_000,
            "under the ST-LINK/V2-1 bridge's 2.25 Mbaud"
        );
        assert_eq!(USART_KERNEL_HZ % GLOBAL_BAUD, 0);
    }
}
