//! `DIR/manifest.json` (what was compiled, for which machine and profile, each image's
//! size and CRC) and the whole `pe compile` into a directory.

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use link_proto::Machine;
use pe_firmware::image::{CompilationId, ImageHeader, Integration, Precision, FORMAT_VERSION};
use pe_firmware::profile::BoardProfile;
use serde::{Deserialize, Serialize};

use super::{check_fit, image_file_name, plan_for_real_time, report, write_images, CompileReport};
use crate::problem::Problem;
use crate::scene::settings::{integration_text, precision_text};

/// `DIR/manifest.json`: written by [`compile_to_dir`], read back as this type
/// ([`Manifest::read`]); the profile, precision and integration are their names in the
/// file, and an unknown name is an error.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Manifest {
    pub format_version: u16,
    pub scene: String,
    /// The compilation id every image of the set carries in its header (16 hex digits,
    /// [`pe_firmware::image::CompilationId`]'s display); board-sim refuses images without it.
    pub compilation: String,
    /// How to load the scene again (its mesh, for outputs): `builtin:LEVEL` or a file path.
    pub scene_source: String,
    pub machine: [usize; 3],
    #[serde(with = "pe_firmware::profile::by_name")]
    pub profile: &'static BoardProfile,
    #[serde(with = "precision_text")]
    pub precision: Precision,
    #[serde(with = "integration_text")]
    pub integration: Integration,
    pub dt_s: f64,
    pub steps: u64,
    /// How `dt_s` was found: the step at rest, or the smallest step `pe solve`'s tracking
    /// reached, run again from rest (`crate::solver::settle`), so that `pe solve` and the
    /// boards agree.
    #[serde(default)]
    pub dt_settled: Option<crate::solver::settle::SettledStep>,
    pub boards: Vec<ManifestBoard>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ManifestBoard {
    pub board: [usize; 3],
    pub file: String,
    pub bytes: usize,
    /// CRC-32 of the image (what its last four bytes hold), 8 hex digits; board-sim checks
    /// the file against it.
    pub crc32: String,
}

/// Compiles a problem into `dir`: images, manifest.json, report.json and mesh.json (what a
/// run's outputs write and draw, [`super::OutputMesh`]); returns the report.
pub fn compile_to_dir(
    scene: &str,
    scene_source: &str,
    problem: &Problem,
    machine: Machine,
    profile: &BoardProfile,
    dir: &Path,
) -> Result<CompileReport> {
    // The manifest names a registered profile (the figures may be a variant of it).
    let registered = BoardProfile::by_name(profile.name)?;
    super::plan::refuse_tetrahedra(problem)?;
    // One step for the boards and `pe solve`: where tracking would lower dt, the smallest
    // step it reaches, settled as `pe solve` settles it.
    let (settled, dt_settled) = crate::solver::settle::settled_problem(problem, scene)?;
    let problem: &Problem = &settled;
    let (plan, images, balance_other) = plan_for_real_time(problem, machine, profile)?;
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
        machine: machine.dims(),
        profile: registered,
        precision: problem.solver.precision,
        integration: problem.solver.integration,
        dt_s: dt,
        steps: problem.steps(dt),
        dt_settled: Some(dt_settled),
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
    crate::output::file::write_atomic(&p, serde_json::to_string_pretty(&manifest)?)?;
    let mut rep = report(scene, problem, &plan, &images, profile)?;
    rep.balance_other = balance_other;
    let p = dir.join("report.json");
    crate::output::file::write_atomic(&p, serde_json::to_string_pretty(&rep)?)?;
    super::OutputMesh::of(problem).write(dir)?;
    Ok(rep)
}

impl Manifest {
    /// Reads `DIR/manifest.json`, as the type that wrote it.
    /// Reads `DIR/manifest.json`, refusing one of another image format than this build's
    /// (a directory compiled by an older `pe`).
    pub fn read(dir: &Path) -> Result<Manifest> {
        let p = dir.join("manifest.json");
        let m: Manifest = read_json(&p)?;
        if m.format_version != FORMAT_VERSION {
            bail!(
                "{}: image format version {}, but this build reads version {FORMAT_VERSION}: compile the scene again with this pe",
                p.display(),
                m.format_version
            );
        }
        Ok(m)
    }
}

