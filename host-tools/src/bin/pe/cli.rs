//! The command line of `pe`: the subcommands and their arguments. The help texts are the
//! doc comments of the variants and fields.

use std::path::PathBuf;

use clap::{Parser, Subcommand};
use host_tools::output::OutputArgs;
use host_tools::scene::settings::{IntegrationArg, PrecisionArg};
pub use host_tools::scene::SceneArgs;

#[derive(Parser)]
#[command(
    name = "pe",
    version,
    about = "Soft-tissue simulator host tools",
    after_help = "Examples:\n  pe solve --builtin --level coarse --vtk out/frames --output-nodes out/nodes.csv\n  pe compile --builtin --level coarse --boards 2x2x2 -o out/compiled\n  board-sim run out/compiled --output-nodes out/board.csv\n  pe compare out/nodes.csv out/board.csv"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// On an error, also print where in the code it arose (for reporting a bug; a bad
    /// input's message names what to fix without it).
    #[arg(long, global = true)]
    pub backtrace: bool,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run a scene on this machine (the reference solver every board run is compared with).
    #[command(
        after_help = "Example:\n  pe solve scenes/liver.toml --vtk out/frames --output-nodes out/nodes.csv --report out/report.json\n  (open out/frames/series.pvd in ParaView; Warp By Vector on displacement_m shows the deformed shape)"
    )]
    Solve(SolveArgs),
    /// Print a scene (e.g. the built-in one) as TOML, to start a scene file from.
    #[command(after_help = "Example:\n  pe scene --builtin --level coarse > my_scene.toml")]
    Scene(SceneArgs),
    /// Partition a scene onto a board mesh and write one schedule image per board.
    #[command(
        after_help = "Example:\n  pe compile --builtin --level coarse --boards 2x2x2 -o out/compiled"
    )]
    Compile(CompileArgs),
    /// Flashable artefacts per board of a compiled schedule: the firmware ELF with the
    /// board's position, the schedule blob, and OUT/manifest.json with the commands that
    /// flash (probe-rs) or run (QEMU) each board.
    #[command(after_help = "Example:\n  pe image out/compiled -o out/flash")]
    Image(ImageArgs),
    /// Flash every board of an array with probe-rs, each through the probe a board map
    /// names, and check what each board then holds (its identity record and the head of its
    /// schedule); then reset them all. OUT is a `pe image` directory of a board profile.
    #[command(
        after_help = "Example:\n  pe compile scenes/seed-box.toml --boards 2x2x2 --profile stm32h743-uart -o out/c\n  pe image out/c -o out/img\n  cat boards.toml   # [[board]] position = [0, 0, 0]  probe = \"0483:374e:002C00283132510D33353533\"  uid = \"003A0028:31385104:33333439\" ... one per board\n  pe flash out/img --map boards.toml --dry-run   # the commands, nothing run\n  pe flash out/img --map boards.toml"
    )]
    Flash(FlashArgs),
    /// Compare final displacements bit for bit: REFERENCE is a nodes CSV (`pe solve
    /// --output-nodes`), OTHER a nodes CSV (board-sim) or a board's semihosting report.
    /// Fails on any difference (with --tolerance, on a larger one).
    #[command(
        after_help = "Examples:\n  pe compare out/nodes.csv out/board-sim.csv\n  pe compare out/solve.csv out/array.csv --tolerance 1e-12 --min-displacement 1e-4"
    )]
    Compare(CompareArgs),
    /// Show a board's compiled schedule: batches and exchange lists.
    #[command(after_help = "Example:\n  pe inspect out/compiled --board 1,0,0")]
    Inspect(InspectArgs),
    /// Measure ns per element-step and the flop count of one element-step.
    #[command(after_help = "Example:\n  pe bench --elements 2000 --precision f32 --threads 1")]
    Bench(BenchArgs),
    /// Run a scene over a grid of solver configurations; write cost and error against the
    /// most accurate configuration to DIR/tradeoff.csv, .md and .png.
    #[command(after_help = "Example:\n  pe tradeoff --builtin --level coarse -o out/tradeoff")]
    Tradeoff(TradeoffArgs),
    /// Serve a scene live: the trainer page and the WebSocket session on --listen,
    /// OpenIGTLink on --igtl-port, paced to the wall clock (docs/live.md).
    #[command(
        after_help = "Example:\n  pe live --builtin --record out/session.jsonl   # open http://127.0.0.1:8080/\n  pe solve --builtin --replay out/session.jsonl --steps N"
    )]
    Live(host_tools::live::cli::LiveArgs),
    /// The cheapest model of a scene within an accuracy budget on its quantities of
    /// interest (tool forces, the displacement of the touched surfaces): a coarser level,
    /// the elements the loads hardly move pruned, then mass scaling and precision, each
    /// measured against the full scene. Writes DIR/scene.toml and its mesh (a scene every
    /// command takes), read back and run again to prove it, and DIR/plan.md, .json, .png.
    #[command(
        after_help = "Example:\n  pe plan --builtin --budget 2% --target boards=4x4x4 -o out/plan\n  pe solve out/plan/scene.toml"
    )]
    Plan(PlanArgs),
    /// Run the stability suite and write a readable report.
    #[command(after_help = "Example:\n  pe stability --only poisson -o out/stability.md")]
    Stability(StabilityArgs),
    /// Compare the hourglass controls: tip errors of MacNeal-Harder's cantilever, Cook's
    /// membrane and a compressed block against closed forms, for the physical form and
    /// the scalar one per coefficient.
    #[command(
        name = "hourglass-study",
        after_help = "Example:\n  pe hourglass-study -o docs/measurements/hourglass-tables.md"
    )]
    HourglassStudy(HourglassStudyArgs),
}

