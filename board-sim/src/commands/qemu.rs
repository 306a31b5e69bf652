//! `board-sim qemu DIR`: the firmware itself on an emulated array ([`crate::qemu`]), its
//! outputs and summary.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{anyhow, bail, Result};
use host_tools::compile::{read_manifest, OutputMesh};
use host_tools::output::write_nodes_csv;

use crate::commands::run::replay_poses;
use crate::outputs::{ResultArgs, OUTPUT_MESH_SOURCE};
use crate::qemu::{parse_board, run_array, ArrayFault, ArrayOptions, Connector};
use crate::report::array::{write_array_fault_report, write_array_report};

/// `board-sim qemu`'s options.
#[derive(clap::Args)]
pub struct QemuArgs {
    #[command(flatten)]
    pub result: ResultArgs,
    /// The firmware ELF (default: built with cargo for the images' precision and
    /// integration).
    #[arg(long)]
    pub firmware: Option<PathBuf>,
    /// Where the per-board ELFs and schedule blobs go (default DIR/qemu).
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// End board X,Y,Z's QEMU S seconds after every board began (X,Y,Z@S): each has
    /// told the host its compilation id, before its step 0.
    #[arg(long)]
    pub kill: Option<String>,
    /// Swap the far ends of the cables at two connectors (X,Y,Z:FACE,X,Y,Z:FACE, FACE
    /// one of +x -x +y -y +z -z).
    #[arg(long, allow_hyphen_values = true)]
    pub cross: Option<String>,
    /// The whole run's bound (s).
    #[arg(long, default_value_t = 1800.0, value_parser = host_tools::domain::positive)]
    pub timeout_s: f64,
    /// The emulator.
    #[arg(long, default_value = "qemu-system-arm")]
    pub qemu: PathBuf,
    /// Replay a recorded live session (`pe live`/`board-sim live --record FILE`): its poses
    /// sent to the boards holding each tool, the boards held to them by the host's step
    /// gate; bit for bit `board-sim run DIR --replay FILE`.
    #[arg(long)]
    pub replay: Option<PathBuf>,
    /// The force on each tool every step (step,time_s,tool,fx_n,fy_n,fz_n), as the host
    /// received it.
    #[arg(long)]
    pub tool_force: Option<PathBuf>,
    /// Do not echo the boards' FAULT lines as they arrive (a fault still ends the run with an
    /// error naming the board).
    #[arg(long)]
    pub quiet: bool,
}

impl QemuArgs {
    /// The array's options.
    pub fn options(self) -> Result<ArrayOptions> {
        Ok(ArrayOptions {
            qemu: self.qemu,
            firmware: self.firmware,
            images: self.images,
            deadline: Duration::from_secs_f64(self.timeout_s.max(0.0)),
            kill: self.kill.as_deref().map(parse_kill).transpose()?,
            cross: self.cross.as_deref().map(parse_cross).transpose()?,
            quiet: self.quiet,
            poses: Default::default(),
        })
    }
}

/// `--kill X,Y,Z@S`.
fn parse_kill(s: &str) -> Result<([usize; 3], Duration)> {
    let bad = || anyhow!("--kill {s:?}: expected X,Y,Z@SECONDS, e.g. 1,0,0@3");
    let (b, t) = s.split_once('@').ok_or_else(bad)?;
    let [x, y, z] = parse_board(b).ok_or_else(bad)?;
    let t: f64 = t.trim().parse().map_err(|_| bad())?;
    if !(t.is_finite() && t >= 0.0) {
        return Err(bad());
    }
    Ok(([x, y, z], Duration::from_secs_f64(t)))
}

/// `--cross X,Y,Z:FACE,X,Y,Z:FACE`.
fn parse_cross(s: &str) -> Result<[Connector; 2]> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 6 {
        bail!("--cross {s:?}: expected X,Y,Z:FACE,X,Y,Z:FACE, e.g. 0,0,0:+x,0,0,0:+y");
    }
    let a = Connector::parse(&parts[..3].join(","))?;
    let b = Connector::parse(&parts[3..].join(","))?;
    Ok([a, b])
}

/// `board-sim qemu`: runs the array, writes the outputs, prints a summary.
pub fn qemu_array(dir: &Path, args: QemuArgs) -> Result<()> {
    let result = args.result.clone();
    let (replay, tool_force) = (args.replay.clone(), args.tool_force.clone());
    result.check()?;
    if let Some(p) = &tool_force {
        host_tools::output::file::check_file(p, "--tool-force")?;
    }
    let mut opts = args.options()?;
    let manifest = read_manifest(dir)?;
    if let Some(r) = &replay {
        opts.poses = replay_poses(r, &manifest, &OutputMesh::read(dir)?)?;
    }
    eprintln!(
        "{}: {} boards ({}x{}x{}) under QEMU mps2-an500, {} steps",
        manifest.scene,
        manifest.boards.len(),
        manifest.machine[0],
        manifest.machine[1],
        manifest.machine[2],
        manifest.steps
    );
    let out = match run_array(dir, &opts) {
        Ok(o) => o,
        Err(e) => {
            if let (Some(p), Some(f)) = (&result.report, e.downcast_ref::<ArrayFault>()) {
                write_array_fault_report(p, f)?;
            }
            return Err(e);
        }
    };
    let max_u = host_tools::compare::max_abs(&out.displacements);
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
    if let Some(p) = &result.output_nodes {
        let mesh = OutputMesh::read(dir)?.mesh(OUTPUT_MESH_SOURCE);
        write_nodes_csv(p, &mesh, &out.displacements)?;
    }
    if out.pose_packets > 0 {
        println!("{} tool-pose packets sent", out.pose_packets);
    }
    if let Some(p) = &result.report {
        write_array_report(p, &out, max_u, per_step)?;
    }
    if let Some(p) = &tool_force {
        let (tools, dt_s) = (OutputMesh::read(dir)?.tools.len(), manifest.dt_s);
        host_tools::output::tool_force::write_tool_force_csv(p, &out.tool_force, tools, |s| {
            s as f64 * dt_s
        })?;
    }
    Ok(())
}
