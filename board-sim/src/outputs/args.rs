//! The output flags of board-sim's commands: the run's ([`OutputArgs`]: host-tools' one
//! declaration, shared with `pe solve`) and the picture board-sim adds.

use std::path::PathBuf;

pub use host_tools::output::ResultArgs;

/// Every output of a run on host threads (`run`, `builtin`): the result, the ParaView series
/// and the tool forces (`pe solve`'s flags), and a picture of what the graphics engine
/// received.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct OutputArgs {
    #[command(flatten)]
    pub run: host_tools::output::OutputArgs,
    /// PNG of the last surface frame the graphics engine received.
    #[arg(long)]
    pub png: Option<PathBuf>,
}

impl OutputArgs {
    /// Checks every asked-for output path before the run ([`host_tools::output::OutputArgs::check`]
    /// and `--png`).
    pub fn check(&self) -> anyhow::Result<()> {
        self.run.check()?;
        if let Some(p) = &self.png {
            host_tools::output::file::check_file(p, "--png")?;
        }
        Ok(())
    }
}
