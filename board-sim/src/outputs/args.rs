//! The output flags of board-sim's commands, declared once (`pe`'s CLI declares its own;
//! these are meant to be shared with it).

use std::path::PathBuf;

/// Where a run's result goes: the final state and the run report (`run`, `builtin`,
/// `qemu`).
#[derive(clap::Args, Clone, Debug, Default)]
pub struct ResultArgs {
    /// node,x_m,y_m,z_m,ux_m,uy_m,uz_m of every mesh node at the end (under `qemu`: as the
    /// boards reported it).
    #[arg(long)]
    pub output_nodes: Option<PathBuf>,
    /// Run report (JSON). `run`: as `pe solve`, plus per-link traffic, waiting and the link
    /// model; `qemu`: wall time per step, per-board exits, link and global bytes.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

/// Every output of a run on host threads (`run`, `builtin`): the result, and what the
/// graphics engine and the host received.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct OutputArgs {
    #[command(flatten)]
    pub result: ResultArgs,
    /// ParaView time series into this directory: the surface frames the graphics engine
    /// received over the global network (every graphics interval).
    #[arg(long)]
    pub vtk: Option<PathBuf>,
    /// PNG of the last surface frame the graphics engine received.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// step,time_s,tool,fx_n,fy_n,fz_n: the force of the tissue on each tool every step, as the
    /// host summed it from the boards' packets (what a haptic device renders).
    #[arg(long)]
    pub tool_force: Option<PathBuf>,
}
