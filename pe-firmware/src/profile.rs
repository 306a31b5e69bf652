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
    /// are sized for); the parallelepiped, external-force and graphics tables follow it.
    pub nodes_max: u32,
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
    // Contact tables (the whole scene's, on every board): some 190 bytes per contact node
    // and 76 per face (with the face's bounds for a step). 384 each, twice the built-in
    // medium scene's 178 nodes and 160 faces, leave the elements more of the RAM than 512
    // did before the face bounds.
    contact_nodes_max: 384,
    contact_faces_max: 384,
    nodes_max: 512,
    materials_max: 8,
    exchange_max: 4096,
    path_points_max: 64,
    loads_max: 256,
    contact_candidates_max: 2048,
    contact_sends_max: 1024,
};

/// The prototype array: STM32H743 boards (NUCLEO-H743ZI or any board with the part and the
/// pins of `pe-firmware/board/src/bsp/stm32h743.rs`) whose six faces and global port are
/// USART/UARTs driven by DMA, one cable (TX, RX, ground) per face. The PE board's memory and
/// tables. Rate: 7.5 Mbaud, the USART's kernel clock (`rcc_pclk1`/`rcc_pclk2`, 120 MHz at a
/// 480 MHz core) divided by 16 (RM0433, USART baud rate generation, 16x oversampling, as
/// stm32h7xx-hal configures it); ten bits a byte (start, 8 data, stop): 750 000 bytes/s
/// each way. Per frame: 5 us to restart the TX DMA stream and let the last byte leave the
/// shift register (an assumption, to be measured). DS12110 gives the USARTs up to
/// 12.5 Mbit/s with 8x oversampling; the PE board's SPI links (about 4x this rate) are the
/// design for real time.
pub const STM32H743_UART: BoardProfile = BoardProfile {
    name: "stm32h743-uart",
    link_bytes_per_s: 750_000,
    link_latency_ns: 5_000,
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
    // The frames' node limit, and otherwise the PE board's tables (the RAM decides the
    // elements).
    nodes_max: link_proto::NODES_PER_BOARD_MAX as u32,
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

pub const PROFILES: [BoardProfile; 3] = [PE_BOARD, STM32H743_UART, QEMU_MPS2_AN500];

/// Looks a profile up by name.
pub fn profile(name: &str) -> Option<BoardProfile> {
    PROFILES.iter().copied().find(|p| p.name == name)
}

use crate::physics::Kernel;

/// Executed instructions of the board firmware per element and per node in one step,
/// measured under QEMU (mps2-an500, Cortex-M7 with FPU, `-C target-cpu=cortex-m7`) with an
/// exact instruction counter by `scripts/board-cost.sh`: the general kernel and the node
/// update on the built-in coarse scene (351 elements, all distorted, 731 nodes, 1x1x1) after
/// 900 steps, the probe pressing the tube; the cuboid kernel on a 10x5x5 box sagging under
/// gravity, the parallelepiped kernel on the same box turned by 30° about x. The node update includes the step's contact, graphics and external-force
/// work. Instructions, not cycles: capacity figures take one instruction per cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FirmwareCost {
    pub precision: crate::image::Precision,
    pub integration: crate::image::Integration,
    /// One general element's internal forces (the physics kernel alone).
    pub kernel_per_element: u32,
    /// Per general element of the element loop: kernel, gathering displacements,
    /// scattering forces.
    pub per_element_step: u32,
    /// The same for a parallelepiped ([`crate::physics::HexBox`]; 0 for full
    /// integration, which has no such kernel).
    pub box_kernel_per_element: u32,
    pub box_per_element_step: u32,
    /// The same for an axis-aligned cuboid ([`crate::physics::HexCuboid`]; 0 for full
    /// integration).
    pub cuboid_kernel_per_element: u32,
    pub cuboid_per_element_step: u32,
    /// Per node and step: external forces, central-difference update, checks (a node
    /// without contact: measured on the regular box).
    pub per_node_update: u32,
    /// Per contact-surface node and step, on a board that evaluates the contact of the
    /// whole table: a step's contact evaluation (positions, travel check, tool and pair
    /// tests) over the table's nodes, measured on its own between marks on the built-in
    /// scene (one board owning every contact node, in the board-cost state). Not in it: a
    /// check step's candidate search (once per check interval: [`Self::per_search_test`])
    /// and the contact-node packets a board of a partition sends and receives.
    pub per_contact_node: u32,
    /// Per node-face test of a check step's candidate search
    /// ([`crate::physics::contact::search_tests`]): a check step's contact evaluation less
    /// a step's, over the search's tests, measured on the same state (the search and
    /// keeping the groups that give the board's nodes a force). It carries the search's
    /// work per face (the boxes) and per candidate (the sort, the groups kept) too: on
    /// the built-in coarse scene 186 040 against a step's 31 367 instructions for 5 184
    /// tests, the box test itself some 14 of the 30 (`scripts/firmware-profile.sh`).
    pub per_search_test: u32,
    /// A whole step divided by the elements, on the measured scene.
    pub step_per_element: u32,
}

