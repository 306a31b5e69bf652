//! `board-sim run DIR`: run a compiled machine on host threads over emulated links, print
//! what it did and write the outputs asked for.

use std::path::Path;
use std::time::Duration;

use anyhow::Result;
use host_tools::compile::{read_manifest, Manifest, OutputMesh};
use host_tools::live::session::record::replay_schedule_for;
use host_tools::solver::PoseSchedule;
use pe_firmware::physics::vec3::norm;

use crate::check::SimFault;
use crate::clock::Clocking;
use crate::faults::FaultSpec;
use crate::outputs::{graphics, write_outputs, OutputArgs};
use crate::report::{global_summary, recovery_summary, write_fault_report, write_report, RunFacts};
use crate::results::SimOutput;
use crate::runner::{run, SimOptions};
use crate::storage::StorageSizing;
use crate::timing::{model, SimTiming, StepTiming};

/// `board-sim run`'s options.
#[derive(clap::Args, Default)]
pub struct RunArgs {
    #[command(flatten)]
    pub outputs: OutputArgs,
    /// Stop after N steps.
    #[arg(long, value_parser = host_tools::domain::steps, conflicts_with = "duration")]
    pub steps: Option<u64>,
    /// Stop after this much simulated time (s).
    #[arg(long, value_parser = host_tools::domain::positive)]
    pub duration: Option<f64>,
    /// Inject faults: seed=S,drop=P,corrupt=P,delay=MS,stall=X.Y.Z@STEP[,on=all|links|global].
    /// drop and corrupt apply to each point-to-point frame and each global packet a board
    /// sends (on=links or on=global for one kind only); delay to the frames; a stalled board
    /// sends no more frames or packets from STEP on
    #[arg(long)]
    pub faults: Option<String>,
    /// Run without link-level and global-network recovery: every lost or damaged frame or
    /// packet stops the run (for fault detection). Default: frames and global packets are
    /// numbered, acknowledged and retransmitted.
    #[arg(long)]
    pub no_recovery: bool,
    /// Run the boards' element batches on the firmware's scalar loop, as a board does.
    /// Default: on the host's SIMD lanes (AVX where the CPU has it), which compute the same
    /// bits.
    #[arg(long)]
    pub scalar_kernel: bool,
    /// A link silent this long is a fault (s).
    #[arg(long, default_value_t = 10.0, value_parser = host_tools::domain::positive)]
    pub link_timeout_s: f64,
    /// The run's time: `wall` (the host's clock) or `simulated` (time that advances, 100 us
    /// at a time, only while every board waits: link timeouts, recovery's timers, injected
    /// delays and the grace after a fault then do not depend on how busy the host is; for
    /// fault runs whose blame must not depend on the machine).
    #[arg(long, value_enum, default_value_t = Clock::Wall)]
    pub clock: Clock,
    /// Link bandwidth for the timing model (bytes/s; default from the board profile).
    #[arg(long, value_parser = host_tools::domain::positive)]
    pub link_bandwidth: Option<f64>,
    /// Link latency for the timing model (s).
    #[arg(long, value_parser = host_tools::domain::non_negative)]
    pub link_latency_s: Option<f64>,
    /// Host threads to multiplex the boards over (default: the machine's cores; as many as
    /// boards runs one thread per board).
    #[arg(long, value_parser = host_tools::domain::count)]
    pub workers: Option<usize>,
    /// Storage per board: `exact` (what each image needs) or `board` (what the firmware of
    /// the manifest's profile holds: an image the board would refuse is refused here).
    #[arg(long, value_enum, default_value_t = Storage::Exact)]
    pub storage: Storage,
    /// Replay a recorded live session (`pe live --record FILE`): the host sends each pose
    /// to the boards holding its tool, to take effect at its recorded step, as
    /// `pe solve --replay FILE` applies it.
    #[arg(long, value_name = "FILE")]
    pub replay: Option<std::path::PathBuf>,
    /// No progress bar (the summary is still printed).
    #[arg(long)]
    pub quiet: bool,
}

/// `--clock`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Clock {
    #[default]
    Wall,
    Simulated,
}

impl Clock {
    /// The runner's clocking for this choice.
    pub fn clocking(self) -> Clocking {
        match self {
            Clock::Wall => Clocking::Wall,
            Clock::Simulated => Clocking::Simulated {
                quantum_ns: Clocking::QUANTUM_NS,
            },
        }
    }
}

/// `--storage`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Storage {
    #[default]
    Exact,
    Board,
}

