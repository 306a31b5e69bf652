//! `board-sim`'s command line; the subcommands' bodies are in the library
//! (`board_sim::commands`, `board_sim::campaign`).

use std::path::PathBuf;

use anyhow::Result;
use board_sim::commands::{bench, builtin, execute, live, qemu_array, LiveArgs, QemuArgs, RunArgs};
use clap::{Parser, Subcommand};

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
    /// On an error, also print where in the code it arose (for reporting a bug; a bad
    /// input's message names what to fix without it).
    #[arg(long, global = true)]
    backtrace: bool,
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
    /// Serve the images of DIR as a live session (the trainer page, the WebSocket session,
    /// OpenIGTLink), as `pe live` serves the host solver: the host steps the boards, sends
    /// them the tools' poses and sums their tool forces (docs/live.md).
    #[command(
        after_help = "Example:\n  pe compile --builtin --level coarse --boards 2x2x2 -o out/compiled\n  board-sim live out/compiled --listen 127.0.0.1:8080 --record out/session.jsonl\n  board-sim run out/compiled --replay out/session.jsonl --tool-force out/tool_force.csv"
    )]
    Live {
        dir: PathBuf,
        #[command(flatten)]
        args: LiveArgs,
    },
    /// Benchmark: steps per second of the serial solver and of board-sim on the same scene,
    /// in one run, as a ratio.
    #[command(
        after_help = "Example:\n  board-sim bench --level coarse --boards 2x2x2 --steps 500"
    )]
    Bench {
        /// Mesh level of the built-in scene: coarse | medium | fine.
        #[arg(long, default_value = "medium")]
        level: String,
        /// Machine size.
        #[arg(long, default_value = "4x4x4")]
        boards: String,
        /// Steps of each run.
        #[arg(long, default_value_t = 1000, value_parser = host_tools::domain::steps)]
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
        #[arg(long, default_value_t = 1000, value_parser = host_tools::domain::steps)]
        runs: u64,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long, default_value_t = 100, value_parser = host_tools::domain::steps)]
        steps: u64,
        /// Without link recovery (every fault must stop the run, naming its cause).
        #[arg(long)]
        no_recovery: bool,
        /// Another compilation of the same machine (e.g. another Young's modulus): some
        /// runs take one board's image from it (alone, with its manifest, or with the
        /// host's manifest check off), and must be refused naming that board.
        #[arg(long, value_name = "DIR2")]
        swap_from: Option<PathBuf>,
        /// The runs' time (as `board-sim run --clock`): with `simulated`, whether a run
        /// stops and what it blames do not depend on how busy the host is.
        #[arg(long, value_enum, default_value_t = board_sim::commands::run::Clock::Wall)]
        clock: board_sim::commands::run::Clock,
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
        #[command(flatten)]
        args: QemuArgs,
    },
    /// The main job: compile the built-in scene (uterus, tubes, probe) for a board mesh and
    /// run it, writing OUT/images, OUT/frames (ParaView), OUT/final.png, OUT/tool_force.csv,
    /// OUT/nodes.csv, OUT/report.json and a summary.
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
        #[arg(long, value_parser = host_tools::domain::steps)]
        steps: Option<u64>,
        /// No progress bar (the summaries are still printed).
        #[arg(long)]
        quiet: bool,
    },
}

fn main() -> std::process::ExitCode {
    host_tools::output::exit_quietly_when_stdout_closes();
    let cli = Cli::parse();
    if cli.backtrace {
        host_tools::output::capture_backtraces();
    }
    host_tools::output::finish(run(cli.command), cli.backtrace)
}

fn run(command: Command) -> Result<()> {
    // A bad PE_ISA is refused before any work.
    host_tools::problem::batched::Isa::cap_from_env().map_err(anyhow::Error::msg)?;
    match command {
        Command::Run { dir, args } => execute(&dir, args).map(|_| ()),
        Command::Live { dir, args } => live(&dir, &args),
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
            clock,
        } => board_sim::campaign::campaign(
            &dir,
            swap_from.as_deref(),
            runs,
            seed,
            steps,
            !no_recovery,
            clock.clocking(),
        ),
        Command::Qemu { dir, args } => qemu_array(&dir, args),
    }
}
