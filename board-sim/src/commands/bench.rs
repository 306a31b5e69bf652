//! `board-sim bench`: steps per second of the serial solver and of board-sim on the same
//! scene, in one run, as a ratio.

use std::path::Path;

use anyhow::Result;
use host_tools::problem::Problem;
use host_tools::scene::builtin::builtin_scene;
use link_proto::Machine;

use crate::runner::{run, SimOptions};

/// The built-in scene at `level` for `steps` steps: the serial solver, then board-sim on a
/// `boards` machine (batched and scalar element kernels on as many workers as cores, then
/// one worker per board).
pub fn bench(level: &str, boards: &str, steps: u64) -> Result<()> {
    let mut scene = builtin_scene(level)?;
    scene.solver.steps = Some(steps);
    let problem = Problem::from_scene(&scene, Path::new("."))?;
    problem.print_notes();
    let t = std::time::Instant::now();
    let serial = host_tools::solver::run(&problem, "serial", &mut ())?;
    let serial_s = t.elapsed().as_secs_f64();
    let dir = std::env::temp_dir().join(format!("board-sim-bench-{}", std::process::id()));
    let name = format!("builtin:{level}");
    let machine = Machine::parse(boards)?;
    host_tools::compile::compile_to_dir(
        &name,
        &name,
        &problem,
        machine,
        &pe_firmware::profile::PE_BOARD,
        &dir,
    )?;
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(2);
    println!(
        "{name}, {} elements, {steps} steps, {boards} boards, {cores} cores",
        problem.mesh.cells.len()
    );
    println!("  serial solver: {:.1} steps/s", steps as f64 / serial_s);
    // The boards' element batches on the host's lanes (the default) and on the firmware's
    // scalar loop, on as many workers as cores; then one worker per board.
    let runs = [(cores, true), (cores, false), (machine.count(), true)];
    for (workers, batched) in runs {
        let opts = SimOptions {
            workers: Some(workers),
            batched,
            ..Default::default()
        };
        let out = run(&dir, &opts, &mut |_, _| {})?;
        let d = host_tools::compare::max_rel_diff(&serial.displacements, &out.displacements);
        let kernel = if batched { "batched" } else { "scalar" };
        println!(
            "  board-sim, {workers} worker threads, {kernel} element kernel: {:.1} steps/s = {:.2}x the serial run's time (max relative difference {d:.1e})",
            steps as f64 / out.wall_s,
            out.wall_s / serial_s
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