/// Runs a compiled machine and writes the requested outputs; returns the run. Reads the
/// compiled directory only: its manifest, images, report and mesh (`DIR/mesh.json`).
pub fn execute(dir: &Path, a: RunArgs) -> Result<SimOutput> {
    a.outputs.check()?;
    let manifest = read_manifest(dir)?;
    let mut opts = sim_options(&a, &manifest)?;
    let total = opts.steps.unwrap_or(manifest.steps).min(manifest.steps);
    // The mesh the outputs write and draw.
    let mesh = OutputMesh::read(dir)?;
    if let Some(r) = &a.replay {
        opts.poses = replay_poses(r, &manifest, &mesh)?;
    }
    let (elements, graphics_stream) = compile_report_facts(dir)?;
    if a.outputs.run.vtk.is_some() && !graphics_stream {
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
    let out = match run_with_progress(dir, &opts, total, a.quiet) {
        Ok(o) => o,
        Err(e) => {
            if let (Some(p), Some(f)) = (&a.outputs.run.result.report, e.downcast_ref::<SimFault>())
            {
                write_fault_report(p, &manifest, f)?;
            }
            return Err(e);
        }
    };
    let sim_s = out.steps as f64 * manifest.dt_s;
    let max_displacement = print_run(&out, &mesh, sim_s);
    let modelled = link_model(dir, &manifest, &a)?;
    // The frames the graphics engine could assemble (every surface node received): the
    // ones written to the ParaView series and counted in the summary and the report.
    let frames = graphics::surface_frames(&mesh, &out);
    let paraview_frames = write_outputs(&a.outputs, &mesh, &out, &frames, graphics_stream)?;
    let entry_bytes = link_proto::payload::node_entry_len(manifest.precision.wire());
    let global = global_summary(&out, sim_s, frames.len(), entry_bytes as f64);
    if let Some(g) = &global {
        println!("{}", g.text);
    }
    if let Some(p) = &a.outputs.run.result.report {
        let facts = RunFacts {
            elements,
            sim_s,
            max_displacement,
            paraview_frames,
        };
        write_report(p, &manifest, &out, &facts, &modelled, global.as_ref())?;
    }
    Ok(out)
}

/// Runs with a progress bar of `total` steps (none when `quiet`).
fn run_with_progress(dir: &Path, opts: &SimOptions, total: u64, quiet: bool) -> Result<SimOutput> {
    let bar = (!quiet).then(|| host_tools::output::progress_bar(total));
    let out = run(dir, opts, &mut |s, _| {
        if let Some(b) = &bar {
            b.set_position(s);
        }
    });
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    out
}

/// Prints what the run did: its speed and largest displacement, the prescribed reaction,
/// what link recovery cost; returns the largest displacement (m).
fn print_run(out: &SimOutput, mesh: &OutputMesh, sim_s: f64) -> f64 {
    let max = out
        .displacements
        .iter()
        .enumerate()
        .map(|(k, u)| (k, norm(*u)))
        .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    println!(
        "{} steps on {} boards in {:.2} s: {:.1} steps/s, real-time factor {:.3}; max |u| = {:.4e} m",
        out.steps, out.boards.len(), out.wall_s, out.steps as f64 / out.wall_s, sim_s / out.wall_s, max.1,
    );
    let prescribed = mesh.prescribed_nodes;
    if prescribed > 0 {
        let f = out.reaction_prescribed;
        println!(
            "  prescribed reaction ({prescribed} prescribed nodes on the tissue, at the end) = [{:.4e}, {:.4e}, {:.4e}] N",
            f[0], f[1], f[2]
        );
    }
    if let Some(r) = recovery_summary(out) {
        print_recovery(&r);
    }
    max.1
}

/// Link and global recovery's cost, from [`recovery_summary`].
fn print_recovery(r: &serde_json::Value) {
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

/// The simulation options from the command line (steps from `--steps` or `--duration`).
fn sim_options(a: &RunArgs, manifest: &Manifest) -> Result<SimOptions> {
    let storage = match a.storage {
        Storage::Exact => StorageSizing::Exact,
        // The manifest's profile is a registered one (an unknown name fails to read).
        Storage::Board => StorageSizing::Board(*manifest.profile),
    };
    let mut opts = SimOptions {
        link_timeout: Duration::from_secs_f64(a.link_timeout_s),
        workers: a.workers,
        storage,
        batched: !a.scalar_kernel,
        clocking: a.clock.clocking(),
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

/// The poses of the record `path` (host-tools' reader: the scene, time step and tools
/// checked against the compiled scene's).
pub(crate) fn replay_poses(
    path: &Path,
    manifest: &Manifest,
    mesh: &OutputMesh,
) -> Result<PoseSchedule> {
    // The images step at the manifest's dt and hold the tools `mesh.json` names.
    let tools: Vec<&str> = mesh.tools.iter().map(|t| t.name.as_str()).collect();
    let poses = replay_schedule_for(path, &manifest.scene, manifest.dt_s, &tools)?;
    eprintln!(
        "replaying {} poses of {} (each sent {} steps ahead)",
        poses.poses.len(),
        path.display(),
        link_proto::tool_pose::POSE_DELAY_STEPS
    );
    Ok(poses)
}

/// The link timing model of the run's images (profile links unless overridden), printed.
fn link_model(dir: &Path, manifest: &Manifest, a: &RunArgs) -> Result<StepTiming> {
    let mut timing = SimTiming::for_precision(manifest.profile, manifest.precision);
    if let Some(b) = a.link_bandwidth {
        timing.link_bytes_per_s = b;
    }
    if let Some(l) = a.link_latency_s {
        timing.link_latency_s = l;
    }
    if !a.no_recovery {
        timing.frame_overhead_bytes = link_proto::recovery::OVERHEAD;
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
            link_proto::recovery::OVERHEAD,
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
        manifest.profile.name, modelled.step_s * 1e6, modelled.compute_s * 1e6, modelled.dt_s * 1e6,
        if modelled.real_time { "keeps real time" } else { "does NOT keep real time" }
    );
    Ok(modelled)
}

/// From the compile report (read as the type that wrote it): the scene's elements, and
/// whether the images send surface frames to the graphics engine.
fn compile_report_facts(dir: &Path) -> Result<(usize, bool)> {
    let r = host_tools::compile::CompileReport::read(dir)?;
    Ok((r.elements, r.graphics.interval_steps > 0))
}