// `pe solve`.
#[derive(clap::Args)]
pub struct SolveArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Solver threads (default: all cores). The result is the same, bit for bit,
    /// whatever the count.
    #[arg(long, value_parser = host_tools::domain::count)]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub outputs: OutputArgs,
    /// Override the scene's step count.
    #[arg(long, value_parser = host_tools::domain::steps)]
    pub steps: Option<u64>,
    /// Override the scene's precision (f32 | f64).
    #[arg(long)]
    pub precision: Option<PrecisionArg>,
    /// Override the scene's integration (reduced | full).
    #[arg(long)]
    pub integration: Option<IntegrationArg>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Compute with IEEE subnormal numbers instead of flushing them to zero as the boards
    /// do: slower where the tissue is nearly at rest, and no longer the boards' bits where
    /// subnormals arise (to see whether they do).
    #[arg(long)]
    pub keep_subnormals: bool,
    /// Keep the run whose tracking lowered dt as it went, instead of running again from
    /// rest at the smallest step reached (the default, so that this reference and the
    /// boards, which run one step, agree bit for bit; `host_tools::solver::settle`).
    #[arg(long)]
    pub dt_as_tracked: bool,
    /// Apply the poses a `pe live --record FILE` session recorded, at their steps (its
    /// bits; give --steps the session's step count to end where it ended).
    #[arg(long)]
    pub replay: Option<PathBuf>,
}

// `pe compile`.
#[derive(clap::Args)]
pub struct CompileArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Machine size, X x Y x Z boards.
    #[arg(long, default_value = "4x4x4")]
    pub boards: String,
    /// Board profile the images must fit: pe-board (the PE board's design, SPI links),
    /// stm32h743-uart (the prototype array: STM32H743 boards over USART cables) or
    /// qemu-mps2-an500 (the emulation).
    #[arg(long, default_value = "pe-board")]
    pub profile: String,
    /// Output directory.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Override the scene's precision (f32 | f64).
    #[arg(long)]
    pub precision: Option<PrecisionArg>,
    /// Override the scene's step count.
    #[arg(long, value_parser = host_tools::domain::steps)]
    pub steps: Option<u64>,
    /// Override the scene's integration (reduced | full).
    #[arg(long)]
    pub integration: Option<IntegrationArg>,
}

// `pe image`.
#[derive(clap::Args)]
pub struct ImageArgs {
    /// Directory written by `pe compile`.
    pub dir: PathBuf,
    /// Output directory.
    #[arg(short, long)]
    pub output: PathBuf,
    /// A prebuilt firmware ELF (pe-firmware/board, built with the features matching the
    /// schedule: qemu for the emulation profile, f32, full). Without it, cargo builds it.
    #[arg(long)]
    pub firmware: Option<PathBuf>,
}

