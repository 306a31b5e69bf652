//! Board firmware artefacts on the host: `pe image` (per board: the firmware ELF with the
//! board's position written in, and the schedule blob with the address to flash it at). A
//! board's report is compared with `pe solve`'s in [`crate::compare`].
//!
//! The firmware is the crate `pe-firmware/board` (its own workspace, built only for
//! `thumbv7em-none-eabihf`). The schedule blob and the identity record are defined once, in
//! [`pe_firmware::image::blob`].

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use serde::Serialize;

use pe_firmware::image::{blob, Feature, Integration, Precision};
use pe_firmware::profile::BoardProfile;

use crate::compile::{image_file_name, Manifest};
use crate::scene::settings::{integration_text, precision_text};

/// The firmware's parts some image of a set needs (its home: [`crate::compile::parts_of`]).
pub use crate::compile::parts_needed;

/// The schedule region's content for an image ([`blob::write_blob`]).
pub fn schedule_blob(image: &[u8]) -> Vec<u8> {
    let mut b = vec![0; blob::blob_len(image.len())];
    let len = blob::write_blob(image, &mut b).unwrap_or(0);
    b.truncate(len);
    b
}

/// A copy of the firmware ELF that believes it is board `board`: its one identity record
/// ([`blob::find_identity`]) rewritten with [`blob::identity_record`].
pub fn patch_identity(elf: &[u8], board: [u8; 3]) -> Result<Vec<u8>> {
    let hits = blob::find_identity(elf).collect();
    let record = blob::identity_record(board);
    patch_record(elf, hits, &record, "identity", "not a pe-board ELF?")
}

/// A copy of the firmware ELF whose run options record ([`blob::find_run_options`]) holds
/// `flags` ([`blob::RUN_HOST_GATE`]: the host's step gate, `link_proto::gate`).
pub fn patch_run_options(elf: &[u8], flags: u8) -> Result<Vec<u8>> {
    let hits = blob::find_run_options(elf).collect();
    let record = blob::run_options_record(flags);
    patch_record(
        elf,
        hits,
        &record,
        "run options",
        "built before run options?",
    )
}

/// A copy of `elf` with `record` written over the one record of its kind found at `hits`
/// (`what` names the kind; `hint` says what several or none may mean).
fn patch_record(
    elf: &[u8],
    hits: Vec<usize>,
    record: &[u8],
    what: &str,
    hint: &str,
) -> Result<Vec<u8>> {
    let [at] = hits[..] else {
        bail!(
            "the firmware ELF holds {} {what} records (expected exactly one): {hint}",
            hits.len()
        );
    };
    let mut out = elf.to_vec();
    out.get_mut(at..at + record.len())
        .with_context(|| format!("{what} record cut off at the end of the ELF"))?
        .copy_from_slice(record);
    Ok(out)
}

/// The repository root (for building the firmware).
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Cargo features of the firmware for a set's precision, integration and board profile:
/// the board's support ([`BoardProfile::board_features`]), then `f32` and `full` when the
/// set needs them.
pub fn firmware_features(
    precision: Precision,
    integration: Integration,
    profile: &BoardProfile,
) -> Vec<&'static str> {
    let mut f = profile.board_features.to_vec();
    if precision == Precision::F32 {
        f.push("f32");
    }
    if integration == Integration::Full {
        f.push("full");
    }
    f
}

/// The cargo features a firmware ELF was built with, read from its build record
/// ([`blob::find_build`]): an error naming the difference when it was built for another
/// profile, precision or integration than the images', or without a part `needed` names.
/// A build carrying more parts than needed is accepted (it refuses nothing the images hold).
pub fn firmware_build(
    elf: &[u8],
    precision: Precision,
    integration: Integration,
    profile: &BoardProfile,
    needed: &[Feature],
) -> Result<Vec<&'static str>> {
    let hits: Vec<usize> = blob::find_build(elf).collect();
    let [at] = hits[..] else {
        bail!(
            "holds {} build records (expected exactly one): not a pe-board ELF, or built before build records",
            hits.len()
        );
    };
    let record: &[u8; blob::BUILD_LEN] = elf
        .get(at..at + blob::BUILD_LEN)
        .and_then(|r| r.try_into().ok())
        .context("build record cut off")?;
    let (index, flags) = blob::build_of(record).context("build record damaged")?;
    let built = pe_firmware::profile::PROFILES
        .get(index as usize)
        .with_context(|| {
            format!("built for board profile number {index}, which this pe does not know")
        })?;
    if built.name != profile.name {
        bail!(
            "built for the board profile {}, the images for {} (build it with pe image without --firmware, or cargo features {})",
            built.name,
            profile.name,
            profile.board_features.join(",")
        );
    }
    let has = |bit: u8| flags & bit != 0;
    let elf_precision = if has(blob::BUILD_F32) {
        Precision::F32
    } else {
        Precision::F64
    };
    let elf_integration = if has(blob::BUILD_FULL) {
        Integration::Full
    } else {
        Integration::Reduced
    };
    if elf_precision != precision || elf_integration != integration {
        bail!(
            "built for {} {}, the images are {} {}",
            elf_precision.name(),
            elf_integration.name(),
            precision.name(),
            integration.name()
        );
    }
    let missing: Vec<&str> = (needed.iter())
        .filter(|&&f| !has(blob::build_flag(f)))
        .map(|f| f.name())
        .collect();
    if !missing.is_empty() {
        bail!(
            "built without {}, which the images need (cargo features of pe-firmware/board)",
            missing.join(", ")
        );
    }
    let mut features = firmware_features(precision, integration, profile);
    features.extend(
        Feature::ALL
            .into_iter()
            .filter(|&f| has(blob::build_flag(f)))
            .map(Feature::name),
    );
    Ok(features)
}

