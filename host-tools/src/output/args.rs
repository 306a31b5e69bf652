//! The output flags of a run, declared once for both command lines: [`ResultArgs`] (the
//! final state and the report: `pe solve`, board-sim's `run`, `builtin` and `qemu`) inside
//! [`OutputArgs`] (with the ParaView series and the tool forces: `pe solve`, board-sim's
//! `run` and `builtin`, which add their picture).

use std::path::PathBuf;

use anyhow::Result;
use serde::Serialize;

use crate::mesh::Mesh;

/// Where a run's result goes, each file only when its flag is given:
///
/// - `output_nodes` (`--output-nodes FILE`): the final state of every mesh node as the
///   nodes CSV ([`super::write_nodes_csv`], columns [`super::NODES_CSV_HEADER`]), the file
///   `pe compare` compares;
/// - `report` (`--report FILE`): the run's report as pretty-printed JSON (`pe solve`:
///   [`crate::solver::RunReport`]; a board run writes its own report type).
#[derive(clap::Args, Clone, Debug, Default, PartialEq, Eq)]
pub struct ResultArgs {
    /// Final state of every mesh node: node,x_m,y_m,z_m,ux_m,uy_m,uz_m (`board-sim qemu`:
    /// as the boards reported it).
    #[arg(long)]
    pub output_nodes: Option<PathBuf>,
    /// Run report (JSON). `pe solve`: its run report; `board-sim run`: that, plus per-link
    /// traffic, waiting and the link model; `board-sim qemu`: wall time per step, per-board
    /// exits, link and global bytes.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

/// What a run writes besides its console summary: the [`ResultArgs`], and
///
/// - `vtk` (`--vtk DIR`): a ParaView time series in the directory (`frame_NNNNN.vtu` and
///   `series.pvd`, see [`super::vtk`]): `pe solve` writes the volume mesh every output
///   interval ([`super::FrameWriter`]), a board run the surface frames its graphics engine
///   received;
/// - `tool_force` (`--tool-force FILE`): the force on each tool every step
///   ([`super::tool_force`]).
#[derive(clap::Args, Clone, Debug, Default, PartialEq, Eq)]
pub struct OutputArgs {
    #[command(flatten)]
    pub result: ResultArgs,
    /// ParaView time series (.vtu frames and series.pvd) into this directory: `pe solve` the
    /// volume mesh every output interval; board-sim the surface frames the graphics engine
    /// received over the global network (every graphics interval).
    #[arg(long)]
    pub vtk: Option<PathBuf>,
    /// The force of the tissue on each tool every step: step,time_s,tool,fx_n,fy_n,fz_n
    /// (board-sim: as the host summed it from the boards' packets, what a haptic device
    /// renders).
    #[arg(long)]
    pub tool_force: Option<PathBuf>,
}

impl ResultArgs {
    /// Checks, before the run, that every asked-for file can be written (its directory
    /// exists and takes files): a typo is named now, not after a long run.
    pub fn check(&self) -> Result<()> {
        if let Some(p) = &self.output_nodes {
            super::file::check_file(p, "--output-nodes")?;
        }
        if let Some(p) = &self.report {
            super::file::check_file(p, "--report")?;
        }
        Ok(())
    }

    /// Writes the nodes CSV of displacements `u` on `mesh` when `--output-nodes` asks for it.
    pub fn write_nodes(&self, mesh: &Mesh, u: &[[f64; 3]]) -> Result<()> {
        match &self.output_nodes {
            Some(p) => super::write_nodes_csv(p, mesh, u),
            None => Ok(()),
        }
    }

    /// Writes `report` as pretty-printed JSON when `--report` asks for it.
    pub fn write_report<R: Serialize>(&self, report: &R) -> Result<()> {
        match &self.report {
            Some(p) => super::file::write_atomic(p, serde_json::to_string_pretty(report)?),
            None => Ok(()),
        }
    }
}

impl OutputArgs {
    /// [`ResultArgs::check`], and the `--tool-force` file and the `--vtk` directory (made
    /// if missing).
    pub fn check(&self) -> Result<()> {
        self.result.check()?;
        if let Some(p) = &self.tool_force {
            super::file::check_file(p, "--tool-force")?;
        }
        if let Some(d) = &self.vtk {
            super::file::check_dir(d, "--vtk")?;
        }
        Ok(())
    }
}
