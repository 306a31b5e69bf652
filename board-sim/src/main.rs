//! `board-sim run DIR`: run a compiled machine on host threads over emulated links.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use board_sim::faults::FaultSpec;
use board_sim::timing::{model, SimTiming};
use board_sim::{run, SimOptions};
use clap::{Parser, Subcommand};
use host_tools::output::write_nodes_csv;
use host_tools::problem::Problem;
use host_tools::scene::builtin::builtin_scene;
use host_tools::scene::Scene;

mod campaign;
mod graphics;

#[derive(Parser)]
#[command(
    name = "board-sim",
    version,
    about = "Run a compiled board array on host threads over emulated links",
    after_help = "Examples:\n  board-sim builtin --level coarse --out out/builtin\n  pe compile --builtin --level coarse --boards 2x2x2 -o out/compiled\n  board-sim run out/compiled --vtk out/frames --tool-force out/tool_force.csv"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the images of DIR (written by `pe compile`).
    #[command(
        after_help = "Example:\n  pe compile --builtin --level coarse --boards 2x2x2 -o out/compiled\n  board-sim run out/compiled --vtk out/frames --tool-force out/tool_force.csv --report out/report.json"
    )]
    Run {
        dir: PathBuf,
        #[command(flatten)]
        args: RunArgs,
    },
    /// Benchmark: steps per second of the serial solver and of board-sim on the same scene,
    /// in one run, as a ratio.
    #[command(
        after_help = "Example:\n  board-sim bench --level coarse --boards 2x2x2 --steps 500"
    )]
    Bench {
        #[arg(long, default_value = "medium")]
        level: String,
        #[arg(long, default_value = "4x4x4")]
        boards: String,
        #[arg(long, default_value_t = 1000)]
        steps: u64,
    },
    /// A seeded fault campaign on the machine in DIR: RUNS short runs, each with faults
    /// drawn from SEED (drop, corrupt, delay, stall, alone and mixed; with --swap-from, also
    /// one board's image taken from another compilation), each classified as bit-identical
    /// to the clean run or stopped naming the true first cause; a summary.
    #[command(
        after_help = "Example (scripts/fault-campaign.sh does this):\n  pe compile scenes/seed-box.toml --boards 2x2x2 -o out/campaign\n  sed 's/^youngs_modulus = .*/youngs_modulus = 4.5e3/' scenes/seed-box.toml > /tmp/stiffer.toml\n  pe compile /tmp/stiffer.toml --boards 2x2x2 -o out/campaign-other\n  board-sim campaign out/campaign --swap-from out/campaign-other --runs 1000 --seed 1 --steps 100"
    )]
    Campaign {
        dir: PathBuf,
        #[arg(long, default_value_t = 1000)]
        runs: u64,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long, default_value_t = 100)]
        steps: u64,
        /// Without link recovery (every fault must stop the run, naming its cause).
        #[arg(long)]
        no_recovery: bool,
        /// Another compilation of the same machine (e.g. another Young's modulus): some
        /// runs take one board's image from it (alone, with its manifest, or with the
        /// host's manifest check off), and must be refused naming that board.
        #[arg(long, value_name = "DIR2")]
        swap_from: Option<PathBuf>,
    },
    /// The firmware itself on an emulated array: one QEMU mps2-an500 (Cortex-M7) per
    /// board of DIR (written by `pe compile --profile qemu-mps2-an500`), their UARTs wired
    /// as the machine's cables, this process the global network, host and graphics engine.
    /// Writes the merged final state; exits non-zero, naming boards, links and steps, when a
    /// board faults, dies or is miscabled.
    #[command(
        after_help = "Example (scripts/qemu-array.sh does this on 2x1x1, 2x2x1 and 2x2x2):\n  pe compile scenes/seed-box.toml --boards 2x2x2 --profile qemu-mps2-an500 --steps 300 -o out/q8\n  board-sim qemu out/q8 --output-nodes out/q8-qemu.csv\n  board-sim run out/q8 --output-nodes out/q8-sim.csv && pe compare out/q8-sim.csv out/q8-qemu.csv\n  board-sim qemu out/q8 --kill 1,0,0@3     # a board dies: its neighbours name the dead link\n  board-sim qemu out/q8 --cross 0,0,0:+x,0,0,0:+y   # two cables crossed: refused at boot"
    )]
    Qemu {
        dir: PathBuf,
        /// node,x_m,y_m,z_m,ux_m,uy_m,uz_m of every mesh node at the end, as the boards
        /// reported it.
        #[arg(long)]
        output_nodes: Option<PathBuf>,
        /// Run report (JSON): wall time per step, per-board exits, link and global bytes.
        #[arg(long)]
        report: Option<PathBuf>,
        /// The firmware ELF (default: built with cargo for the images' precision and
        /// integration).
        #[arg(long)]
        firmware: Option<PathBuf>,
        /// Where the per-board ELFs and schedule blobs go (default DIR/qemu).
        #[arg(long)]
        images: Option<PathBuf>,
        /// End board X,Y,Z's QEMU S seconds after every board began (X,Y,Z@S): each has
        /// told the host its compilation id, before its step 0.
        #[arg(long)]
        kill: Option<String>,
        /// Swap the far ends of the cables at two connectors (X,Y,Z:FACE,X,Y,Z:FACE, FACE
        /// one of +x -x +y -y +z -z).
        #[arg(long, allow_hyphen_values = true)]
        cross: Option<String>,
        /// The whole run's bound (s).
        #[arg(long, default_value_t = 1800.0)]
        timeout_s: f64,
        /// The emulator.
        #[arg(long, default_value = "qemu-system-arm")]
        qemu: PathBuf,
        #[arg(long)]
        quiet: bool,
    },
    /// The main job: compile the built-in scene (uterus, tubes, probe) for a board mesh and
    /// run it, writing OUT/images, OUT/frames (ParaView), OUT/report.json and a summary.
    #[command(after_help = "Example:\n  board-sim builtin --level coarse --out out/builtin")]
    Builtin {
        /// Mesh level: coarse | medium | fine.
        #[arg(long, default_value = "medium")]
        level: String,
        /// Machine size.
        #[arg(long, default_value = "4x4x4")]
        boards: String,
        /// Output directory.
        #[arg(long, default_value = "out/builtin")]
        out: PathBuf,
        /// Stop after N steps.
        #[arg(long)]
        steps: Option<u64>,
        #[arg(long)]
        quiet: bool,
    },
}

