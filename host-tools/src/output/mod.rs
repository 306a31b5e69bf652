//! Run outputs shared by `pe solve` and board-sim: the nodes CSV (and the CSV writer every
//! table goes through), ParaView frames and the progress bar.
//!
//! Every CSV column that has a unit carries it as the suffix of its name, in SI (`x_m`,
//! `ux_m`, `time_s`, `fx_n`, `energy_j`); ids, counts and ratios have none. The ParaView
//! frames name their arrays the same way (see [`vtk`]).

mod args;
pub mod file;
pub mod font;
pub mod render;
pub mod tool_force;
pub mod vtk;

pub use args::{OutputArgs, ResultArgs};

use std::io::Write;
use std::path::Path;

use anyhow::{Context, Result};

use crate::mesh::Mesh;
use crate::output::vtk::{PointField, VtkSeriesWriter, VELOCITY};
use crate::solver::StepState;

/// A standard output closed early (`pe compile ... | head`) ends the process quietly, as
/// it does any Unix tool, instead of panicking in `println!`: restores the default action of
/// SIGPIPE, which the Rust runtime sets to ignore. Called first in `main` by `pe` and
/// board-sim. Elsewhere than on Unix it does nothing.
pub fn exit_quietly_when_stdout_closes() {
    #[cfg(unix)]
    // SAFETY: called at the start of `main`, before any thread exists; it only sets one
    // signal's disposition back to the system default.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// Asks errors to capture where they arose (for [`finish`] with `backtrace` set): called by
/// `pe` and board-sim after parsing `--backtrace`, before any work or thread.
pub fn capture_backtraces() {
    std::env::set_var("RUST_LIB_BACKTRACE", "1");
}

/// How `pe` and board-sim end: `Ok` exits 0; an error prints `error: MESSAGE` and then each
/// cause of its chain on a `  caused by:` line, and exits 1. A backtrace is printed only when
/// `backtrace` is set (the `--backtrace` flag), never because `RUST_BACKTRACE` is set in the
/// user's shell: a bad input is the user's to fix, not a crash.
pub fn finish(result: Result<()>, backtrace: bool) -> std::process::ExitCode {
    let Err(e) = result else {
        return std::process::ExitCode::SUCCESS;
    };
    eprintln!("error: {e}");
    for cause in e.chain().skip(1) {
        eprintln!("  caused by: {cause}");
    }
    if backtrace {
        eprintln!("backtrace:\n{}", e.backtrace());
    }
    std::process::ExitCode::FAILURE
}

/// The nodes CSV's header: the node tag, the initial position and the displacement, with
/// their units (m).
pub const NODES_CSV_HEADER: [&str; 7] = ["node", "x_m", "y_m", "z_m", "ux_m", "uy_m", "uz_m"];

/// `node,x_m,y_m,z_m,ux_m,uy_m,uz_m`: every mesh node once, in mesh node order (node = its
/// tag): initial position and displacement, m. Values are written with 17 significant
/// digits so the CSV round-trips f64 exactly.
pub fn write_nodes_csv(path: &Path, mesh: &Mesh, u: &[[f64; 3]]) -> Result<()> {
    let rows = mesh.nodes.iter().zip(u).enumerate().map(|(k, (p, d))| {
        let tag = mesh.node_tags.get(k).copied().unwrap_or(k as u64 + 1);
        let mut row = vec![tag.to_string()];
        row.extend(p.iter().chain(d).map(|v| format!("{v:.17e}")));
        row
    });
    write_csv(path, &NODES_CSV_HEADER, rows)
}

/// Writes the CSV file `path`: the header, then one record per row. The fields come
/// formatted, so every number keeps the spelling its writer chose; the csv crate quotes
/// where needed.
pub fn write_csv<R, F>(path: &Path, header: &[&str], rows: R) -> Result<()>
where
    R: IntoIterator,
    R::Item: IntoIterator<Item = F>,
    F: AsRef<[u8]>,
{
    let mut file = file::AtomicFile::create(path)?;
    csv_records(&mut file, header, rows).with_context(|| format!("writing {}", path.display()))?;
    file.commit()
}

/// The CSV text of `header` and `rows` (see [`write_csv`]).
pub fn csv_string<R, F>(header: &[&str], rows: R) -> Result<String>
where
    R: IntoIterator,
    R::Item: IntoIterator<Item = F>,
    F: AsRef<[u8]>,
{
    let bytes = csv_records(Vec::new(), header, rows)?;
    Ok(String::from_utf8(bytes)?)
}

/// Writes the header and the rows to `out` through the csv crate; returns `out`.
fn csv_records<W, R, F>(out: W, header: &[&str], rows: R) -> Result<W>
where
    W: Write,
    R: IntoIterator,
    R::Item: IntoIterator<Item = F>,
    F: AsRef<[u8]>,
{
    let mut w = csv::Writer::from_writer(out);
    w.write_record(header)?;
    for row in rows {
        w.write_record(row)?;
    }
    w.into_inner().map_err(|e| anyhow::anyhow!("{}", e.error()))
}

/// The step counter of a long run (`pe solve`, board-sim).
pub fn progress_bar(total: u64) -> indicatif::ProgressBar {
    let b = indicatif::ProgressBar::new(total);
    b.set_style(
        indicatif::ProgressStyle::with_template(
            "{bar:40} {pos}/{len} steps  {elapsed} (eta {eta})",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    b
}

/// Writes a frame every `interval_s` of simulated time (and the last one): the reference
/// points with `displacement_m` and `velocity_m_per_s` (see [`vtk`]'s conventions), from
/// rest at time 0.
pub struct FrameWriter {
    writer: VtkSeriesWriter,
    every_steps: u64,
}

impl FrameWriter {
    pub fn new(dir: &Path, mesh: &Mesh, interval_s: f64, dt_s: f64) -> Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let mut writer = VtkSeriesWriter::new(dir, mesh)?;
        let rest = vec![[0.0; 3]; mesh.nodes.len()];
        writer.write_frame_with(0.0, &rest, &[(VELOCITY, PointField::Vector(&rest))])?;
        Ok(FrameWriter {
            writer,
            every_steps: ((interval_s / dt_s).round() as u64).max(1),
        })
    }

    /// After step `step` of `total`: a frame if one is due, of the state `state` gives.
    pub fn maybe_write(
        &mut self,
        step: u64,
        time_s: f64,
        total: u64,
        state: &dyn StepState,
    ) -> Result<()> {
        if step.is_multiple_of(self.every_steps) || step == total {
            let v = state.velocities();
            self.writer.write_frame_with(
                time_s,
                &state.displacements(),
                &[(VELOCITY, PointField::Vector(&v))],
            )?;
        }
        Ok(())
    }

    /// Number of frames written so far (the rest frame included).
    pub fn frame_count(&self) -> usize {
        self.writer.frame_count()
    }

    pub fn finish(self) -> Result<()> {
        self.writer.finish()?;
        Ok(())
    }
}
