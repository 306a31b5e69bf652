//! `board-sim builtin`: the main job. Compiles the built-in scene (uterus, tubes, probe)
//! for a board mesh and runs it, writing OUT/images, OUT/frames (ParaView),
//! OUT/report.json and a summary.

use std::path::Path;

use anyhow::Result;
use host_tools::output::OutputArgs as RunOutputs;
use host_tools::problem::Problem;
use host_tools::scene::builtin::builtin_scene;
use link_proto::Machine;
use pe_firmware::physics::vec3::norm;

use super::run::{execute, RunArgs};

use crate::outputs::{OutputArgs, ResultArgs};

/// The main job (see the module doc).
pub fn builtin(
    level: &str,
    boards: &str,
    out: &Path,
    steps: Option<u64>,
    quiet: bool,
) -> Result<()> {
    let scene = builtin_scene(level)?;
    let problem = Problem::from_scene(&scene, Path::new("."))?;
    problem.print_notes();
    let images = out.join("images");
    let machine = Machine::parse(boards)?;
    let name = format!("builtin:{level}");
    let rep = host_tools::compile::compile_to_dir(
        &name,
        &name,
        &problem,
        machine,
        &pe_firmware::profile::PE_BOARD,
        &images,
    )?;
    print!("{}", host_tools::compile::summary(&rep));
    let args = RunArgs {
        outputs: OutputArgs {
            run: RunOutputs {
                result: ResultArgs {
                    output_nodes: Some(out.join("nodes.csv")),
                    report: Some(out.join("report.json")),
                },
                vtk: Some(out.join("frames")),
                tool_force: Some(out.join("tool_force.csv")),
            },
            png: Some(out.join("final.png")),
        },
        steps,
        link_timeout_s: 10.0,
        quiet,
        ..Default::default()
    };
    let sim = execute(&images, args)?;
    // What a user of the trainer wants to know: what the probe did to the tube (and, through
    // their contact pair, the tube to the ovary).
    let moved = host_tools::scene::builtin::builtin_summary(&problem.mesh, &sim.displacements);
    let tube_max = moved.right_tube_max_displacement_m;
    let ovary_max = moved.right_ovary_max_displacement_m;
    let sim_s = sim.steps as f64 * sim.manifest.dt_s;
    let f = sim.tool_force.last().copied().unwrap_or([0.0; 3]);
    println!("summary:");
    println!(
        "  force of the right tube on the probe at the end (capsule contact, summed by the host from the boards' packets): [{:.4e}, {:.4e}, {:.4e}] N (|F| = {:.4e} N)",
        f[0],
        f[1],
        f[2],
        norm(f)
    );
    println!(
        "  right tube: largest displacement {:.3} mm; right ovary (pressed by the tube through their contact pair): {:.3} mm",
        tube_max * 1e3,
        ovary_max * 1e3
    );
    println!(
        "  {} steps, {:.3} s simulated in {:.2} s wall on {} emulated boards: real-time factor {:.3}",
        sim.steps, sim_s, sim.wall_s, sim.boards.len(), sim_s / sim.wall_s
    );
    println!(
        "  ParaView (what the graphics engine received): {}; picture of the last frame: {}; tool force per step: {}; report: {}",
        out.join("frames/series.pvd").display(),
        out.join("final.png").display(),
        out.join("tool_force.csv").display(),
        out.join("report.json").display()
    );
    Ok(())
}
