//! Board profiles: the figures `memory.x`, the firmware's storage, the schedule compiler's
//! fit check, board-sim's board-sized storage and the capacity report share. The capacity
//! table is here and in [`crate::runtime::Capacities::for_board`], nowhere else.

/// What the compiler needs to know about a board.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoardProfile {
    pub name: &'static str,
    /// Core clock (Hz).
    pub clock_hz: u64,
    /// RAM available to the firmware (bytes), as in `memory.x`.
    pub ram_bytes: u64,
    /// RAM kept for the stack and the runtime itself (bytes); the link buffers and the
    /// storage are counted by [`crate::runtime::Capacities::for_board`].
    pub ram_reserved_bytes: u64,
    /// A RAM region of its own for the link buffers (bytes; `SRAM_D2` in `memory.x`), or 0
    /// when they share `ram_bytes` with the storage.
    pub link_ram_bytes: u64,
    /// Flash (bytes), as in `memory.x`.
    pub flash_bytes: u64,
    /// Flash region that holds the schedule image (bytes).
    pub image_flash_bytes: u64,
    /// Point-to-point link bandwidth, each direction (bytes/s): payload bits on the wire,
    /// the frame's header and CRC included (the compile report adds them per frame).
    pub link_bytes_per_s: u64,
    /// Fixed cost of one link frame (ns): from the send being started to the receiver
    /// holding the last byte, beyond the bytes' time on the wire.
    pub link_latency_ns: u64,
    /// Global network bandwidth into one board (bytes/s).
    pub global_bytes_per_s: u64,
    /// Face links the firmware has drivers for: a board whose schedule exchanges over more
    /// faces cannot run on this profile (`pe compile` refuses it, naming the board).
    pub face_ports: u8,
    /// Address of the schedule image region (`ORIGIN(IMAGE)` in the memory map), where
    /// `pe image` says to flash a board's schedule blob.
    pub image_origin: u64,
    /// probe-rs `--chip` of the board's MCU (empty for an emulation profile).
    pub probe_chip: &'static str,
    /// Address of the MCU's 96-bit unique device ID (three little-endian words), which
    /// `pe flash` reads through each probe before writing anything, to know the boards by
    /// their chips; 0: none.
    pub unique_id_address: u64,
    /// The board crate's cargo features of this board's support (`pe image` builds the
    /// firmware with them, beside the precision's, the element's and the parts'): its
    /// drivers, clocks and log transport.
    pub board_features: &'static [&'static str],
    /// Contact tables the firmware holds (the same on every board that owns a contact node;
    /// a board that owns none gets none): surface nodes and faces of all declared contact
    /// surfaces.
    pub contact_nodes_max: u32,
    pub contact_faces_max: u32,
    /// The rest of the firmware's capacity table (see
    /// [`crate::runtime::Capacities::for_board`], which adds the elements and nodes):
    /// materials, exchange entries (sends and receives each), path points, loads, contact
    /// candidates found at a check, contact-node displacements sent until the next check.
    /// Nodes a board holds (at most `link_proto::NODES_PER_BOARD_MAX`, which the frames
    /// are sized for); the external-force and graphics tables follow it.
    pub nodes_max: u32,
    /// Parallelepipeds and axis-aligned cuboids a board holds with reduced integration
    /// (none with full integration): tables of their own beside the general elements,
    /// which take the RAM left.
    pub boxes_max: u32,
    pub cuboids_max: u32,
    pub materials_max: u32,
    pub exchange_max: u32,
    pub path_points_max: u32,
    pub loads_max: u32,
    pub contact_candidates_max: u32,
    pub contact_sends_max: u32,
}

