//! `pe live`: the host solver as a live session, served over one address (the page and
//! the WebSocket session) and OpenIGTLink, until Ctrl-C, the end of standard input (a
//! terminal or a pipe) or `--duration`.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

use anyhow::{bail, Result};

use super::engine::Engine;
use super::http::{Link, Server};
use super::model::{self, ModelArgs};
use super::session::{self, Config, Summary, GRAPHICS_HZ_MIN};
use super::solver_engine::solver_engine;
use crate::scene::SceneArgs;

#[derive(clap::Args, Debug, Clone)]
pub struct LiveArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Solver threads (default: all cores); the same bits whatever the count.
    #[arg(long, value_parser = crate::domain::count)]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub model: ModelArgs,
    #[command(flatten)]
    pub session: SessionArgs,
}

/// How a live session is served and paced, whatever its engine (`pe live`, `board-sim live`).
#[derive(clap::Args, Debug, Clone)]
pub struct SessionArgs {
    /// Address of the page (http://ADDR/) and the WebSocket session (ws://ADDR/session).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub listen: String,
    /// OpenIGTLink port (0: off).
    #[arg(long, default_value_t = 18944)]
    pub igtl_port: u16,
    /// Write every pose as applied to FILE (JSON lines), for `pe solve --replay FILE` or
    /// `board-sim run DIR --replay FILE`.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// End after S seconds of wall time (default: at Ctrl-C or when standard input closes).
    #[arg(long, value_parser = crate::domain::positive)]
    pub duration: Option<f64>,
    /// Surface frames per second of wall time (at least 25).
    #[arg(long, default_value_t = 30.0, value_parser = crate::domain::positive)]
    pub graphics_hz: f64,
    /// Lag (s) past which the session's clock slips.
    #[arg(long, default_value_t = 0.1, value_parser = crate::domain::positive)]
    pub max_lag: f64,
    /// Run as fast as possible, not paced to the wall clock (tests, benchmarks).
    #[arg(long)]
    pub no_pace: bool,
    /// No log lines (the URL and the summary are still printed).
    #[arg(long)]
    pub quiet: bool,
}

/// Set by SIGINT (Ctrl-C).
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

#[cfg(unix)]
extern "C" fn on_interrupt(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
    // A second Ctrl-C ends the process the usual way.
    // SAFETY: signal() is async-signal-safe; it restores the default action.
    unsafe {
        libc::signal(libc::SIGINT, libc::SIG_DFL);
    }
}

fn catch_interrupt() {
    #[cfg(unix)]
    // SAFETY: installs a handler that only stores to an atomic and resets the action.
    unsafe {
        libc::signal(
            libc::SIGINT,
            on_interrupt as *const () as libc::sighandler_t,
        );
    }
}

/// Whether standard input is something that ends when its user is done: a terminal or a
/// pipe (not /dev/null, as for a job started with `&`).
fn stdin_is_watched() -> bool {
    use std::io::IsTerminal;
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let fifo = std::fs::metadata("/dev/stdin").is_ok_and(|m| m.file_type().is_fifo());
        fifo || std::io::stdin().is_terminal()
    }
    #[cfg(not(unix))]
    std::io::stdin().is_terminal()
}

/// The session's configuration from the command line.
pub fn config(args: &SessionArgs) -> Result<Config> {
    if !(args.graphics_hz >= GRAPHICS_HZ_MIN && args.graphics_hz.is_finite()) {
        bail!(
            "--graphics-hz {}: at least {GRAPHICS_HZ_MIN} (a surface that moves smoothly)",
            args.graphics_hz
        );
    }
    if !(args.max_lag > 0.0) {
        bail!("--max-lag {}: a positive number of seconds", args.max_lag);
    }
    if let Some(d) = args.duration {
        if !(d > 0.0) {
            bail!("--duration {d}: a positive number of seconds");
        }
    }
    Ok(Config {
        graphics_hz: args.graphics_hz,
        max_lag_s: args.max_lag,
        pace: !args.no_pace,
        duration_s: args.duration,
        record: args.record.clone(),
        quiet: args.quiet,
        ..Config::default()
    })
}

