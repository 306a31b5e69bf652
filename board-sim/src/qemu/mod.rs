//! `board-sim qemu DIR`: the board firmware itself on an emulated array. One QEMU
//! `mps2-an500` (Cortex-M7) per board runs the `pe image` ELF and schedule blob of its
//! position; this process wires their UARTs as the cables of the machine and plays the
//! global network, the host and the graphics engine.
//!
//! Wiring (one home for which UART carries what: `pe_firmware::profile::mps2_uarts`): QEMU's
//! `-serial` `i` is UART `i`; each UART a board uses is a TCP socket QEMU connects to this
//! process at start. A cable joins two face connectors (a board's face and its neighbour's
//! opposite face): the bytes are relayed both ways as they come, untouched (the frames
//! carry no address, the boards' Hello check finds a crossed cable). The global ports'
//! bytes are COBS-framed packets: each is routed on its destination like the global
//! network's switch: to a board's global UART, or to the host and graphics sinks, which
//! keep them as board-sim's do (tool forces, surface frames, each board's compilation id,
//! fault reports).
//!
//! Faults are the boards' own: a board that faults sends a fault packet and exits; its
//! neighbours time out on the dead link (the runtime's link timeout) and report in turn.
//! `kill` ends one board's QEMU mid-run (the harness's fault wrapper); `cross` swaps the
//! far ends of two cables. The run never hangs: a whole-run deadline and a watchdog on
//! progress (no byte on any link, global port or console for twice the boards' link
//! timeout) end every QEMU and say which boards were still running.
//!
//! A run's steps, one room each: [`wiring`] (faces, UARTs, cables), [`start`] (the QEMUs
//! and their connections), [`relay`] (cables and the global switch), [`watch`] (exits,
//! kill, deadline, watchdog), [`collect`] (the boards' account and the final state).

mod collect;
mod options;
mod output;
mod relay;
mod replay;
mod start;
mod watch;
mod wiring;

use std::path::Path;
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use host_tools::compile::{read_manifest, Manifest};
use link_proto::Machine;
use pe_firmware::runtime::RuntimeConfig;

pub use options::ArrayOptions;
pub use output::{ArrayFault, ArrayOutput, BoardRun};
pub use wiring::{cables, parse_board, Connector, Linked};

use crate::check::{collect_sinks, HostCheck};
use crate::runner::{manifest_machine, one_per_tool_and_step, read_images, tool_holders};
use relay::{Activity, Network};
use replay::{feed, gated_elfs, Replay};
use start::{connect, listen, start_boards, Emulated};
use wiring::Wiring;

/// Runs the images of `dir` (`pe compile --profile qemu-mps2-an500`) on one QEMU per board:
/// start, wire, relay, watch, collect.
pub fn run_array(dir: &Path, opts: &ArrayOptions) -> Result<ArrayOutput> {
    let m = read_manifest(dir)?;
    check_setup(dir, &m, opts)?;
    let machine = manifest_machine(dir, &m)?;
    let images = opts.images.clone().unwrap_or_else(|| dir.join("qemu"));
    let mut im = host_tools::firmware::image_dir(dir, &images, opts.firmware.as_deref())?;
    let replay = replay_of(dir, &m, machine, opts)?;
    if replay.is_some() {
        gated_elfs(&mut im.boards, &images)?;
    }
    let wiring = Wiring::read(dir, &m, opts.cross)?;
    let listeners = listen(wiring.board_uarts())?;
    let act = Arc::new(Activity::default());
    let start = Instant::now();
    let mut boards = start_boards(&im.boards, &images, &listeners, opts, &act)?;
    let sockets = connect(&listeners, &mut boards)?;
    let mut net = Network::wire(&wiring, sockets, &act)?;
    let stop = Arc::new(AtomicBool::new(false));
    let feeder = replay.map(|r| {
        let (switch, stop) = (net.switch.clone(), stop.clone());
        std::thread::spawn(move || feed(&r, &switch, &switch.gate, &stop))
    });
    let timeout = Duration::from_nanos(RuntimeConfig::default().link_timeout_ns);
    let quiet_limit = 2 * timeout + Duration::from_secs(5);
    watch::watch(&mut boards, &net.switch, &act, start, quiet_limit, opts);
    let wall_s = start.elapsed().as_secs_f64();
    stop.store(true, Ordering::Relaxed);
    let pose_packets = match feeder.map(|f| f.join()) {
        None => 0,
        Some(Ok(sent)) => sent?,
        Some(Err(_)) => bail!("the host's pose feeder panicked"),
    };
    end(&mut boards, std::mem::take(&mut net.threads));
    let runs = collect::failure(collect::account(&boards, &net, wall_s), &net, timeout)?;
    let displacements = collect::merged_state(&boards)?;
    let sinks = &net.switch.sinks;
    HostCheck::new(&m.compilation, machine).finish(sinks)?;
    let (frames, tool_force) = collect_sinks(sinks, m.steps, wiring.tools)?;
    Ok(ArrayOutput {
        machine: m.machine,
        steps: m.steps,
        wall_s,
        boards: runs,
        displacements,
        packets_between_boards: net.switch.between_boards.load(Ordering::Relaxed),
        packets_to_sinks: net.switch.to_sinks.load(Ordering::Relaxed),
        graphics_frames: frames.len(),
        tool_force,
        pose_packets,
    })
}

/// The replay `opts` asks for: its poses, the boards holding each tool (from the images).
fn replay_of(
    dir: &Path,
    m: &Manifest,
    machine: Machine,
    opts: &ArrayOptions,
) -> Result<Option<Replay>> {
    if opts.poses.poses.is_empty() {
        return Ok(None);
    }
    let (images, _, tools) = read_images(dir, m, machine, true)?;
    let holders = tool_holders(machine, &images, tools);
    Replay::new(one_per_tool_and_step(&opts.poses), holders).map(Some)
}

/// Refuses images of another profile than QEMU's, and a missing emulator.
fn check_setup(dir: &Path, m: &Manifest, opts: &ArrayOptions) -> Result<()> {
    let qemu_profile = pe_firmware::profile::QEMU_MPS2_AN500;
    if m.profile.name != qemu_profile.name {
        bail!(
            "{}: compiled for the {} profile; the emulated array runs images of the {} profile (pe compile ... --profile {})",
            dir.display(),
            m.profile.name,
            qemu_profile.name,
            qemu_profile.name
        );
    }
    let version = Command::new(&opts.qemu).arg("--version").output();
    if !version.is_ok_and(|o| o.status.success()) {
        bail!(
            "{} not found or not working: install QEMU's Arm system emulator (apt-get install qemu-system-arm)",
            opts.qemu.display()
        );
    }
    Ok(())
}

/// Waits for every QEMU and its console readers, and for the relay threads.
fn end(boards: &mut [Emulated], threads: Vec<std::thread::JoinHandle<()>>) {
    for e in boards.iter_mut() {
        let _ = e.child.wait();
        for r in e.readers.drain(..) {
            let _ = r.join();
        }
    }
    for t in threads {
        let _ = t.join();
    }
}