/// The custom PE board: STM32H743 (Cortex-M7 at 480 MHz with a double-precision FPU),
/// 2 MiB flash (bank 2, the upper 1 MiB, holds the schedule image), six point-to-point links
/// and a global network port. RAM as `memory.x` lays it out: the runtime's storage in the
/// 512 KiB AXI SRAM, the stack in the 128 KiB DTCM, the link buffers and the links' DMA
/// buffers in SRAM1-3 (288 KiB); the reserve is what else the firmware keeps in the AXI
/// SRAM (logging buffers, drivers). The AXI SRAM holds the fixed tables for 512 nodes
/// (about 360 KiB in f64) and leaves the rest to elements.
///
/// The links of a prototype built from the MCU alone (no LVDS serialiser): one SPI per
/// face, SPI1 to SPI6 (the STM32H743 has six), full duplex (MOSI one way, MISO the other),
/// the lower board of each pair the master; the frames go by DMA. Rate: 25 Mbit/s each
/// way, `3_125_000` bytes/s. Where it comes from (ST: DS12110, the STM32H742xI/G and
/// STM32H743xI/G datasheet, and RM0433, the reference manual):
/// - RM0433, SPI: SCK is the SPI kernel clock divided by a power of two (2 to 256); the
///   kernel clock of SPI1/2/3 (pll1_q, pll2_p, pll3_p, ...) is taken as 200 MHz here, and
///   200 MHz / 8 = 25 MHz.
/// - DS12110, SPI dynamic characteristics: the master-mode and slave-receiver SCK maxima
///   are far above 25 MHz (of the order of 100 MHz; the exact figures, per SPI group and
///   supply, are not checked here: an assumption), but in full duplex the slave must drive
///   MISO, and its data output valid time tv(SO) (tens of ns), plus the cable between two
///   boards both ways, limits a full-duplex link to well under that: 25 MHz is assumed.
///   A simplex link per direction would need twelve SPIs, the MCU has six; the USARTs
///   (about 12.5 Mbit/s at most, with start and stop bits) are slower.
/// - Per frame, besides its header and CRC bytes (counted as bytes): 2 us to start the
///   DMA on both sides, assert NSS, and take the end-of-transfer interrupt (an assumption,
///   about a thousand cycles at 480 MHz).
///
/// Measure these on the prototype and update them here (one home: the compile report and
/// board-sim's link timing model read them).
pub const PE_BOARD: BoardProfile = BoardProfile {
    name: "pe-board",
    clock_hz: 480_000_000,
    ram_bytes: 512 * 1024,
    ram_reserved_bytes: 16 * 1024,
    link_ram_bytes: 288 * 1024,
    flash_bytes: 2 * 1024 * 1024,
    image_flash_bytes: 1024 * 1024,
    link_bytes_per_s: 3_125_000,
    link_latency_ns: 2_000,
    global_bytes_per_s: 12_500_000,
    face_ports: 6,
    image_origin: 0x0810_0000,
    probe_chip: "STM32H743ZITx",
    // RM0433, "Unique device ID register (96 bits)": base address 0x1FF1_E800.
    unique_id_address: 0x1FF1_E800,
    // Logs and fault messages over RTT (probe-rs attach).
    board_features: &["defmt"],
    // Contact tables (the whole scene's, on every board): some 190 bytes per contact node
    // and 76 per face (with the face's bounds for a step). 384 each, twice the built-in
    // medium scene's 178 nodes and 160 faces, leave the elements more of the RAM than 512
    // did before the face bounds.
    contact_nodes_max: 384,
    contact_faces_max: 384,
    nodes_max: 512,
    // The parallelepiped and cuboid records carry the physical hourglass form's stiffnesses
    // (384 and 216 bytes in f64). Voxel meshes are cuboids: 256 hold a 2x2x2 array's share
    // of the seed box (250) and half the nodes' cells; parallelepipeds (sheared grids)
    // 128. That leaves some 250 general elements in f64 (the built-in coarse scene on two
    // boards needs 176 each); real time binds far earlier (docs/boards.md).
    boxes_max: 128,
    cuboids_max: 256,
    materials_max: 8,
    exchange_max: 4096,
    path_points_max: 64,
    loads_max: 256,
    contact_candidates_max: 2048,
    contact_sends_max: 1024,
};