// `pe flash`.
#[derive(clap::Args)]
pub struct FlashArgs {
    /// Directory written by `pe image`.
    pub out: PathBuf,
    /// Board map (TOML): one `[[board]]` with `position = [x, y, z]`, `probe =
    /// "VID:PID:SERIAL"` and (recommended) `uid = "W0:W1:W2"`, the MCU's unique ID, per
    /// board of the machine.
    #[arg(long)]
    pub map: PathBuf,
    /// The probe-rs binary (default: probe-rs on PATH).
    #[arg(long)]
    pub probe_rs: Option<PathBuf>,
    /// Print the commands, run none.
    #[arg(long)]
    pub dry_run: bool,
}

// `pe compare`.
#[derive(clap::Args)]
pub struct CompareArgs {
    pub reference: PathBuf,
    pub other: PathBuf,
    /// Accept differences up to this fraction of the reference's largest |component|
    /// (default: none, bit for bit).
    #[arg(long, value_parser = host_tools::domain::non_negative)]
    pub tolerance: Option<f64>,
    /// Refuse the comparison when the reference's largest |component| is below this (m):
    /// fields at rest agree whatever the code does.
    #[arg(long, value_parser = host_tools::domain::positive)]
    pub min_displacement: Option<f64>,
}

// `pe inspect`.
#[derive(clap::Args)]
pub struct InspectArgs {
    /// Directory written by `pe compile`.
    pub dir: PathBuf,
    /// Board coordinates X,Y,Z.
    #[arg(long, default_value = "0,0,0")]
    pub board: String,
}

// `pe bench`.
#[derive(clap::Args)]
pub struct BenchArgs {
    /// Elements of the benchmark mesh (a box).
    #[arg(long, default_value_t = 2000, value_parser = host_tools::domain::count)]
    pub elements: usize,
    /// Seconds each timed run lasts at least.
    #[arg(long, default_value_t = 1.0, value_parser = host_tools::domain::positive)]
    pub seconds: f64,
    /// Timed runs per configuration (the median is reported).
    #[arg(long, default_value_t = 3, value_parser = host_tools::domain::count)]
    pub runs: usize,
    /// Only this precision (default: both).
    #[arg(long, value_enum)]
    pub precision: Option<PrecisionArg>,
    /// Only this integration (default: both).
    #[arg(long, value_enum)]
    pub integration: Option<IntegrationArg>,
    /// Only this many threads (default: one and all cores).
    #[arg(long, value_parser = host_tools::domain::count)]
    pub threads: Option<usize>,
}

// `pe tradeoff`.
#[derive(clap::Args)]
pub struct TradeoffArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Output directory.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Add the fine built-in level (slow: minutes) or a 4× box level.
    #[arg(long)]
    pub fine: bool,
    /// Board profile whose clock gives the board real-time factor.
    #[arg(long, default_value = "pe-board")]
    pub profile: String,
}

// `pe plan`.
#[derive(clap::Args)]
pub struct PlanArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Largest error accepted on each quantity of interest, relative to its largest
    /// value in the full scene: "2%" or "0.02". 0 returns the full model.
    #[arg(long, default_value = "2%")]
    pub budget: String,
    /// real-time (`pe solve` keeps real time here), boards=XxYxZ (the compiler's
    /// verdict on that array) or cheapest.
    #[arg(long, default_value = "cheapest")]
    pub target: String,
    /// A node set of the mesh whose displacement is a quantity of interest too (and
    /// is never pruned); repeat for more.
    #[arg(long)]
    pub watch: Vec<String>,
    /// Board profile of the array's figures.
    #[arg(long, default_value = "pe-board")]
    pub profile: String,
    /// Output directory.
    #[arg(short, long)]
    pub output: PathBuf,
}

// `pe stability`.
#[derive(clap::Args)]
pub struct StabilityArgs {
    /// Markdown report (printed when not given).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Also run the slow cases (a 1e7-step run in f64 and f32).
    #[arg(long)]
    pub long: bool,
    /// Run only the cases whose name contains this.
    #[arg(long)]
    pub only: Option<String>,
}

// `pe hourglass-study`.
#[derive(clap::Args)]
pub struct HourglassStudyArgs {
    /// Markdown tables (printed when not given).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Hourglass controls to compare: "physical" and scalar coefficients (default
    /// physical,0.01,0.03,0.05,0.1,0.2,0.3,0.5).
    #[arg(long, value_delimiter = ',', value_parser = host_tools::scene::settings::hourglass_from_text)]
    pub coefficients: Vec<pe_firmware::physics::HourglassControl>,
}