impl FirmwareCost {
    /// Instructions per element-step (kernel, gather, scatter) of kernel `k`.
    pub fn element_step(&self, k: Kernel) -> u32 {
        match k {
            Kernel::General => self.per_element_step,
            Kernel::Parallelepiped => self.box_per_element_step,
            Kernel::Cuboid => self.cuboid_per_element_step,
        }
    }

    /// Instructions of one step of a board holding `per_kernel[k]` elements of each kernel
    /// ([`Kernel`] order) and `nodes` nodes, charged for `contact_nodes` contact nodes
    /// ([`Self::charged_contact_nodes`]; no exchange).
    pub fn step_instructions(
        &self,
        per_kernel: [usize; 3],
        nodes: usize,
        contact_nodes: usize,
    ) -> f64 {
        Kernel::ALL
            .iter()
            .map(|&k| per_kernel[k as usize] as f64 * self.element_step(k) as f64)
            .sum::<f64>()
            + nodes as f64 * self.per_node_update as f64
            + contact_nodes as f64 * self.per_contact_node as f64
    }

    /// The contact-surface nodes a board's step is charged [`Self::per_contact_node`] for
    /// (the one rule of the compile report and board-sim's timing model), from the
    /// contact table's length (every board that owns a contact node holds the whole table)
    /// and the contact nodes the board owns:
    /// - a board that owns a contact node evaluates the contact problem of the whole
    ///   table: its positions and, at each check, the candidate groups that give one of
    ///   its nodes a force, which on a small contact surface are most of them (measured by
    ///   `scripts/contact-cost.sh`: see the README's board-cost section);
    /// - a board that owns none has no contact tables and no contact operation in its step
    ///   (every result would be zero), and is charged nothing.
    pub fn charged_contact_nodes(table_nodes: usize, owned_contact_nodes: usize) -> usize {
        if owned_contact_nodes > 0 {
            table_nodes
        } else {
            0
        }
    }

    /// Per element of a mix with fractions `mix[k]` of each kernel ([`Kernel`] order).
    pub fn per_element_of_mix(&self, mix: [f64; 3]) -> f64 {
        Kernel::ALL
            .iter()
            .map(|&k| mix[k as usize] * self.element_step(k) as f64)
            .sum()
    }

    /// Elements one board of `profile` computes at `rate_hz` steps per second, with
    /// `nodes_per_element` nodes (`contact_per_element` contact nodes) per element and
    /// fractions `mix` of each kernel, taking one instruction per cycle.
    pub fn elements_per_board(
        &self,
        profile: &BoardProfile,
        rate_hz: f64,
        nodes_per_element: f64,
        contact_per_element: f64,
        mix: [f64; 3],
    ) -> f64 {
        profile.clock_hz as f64
            / rate_hz
            / (self.per_element_of_mix(mix)
                + nodes_per_element * self.per_node_update as f64
                + contact_per_element * self.per_contact_node as f64)
    }
}

/// The measured table (scripts/board-cost.sh, run by CI: a test fails when a figure here is
/// more than 3% off the measurement; update it from that script's output).
pub const MEASURED_COST: [FirmwareCost; 4] = {
    use crate::image::{Integration::*, Precision::*};
    [
        FirmwareCost {
            precision: F64,
            integration: Reduced,
            kernel_per_element: 938,
            per_element_step: 957,
            box_kernel_per_element: 552,
            box_per_element_step: 668,
            cuboid_kernel_per_element: 464,
            cuboid_per_element_step: 539,
            per_node_update: 79,
            per_contact_node: 275,
            per_search_test: 30,
            step_per_element: 1176,
        },
        FirmwareCost {
            precision: F64,
            integration: Full,
            kernel_per_element: 4038,
            per_element_step: 4110,
            box_kernel_per_element: 0,
            box_per_element_step: 0,
            cuboid_kernel_per_element: 0,
            cuboid_per_element_step: 0,
            per_node_update: 79,
            per_contact_node: 274,
            per_search_test: 30,
            step_per_element: 4328,
        },
        FirmwareCost {
            precision: F32,
            integration: Reduced,
            kernel_per_element: 739,
            per_element_step: 815,
            box_kernel_per_element: 466,
            box_per_element_step: 562,
            cuboid_kernel_per_element: 375,
            cuboid_per_element_step: 493,
            per_node_update: 88,
            per_contact_node: 268,
            per_search_test: 30,
            step_per_element: 1050,
        },
        FirmwareCost {
            precision: F32,
            integration: Full,
            kernel_per_element: 3239,
            per_element_step: 3350,
            box_kernel_per_element: 0,
            box_per_element_step: 0,
            cuboid_kernel_per_element: 0,
            cuboid_per_element_step: 0,
            per_node_update: 88,
            per_contact_node: 268,
            per_search_test: 30,
            step_per_element: 3585,
        },
    ]
};

/// The measured cost of a variant.
pub fn measured_cost(
    precision: crate::image::Precision,
    integration: crate::image::Integration,
) -> FirmwareCost {
    let mut c = MEASURED_COST[0];
    for m in MEASURED_COST {
        if m.precision == precision && m.integration == integration {
            c = m;
        }
    }
    c
}
