//! The scene a command runs, as one clap argument group ([`SceneArgs`]): a file, or the
//! built-in one at a level. `pe`'s subcommands and `pe live` flatten it.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use super::builtin::builtin_scene;
use super::Scene;

/// The scene a subcommand runs: a file, or the built-in one at a level.
#[derive(clap::Args, Debug, Clone)]
pub struct SceneArgs {
    /// Scene file (TOML).
    pub scene: Option<PathBuf>,
    /// Use the built-in scene (uterus, both tubes, probe) instead of a file.
    #[arg(long, conflicts_with = "scene")]
    pub builtin: bool,
    /// Mesh level of the built-in scene: coarse (~300), medium (~2000), fine (~20000).
    #[arg(long, default_value = "medium")]
    pub level: String,
}

impl SceneArgs {
    /// The scene, the directory its paths are relative to, and its name.
    pub fn load(&self) -> Result<(Scene, PathBuf, String)> {
        if self.builtin {
            return Ok((
                builtin_scene(&self.level)?,
                PathBuf::from("."),
                format!("builtin:{}", self.level),
            ));
        }
        let path = self
            .scene
            .as_ref()
            .context("give a scene file or --builtin")?;
        let scene = Scene::from_file(path)?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok((scene, dir, path.display().to_string()))
    }
}
