//! `pe`: the command line of the soft-tissue simulator's host tools.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use host_tools::output;
use host_tools::problem::Problem;
use host_tools::scene::builtin::builtin_scene;
use host_tools::scene::settings::{IntegrationArg, PrecisionArg};
use host_tools::scene::Scene;
use host_tools::solver::{self, Observer, StepState};

#[derive(Parser)]
#[command(
    name = "pe",
    version,
    about = "Soft-tissue simulator host tools",
    after_help = "Examples:\n  pe solve --builtin --level coarse --vtk out/frames --output-nodes out/nodes.csv\n  pe compile --builtin --level coarse --boards 2x2x2 -o out/compiled\n  board-sim run out/compiled --output-nodes out/board.csv\n  pe compare out/nodes.csv out/board.csv"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Args)]
struct SceneArgs {
    /// Scene file (TOML).
    scene: Option<PathBuf>,
    /// Use the built-in scene (uterus, both tubes, probe) instead of a file.
    #[arg(long, conflicts_with = "scene")]
    builtin: bool,
    /// Mesh level of the built-in scene: coarse (~300), medium (~2000), fine (~20000).
    #[arg(long, default_value = "medium")]
    level: String,
}

impl SceneArgs {
    fn load(&self) -> Result<(Scene, PathBuf, String)> {
        if self.builtin {
            return Ok((
                builtin_scene(&self.level)?,
                PathBuf::from("."),
                format!("builtin:{}", self.level),
            ));
        }
        let path = self
            .scene
            .as_ref()
            .context("give a scene file or --builtin")?;
        let scene = Scene::from_file(path)?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok((scene, dir, path.display().to_string()))
    }
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene on this machine (the reference solver every board run is compared with).
    #[command(
        after_help = "Example:\n  pe solve scenes/liver.toml --vtk out/frames --output-nodes out/nodes.csv --report out/report.json\n  (open out/frames/series.pvd in ParaView; Warp By Vector on displacement_m shows the deformed shape)"
    )]
    Solve {
        #[command(flatten)]
        scene: SceneArgs,
        /// Solver threads (default: all cores). The result is the same, bit for bit,
        /// whatever the count.
        #[arg(long)]
        threads: Option<usize>,
        /// Final nodal positions and displacements: node,x_m,y_m,z_m,ux_m,uy_m,uz_m.
        #[arg(long)]
        output_nodes: Option<PathBuf>,
        /// Run report (JSON).
        #[arg(long)]
        report: Option<PathBuf>,
        /// ParaView time series (.vtu frames and series.pvd) into this directory.
        #[arg(long)]
        vtk: Option<PathBuf>,
        /// Override the scene's step count.
        #[arg(long)]
        steps: Option<u64>,
        /// Override the scene's precision (f32 | f64).
        #[arg(long)]
        precision: Option<PrecisionArg>,
        /// Override the scene's integration (reduced | full).
        #[arg(long)]
        integration: Option<IntegrationArg>,
        /// No progress bar.
        #[arg(long)]
        quiet: bool,
    },
    /// Print a scene (e.g. the built-in one) as TOML, to start a scene file from.
    #[command(after_help = "Example:\n  pe scene --builtin --level coarse > my_scene.toml")]
    Scene {
        #[command(flatten)]
        scene: SceneArgs,
    },
    /// Partition a scene onto a board mesh and write one schedule image per board.
    #[command(
        after_help = "Example:\n  pe compile --builtin --level coarse --boards 2x2x2 -o out/compiled"
    )]
    Compile {
        #[command(flatten)]
        scene: SceneArgs,
        /// Machine size, X x Y x Z boards.
        #[arg(long, default_value = "4x4x4")]
        boards: String,
        /// Board profile the images must fit: pe-board (the PE board's design, SPI links),
        /// stm32h743-uart (the prototype array: STM32H743 boards over USART cables) or
        /// qemu-mps2-an500 (the emulation).
        #[arg(long, default_value = "pe-board")]
        profile: String,
        /// Output directory.
        #[arg(short, long)]
        output: PathBuf,
        /// Override the scene's precision (f32 | f64).
        #[arg(long)]
        precision: Option<PrecisionArg>,
        /// Override the scene's step count.
        #[arg(long)]
        steps: Option<u64>,
        /// Override the scene's integration (reduced | full).
        #[arg(long)]
        integration: Option<IntegrationArg>,
    },
    /// Flashable artefacts per board of a compiled schedule: the firmware ELF with the
    /// board's position, the schedule blob, and OUT/manifest.json with the commands that
    /// flash (probe-rs) or run (QEMU) each board.
    #[command(after_help = "Example:\n  pe image out/compiled -o out/flash")]
    Image {
        /// Directory written by `pe compile`.
        dir: PathBuf,
        /// Output directory.
        #[arg(short, long)]
        output: PathBuf,
        /// A prebuilt firmware ELF (pe-firmware/board, built with the features matching the
        /// schedule: qemu for the emulation profile, f32, full). Without it, cargo builds it.
        #[arg(long)]
        firmware: Option<PathBuf>,
    },
    /// Flash every board of an array with probe-rs, each through the probe a board map
    /// names, and check what each board then holds (its identity record and the head of its
    /// schedule); then reset them all. OUT is a `pe image` directory of a board profile.
    #[command(
        after_help = "Example:\n  pe compile scenes/seed-box.toml --boards 2x2x2 --profile stm32h743-uart -o out/c\n  pe image out/c -o out/img\n  cat boards.toml   # [[board]] position = [0, 0, 0]  probe = \"0483:374e:002C00283132510D33353533\" ... one per board\n  pe flash out/img --map boards.toml --dry-run   # the commands, nothing run\n  pe flash out/img --map boards.toml"
    )]
    Flash {
        /// Directory written by `pe image`.
        out: PathBuf,
        /// Board map (TOML): one `[[board]]` with `position = [x, y, z]` and `probe =
        /// "VID:PID:SERIAL"` per board of the machine.
        #[arg(long)]
        map: PathBuf,
        /// The probe-rs binary (default: probe-rs on PATH).
        #[arg(long)]
        probe_rs: Option<PathBuf>,
        /// Print the commands, run none.
        #[arg(long)]
        dry_run: bool,
    },
    /// Compare final displacements bit for bit: REFERENCE is a nodes CSV (`pe solve
    /// --output-nodes`), OTHER a nodes CSV (board-sim) or a board's semihosting report.
    /// Fails on any difference (with --tolerance, on a larger one).
    #[command(
        after_help = "Examples:\n  pe compare out/nodes.csv out/board-sim.csv\n  pe compare out/solve.csv out/array.csv --tolerance 1e-12 --min-displacement 1e-4"
    )]
    Compare {
        reference: PathBuf,
        other: PathBuf,
        /// Accept differences up to this fraction of the reference's largest |component|
        /// (default: none, bit for bit).
        #[arg(long)]
        tolerance: Option<f64>,
        /// Refuse the comparison when the reference's largest |component| is below this (m):
        /// fields at rest agree whatever the code does.
        #[arg(long)]
        min_displacement: Option<f64>,
    },
    /// Show a board's compiled schedule: batches and exchange lists.
    #[command(after_help = "Example:\n  pe inspect out/compiled --board 1,0,0")]
    Inspect {
        /// Directory written by `pe compile`.
        dir: PathBuf,
        /// Board coordinates X,Y,Z.
        #[arg(long, default_value = "0,0,0")]
        board: String,
    },
    /// Measure ns per element-step and the flop count of one element-step.
    #[command(after_help = "Example:\n  pe bench --elements 2000 --precision f32 --threads 1")]
    Bench {
        /// Elements of the benchmark mesh (a box).
        #[arg(long, default_value_t = 2000)]
        elements: usize,
        /// Seconds each timed run lasts at least.
        #[arg(long, default_value_t = 1.0)]
        seconds: f64,
        /// Timed runs per configuration (the median is reported).
        #[arg(long, default_value_t = 3)]
        runs: usize,
        /// Only this precision (default: both).
        #[arg(long, value_enum)]
        precision: Option<PrecisionArg>,
        /// Only this integration (default: both).
        #[arg(long, value_enum)]
        integration: Option<IntegrationArg>,
        /// Only this many threads (default: one and all cores).
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Run a scene over a grid of solver configurations; write cost and error against the
    /// most accurate configuration to DIR/tradeoff.csv, .md and .png.
    #[command(after_help = "Example:\n  pe tradeoff --builtin --level coarse -o out/tradeoff")]
    Tradeoff {
        #[command(flatten)]
        scene: SceneArgs,
        /// Output directory.
        #[arg(short, long)]
        output: PathBuf,
        /// Add the fine built-in level (slow: minutes) or a 4× box level.
        #[arg(long)]
        fine: bool,
    },
    /// The cheapest model of a scene within an accuracy budget on its quantities of
    /// interest (tool forces, the displacement of the touched surfaces): a coarser level,
    /// the elements the loads hardly move pruned, then mass scaling and precision, each
    /// measured against the full scene. Writes DIR/scene.toml and its mesh (a scene every
    /// command takes), read back and run again to prove it, and DIR/plan.md, .json, .png.
    #[command(
        after_help = "Example:\n  pe plan --builtin --budget 2% --target boards=4x4x4 -o out/plan\n  pe solve out/plan/scene.toml"
    )]
    Plan {
        #[command(flatten)]
        scene: SceneArgs,
        /// Largest error accepted on each quantity of interest, relative to its largest
        /// value in the full scene: "2%" or "0.02". 0 returns the full model.
        #[arg(long, default_value = "2%")]
        budget: String,
        /// real-time (`pe solve` keeps real time here), boards=XxYxZ (the compiler's
        /// verdict on that array) or cheapest.
        #[arg(long, default_value = "cheapest")]
        target: String,
        /// A node set of the mesh whose displacement is a quantity of interest too (and
        /// is never pruned); repeat for more.
        #[arg(long)]
        watch: Vec<String>,
        /// Board profile of the array's figures.
        #[arg(long, default_value = "pe-board")]
        profile: String,
        /// Output directory.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Run the stability suite and write a readable report.
    #[command(after_help = "Example:\n  pe stability --only poisson -o out/stability.md")]
    Stability {
        /// Markdown report (printed when not given).
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Also run the slow cases (a 1e7-step run in f64 and f32).
        #[arg(long)]
        long: bool,
        /// Run only the cases whose name contains this.
        #[arg(long)]
        only: Option<String>,
    },
    /// Calibrate the hourglass coefficient: tip errors of MacNeal-Harder's cantilever,
    /// Cook's membrane and a compressed block against closed forms, per coefficient.
    #[command(
        name = "hourglass-study",
        after_help = "Example:\n  pe hourglass-study -o docs/measurements/hourglass-tables.md"
    )]
    HourglassStudy {
        /// Markdown tables (printed when not given).
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Coefficients to sweep (default 0.01,0.03,0.05,0.1,0.2,0.3,0.5).
        #[arg(long, value_delimiter = ',')]
        coefficients: Vec<f64>,
    },
}

