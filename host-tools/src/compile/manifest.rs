//! `DIR/manifest.json` (what was compiled, for which machine and profile, each image's
//! size and CRC) and the whole `pe compile` into a directory.

use std::path::Path;

use anyhow::{Context, Result};
use pe_firmware::image::FORMAT_VERSION;
use pe_firmware::profile::BoardProfile;
use serde::Serialize;

use super::partition::Machine;
use super::{
    check_fit, compile_images, image_file_name, plan, report, write_images, CompileReport,
};
use crate::problem::Problem;

/// `DIR/manifest.json`.
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct Manifest {
    pub format_version: u16,
    pub scene: String,
    /// The compilation id every image of the set carries in its header (16 hex digits,
    /// [`pe_firmware::image::CompilationId`]'s display); board-sim refuses images without it.
    pub compilation: String,
    /// How to load the scene again (its mesh, for outputs): `builtin:LEVEL` or a file path.
    pub scene_source: String,
    pub machine: [usize; 3],
    pub profile: String,
    pub precision: String,
    pub integration: String,
    pub dt_s: f64,
    pub steps: u64,
    pub boards: Vec<ManifestBoard>,
}

#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct ManifestBoard {
    pub board: [usize; 3],
    pub file: String,
    pub bytes: usize,
    /// CRC-32 of the image (what its last four bytes hold), 8 hex digits; board-sim checks
    /// the file against it.
    pub crc32: String,
}

/// Compiles a problem into `dir`: images, manifest.json, report.json; returns the report.
pub fn compile_to_dir(
    scene: &str,
    scene_source: &str,
    problem: &Problem,
    machine: Machine,
    profile: &BoardProfile,
    dir: &Path,
) -> Result<CompileReport> {
    let plan = plan(problem, machine)?;
    let images = compile_images(problem, &plan)?;
    check_fit(&images, profile)?;
    write_images(dir, &images)?;
    let dt = problem.time_step.dt_s;
    let manifest = Manifest {
        format_version: FORMAT_VERSION,
        scene: scene.to_string(),
        compilation: images
            .first()
            .map(|im| im.header.compilation.to_string())
            .unwrap_or_default(),
        scene_source: scene_source.to_string(),
        machine: machine.dims,
        profile: profile.name.to_string(),
        precision: problem.solver.precision.name().to_string(),
        integration: problem.solver.integration.name().to_string(),
        dt_s: dt,
        steps: problem.steps(dt),
        boards: images
            .iter()
            .map(|im| ManifestBoard {
                board: im.coords,
                file: image_file_name(im.coords),
                bytes: im.bytes.len(),
                crc32: format!(
                    "{:08x}",
                    link_proto::frame::crc32(&im.bytes[..im.bytes.len() - 4])
                ),
            })
            .collect(),
    };
    let p = dir.join("manifest.json");
    std::fs::write(&p, serde_json::to_string_pretty(&manifest)?)
        .with_context(|| format!("writing {}", p.display()))?;
    let rep = report(scene, problem, &plan, &images, profile)?;
    let p = dir.join("report.json");
    std::fs::write(&p, serde_json::to_string_pretty(&rep)?)
        .with_context(|| format!("writing {}", p.display()))?;
    Ok(rep)
}

/// Reads `DIR/manifest.json`.
pub fn read_manifest(dir: &Path) -> Result<Manifest> {
    let p = dir.join("manifest.json");
    let text = std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", p.display()))
}