/// `pe live`.
pub fn run(args: &LiveArgs) -> Result<()> {
    let cfg = config(&args.session)?;
    let (scene, dir, name) = args.scene.load()?;
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .max(1);
    let scene_arg = if args.scene.builtin {
        format!("--builtin --level {}", args.scene.level)
    } else {
        name.clone()
    };
    let chosen = model::choose(&scene, &dir, &name, &scene_arg, &args.model, threads)?;
    chosen.problem.print_notes();
    let (problem, name) = (&chosen.problem, &chosen.name);
    let mut engine = solver_engine(problem, name, threads, &chosen.note)?;
    let summary = serve_until_stopped(engine.as_mut(), name, &args.session, &cfg, "pe live")?;
    if let Some(p) = &args.session.record {
        println!(
            "  recorded to {} (replay: pe solve {} --replay {} --steps {})",
            p.display(),
            chosen.scene_arg,
            p.display(),
            summary.steps
        );
    }
    match summary.error {
        Some(e) => bail!("the session stopped: {e}"),
        None => Ok(()),
    }
}

/// Serves `engine` (the scene `name`) as `args` and `cfg` say until Ctrl-C, the end of
/// standard input (a terminal or a pipe) or `--duration`, printing where it listens (as
/// `command`) and its summary: what `pe live` and `board-sim live` share.
pub fn serve_until_stopped(
    engine: &mut (dyn Engine + Send),
    name: &str,
    args: &SessionArgs,
    cfg: &Config,
    command: &str,
) -> Result<Summary> {
    let stop = Arc::new(AtomicBool::new(false));
    catch_interrupt();
    if stdin_is_watched() {
        let stop = stop.clone();
        let _ = std::thread::Builder::new()
            .name("pe-live-stdin".into())
            .spawn(move || {
                let _ = std::io::copy(&mut std::io::stdin().lock(), &mut std::io::sink());
                stop.store(true, Ordering::SeqCst);
            });
    }
    let watch = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            while !stop.load(Ordering::SeqCst) {
                if INTERRUPTED.load(Ordering::SeqCst) {
                    stop.store(true, Ordering::SeqCst);
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        })
    };
    let info = engine.info();
    eprintln!(
        "{name}: {}, dt = {:.3e} s, {} tool(s), {} surface nodes, {} triangles",
        info.model,
        engine.dt_s(),
        info.tools.len(),
        info.surface.reference_m.len(),
        info.surface.triangles.len()
    );
    let summary = serve(engine, &args.listen, args.igtl_port, cfg, &stop, |addr| {
        println!("{command}: the trainer page is at http://{addr}/ (the WebSocket session at ws://{addr}/session)");
    });
    stop.store(true, Ordering::SeqCst);
    let _ = watch.join();
    let summary = summary?;
    print!("{summary}");
    Ok(summary)
}

/// Serves `engine` as a live session on `listen` (and OpenIGTLink on `igtl_port`, 0: off)
/// until `stop`, the configured duration or steps, or a failed step; `ready` is told the
/// address once it listens. The session runs on its own thread.
pub fn serve(
    engine: &mut (dyn Engine + Send),
    listen: &str,
    igtl_port: u16,
    cfg: &Config,
    stop: &AtomicBool,
    ready: impl FnOnce(SocketAddr),
) -> Result<Summary> {
    let (tx, rx) = mpsc::channel();
    let link = Link {
        inbound: tx,
        ids: Arc::new(AtomicU32::new(0)),
    };
    let mut server = Server::start(listen, link.clone(), cfg.quiet)?;
    let _igtl = super::igtl::start(
        listen,
        igtl_port,
        engine.info(),
        link.inbound.clone(),
        link.ids.clone(),
        cfg.quiet,
    )?;
    drop(link);
    ready(server.addr());
    let summary = std::thread::scope(|s| {
        std::thread::Builder::new()
            .name("pe-live-session".into())
            .spawn_scoped(s, move || session::run(engine, &rx, cfg, stop))
            .map_err(anyhow::Error::from)
            .and_then(|t| {
                t.join()
                    .unwrap_or_else(|_| bail!("the session's thread panicked"))
            })
    });
    server.stop();
    summary
}