/// The prototype array: STM32H743 boards (NUCLEO-H743ZI2 or any board with the part and the
/// pins of `pe-firmware/board/src/bsp/stm32h743/`) whose six faces and global port are
/// USART/UARTs driven by DMA, one cable (TX, RX, ground) per face. The PE board's memory and
/// tables. Rate: 7.5 Mbaud, the U(S)ARTs' kernel clock (PLL2 Q at 120 MHz on every silicon
/// revision: the core runs 480 MHz on revision V, 400 MHz on Y) divided by 16 (RM0433, USART baud rate generation, 16x oversampling, as
/// stm32h7xx-hal configures it); ten bits a byte (start, 8 data, stop): 750 000 bytes/s
/// each way. Per frame: 5 us to restart the TX DMA stream and let the last byte leave the
/// shift register (an assumption, to be measured). DS12110 gives the USARTs up to
/// 12.5 Mbit/s with 8x oversampling; the PE board's SPI links (about 4x this rate) are the
/// design for real time.
pub const STM32H743_UART: BoardProfile = BoardProfile {
    name: "stm32h743-uart",
    // The prototype's board support (USART faces and global port by DMA, clocks), and RTT
    // logs.
    board_features: &["stm32h743", "defmt"],
    link_bytes_per_s: 750_000,
    link_latency_ns: 5_000,
    // The global port is USART3 on the NUCLEO-H743ZI2's STLINK-V3E virtual COM port: 2 Mbaud
    // (an exact divisor of the 120 MHz kernel clock, under the older ST-LINK/V2-1 bridge's
    // ~2.25 Mbaud), ten bits a byte.
    global_bytes_per_s: 200_000,
    ..PE_BOARD
};

/// QEMU's `mps2-an500` (Cortex-M7, FLASH at 0x0 and RAM at 0x20000000, 4 MiB each), the
/// emulation profile used in CI. The clock and the link figures are nominal (QEMU does not
/// model time). Its five CMSDK UARTs carry the global port and up to four faces
/// ([`mps2_uarts`]).
pub const QEMU_MPS2_AN500: BoardProfile = BoardProfile {
    name: "qemu-mps2-an500",
    clock_hz: 25_000_000,
    ram_bytes: 4 * 1024 * 1024,
    ram_reserved_bytes: 256 * 1024,
    link_ram_bytes: 0,
    flash_bytes: 4 * 1024 * 1024,
    image_flash_bytes: 2 * 1024 * 1024,
    link_bytes_per_s: 25_000_000,
    link_latency_ns: 2_000,
    global_bytes_per_s: 12_500_000,
    face_ports: mps2_uarts::FACE_UARTS.len() as u8,
    image_origin: 0x0020_0000,
    probe_chip: "",
    unique_id_address: 0,
    board_features: &["qemu"],
    // The frames' node limit, and otherwise the PE board's tables (the RAM decides the
    // elements).
    nodes_max: link_proto::NODES_PER_BOARD_MAX as u32,
    // A block of hexahedra has fewer cells than nodes: a table per node each.
    boxes_max: link_proto::NODES_PER_BOARD_MAX as u32,
    cuboids_max: link_proto::NODES_PER_BOARD_MAX as u32,
    ..PE_BOARD
};

/// What the five CMSDK UARTs of QEMU's `mps2-an500` carry, for the firmware's drivers and
/// for the harness that wires emulated boards together (QEMU's `-serial` number `i` is
/// UART `i`): UART [`GLOBAL_UART`](mps2_uarts::GLOBAL_UART) is the global port; the faces a
/// board exchanges over ([`crate::image::linked_faces`]) take the others in
/// [`link_proto::Face::ALL`] order. Four face UARTs serve every board of a machine up to
/// 2x2x2 (three faces each), and of 3x2x2, 3x3x1 or 5x2x1 (at most four); a board with five
/// or six linked faces (a 3x3x2 machine's middle boards) does not fit.
pub mod mps2_uarts {
    /// Base addresses of UART 0 to 4.
    pub const UART_BASES: [usize; 5] = [
        0x4000_4000,
        0x4000_5000,
        0x4000_6000,
        0x4000_7000,
        0x4000_9000,
    ];
    /// Each UART's receive interrupt (its transmit interrupt is the next number), as
    /// QEMU's `mps2-an500` wires them to the NVIC.
    pub const RX_IRQS: [u16; 5] = [0, 2, 4, 18, 20];
    /// The global port's UART.
    pub const GLOBAL_UART: usize = 2;
    /// The UARTs the faces take, in order.
    pub const FACE_UARTS: [usize; 4] = [0, 1, 3, 4];