struct Progress {
    bar: Option<indicatif::ProgressBar>,
    frames: Option<output::FrameWriter>,
    error: Option<anyhow::Error>,
}

impl Observer for Progress {
    fn after_step(&mut self, step: u64, time_s: f64, total: u64, state: &dyn StepState) {
        if let Some(b) = &self.bar {
            if step.is_multiple_of(64) || step == total {
                b.set_position(step);
            }
        }
        if let Some(f) = &mut self.frames {
            if let Err(e) = f.maybe_write(step, time_s, total, state) {
                self.error.get_or_insert(e);
            }
        }
    }
}

/// The `[solver]` settings a subcommand may override from the command line.
struct Overrides {
    steps: Option<u64>,
    precision: Option<PrecisionArg>,
    integration: Option<IntegrationArg>,
}

impl Overrides {
    fn apply(&self, sc: &mut Scene) {
        if let Some(n) = self.steps {
            sc.solver.steps = Some(n);
        }
        if let Some(p) = self.precision {
            sc.solver.precision = p.into();
        }
        if let Some(i) = self.integration {
            sc.solver.integration = i.into();
        }
    }
}

/// What `pe solve` writes besides its summary.
struct SolveOutputs {
    output_nodes: Option<PathBuf>,
    report: Option<PathBuf>,
    vtk: Option<PathBuf>,
    quiet: bool,
    threads: usize,
}