#[derive(clap::Args, Default)]
struct RunArgs {
    /// node,x_m,y_m,z_m,ux_m,uy_m,uz_m of every mesh node at the end.
    #[arg(long)]
    output_nodes: Option<PathBuf>,
    /// Run report (JSON): as `pe solve`, plus per-link traffic, waiting and the link model.
    #[arg(long)]
    report: Option<PathBuf>,
    /// ParaView time series into this directory: the surface frames the graphics engine
    /// received over the global network (every graphics interval).
    #[arg(long)]
    vtk: Option<PathBuf>,
    /// PNG of the last surface frame the graphics engine received.
    #[arg(long)]
    png: Option<PathBuf>,
    /// step,time_s,tool,fx_n,fy_n,fz_n: the force of the tissue on each tool every step, as the
    /// host summed it from the boards' packets (what a haptic device renders).
    #[arg(long)]
    tool_force: Option<PathBuf>,
    /// Stop after N steps.
    #[arg(long)]
    steps: Option<u64>,
    /// Stop after this much simulated time (s).
    #[arg(long)]
    duration: Option<f64>,
    /// Inject faults: seed=S,drop=P,corrupt=P,delay=MS,stall=X.Y.Z@STEP[,on=all|links|global].
    /// drop and corrupt apply to each point-to-point frame and each global packet a board
    /// sends (on=links or on=global for one kind only); delay to the frames; a stalled board
    /// sends no more frames or packets from STEP on
    #[arg(long)]
    faults: Option<String>,
    /// Run without link-level and global-network recovery: every lost or damaged frame or
    /// packet stops the run (for fault detection). Default: frames and global packets are
    /// numbered, acknowledged and retransmitted.
    #[arg(long)]
    no_recovery: bool,
    /// Run the boards' element batches on the firmware's scalar loop, as a board does.
    /// Default: on the host's SIMD lanes (AVX where the CPU has it), which compute the same
    /// bits.
    #[arg(long)]
    scalar_kernel: bool,
    /// A link silent this long is a fault (s).
    #[arg(long, default_value_t = 10.0)]
    link_timeout_s: f64,
    /// Link bandwidth for the timing model (bytes/s; default from the board profile).
    #[arg(long)]
    link_bandwidth: Option<f64>,
    /// Link latency for the timing model (s).
    #[arg(long)]
    link_latency_s: Option<f64>,
    /// Host threads to multiplex the boards over (default: the machine's cores; as many as
    /// boards runs one thread per board).
    #[arg(long)]
    workers: Option<usize>,
    /// Storage per board: `exact` (what each image needs) or `board` (what the firmware of
    /// the manifest's profile holds: an image the board would refuse is refused here).
    #[arg(long, value_enum, default_value_t = Storage::Exact)]
    storage: Storage,
    #[arg(long)]
    quiet: bool,
}

/// `--storage`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
enum Storage {
    #[default]
    Exact,
    Board,
}