/// Builds the firmware with cargo (release, thumbv7em-none-eabihf, -C target-cpu=cortex-m7
/// from the repository's .cargo/config.toml); returns the ELF's path.
pub fn build_firmware(features: &[&str], bin: &str) -> Result<PathBuf> {
    let root = repo_root();
    let target_dir = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target"));
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(&root)
        .env_remove("PE_SCHEDULE_IMAGE")
        .args(["build", "--release", "--target", "thumbv7em-none-eabihf"])
        .arg("--manifest-path")
        .arg(root.join("pe-firmware/board/Cargo.toml"))
        .arg("--target-dir")
        .arg(&target_dir)
        .args(["--bin", bin, "--no-default-features"])
        .args(["--features", &features.join(",")])
        .status()
        .context("running cargo to build the board firmware")?;
    if !status.success() {
        bail!("building the board firmware failed ({status})");
    }
    Ok(target_dir.join("thumbv7em-none-eabihf/release").join(bin))
}

/// One board's flashable artefacts.
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct ImageBoard {
    pub board: [usize; 3],
    /// The firmware with this board's position (OUT/board-X-Y-Z.elf).
    pub elf: String,
    /// The schedule blob (OUT/board-X-Y-Z.sched) and where it goes.
    pub schedule: String,
    pub schedule_address: String,
    pub schedule_bytes: usize,
    /// Commands that flash this board (probe-rs), or run it (QEMU profile).
    pub flash: Vec<String>,
}

/// `OUT/manifest.json` of `pe image`.
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct ImageManifest {
    pub scene: String,
    /// The compilation every board's schedule comes from (16 hex digits).
    #[serde(default)]
    pub compilation: String,
    pub machine: [usize; 3],
    #[serde(with = "pe_firmware::profile::by_name")]
    pub profile: &'static BoardProfile,
    #[serde(with = "precision_text")]
    pub precision: Precision,
    #[serde(with = "integration_text")]
    pub integration: Integration,
    pub steps: u64,
    /// The firmware ELF the per-board copies were made from, and its cargo features.
    pub firmware: String,
    pub firmware_features: Vec<String>,
    pub boards: Vec<ImageBoard>,
}