    /// The UART of each face ([`link_proto::Face::index`] order) for a board whose linked
    /// faces are `linked`; `Err(n)` when it has `n` linked faces, more than there are face
    /// UARTs.
    pub const fn face_uarts(linked: [bool; 6]) -> Result<[Option<usize>; 6], usize> {
        let mut out = [None; 6];
        let (mut face, mut next) = (0, 0);
        while face < 6 {
            if linked[face] {
                if next < FACE_UARTS.len() {
                    out[face] = Some(FACE_UARTS[next]);
                }
                next += 1;
            }
            face += 1;
        }
        if next > FACE_UARTS.len() {
            Err(next)
        } else {
            Ok(out)
        }
    }
}

/// The board profiles, the one registry every name is looked up in
/// ([`BoardProfile::by_name`]): a new board is a `BoardProfile` constant above and its entry
/// here.
pub static PROFILES: [&BoardProfile; 3] = [&PE_BOARD, &STM32H743_UART, &QEMU_MPS2_AN500];

/// The index of the profile called `name` in [`PROFILES`] (for the firmware's build record,
/// [`crate::image::blob::build_record`]), in a `const` context.
pub const fn profile_index(name: &str) -> Option<u8> {
    let mut i = 0;
    while i < PROFILES.len() {
        let (a, b) = (PROFILES[i].name.as_bytes(), name.as_bytes());
        if a.len() == b.len() {
            let mut k = 0;
            while k < a.len() && a[k] == b[k] {
                k += 1;
            }
            if k == a.len() {
                return Some(i as u8);
            }
        }
        i += 1;
    }
    None
}

impl BoardProfile {
    /// The registered profile called `name` ([`PROFILES`]); an unknown name is an error
    /// that names it and lists the known ones.
    pub fn by_name(name: &str) -> Result<&'static BoardProfile, UnknownProfile> {
        PROFILES
            .into_iter()
            .find(|p| p.name == name)
            .ok_or_else(|| UnknownProfile::new(name))
    }

    /// The fixed cost of one link frame (s): [`Self::link_latency_ns`] in seconds.
    pub fn link_latency_s(&self) -> f64 {
        self.link_latency_ns as f64 * 1e-9
    }

    /// The time one link direction of this profile needs for `frames` frames of
    /// `bytes_on_wire` bytes in all ([`link_time_s`] at its rate and fixed cost).
    pub fn link_time_s(&self, bytes_on_wire: usize, frames: usize) -> f64 {
        link_time_s(
            bytes_on_wire,
            frames,
            self.link_bytes_per_s as f64,
            self.link_latency_s(),
        )
    }

    /// The time of one frame of `len_on_wire` bytes on this profile's links
    /// ([`link_time_s`] of one frame).
    pub fn frame_time_s(&self, len_on_wire: usize) -> f64 {
        self.link_time_s(len_on_wire, 1)
    }
}

/// The link time of `frames` frames of `bytes_on_wire` bytes in all, on a link of
/// `bytes_per_s` each way whose every frame costs `frame_latency_s` beyond its bytes:
///
/// `t = bytes_on_wire / bytes_per_s + frames · frame_latency_s`
///
/// The one formula of a frame's time on a face link (the compile report's links, the step
/// model's frames, board-sim's link model). A frame's bytes on the wire are its length
/// ([`link_proto::frame::frame_len`]), inside link recovery's envelope when the links run
/// it ([`link_proto::limits::enveloped_len`]): the caller says which by the length it
/// passes.
pub fn link_time_s(
    bytes_on_wire: usize,
    frames: usize,
    bytes_per_s: f64,
    frame_latency_s: f64,
) -> f64 {
    bytes_on_wire as f64 / bytes_per_s + frames as f64 * frame_latency_s
}

/// A profile shows as its name.
impl core::fmt::Display for BoardProfile {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name)
    }
}

/// A board profile name not in the registry ([`PROFILES`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnknownProfile {
    /// The name asked for (its first [`UNKNOWN_NAME_MAX`] bytes).
    name: heapless::String<UNKNOWN_NAME_MAX>,
    truncated: bool,
}

/// Bytes of an unknown profile name its error keeps.
pub const UNKNOWN_NAME_MAX: usize = 48;

