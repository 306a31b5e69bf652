//! `pe`: the command line of the soft-tissue simulator's host tools (its arguments in
//! `cli.rs`), one function per subcommand.

use std::path::Path;

use anyhow::{Context, Result};
use clap::Parser;
use host_tools::output;
use host_tools::problem::Problem;
use host_tools::scene::settings::{IntegrationArg, PrecisionArg};
use host_tools::scene::Scene;
use host_tools::solver::{self, Observer, StepState};

mod cli;

use cli::{
    BenchArgs, Cli, Command, CompileArgs, FlashArgs, HourglassStudyArgs, InspectArgs, PlanArgs,
    SceneArgs, SolveArgs, StabilityArgs, TradeoffArgs,
};

fn main() -> std::process::ExitCode {
    host_tools::output::exit_quietly_when_stdout_closes();
    let cli = Cli::parse();
    if cli.backtrace {
        host_tools::output::capture_backtraces();
    }
    output::finish(run(cli.command), cli.backtrace)
}

fn run(command: Command) -> Result<()> {
    // A bad PE_ISA is refused before any work.
    host_tools::problem::batched::Isa::cap_from_env().map_err(anyhow::Error::msg)?;
    match command {
        Command::Solve(a) => solve(a),
        Command::Scene(a) => scene(&a),
        Command::Compile(a) => compile(&a),
        Command::Image(a) => image(&a.dir, &a.output, a.firmware.as_deref()),
        Command::Flash(a) => flash(a),
        Command::Compare(a) => compare(&a.reference, &a.other, a.tolerance, a.min_displacement),
        Command::Inspect(a) => inspect(&a),
        Command::Bench(a) => bench(a),
        Command::Tradeoff(a) => tradeoff(&a),
        Command::Live(a) => host_tools::live::cli::run(&a),
        Command::Plan(a) => plan(a),
        Command::Stability(a) => stability(&a),
        Command::HourglassStudy(a) => hourglass_study(a),
    }
}

struct Progress<'m> {
    bar: Option<indicatif::ProgressBar>,
    frames: Option<output::FrameWriter>,
    error: Option<anyhow::Error>,
    /// What the frames are of, for a run that starts again: the directory, the mesh and the
    /// interval (s).
    vtk: Option<(&'m std::path::Path, host_tools::mesh::Mesh, f64)>,
}

impl Progress<'_> {
    /// The ParaView frames' writer, from rest, at step `dt_s` (None without `--vtk`).
    fn frame_writer(&self, dt_s: f64) -> Result<Option<output::FrameWriter>> {
        self.vtk
            .as_ref()
            .map(|(d, mesh, interval)| output::FrameWriter::new(d, mesh, *interval, dt_s))
            .transpose()
    }
}

impl Observer for Progress<'_> {
    fn restart(&mut self, dt_s: f64) -> Result<()> {
        if let Some(b) = &self.bar {
            b.set_position(0);
        }
        // The frames of the run whose step moved go; the new run's are written afresh.
        self.frames = self.frame_writer(dt_s)?;
        self.error = None;
        Ok(())
    }

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