/// Reads `DIR/manifest.json` ([`Manifest::read`]).
pub fn read_manifest(dir: &Path) -> Result<Manifest> {
    Manifest::read(dir)
}

/// A JSON artefact of a compiled directory, read back as the type that wrote it; the
/// error names the file (and, from serde, the line and column).
pub(super) fn read_json<T: serde::de::DeserializeOwned>(p: &Path) -> Result<T> {
    let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", p.display()))
}

/// One image file of a set, as read (its header checked for its position).
pub struct ImageFile {
    pub board: [usize; 3],
    pub path: std::path::PathBuf,
    pub bytes: Vec<u8>,
    pub header: ImageHeader,
}

/// The set against the manifest (board-sim before any board runs, `pe image` before it
/// writes anything): every image's compilation id is the manifest's, every
/// file's CRC the one the manifest recorded, and the step the manifest repeats. A mixed set
/// is refused naming each odd board, its file and both ids.
pub fn check_image_set(manifest: &Manifest, files: &[ImageFile]) -> Result<()> {
    let named = |f: &ImageFile| {
        let [x, y, z] = f.board;
        format!("board ({x},{y},{z}): {}", f.path.display())
    };
    let expected = u64::from_str_radix(&manifest.compilation, 16)
        .ok()
        .filter(|_| manifest.compilation.len() == 16)
        .map(CompilationId::from_u64)
        .ok_or_else(|| {
            anyhow!(
                "manifest.json: compilation {:?} is not 16 hex digits: recompile",
                manifest.compilation
            )
        })?;
    let odd: Vec<&ImageFile> = files
        .iter()
        .filter(|f| f.header.compilation != expected)
        .collect();
    if !odd.is_empty() {
        let agree = files.len() - odd.len();
        let mut msg = if agree == 0
            && odd
                .iter()
                .all(|f| f.header.compilation == odd[0].header.compilation)
        {
            format!(
                "manifest.json is from compilation {expected} but all {} images are from {}",
                files.len(),
                odd[0].header.compilation
            )
        } else if agree * 2 < files.len()
            && odd
                .iter()
                .all(|f| f.header.compilation == odd[0].header.compilation)
        {
            // Most images agree among themselves: the manifest came with the few others.
            let mut m = format!(
                "mixed image set: manifest.json is from compilation {expected}, as are only {agree} of {} images; the other {} are from {}:",
                files.len(),
                odd.len(),
                odd[0].header.compilation
            );
            for f in files
                .iter()
                .filter(|f| f.header.compilation == expected)
                .take(8)
            {
                m += &format!("\n  {} is from compilation {expected}", named(f));
            }
            m
        } else {
            let mut m = format!(
                "mixed image set: {} of {} images are not from the manifest's compilation {expected}:",
                odd.len(),
                files.len()
            );
            for f in odd.iter().take(8) {
                m += &format!(
                    "\n  {} is from compilation {} but the manifest (and {agree} other boards) are from {expected}",
                    named(f),
                    f.header.compilation
                );
            }
            if odd.len() > 8 {
                m += &format!("\n  ... and {} more", odd.len() - 8);
            }
            m
        };
        msg += "\nrecompile, or copy the whole set (images and manifest.json) from one compilation";
        bail!(msg);
    }
    for (f, b) in files.iter().zip(&manifest.boards) {
        let crc = f
            .bytes
            .len()
            .checked_sub(4)
            .map(|n| link_proto::frame::crc32(&f.bytes[..n]))
            .unwrap_or(0);
        if format!("{crc:08x}") != b.crc32.to_ascii_lowercase() {
            bail!(
                "{}: CRC {crc:08x}, but manifest.json records {} for it: the file changed after compilation {expected}; recompile or copy the whole set",
                named(f),
                b.crc32
            );
        }
        if (f.header.precision, f.header.integration) != (manifest.precision, manifest.integration)
        {
            bail!(
                "{}: {:?} {:?}, but manifest.json says {:?} {:?}: the image is from another compilation",
                named(f),
                f.header.precision,
                f.header.integration,
                manifest.precision,
                manifest.integration
            );
        }
        // The manifest repeats the step for its readers; the images are what runs.
        let params = f.header.params;
        if params.dt_s != manifest.dt_s || params.steps != manifest.steps {
            bail!(
                "{}: dt {} s and {} steps, but manifest.json says dt {} s and {} steps: the image is from another compilation",
                named(f),
                params.dt_s,
                params.steps,
                manifest.dt_s,
                manifest.steps
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `manifest.json` and `report.json` read back as the types that wrote them: written
    /// again they are the same bytes, the profile is the registry's entry and the
    /// precision and integration the problem's (their names in the file); a manifest
    /// naming an unknown profile is refused, naming the file, the name and the known ones.
    /// `mesh.json` holds the problem's outputs mesh.
    #[test]
    fn the_artefacts_read_back_as_their_types() {
        let scene = crate::scene::builtin::builtin_scene("coarse").expect("scene");
        let p = Problem::from_scene(&scene, Path::new(".")).expect("problem");
        let dir = std::env::temp_dir().join(format!("pe-typed-artefacts-{}", std::process::id()));
        let machine = Machine::parse("2x2x2").expect("machine");
        let profile = &pe_firmware::profile::PE_BOARD;
        compile_to_dir("coarse", "builtin:coarse", &p, machine, profile, &dir).expect("compiles");
        let text = |f: &str| std::fs::read_to_string(dir.join(f)).expect("written");
        let m = Manifest::read(&dir).expect("manifest");
        assert_eq!(m.boards.len(), 8);
        assert!(core::ptr::eq(
            m.profile,
            BoardProfile::by_name("pe-board").unwrap()
        ));
        assert_eq!(
            (m.precision, m.integration),
            (p.solver.precision, p.solver.integration)
        );
        assert_eq!(
            serde_json::to_string_pretty(&m).unwrap(),
            text("manifest.json")
        );
        assert!(text("manifest.json").contains("\"profile\": \"pe-board\""));
        assert!(text("manifest.json").contains("\"precision\": \"f64\""));
        let r = CompileReport::read(&dir).expect("report");
        assert_eq!(r.elements, p.mesh.cells.len());
        assert!(r.elements > 100 && r.boards.len() == 8);
        assert_eq!(
            serde_json::to_string_pretty(&r).unwrap(),
            text("report.json")
        );
        // Beside them, what a run's outputs need: the problem's mesh and surface.
        let mesh = super::super::OutputMesh::read(&dir).expect("mesh.json");
        assert_eq!(mesh.nodes.len(), p.mesh.nodes.len());
        assert_eq!(mesh, super::super::OutputMesh::of(&p));
        let bad = text("manifest.json").replace("\"pe-board\"", "\"pe-bord\"");
        std::fs::write(dir.join("manifest.json"), bad).expect("written");
        let e = format!("{:#}", Manifest::read(&dir).unwrap_err());
        assert!(
            e.contains("manifest.json")
                && e.contains("\"pe-bord\"")
                && e.contains("known: pe-board, stm32h743-uart, qemu-mps2-an500"),
            "{e}"
        );
        // A directory of an older image format is refused, naming both versions.
        let old = text("manifest.json")
            .replace("\"pe-bord\"", "\"pe-board\"")
            .replace(
                &format!("\"format_version\": {FORMAT_VERSION}"),
                &format!("\"format_version\": {}", FORMAT_VERSION - 1),
            );
        assert!(old.contains(&format!("\"format_version\": {}", FORMAT_VERSION - 1)));
        std::fs::write(dir.join("manifest.json"), old).expect("written");
        let e = format!("{:#}", Manifest::read(&dir).unwrap_err());
        assert!(
            e.contains(&format!("version {}", FORMAT_VERSION - 1))
                && e.contains(&format!("reads version {FORMAT_VERSION}")),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