impl UnknownProfile {
    fn new(name: &str) -> UnknownProfile {
        let mut kept = heapless::String::new();
        let mut truncated = false;
        for c in name.chars() {
            if kept.push(c).is_err() {
                truncated = true;
                break;
            }
        }
        UnknownProfile {
            name: kept,
            truncated,
        }
    }
}

impl core::fmt::Display for UnknownProfile {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "unknown board profile {:?}{} (known:",
            self.name.as_str(),
            if self.truncated { "..." } else { "" }
        )?;
        for (k, p) in PROFILES.iter().enumerate() {
            write!(f, "{}{}", if k == 0 { " " } else { ", " }, p.name)?;
        }
        f.write_str(")")
    }
}

impl core::error::Error for UnknownProfile {}

/// `#[serde(with = "pe_firmware::profile::by_name")]`: a registered profile
/// (`&'static BoardProfile`) as its name; reading an unknown name is an error listing the
/// known ones ([`BoardProfile::by_name`]).
pub mod by_name {
    use super::BoardProfile;

    pub fn serialize<S: serde::Serializer>(
        p: &&'static BoardProfile,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.serialize_str(p.name)
    }

    pub fn deserialize<'de, D: serde::Deserializer<'de>>(
        d: D,
    ) -> Result<&'static BoardProfile, D::Error> {
        struct Name;
        impl serde::de::Visitor<'_> for Name {
            type Value = &'static BoardProfile;
            fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.write_str("a board profile's name")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
                BoardProfile::by_name(v).map_err(E::custom)
            }
        }
        d.deserialize_str(Name)
    }
}

mod cost;
pub use cost::{measured_cost, FirmwareCost, StepCost, MEASURED_COST};
pub mod tet_cost;
pub use tet_cost::{measured_tet_cost, TetCost, MEASURED_TET_COST};

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::ToString;

    /// Every registered profile is found by its name (the registry's own entry); a name
    /// off by a letter is refused, and its error names it and every known profile; a long
    /// unknown name is kept cut, marked as cut.
    #[test]
    fn profiles_are_found_by_their_names_only() {
        assert_eq!(PROFILES.len(), 3);
        for (i, p) in PROFILES.into_iter().enumerate() {
            let found = BoardProfile::by_name(p.name).expect("registered");
            assert!(core::ptr::eq(found, p), "{}", p.name);
            assert_eq!(profile_index(p.name), Some(i as u8), "{}", p.name);
        }
        // A prefix, an extension and another case are other names.
        for name in ["pe-boar", "pe-board-2", "PE-BOARD", ""] {
            assert_eq!(profile_index(name), None, "{name:?}");
        }
        assert_eq!(
            BoardProfile::by_name("pe-board").unwrap().clock_hz,
            480_000_000
        );
        let e = BoardProfile::by_name("pe-bord").unwrap_err().to_string();
        assert_eq!(
            e,
            "unknown board profile \"pe-bord\" (known: pe-board, stm32h743-uart, qemu-mps2-an500)"
        );
        let long = "x".repeat(100);
        let e = BoardProfile::by_name(&long).unwrap_err().to_string();
        assert!(
            e.contains(&std::format!("\"{}\"...", "x".repeat(UNKNOWN_NAME_MAX))),
            "{e}"
        );
    }

    /// A frame's time is its bytes at the link rate plus the frame's fixed cost: on the PE
    /// board (3 125 000 bytes/s, 2 us a frame) 100 bytes take 32 + 2 us, and 1000 bytes in
    /// four frames 320 + 8 us (to 1e-18 s: the sums of two rounded terms).
    #[test]
    fn a_frame_takes_its_bytes_at_the_rate_and_its_fixed_cost() {
        let close = |a: f64, b: f64| (a - b).abs() < 1e-18;
        assert!(
            close(PE_BOARD.frame_time_s(100), 34e-6),
            "{}",
            PE_BOARD.frame_time_s(100)
        );
        assert!(close(PE_BOARD.link_time_s(1000, 4), 328e-6));
        assert_eq!(PE_BOARD.frame_time_s(100), PE_BOARD.link_time_s(100, 1));
        // The UART profile: 750 000 bytes/s, 5 us a frame.
        assert!(close(STM32H743_UART.frame_time_s(750), 1e-3 + 5e-6));
    }
}