/// The machine's cores (1 when unknown).
fn all_cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// `pe solve`: the serial reference run, with its summary and the asked-for outputs.
fn solve(a: SolveArgs) -> Result<()> {
    a.outputs.check()?;
    let (mut sc, dir, name) = a.scene.load()?;
    Overrides {
        steps: a.steps,
        precision: a.precision,
        integration: a.integration,
    }
    .apply(&mut sc);
    let threads = a.threads.unwrap_or_else(all_cores).max(1);
    let mut problem = Problem::from_scene(&sc, &dir).with_context(|| format!("scene {name}"))?;
    if a.keep_subnormals {
        problem.subnormals = host_tools::subnormals::Subnormals::Keep;
    }
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
    let bar = (!a.quiet && total > 2000).then(|| output::progress_bar(total));
    let mut obs = Progress {
        bar,
        frames: None,
        error: None,
        vtk: a
            .outputs
            .vtk
            .as_deref()
            // Its own copy of the mesh (only with --vtk): the problem goes to the runs.
            .map(|d| (d, problem.mesh.clone(), problem.solver.output_interval)),
    };
    obs.frames = obs.frame_writer(dt)?;
    let poses = match &a.replay {
        Some(p) => host_tools::live::session::record::replay_schedule(p, &name, &problem)?,
        None => Default::default(),
    };
    // One step for this reference and the boards (`solver::settle`): where tracking lowers
    // dt, the scene runs again from rest at the smallest step reached.
    let (problem, out, step) = if a.dt_as_tracked {
        let out = solver::run_with_poses(&problem, &name, &mut obs, threads, poses)?;
        (problem, out, None)
    } else {
        let s = solver::settle::settle(problem, &name, threads, &poses, &mut obs)?;
        let out = match s.output {
            Some(out) => out,
            None => solver::run_with_poses(&s.problem, &name, &mut obs, threads, poses)?,
        };
        (s.problem, out, Some(s.step))
    };
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
    if let Some(st) = step.as_ref().filter(|st| st.runs > 1) {
        println!(
            "  step settled at {:.4e} s (at rest {:.4e} s) in {} runs: {}",
            st.dt_s, st.dt_at_rest_s, st.runs, st.how
        );
    }
    a.outputs
        .result
        .write_nodes(&problem.mesh, &out.displacements)?;
    if let Some(p) = &a.outputs.tool_force {
        output::tool_force::write_run_tool_force(p, &out)?;
    }
    a.outputs.result.write_report(&out.report)
}

/// `pe compile`: one schedule image per board, the manifest and the report.
fn compile(a: &CompileArgs) -> Result<()> {
    let (scene, boards, profile, output) = (&a.scene, &a.boards, &a.profile, &a.output);
    let (mut sc, dir, name) = scene.load()?;
    Overrides {
        steps: a.steps,
        precision: a.precision,
        integration: a.integration,
    }
    .apply(&mut sc);
    let machine = host_tools::compile::partition::Machine::parse(boards)
        .map_err(|e| anyhow::anyhow!("--boards {boards:?}: {e}"))?;
    let prof = pe_firmware::profile::BoardProfile::by_name(profile)
        .map_err(|e| anyhow::anyhow!("--profile: {e}"))?;
    let problem = Problem::from_scene(&sc, &dir).with_context(|| format!("scene {name}"))?;
    problem.print_notes();
    let source = match (&scene.scene, scene.builtin) {
        (Some(p), false) => std::fs::canonicalize(p)
            .unwrap_or(p.clone())
            .display()
            .to_string(),
        _ => format!("builtin:{}", scene.level),
    };
    let rep = host_tools::compile::compile_to_dir(&name, &source, &problem, machine, prof, output)?;
    print!("{}", host_tools::compile::summary(&rep));
    println!(
        "  wrote {} images, manifest.json and report.json to {}",
        rep.boards.len(),
        output.display()
    );
    Ok(())
}

/// `pe scene`: the scene as TOML.
fn scene(a: &SceneArgs) -> Result<()> {
    let (sc, _, _) = a.load()?;
    print!("{}", sc.to_toml()?);
    Ok(())
}

/// `pe flash`: every board flashed, checked and reset (or the commands, with --dry-run).
fn flash(a: FlashArgs) -> Result<()> {
    let dry_run = a.dry_run;
    let probe_rs = host_tools::flash::probe_rs_path(a.probe_rs);
    let boards = host_tools::flash::flash_array(&a.out, &a.map, &probe_rs, dry_run)?;
    for b in &boards {
        let [x, y, z] = b.board;
        if dry_run {
            for c in &b.commands {
                println!("{} {}", probe_rs.display(), c.join(" "));
            }
        } else {
            let chip = match (b.uid, b.uid_in_map) {
                (Some(u), true) => format!("chip {u} as mapped, "),
                (Some(u), false) => format!("chip {u} (not in the map), "),
                (None, _) => String::new(),
            };
            println!(
                "board ({x},{y},{z}): {chip}flashed through probe {}, identity and schedule read back",
                b.probe
            );
        }
    }
    let unmapped: Vec<_> = (boards.iter())
        .filter_map(|b| b.uid.filter(|_| !b.uid_in_map).map(|u| (b.board, u)))
        .collect();
    if !unmapped.is_empty() {
        println!(
            "{}: add each board's uid, so that a probe on the wrong board is refused before anything is written:",
            a.map.display()
        );
        for ([x, y, z], u) in unmapped {
            println!("  position = [{x}, {y}, {z}]  uid = \"{u}\"");
        }
    }
    if !dry_run {
        println!("{} boards flashed, checked and reset", boards.len());
    }
    Ok(())
}

