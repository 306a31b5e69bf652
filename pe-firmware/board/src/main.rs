//! PE board firmware: boots (cortex-m-rt), checks the schedule image in its flash region
//! against this board's position, runs every step of the schedule over the links, and
//! reports the final state (QEMU: semihosting) or the first fault (fault packet), then
//! exits. Never hangs: link waits time out, faults and panics end the run.
#![no_std]
#![no_main]

use cortex_m_rt::{entry, exception, ExceptionFrame};
use pe_board::config::{Element, Scalar, CAPACITIES, PROFILE, VARIANT};
use pe_board::log_info;
use pe_board::region::{board_position, schedule_image};
use pe_board::{clock, links, report, storage};
use pe_firmware::physics::Real;
use pe_firmware::runtime::{Fault, FaultKind, Runtime, RuntimeConfig};

/// Board position before the identity is read (for reports).
const UNKNOWN: [u8; 3] = [0xFF; 3];

#[entry]
fn main() -> ! {
    let Some(board) = board_position() else {
        report::fault(UNKNOWN, format_args!("board identity record damaged"));
    };
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
    // Straight into its place (the runtime is about 48 KiB: every copy on the way is stack).
    let mut rt = Runtime::<Scalar, Element>::load(image, board, store, RuntimeConfig::default())
        .unwrap_or_else(|e| {
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
    for face in link_proto::Face::ALL {
        let axis = face.index() / 2;
        let neighbour = if face.sign() > 0 {
            board[axis] + 1 < machine[axis]
        } else {
            board[axis] > 0
        };
        if neighbour && rt.header.counts.rounds[axis] > 0 && !links::face_linked(face) {
            report::fault(
                board,
                format_args!(
                    "board ({},{},{}): the schedule exchanges over link {face:?}, which this firmware has no driver for",
                    board[0], board[1], board[2]
                ),
            );
        }
    }
    let Some(links) = links::take() else {
        report::fault(board, format_args!("links taken twice"));
    };
    let Some(cp) = cortex_m::Peripherals::take() else {
        report::fault(board, format_args!("core peripherals taken twice"));
    };
    let mut env = clock::BoardClock::start(cp.SYST, PROFILE.clock_hz);
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

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    let board = board_position().unwrap_or(UNKNOWN);
    report::fault(board, format_args!("panic: {info}"))
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    let board = board_position().unwrap_or(UNKNOWN);
    report::fault(board, format_args!("hard fault at pc {:#010x}", ef.pc()))
}