fn main() -> Result<()> {
    host_tools::output::exit_quietly_when_stdout_closes();
    let Cli { command } = Cli::parse();
    match command {
        Command::Run { dir, args } => execute(&dir, args).map(|_| ()),
        Command::Builtin {
            level,
            boards,
            out,
            steps,
            quiet,
        } => builtin(&level, &boards, &out, steps, quiet),
        Command::Bench {
            level,
            boards,
            steps,
        } => bench(&level, &boards, steps),
        Command::Campaign {
            dir,
            runs,
            seed,
            steps,
            no_recovery,
            swap_from,
        } => campaign::campaign(&dir, swap_from.as_deref(), runs, seed, steps, !no_recovery),
        Command::Qemu {
            dir,
            output_nodes,
            report,
            firmware,
            images,
            kill,
            cross,
            timeout_s,
            qemu,
            quiet,
        } => {
            let opts = board_sim::qemu::ArrayOptions {
                qemu,
                firmware,
                images,
                deadline: Duration::from_secs_f64(timeout_s.max(0.0)),
                kill: kill.as_deref().map(parse_kill).transpose()?,
                cross: cross.as_deref().map(parse_cross).transpose()?,
                quiet,
            };
            qemu_array(&dir, &opts, output_nodes.as_deref(), report.as_deref())
        }
    }
}

/// `--kill X,Y,Z@S`.
fn parse_kill(s: &str) -> Result<([usize; 3], Duration)> {
    let bad = || anyhow::anyhow!("--kill {s:?}: expected X,Y,Z@SECONDS, e.g. 1,0,0@3");
    let (b, t) = s.split_once('@').ok_or_else(bad)?;
    let [x, y, z] = board_sim::qemu::parse_board(b).ok_or_else(bad)?;
    let t: f64 = t.trim().parse().map_err(|_| bad())?;
    if !(t.is_finite() && t >= 0.0) {
        return Err(bad());
    }
    Ok(([x, y, z], Duration::from_secs_f64(t)))
}

/// `--cross X,Y,Z:FACE,X,Y,Z:FACE`.
fn parse_cross(s: &str) -> Result<[board_sim::qemu::Connector; 2]> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 6 {
        anyhow::bail!("--cross {s:?}: expected X,Y,Z:FACE,X,Y,Z:FACE, e.g. 0,0,0:+x,0,0,0:+y");
    }
    let a = board_sim::qemu::Connector::parse(&parts[..3].join(","))?;
    let b = board_sim::qemu::Connector::parse(&parts[3..].join(","))?;
    Ok([a, b])
}