/// `pe image DIR -o OUT [--firmware ELF]`.
pub fn image_dir(dir: &Path, out: &Path, firmware: Option<&Path>) -> Result<ImageManifest> {
    let m = Manifest::read(dir)?;
    let profile = m.profile;
    // Every image decoded and the set checked against the manifest (one compilation, the
    // CRCs it recorded) before anything is built or written.
    let mut files = Vec::new();
    for b in &m.boards {
        let c = b.board;
        let p = dir.join(&b.file);
        let bytes = std::fs::read(&p).with_context(|| format!("reading {}", p.display()))?;
        let header = crate::compile::decode_image(&bytes, Some(c.map(|v| v as u8)))
            .map_err(|e| {
                anyhow::anyhow!("board ({},{},{}): {}: {e}", c[0], c[1], c[2], p.display())
            })?
            .header;
        files.push(crate::compile::ImageFile {
            board: c,
            path: p,
            bytes,
            header,
        });
    }
    crate::compile::check_image_set(&m, &files)?;
    // The firmware carries the parts some board's image needs, and no other.
    let needed = crate::compile::parts_of(files.iter().map(|f| &f.header));
    let elf_path = match firmware {
        Some(p) => p.to_path_buf(),
        None => {
            let mut features = firmware_features(m.precision, m.integration, profile);
            features.extend(needed.iter().map(|f| f.name()));
            build_firmware(&features, "pe-board")?
        }
    };
    let elf = std::fs::read(&elf_path)
        .with_context(|| format!("reading the firmware {}", elf_path.display()))?;
    // What the ELF holds, from its build record: refused before anything is written when it
    // was built for another board or lacks what the images need.
    let features = firmware_build(&elf, m.precision, m.integration, profile, &needed)
        .with_context(|| format!("the firmware {}", elf_path.display()))?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    // A directory reused from a larger machine: its other boards' files go.
    crate::output::file::remove_owned(out, |n| {
        n.starts_with("board-") && (n.ends_with(".elf") || n.ends_with(".sched"))
    })?;
    let mut boards = Vec::new();
    for f in &files {
        let (c, image) = (f.board, &f.bytes);
        let pos = c.map(|v| v as u8);
        let stem = image_file_name(c);
        let stem = stem.trim_end_matches(".bin");
        let elf_name = format!("{stem}.elf");
        let sched_name = format!("{stem}.sched");
        crate::output::file::write_atomic(&out.join(&elf_name), patch_identity(&elf, pos)?)?;
        let blob = schedule_blob(image);
        crate::output::file::write_atomic(&out.join(&sched_name), &blob)?;
        let addr = format!("{:#010x}", profile.image_origin);
        let flash = if profile.probe_chip.is_empty() {
            vec![format!(
                "qemu-system-arm -cpu cortex-m7 -machine mps2-an500 -nographic -semihosting-config enable=on,target=native -kernel {elf_name} -device loader,file={sched_name},addr={addr}"
            )]
        } else {
            let chip = profile.probe_chip;
            vec![
                format!("probe-rs download --chip {chip} {elf_name}"),
                format!(
                    "probe-rs download --chip {chip} --binary-format bin --base-address {addr} {sched_name}"
                ),
                format!("probe-rs reset --chip {chip}"),
            ]
        };
        boards.push(ImageBoard {
            board: c,
            elf: elf_name,
            schedule: sched_name,
            schedule_address: addr,
            schedule_bytes: blob.len(),
            flash,
        });
    }
    let manifest = ImageManifest {
        scene: m.scene,
        compilation: m.compilation,
        machine: m.machine,
        profile: m.profile,
        precision: m.precision,
        integration: m.integration,
        steps: m.steps,
        firmware: elf_path.display().to_string(),
        firmware_features: features.iter().map(|s| s.to_string()).collect(),
        boards,
    };
    let p = out.join("manifest.json");
    crate::output::file::write_atomic(&p, serde_json::to_string_pretty(&manifest)?)?;
    Ok(manifest)
}

/// Reads `OUT/manifest.json` written by `pe image`.
pub fn read_image_manifest(out: &Path) -> Result<ImageManifest> {
    let p = out.join("manifest.json");
    let text = std::fs::read_to_string(&p).with_context(|| format!("reading {}", p.display()))?;
    serde_json::from_str(&text).with_context(|| {
        format!(
            "parsing {}: not the manifest of `pe image` (a `pe compile` directory needs `pe image DIR -o OUT` first)",
            p.display()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_is_patched_once() {
        let mut elf = vec![0u8; 64];
        elf[20..32].copy_from_slice(&blob::IDENTITY_MARKER);
        elf[32..36].copy_from_slice(&[0, 0, 0, 0xA5]);
        let p = patch_identity(&elf, [1, 2, 3]).unwrap();
        assert_eq!(&p[32..36], &[1, 2, 3, 0xA5]); // 1 ^ 2 ^ 3 == 0
        assert_eq!(p.len(), elf.len());
        elf[40..52].copy_from_slice(&blob::IDENTITY_MARKER);
        elf[52..56].copy_from_slice(&[0, 0, 0, 0xA5]);
        assert!(patch_identity(&elf, [1, 2, 3]).is_err());
        assert!(patch_identity(&[0u8; 8], [0; 3]).is_err());
    }

    #[test]
    fn run_options_are_patched_once() {
        let mut elf = vec![0u8; 64];
        elf[8..24].copy_from_slice(&blob::run_options_record(0));
        let p = patch_run_options(&elf, blob::RUN_HOST_GATE).unwrap();
        assert_eq!(p.len(), elf.len());
        assert_eq!(p[20], blob::RUN_HOST_GATE);
        assert_eq!(p[23], blob::RUN_HOST_GATE ^ 0x5A);
        let rec: [u8; blob::RUN_OPTIONS_LEN] = p[8..24].try_into().unwrap();
        assert_eq!(blob::run_options_flags(&rec), Some(blob::RUN_HOST_GATE));
        // A damaged check byte is no record; two records are refused.
        let mut bad = rec;
        bad[15] ^= 1;
        assert_eq!(blob::run_options_flags(&bad), None);
        elf[40..56].copy_from_slice(&blob::run_options_record(0));
        assert!(patch_run_options(&elf, 1).is_err());
        assert!(patch_run_options(&[0u8; 8], 1).is_err());
    }

    #[test]
    fn blob_is_length_prefixed() {
        assert_eq!(schedule_blob(b"PESIxy"), b"\x06\0\0\0PESIxy");
    }
}