fn main() -> Result<()> {
    host_tools::output::exit_quietly_when_stdout_closes();
    let cli = Cli::parse();
    match cli.command {
        Command::Solve {
            scene,
            threads,
            output_nodes,
            report,
            vtk,
            steps,
            precision,
            integration,
            quiet,
        } => solve(
            &scene,
            &Overrides {
                steps,
                precision,
                integration,
            },
            SolveOutputs {
                output_nodes,
                report,
                vtk,
                quiet,
                threads: threads.unwrap_or_else(all_cores).max(1),
            },
        )?,
        Command::Scene { scene } => {
            let (sc, _, _) = scene.load()?;
            print!("{}", sc.to_toml()?);
        }
        Command::Compile {
            scene,
            boards,
            profile,
            output,
            precision,
            steps,
            integration,
        } => compile(
            &scene,
            &Overrides {
                steps,
                precision,
                integration,
            },
            &boards,
            &profile,
            &output,
        )?,
        Command::Image {
            dir,
            output,
            firmware,
        } => image(&dir, &output, firmware.as_deref())?,
        Command::Flash {
            out,
            map,
            probe_rs,
            dry_run,
        } => {
            let probe_rs = host_tools::flash::probe_rs_path(probe_rs);
            let boards = host_tools::flash::flash_array(&out, &map, &probe_rs, dry_run)?;
            for b in &boards {
                let [x, y, z] = b.board;
                if dry_run {
                    for c in &b.commands {
                        println!("{} {}", probe_rs.display(), c.join(" "));
                    }
                } else {
                    println!(
                        "board ({x},{y},{z}): flashed through probe {}, identity and schedule read back",
                        b.probe
                    );
                }
            }
            if !dry_run {
                println!("{} boards flashed, checked and reset", boards.len());
            }
        }
        Command::Compare {
            reference,
            other,
            tolerance,
            min_displacement,
        } => compare(&reference, &other, tolerance, min_displacement)?,
        Command::Inspect { dir, board } => {
            let c: Vec<usize> = board
                .split(',')
                .filter_map(|v| v.trim().parse().ok())
                .collect();
            if c.len() != 3 {
                anyhow::bail!("--board {board:?}: expected X,Y,Z");
            }
            print!(
                "{}",
                host_tools::compile::inspect(&dir, [c[0], c[1], c[2]])?
            );
        }
        Command::Bench {
            elements,
            seconds,
            runs,
            precision,
            integration,
            threads,
        } => host_tools::analysis::bench::run_cli(
            elements,
            seconds,
            runs,
            host_tools::analysis::bench::Only {
                precision: precision.map(Into::into),
                integration: integration.map(Into::into),
                threads,
            },
        )?,
        Command::Tradeoff {
            scene,
            output,
            fine,
        } => {
            let (sc, dir, name) = scene.load()?;
            let opts = host_tools::analysis::tradeoff::Options {
                fine,
                level: scene.builtin.then(|| scene.level.clone()),
            };
            host_tools::analysis::tradeoff::run_cli(&sc, &dir, &name, &opts, &output)?
        }
        Command::Plan {
            scene,
            budget,
            target,
            watch,
            profile,
            output,
        } => {
            let (sc, dir, name) = scene.load()?;
            let opts = host_tools::analysis::plan::Options {
                budget_rel: host_tools::analysis::plan::parse_budget(&budget)?,
                target: target.parse()?,
                watch,
                profile,
            };
            host_tools::analysis::plan::run_cli(&sc, &dir, &name, &opts, &output)?
        }
        Command::Stability { output, long, only } => {
            host_tools::analysis::stability::run_cli(output.as_deref(), long, only.as_deref())?
        }
        Command::HourglassStudy {
            output,
            coefficients,
        } => {
            let c = if coefficients.is_empty() {
                host_tools::analysis::hourglass::COEFFICIENTS.to_vec()
            } else {
                coefficients
            };
            let tables = host_tools::analysis::hourglass::study(&c)?;
            match output {
                Some(path) => std::fs::write(&path, tables)
                    .with_context(|| format!("writing {}", path.display()))?,
                None => print!("{tables}"),
            }
        }
    }
    Ok(())
}