/// `board-sim qemu`: runs the array, writes the outputs, prints a summary.
fn qemu_array(
    dir: &std::path::Path,
    opts: &board_sim::qemu::ArrayOptions,
    output_nodes: Option<&std::path::Path>,
    report: Option<&std::path::Path>,
) -> Result<()> {
    let manifest = host_tools::compile::read_manifest(dir)?;
    eprintln!(
        "{}: {} boards ({}x{}x{}) under QEMU mps2-an500, {} steps",
        manifest.scene,
        manifest.boards.len(),
        manifest.machine[0],
        manifest.machine[1],
        manifest.machine[2],
        manifest.steps
    );
    let out = match board_sim::qemu::run_array(dir, opts) {
        Ok(o) => o,
        Err(e) => {
            if let (Some(p), Some(f)) = (report, e.downcast_ref::<board_sim::qemu::ArrayFault>()) {
                let j = serde_json::json!({
                    "finished": false,
                    "faults": f.lines,
                    "boards": f.boards,
                });
                std::fs::write(p, serde_json::to_string_pretty(&j)?)
                    .with_context(|| format!("writing {}", p.display()))?;
            }
            return Err(e);
        }
    };
    let max_u = host_tools::firmware::max_abs(&out.displacements);
    let per_step = out.wall_s / out.steps.max(1) as f64;
    println!(
        "{} steps on {} emulated boards in {:.2} s wall: {:.3} ms per step (QEMU start included); max |u| component {:.4e} m; {} global packets between boards, {} to the host and graphics ({} surface frames)",
        out.steps,
        out.boards.len(),
        out.wall_s,
        1e3 * per_step,
        max_u,
        out.packets_between_boards,
        out.packets_to_sinks,
        out.graphics_frames
    );
    if let Some(p) = output_nodes {
        let problem = manifest_problem(&manifest)?;
        write_nodes_csv(p, &problem.mesh, &out.displacements)?;
    }
    if let Some(p) = report {
        let j = serde_json::json!({
            "finished": true,
            "machine": out.machine,
            "steps": out.steps,
            "wall_s": out.wall_s,
            "wall_s_per_step": per_step,
            "max_displacement_component_m": max_u,
            "packets_between_boards": out.packets_between_boards,
            "packets_to_sinks": out.packets_to_sinks,
            "graphics_frames": out.graphics_frames,
            "boards": out.boards,
        });
        std::fs::write(p, serde_json::to_string_pretty(&j)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}

fn bench(level: &str, boards: &str, steps: u64) -> Result<()> {
    let mut scene = builtin_scene(level)?;
    scene.solver.steps = Some(steps);
    let problem = Problem::from_scene(&scene, std::path::Path::new("."))?;
    problem.print_notes();
    let t = std::time::Instant::now();
    let serial = host_tools::solver::run(&problem, "serial", &mut ())?;
    let serial_s = t.elapsed().as_secs_f64();
    let dir = std::env::temp_dir().join(format!("board-sim-bench-{}", std::process::id()));
    let name = format!("builtin:{level}");
    let machine = host_tools::compile::partition::Machine::parse(boards)?;
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
        let d = host_tools::firmware::max_rel_diff(&serial.displacements, &out.displacements);
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

/// The main job (see `Command::Builtin`).
fn builtin(
    level: &str,
    boards: &str,
    out: &std::path::Path,
    steps: Option<u64>,
    quiet: bool,
) -> Result<()> {
    let scene = builtin_scene(level)?;
    let problem = Problem::from_scene(&scene, std::path::Path::new("."))?;
    problem.print_notes();
    let images = out.join("images");
    let machine = host_tools::compile::partition::Machine::parse(boards)?;
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
        output_nodes: Some(out.join("nodes.csv")),
        report: Some(out.join("report.json")),
        vtk: Some(out.join("frames")),
        png: Some(out.join("final.png")),
        tool_force: Some(out.join("tool_force.csv")),
        steps,
        link_timeout_s: 10.0,
        quiet,
        ..Default::default()
    };
    let (sim, pr) = execute(&images, args)?;
    // What a user of the trainer wants to know: what the probe did to the tube (and, through
    // their contact pair, the tube to the ovary).
    let moved = host_tools::scene::builtin::builtin_summary(&pr.mesh, &sim.displacements);
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
        (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt()
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

/// Runs a compiled machine and writes the requested outputs; returns the run and the scene.
fn execute(dir: &std::path::Path, a: RunArgs) -> Result<(board_sim::SimOutput, Problem)> {
    let manifest = host_tools::compile::read_manifest(dir)?;
    let mut opts = sim_options(&a, &manifest, dir)?;
    let total = opts.steps.unwrap_or(manifest.steps).min(manifest.steps);
    // The mesh, for outputs: from the scene the manifest names.
    let problem = manifest_problem(&manifest)?;
    let (elements, graphics_stream) = compile_report_facts(dir)?;
    if a.vtk.is_some() && !graphics_stream {
        opts.frame_every = ((0.04 / manifest.dt_s).round() as u64).max(1);
    }
    eprintln!(
        "{}: {} boards ({}x{}x{}), {} steps of {:.3e} s",
        manifest.scene,
        manifest.boards.len(),
        manifest.machine[0],
        manifest.machine[1],
        manifest.machine[2],
        total,
        manifest.dt_s
    );
    let bar = (!a.quiet).then(|| host_tools::output::progress_bar(total));
    let out = run(dir, &opts, &mut |s, _| {
        if let Some(b) = &bar {
            b.set_position(s);
        }
    });
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let out = match out {
        Ok(o) => o,
        Err(e) => {
            if let (Some(p), Some(f)) = (&a.report, e.downcast_ref::<board_sim::SimFault>()) {
                write_fault_report(p, &manifest, f)?;
            }
            return Err(e);
        }
    };
    let sim_s = out.steps as f64 * manifest.dt_s;
    let max = out
        .displacements
        .iter()
        .enumerate()
        .map(|(k, u)| (k, (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt()))
        .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    println!(
        "{} steps on {} boards in {:.2} s: {:.1} steps/s, real-time factor {:.3}; max |u| = {:.4e} m",
        out.steps, out.boards.len(), out.wall_s, out.steps as f64 / out.wall_s, sim_s / out.wall_s, max.1,
    );
    let prescribed = problem
        .node_kind
        .iter()
        .filter(|k| matches!(k, host_tools::problem::NodeKind::Prescribed(_)))
        .count();
    if prescribed > 0 {
        let f = out.reaction_prescribed;
        println!(
            "  prescribed reaction ({prescribed} prescribed nodes on the tissue, at the end) = [{:.4e}, {:.4e}, {:.4e}] N",
            f[0], f[1], f[2]
        );
    }
    if let Some(r) = recovery_summary(&out) {
        println!(
            "link recovery: {} frames ({} bytes) retransmitted after {} nacks; {} bytes added on the links ({:.2}% of the frames' bytes: envelopes, retransmissions, acks)",
            r["retransmitted_frames"],
            r["retransmitted_bytes"],
            r["nacks_sent"],
            r["faces_overhead_bytes"],
            100.0 * r["overhead_fraction_of_frame_bytes"].as_f64().unwrap_or(0.0)
        );
        let g = &r["global"];
        if !g.is_null() {
            println!(
                "global recovery: {} packets ({} bytes) retransmitted ({} after a timeout, {} nacks received); {} bytes added on the global network ({:.2}% of the packets' bytes: envelopes, retransmissions, acks of boards and sinks)",
                g["retransmitted_packets"],
                g["retransmitted_bytes"],
                g["timeouts"],
                g["nacks_received"],
                g["overhead_bytes"],
                100.0 * g["overhead_fraction_of_packet_bytes"].as_f64().unwrap_or(0.0)
            );
        }
    }
    let modelled = link_model(dir, &manifest, &a)?;
    // The frames the graphics engine could assemble (every surface node received): the
    // ones written to the ParaView series and counted in the summary and the report.
    let frames = graphics::surface_frames(&problem, &out);
    let paraview_frames = write_outputs(&a, &problem, &out, &frames, &manifest, graphics_stream)?;
    let entry_bytes = link_proto::payload::node_entry_len(problem.solver.precision.wire());
    let global = global_summary(&out, sim_s, frames.len(), entry_bytes as f64);
    if let Some(g) = &global {
        println!("{}", g.text);
    }
    if let Some(p) = &a.report {
        let facts = RunFacts {
            elements,
            sim_s,
            max_displacement: max.1,
            paraview_frames,
        };
        write_report(p, &manifest, &out, &facts, &modelled, global.as_ref())?;
    }
    Ok((out, problem))
}

/// The simulation options from the command line (steps from `--steps` or `--duration`).
fn sim_options(
    a: &RunArgs,
    manifest: &host_tools::compile::Manifest,
    dir: &std::path::Path,
) -> Result<SimOptions> {
    let storage = match a.storage {
        Storage::Exact => board_sim::StorageSizing::Exact,
        Storage::Board => board_sim::StorageSizing::Board(
            pe_firmware::profile::profile(&manifest.profile).with_context(|| {
                format!(
                    "{}: unknown board profile {:?} in manifest.json",
                    dir.display(),
                    manifest.profile
                )
            })?,
        ),
    };
    let mut opts = SimOptions {
        link_timeout: Duration::from_secs_f64(a.link_timeout_s),
        workers: a.workers,
        storage,
        batched: !a.scalar_kernel,
        ..Default::default()
    };
    if a.no_recovery {
        opts.recovery = None;
        opts.global_recovery = None;
    }
    if let Some(f) = &a.faults {
        let spec = FaultSpec::parse(f)?;
        eprintln!(
            "fault injection seed {} (replay with --faults {f})",
            spec.seed
        );
        opts.faults = Some(spec);
    }
    opts.steps = match (a.steps, a.duration) {
        (Some(n), _) => Some(n),
        (None, Some(d)) => Some((d / manifest.dt_s).ceil() as u64),
        _ => None,
    };
    Ok(opts)
}

/// The problem of the scene the manifest names (built-in or a file), for the outputs.
fn manifest_problem(manifest: &host_tools::compile::Manifest) -> Result<Problem> {
    let scene = match manifest.scene_source.strip_prefix("builtin:") {
        Some(level) => builtin_scene(level)?,
        None => Scene::from_file(std::path::Path::new(&manifest.scene_source))?,
    };
    let sdir = std::path::Path::new(&manifest.scene_source)
        .parent()
        .map(|p| p.to_path_buf())
        .unwrap_or_default();
    Problem::from_scene(&scene, &sdir)
        .with_context(|| format!("loading scene {} for outputs", manifest.scene_source))
}

/// The link timing model of the run's images (profile links unless overridden), printed.
fn link_model(
    dir: &std::path::Path,
    manifest: &host_tools::compile::Manifest,
    a: &RunArgs,
) -> Result<board_sim::timing::StepTiming> {
    let profile =
        pe_firmware::profile::profile(&manifest.profile).unwrap_or(pe_firmware::profile::PE_BOARD);
    let precision = host_tools::scene::settings::precision_from_name(&manifest.precision)
        .map_err(|e| anyhow::anyhow!("{}: {e}", dir.join("manifest.json").display()))?;
    let mut timing = SimTiming::for_precision(&profile, precision);
    if let Some(b) = a.link_bandwidth {
        timing.link_bytes_per_s = b;
    }
    if let Some(l) = a.link_latency_s {
        timing.link_latency_s = l;
    }
    if !a.no_recovery {
        timing.frame_overhead_bytes = link_proto::reliable::OVERHEAD;
    }
    let modelled = model(dir, manifest.machine, timing)?;
    if !a.no_recovery {
        let bare = model(
            dir,
            manifest.machine,
            SimTiming {
                frame_overhead_bytes: 0,
                ..timing
            },
        )?;
        println!(
            "link model: recovery's envelope ({} bytes a frame) makes the slowest board's step {:.2} us longer ({:.1} us against {:.1} us)",
            link_proto::reliable::OVERHEAD,
            (modelled.step_s - bare.step_s) * 1e6,
            modelled.step_s * 1e6,
            bare.step_s * 1e6
        );
    }
    let check = match modelled.check_step_s {
        Some(c) => {
            let [x, y, z] = modelled.check_slowest_board;
            format!(
                ", a check step (every {} steps: the candidate search) {:.1} us on board ({x},{y},{z})",
                modelled.check_interval_steps,
                c * 1e6
            )
        }
        None => String::new(),
    };
    println!(
        "link model ({}): a step takes {:.1} us on the slowest board ({:.1} us computing){check}, dt = {:.1} us: {}",
        profile.name, modelled.step_s * 1e6, modelled.compute_s * 1e6, modelled.dt_s * 1e6,
        if modelled.real_time { "keeps real time" } else { "does NOT keep real time" }
    );
    Ok(modelled)
}

/// Nodes CSV, ParaView series, PNG of the last frame and tool forces, as asked; returns the
/// number of frames in the ParaView series (None without `--vtk`).
fn write_outputs(
    a: &RunArgs,
    problem: &Problem,
    out: &board_sim::SimOutput,
    frames: &[graphics::SurfaceFrame],
    manifest: &host_tools::compile::Manifest,
    graphics_stream: bool,
) -> Result<Option<usize>> {
    if let Some(p) = &a.output_nodes {
        write_nodes_csv(p, &problem.mesh, &out.displacements)?;
    }
    let mut written = None;
    if let Some(d) = &a.vtk {
        written = Some(if graphics_stream {
            // What the graphics engine received.
            graphics::write_surface_series(d, problem, frames)?
        } else {
            graphics::write_volume_series(d, problem, out, manifest.dt_s)?
        });
    }
    if let Some(p) = &a.png {
        if let Some(last) = frames.last() {
            graphics::render_frame(p, problem, last, out)?;
        }
    }
    if let Some(p) = &a.tool_force {
        write_tool_force(p, out)?;
    }
    Ok(written)
}

/// step,time_s,tool,fx_n,fy_n,fz_n: the force on each tool every step (N).
fn write_tool_force(p: &std::path::Path, out: &board_sim::SimOutput) -> Result<()> {
    let rows = out.tool_force.iter().enumerate().map(|(k, f)| {
        let (step, t) = (k / out.tools.max(1), k % out.tools.max(1));
        [
            step.to_string(),
            format!("{:e}", step as f64 * out.dt_s),
            t.to_string(),
            format!("{:e}", f[0]),
            format!("{:e}", f[1]),
            format!("{:e}", f[2]),
        ]
    });
    host_tools::output::write_csv(p, &["step", "time_s", "tool", "fx_n", "fy_n", "fz_n"], rows)
}

/// Figures of a run the report states besides the run's own output.
struct RunFacts {
    elements: usize,
    sim_s: f64,
    max_displacement: f64,
    /// Frames in the ParaView series (`--vtk`).
    paraview_frames: Option<usize>,
}

/// The run report (JSON): as `pe solve`'s, plus per-link traffic, waiting and the link model.
fn write_report(
    p: &std::path::Path,
    manifest: &host_tools::compile::Manifest,
    out: &board_sim::SimOutput,
    facts: &RunFacts,
    modelled: &board_sim::timing::StepTiming,
    global: Option<&GlobalSummary>,
) -> Result<()> {
    let RunFacts {
        elements,
        sim_s,
        max_displacement,
        paraview_frames,
    } = *facts;
    let links: Vec<serde_json::Value> = out
        .boards
        .iter()
        .map(|b| serde_json::json!({ "board": b.board, "frames_sent": b.frames_sent, "bytes_sent": b.bytes_sent, "wait_s": b.wait_s, "recovery": b.recovery }))
        .collect();
    let rep = serde_json::json!({
        "scene": manifest.scene,
        "machine": manifest.machine,
        "precision": manifest.precision,
        "integration": manifest.integration,
        "steps": out.steps,
        "dt_s": manifest.dt_s,
        "simulated_s": sim_s,
        "elements": elements,
        "nodes": out.displacements.len(),
        "wall_s": out.wall_s,
        "element_steps_per_s": elements as f64 * out.steps as f64 / out.wall_s,
        "real_time_factor": sim_s / out.wall_s,
        "kinetic_energy_final": out.kinetic_energy,
        "max_displacement": max_displacement,
        "prescribed_reaction_n": out.reaction_prescribed,
        "fixed_reaction_n": out.reaction_fixed,
        "wait_s_total": out.boards.iter().map(|b| b.wait_s).sum::<f64>(),
        "bytes_sent_total": out.boards.iter().map(|b| b.bytes_sent.iter().sum::<u64>()).sum::<u64>(),
        "boards": links,
        "link_model": modelled,
        "faults_injected": out.injected,
        "recovery": recovery_summary(out),
        "paraview_frames": paraview_frames,
        "global_network": global.map(|g| &g.json),
    });
    std::fs::write(p, serde_json::to_string_pretty(&rep)?)
        .with_context(|| format!("writing {}", p.display()))
}

/// The report of a run that stopped on a fault: the first cause, the observation that
/// detected it, the consequences (every other board's fault or wait) and what was injected.
fn write_fault_report(
    p: &std::path::Path,
    manifest: &host_tools::compile::Manifest,
    f: &board_sim::SimFault,
) -> Result<()> {
    let obs = |o: &board_sim::Observed| {
        serde_json::json!({
            "board": o.fault.board,
            "step": o.fault.step,
            "link": o.face().map(|f| format!("{f:?}")),
            "waiting": o.waiting,
            "text": o.to_string(),
        })
    };
    let rep = serde_json::json!({
        "scene": manifest.scene,
        "machine": manifest.machine,
        "stopped": true,
        "cause": f.cause,
        "detected": f.observed.get(f.cause.detected).map(obs),
        "consequences": f.consequences().map(obs).collect::<Vec<_>>(),
        "faults_injected": f.injected,
    });
    std::fs::write(p, serde_json::to_string_pretty(&rep)?)
        .with_context(|| format!("writing {}", p.display()))
}

/// Link recovery's totals over the boards (None without recovery): retransmitted frames
/// and bytes, nacks, and the bytes recovery added against the frames' own.
fn recovery_summary(out: &board_sim::SimOutput) -> Option<serde_json::Value> {
    let rs: Vec<&board_sim::LinkRecovery> = out
        .boards
        .iter()
        .filter_map(|b| b.recovery.as_ref())
        .collect();
    if rs.is_empty() {
        return None;
    }
    let sum = |g: fn(&board_sim::LinkRecovery) -> &[u64; 6]| {
        rs.iter().map(|r| g(r).iter().sum::<u64>()).sum::<u64>()
    };
    let frame_bytes: u64 = out
        .boards
        .iter()
        .map(|b| b.bytes_sent.iter().sum::<u64>())
        .sum();
    let overhead: u64 = rs.iter().map(|r| r.overhead_bytes()).sum();
    let gs: Vec<&link_proto::reliable_global::GlobalRecovery> =
        rs.iter().filter_map(|r| r.global.as_ref()).collect();
    let global_overhead: u64 = gs.iter().map(|g| g.overhead_bytes()).sum();
    let sink = out.sink_recovery.unwrap_or_default();
    let packet_bytes: u64 = out.boards.iter().map(|b| b.global.bytes_sent).sum();
    let gsum = |f: fn(&link_proto::reliable_global::GlobalRecovery) -> u64| {
        gs.iter().map(|g| f(g)).sum::<u64>()
    };
    let global = (!gs.is_empty()).then(|| {
        serde_json::json!({
            "data_packets": gsum(|g| g.data_packets),
            "retransmitted_packets": gsum(|g| g.retransmitted_packets),
            "retransmitted_bytes": gsum(|g| g.retransmitted_bytes),
            "timeouts": gsum(|g| g.timeouts),
            "nacks_sent": gsum(|g| g.nacks_sent) + sink.nacks_sent,
            "nacks_received": gsum(|g| g.nacks_received),
            "acks_sent": gsum(|g| g.acks_sent) + sink.acks_sent,
            "control_bytes": gsum(|g| g.control_bytes) + sink.control_bytes,
            "damaged_received": gsum(|g| g.damaged) + sink.damaged,
            "gaps": gsum(|g| g.gaps) + sink.gaps,
            "duplicates": gsum(|g| g.duplicates) + sink.duplicates,
            "sinks": sink,
            "overhead_bytes": global_overhead + sink.control_bytes,
            "overhead_fraction_of_packet_bytes":
                (global_overhead + sink.control_bytes) as f64 / packet_bytes.max(1) as f64,
        })
    });
    Some(serde_json::json!({
        "global": global,
        "faces_overhead_bytes": overhead - global_overhead,
        "retransmitted_frames": sum(|r| &r.retransmitted_frames),
        "retransmitted_bytes": sum(|r| &r.retransmitted_bytes),
        "nacks_sent": sum(|r| &r.nacks_sent),
        "acks_sent": sum(|r| &r.acks_sent),
        "statuses_sent": sum(|r| &r.statuses_sent),
        "control_bytes": sum(|r| &r.control_bytes),
        "damaged_received": sum(|r| &r.damaged),
        "gaps": sum(|r| &r.gaps),
        "duplicates": sum(|r| &r.duplicates),
        "overhead_bytes": overhead + sink.control_bytes,
        "overhead_fraction_of_frame_bytes": (overhead - global_overhead) as f64 / frame_bytes.max(1) as f64,
    }))
}

struct GlobalSummary {
    text: String,
    json: serde_json::Value,
}

/// Global-network figures of a run beside the seed's (about 300 collision vectors per
/// step, 72 MB/s, and 18 MB/s of graphics for its 2000-element model). `complete`: the
/// graphics frames with every surface node received (the surface series' frames); the
/// others were started too close to the end of the run to finish (a frame's chunks are
/// spread over several steps). `entry_bytes`: one contact-node entry's bytes (the index and
/// three values of the run's precision).
fn global_summary(
    out: &board_sim::SimOutput,
    sim_s: f64,
    complete: usize,
    entry_bytes: f64,
) -> Option<GlobalSummary> {
    let g: Vec<&pe_firmware::runtime::GlobalStats> = out.boards.iter().map(|b| &b.global).collect();
    let packets: u64 = g.iter().map(|s| s.packets_sent).sum();
    if packets == 0 {
        return None;
    }
    let steps = out.steps.max(1) as f64;
    let vectors = g.iter().map(|s| s.node_vectors).sum::<u64>() as f64 / steps;
    let bytes = g.iter().map(|s| s.bytes_sent).sum::<u64>() as f64;
    let gbytes = g.iter().map(|s| s.graphics_bytes).sum::<u64>() as f64;
    let boxes = g.iter().map(|s| s.box_packets).sum::<u64>();
    let checks = g.iter().map(|s| s.checks).max().unwrap_or(0);
    let cand = g.iter().map(|s| s.candidates_max).max().unwrap_or(0);
    let peak: Vec<f64> = (0..out.tools)
        .map(|t| {
            out.tool_force
                .iter()
                .skip(t)
                .step_by(out.tools.max(1))
                .map(|f| (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt())
                .fold(0.0, f64::max)
        })
        .collect();
    let last: Vec<[f64; 3]> = if out.tools > 0 {
        out.tool_force[out.tool_force.len().saturating_sub(out.tools)..].to_vec()
    } else {
        vec![]
    };
    let incomplete = out.graphics.len().saturating_sub(complete);
    let text = format!(
        "global network: {packets} packets, {:.1} MB/s in all; contact: {vectors:.1} node vectors per step ({:.1} MB/s at this step rate; the seed: ~300 vectors, 72 MB/s), {boxes} bounding-box packets over {checks} checks, at most {cand} candidates on a board; graphics: {complete} complete frames (the surface series' frames){}, {:.2} MB/s (the seed: 18 MB/s); tool force at the end {:?} N, peak {:?} N",
        bytes / sim_s / 1e6,
        vectors * entry_bytes / (sim_s / steps) / 1e6,
        match incomplete {
            0 => String::new(),
            n => format!(" and {n} started too close to the end to complete"),
        },
        gbytes / sim_s / 1e6,
        last,
        peak
    );
    let json = serde_json::json!({
        "packets": packets,
        "bytes_per_s": bytes / sim_s,
        "contact_vectors_per_step": vectors,
        "contact_bytes_per_s": vectors * entry_bytes / (sim_s / steps),
        "seed_contact_vectors_per_step": 300,
        "seed_contact_bytes_per_s": 72e6,
        "box_packets": boxes,
        "checks": checks,
        "candidates_max": cand,
        "graphics_frames": complete,
        "graphics_frames_incomplete": incomplete,
        "graphics_bytes_per_s": gbytes / sim_s,
        "seed_graphics_bytes_per_s": 18e6,
        "tool_force_final_n": last,
        "tool_force_peak_n": peak,
    });
    Some(GlobalSummary { text, json })
}

/// From the compile report: the scene's elements, and whether the images send surface
/// frames to the graphics engine.
fn compile_report_facts(dir: &std::path::Path) -> Result<(usize, bool)> {
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json"))?)?;
    Ok((
        r["elements"].as_u64().unwrap_or(0) as usize,
        r["graphics"]["interval_steps"].as_u64().unwrap_or(0) > 0,
    ))
}
