//! `board-sim live DIR`: the compiled array in DIR on emulated boards as a live session
//! (the page, the WebSocket session, OpenIGTLink), served by the same session code as
//! `pe live` ([`host_tools::live::cli::serve_until_stopped`]) over [`BoardSimEngine`].

use std::path::Path;

use anyhow::{bail, Result};
use host_tools::live::cli::{config, serve_until_stopped, SessionArgs};

use crate::live::BoardSimEngine;
use crate::runner::SimOptions;

/// `board-sim live`'s options: the session's (as `pe live`'s) and how the boards run.
#[derive(clap::Args, Debug, Clone)]
pub struct LiveArgs {
    #[command(flatten)]
    pub session: SessionArgs,
    /// Host threads to multiplex the boards over (default: the machine's cores).
    #[arg(long, value_parser = host_tools::domain::count)]
    pub workers: Option<usize>,
    /// Run the boards' element batches on the firmware's scalar loop (default: the host's
    /// SIMD lanes, the same bits).
    #[arg(long)]
    pub scalar_kernel: bool,
}

/// `board-sim live DIR`.
pub fn live(dir: &Path, args: &LiveArgs) -> Result<()> {
    let cfg = config(&args.session)?;
    let opts = SimOptions {
        workers: args.workers,
        batched: !args.scalar_kernel,
        ..SimOptions::default()
    };
    let mut engine = BoardSimEngine::start(dir, &opts)?;
    let interval = engine.graphics_interval_steps();
    eprintln!(
        "{}: surface frames from the boards' graphics stream every {interval} steps ({:.1} per simulated second)",
        dir.display(),
        1.0 / (f64::from(interval.max(1)) * engine.dt())
    );
    let name = dir.display().to_string();
    let summary = serve_until_stopped(&mut engine, &name, &args.session, &cfg, "board-sim live")?;
    if let Some(p) = &args.session.record {
        println!(
            "  recorded to {} (replay: board-sim run {} --replay {} --steps {})",
            p.display(),
            dir.display(),
            p.display(),
            summary.steps
        );
    }
    match summary.error {
        Some(e) => bail!("the session stopped: {e}"),
        None => Ok(()),
    }
}
