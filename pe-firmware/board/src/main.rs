//! PE board firmware: boots (cortex-m-rt), checks the schedule image in its flash region
//! against this board's position, runs every step of the schedule over the links, and
//! reports the final state (QEMU: semihosting) or the first fault (fault packet), then
//! exits. Never hangs: link waits time out, faults and panics end the run.
#![no_std]
#![no_main]

use cortex_m_rt::{entry, exception, ExceptionFrame};
#[cfg(not(feature = "stm32h743"))]
use pe_board::clock;
use pe_board::config::{Element, Scalar, CAPACITIES, PROFILE, VARIANT};
use pe_board::log_info;
use pe_board::region::{self, board_position, schedule_image};
use pe_board::{links, report, storage};
use pe_firmware::physics::Real;
use pe_firmware::runtime::{Fault, FaultKind, Runtime, RuntimeConfig};

/// Board position before the identity is read (for reports).
const UNKNOWN: [u8; 3] = [0xFF; 3];

#[entry]
fn main() -> ! {
    // Subnormals flushed to zero, as the host computes: before any floating-point work.
    pe_board::fpu::flush_subnormals();
    // The RTT control block and buffer (memory.x's `.rtt`, in SRAM1) from flash, before the
    // first log.
    #[cfg(not(feature = "qemu"))]
    pe_board::fmt::init_rtt_section();
    let Some(mut cp) = cortex_m::Peripherals::take() else {
        report::fault(UNKNOWN, format_args!("core peripherals taken twice"));
    };
    let chip = early(&mut cp);
    let Some(board) = board_position() else {
        report::fault(UNKNOWN, format_args!("board identity record damaged"));
    };
    if !region::build_record_intact() {
        report::fault(board, format_args!("firmware build record damaged"));
    }
    log_info!(
        "pe-board: {} on {}, position ({},{},{}), capacity {} elements",
        VARIANT,
        PROFILE.name,
        board[0],
        board[1],
        board[2],
        CAPACITIES.elements
    );
    let image = match schedule_image() {
        Ok(i) => i,
        Err(e) => report::fault(
            board,
            format_args!("board ({},{},{}): {e}", board[0], board[1], board[2]),
        ),
    };
    let Some(store) = storage::take() else {
        report::fault(board, format_args!("storage taken twice"));
    };
    let Some(host_gate) = region::host_gate() else {
        report::fault(board, format_args!("run options record damaged"));
    };
    let config = RuntimeConfig {
        host_gate,
        ..RuntimeConfig::default()
    };
    // Straight into its place (the runtime is about 48 KiB: every copy on the way is stack).
    let mut rt =
        Runtime::<Scalar, Element>::load(image, board, store, config).unwrap_or_else(|e| {
            report::fault(
                board,
                format_args!(
                    "{}",
                    Fault {
                        board,
                        step: 0,
                        kind: FaultKind::Image(e)
                    }
                ),
            )
        });
    // Every face the schedule exchanges over needs a driver.
    let machine = rt.header.machine;
    let linked = rt.header.linked_faces();
    let drivers = links::face_drivers(linked).unwrap_or_else(|needed| {
        report::fault(
            board,
            format_args!(
                "board ({},{},{}): the schedule exchanges over {needed} links ({}), more than this firmware has drivers for ({})",
                board[0],
                board[1],
                board[2],
                FaceList(linked),
                if cfg!(feature = "qemu") { "4 UARTs" } else { "none yet" }
            ),
        )
    });
    let mut env = start_board(&mut cp, &chip, board);
    let Some(links) = links::take(drivers) else {
        report::fault(board, format_args!("links taken twice"));
    };
    // QEMU: waits sleep until a link moves (this binary's DefaultHandler clears the UARTs).
    if cfg!(feature = "qemu") {
        links::wake_on_links();
    }
    log_info!(
        "pe-board: image for ({},{},{}) of {}x{}x{}: {} elements, {} nodes, {} steps",
        board[0],
        board[1],
        board[2],
        machine[0],
        machine[1],
        machine[2],
        rt.header.counts.elements,
        rt.header.counts.nodes,
        rt.header.params.steps
    );
    while !rt.is_finished() {
        if let Err(f) = rt.step(links, &mut env) {
            report::fault(board, format_args!("{f}"));
        }
    }
    log_info!("pe-board: {} steps done", rt.step_index());
    log_info!("pe-board: begin nodes");
    for (n, u) in rt.nodes().iter().zip(rt.displacements()) {
        if n.owner {
            report::node(n.global, u.map(|v| v.to_f64()));
        }
    }
    log_info!("pe-board: end nodes");
    report::exit(true)
}

/// The prototype: the chip's revision and its errata fix, caches on; before the storage
/// fills.
#[cfg(feature = "stm32h743")]
fn early(cp: &mut cortex_m::Peripherals) -> pe_board::bsp::stm32h743::Chip {
    pe_board::bsp::stm32h743::early(cp)
        .unwrap_or_else(|e| report::fault(UNKNOWN, format_args!("board start-up: {e}")))
}

/// What other boards know of their chip before the storage fills: nothing.
#[cfg(not(feature = "stm32h743"))]
struct NoChip;

#[cfg(not(feature = "stm32h743"))]
fn early(_cp: &mut cortex_m::Peripherals) -> NoChip {
    NoChip
}

/// Time, and the prototype's own hardware (clocks, ports) before the links use it.
#[cfg(feature = "stm32h743")]
fn start_board(
    cp: &mut cortex_m::Peripherals,
    chip: &pe_board::bsp::stm32h743::Chip,
    board: [u8; 3],
) -> pe_board::bsp::stm32h743::CycleClock {
    log_info!(
        "pe-board: STM32H743 revision {}, core at {} MHz",
        chip.revision.name(),
        chip.clocks.core_hz / 1_000_000
    );
    pe_board::bsp::stm32h743::start(cp, chip)
        .unwrap_or_else(|e| report::fault(board, format_args!("board start-up: {e}")))
}

/// Time from SysTick at the profile's clock.
#[cfg(not(feature = "stm32h743"))]
fn start_board(
    cp: &mut cortex_m::Peripherals,
    _chip: &NoChip,
    _board: [u8; 3],
) -> clock::BoardClock {
    clock::BoardClock::start(cp, PROFILE.clock_hz)
}

/// The linked faces, for messages (`+x -y`).
struct FaceList([bool; 6]);

impl core::fmt::Display for FaceList {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let mut first = true;
        for (name, _) in link_proto::link::FACE_NAMES
            .iter()
            .zip(self.0)
            .filter(|(_, l)| *l)
        {
            if !first {
                f.write_str(" ")?;
            }
            f.write_str(name)?;
            first = false;
        }
        Ok(())
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    let board = board_position().unwrap_or(UNKNOWN);
    report::fault(board, format_args!("panic: {info}"))
}

/// Every device interrupt: only the links' UARTs are unmasked, to wake the core.
#[exception]
unsafe fn DefaultHandler(_irqn: i16) {
    links::on_uart_interrupt();
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    let board = board_position().unwrap_or(UNKNOWN);
    report::fault(board, format_args!("hard fault at pc {:#010x}", ef.pc()))
}