/// The machine's cores (1 when unknown).
fn all_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// `pe solve`: the serial reference run, with its summary and the asked-for outputs.
fn solve(scene: &SceneArgs, overrides: &Overrides, outputs: SolveOutputs) -> Result<()> {
    let (mut sc, dir, name) = scene.load()?;
    overrides.apply(&mut sc);
    let problem = Problem::from_scene(&sc, &dir).with_context(|| format!("scene {name}"))?;
    problem.print_notes();
    let (dt, dt_crit) = (
        problem.time_step.dt_s,
        problem.time_step.critical.dt_critical_s,
    );
    let total = problem.steps(dt);
    eprintln!(
        "{name}: {} elements, {} nodes, {} {}, dt = {dt:.3e} s (critical {dt_crit:.3e} s), {total} steps",
        problem.mesh.cells.len(),
        problem.mesh.nodes.len(),
        problem.solver.precision,
        problem.solver.integration
    );
    let bar = (!outputs.quiet && total > 2000).then(|| output::progress_bar(total));
    let frames = match &outputs.vtk {
        Some(d) => Some(output::FrameWriter::new(
            d,
            &problem.mesh,
            problem.solver.output_interval,
            dt,
        )?),
        None => None,
    };
    let mut obs = Progress {
        bar,
        frames,
        error: None,
    };
    let out = solver::run_threads(&problem, &name, &mut obs, outputs.threads)?;
    if let Some(b) = &obs.bar {
        b.finish_and_clear();
    }
    if let Some(e) = obs.error.take() {
        return Err(e);
    }
    if let Some(f) = obs.frames.take() {
        f.finish()?;
    }
    let prescribed = problem
        .node_kind
        .iter()
        .filter(|k| matches!(k, host_tools::problem::NodeKind::Prescribed(_)))
        .count();
    println!("{}", out.report.console_summary(prescribed));
    if let Some(p) = outputs.output_nodes {
        output::write_nodes_csv(&p, &problem.mesh, &out.displacements)?;
    }
    if let Some(p) = outputs.report {
        std::fs::write(&p, serde_json::to_string_pretty(&out.report)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}

/// `pe compile`: one schedule image per board, the manifest and the report.
fn compile(
    scene: &SceneArgs,
    overrides: &Overrides,
    boards: &str,
    profile: &str,
    output: &Path,
) -> Result<()> {
    let (mut sc, dir, name) = scene.load()?;
    overrides.apply(&mut sc);
    let machine = host_tools::compile::partition::Machine::parse(boards)
        .map_err(|e| anyhow::anyhow!("--boards {boards:?}: {e}"))?;
    let prof = pe_firmware::profile::profile(profile).with_context(|| {
        let known: Vec<&str> = pe_firmware::profile::PROFILES
            .iter()
            .map(|p| p.name)
            .collect();
        format!(
            "--profile {profile:?}: known profiles are {}",
            known.join(", ")
        )
    })?;
    let problem = Problem::from_scene(&sc, &dir).with_context(|| format!("scene {name}"))?;
    problem.print_notes();
    let source = match (&scene.scene, scene.builtin) {
        (Some(p), false) => std::fs::canonicalize(p)
            .unwrap_or(p.clone())
            .display()
            .to_string(),
        _ => format!("builtin:{}", scene.level),
    };
    let rep =
        host_tools::compile::compile_to_dir(&name, &source, &problem, machine, &prof, output)?;
    print!("{}", host_tools::compile::summary(&rep));
    println!(
        "  wrote {} images, manifest.json and report.json to {}",
        rep.boards.len(),
        output.display()
    );
    Ok(())
}

/// `pe image`: the flashable artefacts of a compiled schedule.
fn image(dir: &Path, output: &Path, firmware: Option<&Path>) -> Result<()> {
    let m = host_tools::firmware::image_dir(dir, output, firmware)?;
    println!(
        "{} boards of {} ({}, {} {}): firmware {} (features {})",
        m.boards.len(),
        m.scene,
        m.profile,
        m.precision,
        m.integration,
        m.firmware,
        m.firmware_features.join(",")
    );
    for b in &m.boards {
        println!(
            "  board ({},{},{}): {} + {} at {}",
            b.board[0], b.board[1], b.board[2], b.elf, b.schedule, b.schedule_address
        );
    }
    println!("  wrote {}", output.join("manifest.json").display());
    Ok(())
}

/// `pe compare`: final displacements bit for bit.
fn compare(
    reference: &Path,
    other: &Path,
    tolerance: Option<f64>,
    min_displacement: Option<f64>,
) -> Result<()> {
    let c = host_tools::firmware::compare(reference, other)?;
    if let Some(min) = min_displacement {
        if c.max_abs_reference.is_nan() || c.max_abs_reference < min {
            anyhow::bail!(
                "{}: the largest |displacement| component is {:.3e} m, below --min-displacement {min:.3e} m: a comparison of fields this close to rest proves nothing",
                reference.display(),
                c.max_abs_reference
            );
        }
    }
    let allowed = tolerance.map_or(0.0, |t| t * c.max_abs_reference);
    let fails = match tolerance {
        None => c.differing > 0,
        Some(_) => c.max_abs_diff.is_nan() || c.max_abs_diff > allowed,
    };
    if fails {
        for (n, i, a, b) in &c.first {
            eprintln!(
                "  node {n} component {i}: reference {a:e} ({:016x}), other {b:e} ({:016x})",
                a.to_bits(),
                b.to_bits()
            );
        }
        anyhow::bail!(
            "MISMATCH: {} of {} components differ between {} and {} (max |diff| {:.3e} m{})",
            c.differing,
            3 * c.nodes,
            reference.display(),
            other.display(),
            c.max_abs_diff,
            match tolerance {
                Some(t) => format!(
                    ", above the {t:e} x {:.3e} m = {allowed:.3e} m allowed",
                    c.max_abs_reference
                ),
                None => String::new(),
            }
        );
    }
    match tolerance {
        Some(t) => println!(
            "within {t:e}: {} nodes of {} and {} (max |diff| {:.3e} m = {:.2e} of max |u| {:.3e} m; {} of {} components differ in their bits)",
            c.nodes,
            reference.display(),
            other.display(),
            c.max_abs_diff,
            c.max_abs_diff / c.max_abs_reference.max(f64::MIN_POSITIVE),
            c.max_abs_reference,
            c.differing,
            3 * c.nodes
        ),
        None => println!(
            "bit-identical: {} nodes of {} and {} (max |u| {:.3e} m)",
            c.nodes,
            reference.display(),
            other.display(),
            c.max_abs_reference
        ),
    }
    Ok(())
}