/// `pe inspect`: one board's compiled schedule.
fn inspect(a: &InspectArgs) -> Result<()> {
    let board = &a.board;
    let c: Vec<usize> = board
        .split(',')
        .filter_map(|v| v.trim().parse().ok())
        .collect();
    if c.len() != 3 {
        anyhow::bail!("--board {board:?}: expected X,Y,Z");
    }
    print!(
        "{}",
        host_tools::compile::inspect(&a.dir, [c[0], c[1], c[2]])?
    );
    Ok(())
}

/// `pe bench`: ns per element-step.
fn bench(a: BenchArgs) -> Result<()> {
    host_tools::analysis::bench::run_cli(
        a.elements,
        a.seconds,
        a.runs,
        host_tools::analysis::bench::Only {
            precision: a.precision.map(Into::into),
            integration: a.integration.map(Into::into),
            threads: a.threads,
        },
    )
}

/// `pe tradeoff`: a scene over a grid of solver configurations.
fn tradeoff(a: &TradeoffArgs) -> Result<()> {
    let (sc, dir, name) = a.scene.load()?;
    let opts = host_tools::analysis::tradeoff::Options {
        fine: a.fine,
        level: a.scene.builtin.then(|| a.scene.level.clone()),
        profile: pe_firmware::profile::BoardProfile::by_name(&a.profile)
            .map_err(|e| anyhow::anyhow!("--profile: {e}"))?,
    };
    host_tools::analysis::tradeoff::run_cli(&sc, &dir, &name, &opts, &a.output)
}

/// `pe plan`: the cheapest model within the budget.
fn plan(a: PlanArgs) -> Result<()> {
    let (sc, dir, name) = a.scene.load()?;
    let opts = host_tools::analysis::plan::Options {
        budget_rel: host_tools::analysis::plan::parse_budget(&a.budget)?,
        target: a.target.parse()?,
        watch: a.watch,
        profile: a.profile,
    };
    host_tools::analysis::plan::run_cli(&sc, &dir, &name, &opts, &a.output)
}

/// `pe stability`: the stability suite.
fn stability(a: &StabilityArgs) -> Result<()> {
    host_tools::analysis::stability::run_cli(a.output.as_deref(), a.long, a.only.as_deref())
}

/// `pe hourglass-study`: the hourglass coefficient's tables.
fn hourglass_study(a: HourglassStudyArgs) -> Result<()> {
    let c = if a.coefficients.is_empty() {
        host_tools::analysis::hourglass::COEFFICIENTS.to_vec()
    } else {
        a.coefficients
    };
    let tables = host_tools::analysis::hourglass::study(&c)?;
    match a.output {
        Some(path) => host_tools::output::file::write_atomic(&path, tables)?,
        None => print!("{tables}"),
    }
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
    let c = host_tools::compare::compare(reference, other)?;
    if let Some((node, i, which)) = &c.first_non_finite {
        let file = if *which == "reference" {
            reference
        } else {
            other
        };
        anyhow::bail!(
            "NOT A RESULT: {} components are not finite (first: {node} component {i} in {}); nothing is compared",
            c.non_finite,
            file.display()
        );
    }
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
                "  {n} component {i}: reference {a:e} ({:016x}), other {b:e} ({:016x})",
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
