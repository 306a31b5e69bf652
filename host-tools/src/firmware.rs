//! Board firmware artefacts and checks on the host: `pe image` (per board: the firmware ELF
//! with the board's position written in, and the schedule blob with the address to flash it
//! at), and `pe compare` (a board's semihosting report or a nodes CSV against `pe solve`'s,
//! bit for bit).
//!
//! The firmware is the crate `pe-firmware/board` (its own workspace, built only for
//! `thumbv7em-none-eabihf`). The schedule blob and the identity record are defined once, in
//! [`pe_firmware::image::blob`].

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use serde::Serialize;

use pe_firmware::image::{blob, Integration, Precision};
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

/// Largest `|a − b|` over all components, relative to the largest `|a|`; infinite when the
/// two fields differ in length (a shorter output never passes for an equal one).
pub fn max_rel_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    if a.len() != b.len() {
        return f64::INFINITY;
    }
    let scale = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    let d = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    if scale > 0.0 {
        d / scale
    } else {
        d
    }
}

/// Largest `|component|` of a field: how far it is from rest (a comparison of two fields
/// at rest proves nothing).
pub fn max_abs(a: &[[f64; 3]]) -> f64 {
    a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()))
}

/// `Ok` when `a` and `b` hold the same number of nodes and every component has the same
/// bits; otherwise an error naming both lengths, or the first differing node and component
/// and how many components differ (a shorter output never passes for an equal one).
pub fn bit_identical(a: &[[f64; 3]], b: &[[f64; 3]]) -> Result<()> {
    if a.len() != b.len() {
        bail!(
            "{} nodes against {}: the fields differ in length",
            a.len(),
            b.len()
        );
    }
    let differ = |(x, y): (&f64, &f64)| x.to_bits() != y.to_bits();
    let count = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .filter(|&p| differ(p))
        .count();
    if let Some(k) = a.iter().flatten().zip(b.iter().flatten()).position(differ) {
        bail!(
            "{count} of {} components differ, first node {} component {}: {:e} against {:e}",
            3 * a.len(),
            k / 3,
            k % 3,
            a[k / 3][k % 3],
            b[k / 3][k % 3]
        );
    }
    Ok(())
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
    let mut features = firmware_features(m.precision, m.integration, profile);
    features.extend(parts_needed(files.iter().map(|f| &f.header)));
    let elf_path = match firmware {
        Some(p) => p.to_path_buf(),
        None => build_firmware(&features, "pe-board")?,
    };
    let elf = std::fs::read(&elf_path)
        .with_context(|| format!("reading the firmware {}", elf_path.display()))?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut boards = Vec::new();
    for f in &files {
        let (c, image) = (f.board, &f.bytes);
        let pos = c.map(|v| v as u8);
        let stem = image_file_name(c);
        let stem = stem.trim_end_matches(".bin");
        let elf_name = format!("{stem}.elf");
        let sched_name = format!("{stem}.sched");
        std::fs::write(out.join(&elf_name), patch_identity(&elf, pos)?)
            .with_context(|| format!("writing {}", out.join(&elf_name).display()))?;
        let blob = schedule_blob(image);
        std::fs::write(out.join(&sched_name), &blob)
            .with_context(|| format!("writing {}", out.join(&sched_name).display()))?;
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
    std::fs::write(&p, serde_json::to_string_pretty(&manifest)?)
        .with_context(|| format!("writing {}", p.display()))?;
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

/// Final displacements by mesh node index, from a nodes CSV (`pe solve --output-nodes`,
/// header `node,x_m,y_m,z_m,ux_m,uy_m,uz_m` or the unit-less one of earlier versions, rows
/// in mesh node order) or a board report (semihosting lines `u,GLOBAL,UX,UY,UZ` with the
/// f64 bits in hex, between `pe-board: begin nodes` and `pe-board: end nodes`).
pub fn read_displacements(path: &Path) -> Result<Vec<Option<[f64; 3]>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse_displacements(&text, &path.display().to_string())
}

/// [`read_displacements`] of a text already read; `name` (a path, or a board) names it in
/// errors.
pub fn parse_displacements(text: &str, name: &str) -> Result<Vec<Option<[f64; 3]>>> {
    let mut out: Vec<Option<[f64; 3]>> = Vec::new();
    if text.starts_with("node,") {
        let header = text.lines().next().unwrap_or_default().trim();
        let legacy = "node,x,y,z,ux,uy,uz";
        if header != crate::output::NODES_CSV_HEADER.join(",") && header != legacy {
            bail!(
                "{}:1: header {header:?} is not a nodes CSV's ({:?}, or {legacy:?})",
                name,
                crate::output::NODES_CSV_HEADER.join(",")
            );
        }
        for (k, line) in text.lines().skip(1).enumerate() {
            let f: Vec<&str> = line.split(',').collect();
            if f.len() != 7 {
                bail!("{}:{}: expected 7 fields", name, k + 2);
            }
            let v = |i: usize| -> Result<f64> {
                f[i].trim()
                    .parse()
                    .with_context(|| format!("{}:{}: bad number {:?}", name, k + 2, f[i]))
            };
            out.push(Some([v(4)?, v(5)?, v(6)?]));
        }
        return Ok(out);
    }
    let (mut begun, mut ended) = (false, false);
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.contains("pe-board: FAULT") {
            bail!("{}: the board reported a fault: {line}", name);
        }
        if line == "pe-board: begin nodes" {
            begun = true;
        } else if line == "pe-board: end nodes" {
            ended = true;
        } else if let Some(rest) = line.strip_prefix("u,") {
            let f: Vec<&str> = rest.split(',').collect();
            let bad = || format!("{}:{}: bad node line {line:?}", name, k + 1);
            if f.len() != 4 || !begun || ended {
                bail!(bad());
            }
            let n: usize = f[0].parse().with_context(bad)?;
            let mut u = [0.0; 3];
            for i in 0..3 {
                u[i] = f64::from_bits(u64::from_str_radix(f[i + 1], 16).with_context(bad)?);
            }
            if out.len() <= n {
                out.resize(n + 1, None);
            }
            if out[n].replace(u).is_some() {
                bail!("{}: node {n} reported twice", name);
            }
        }
    }
    if !begun || !ended {
        bail!(
            "{}: no complete node report (missing 'pe-board: begin nodes'/'end nodes'): the run did not finish",
            name
        );
    }
    Ok(out)
}

/// Outcome of a comparison.
#[derive(Clone, Debug)]
pub struct Comparison {
    pub nodes: usize,
    /// Components whose bits differ.
    pub differing: usize,
    /// Largest |a − b| (m) over all components.
    pub max_abs_diff: f64,
    /// Largest |component| of the reference (m): how far the compared fields are from rest.
    pub max_abs_reference: f64,
    /// The first differences: (node, component, reference, other).
    pub first: Vec<(usize, usize, f64, f64)>,
}

/// Compares every node of `reference` with `other`, bit for bit; nodes missing from
/// `other` or extra in it are errors.
pub fn compare(reference: &Path, other: &Path) -> Result<Comparison> {
    let a = read_displacements(reference)?;
    let b = read_displacements(other)?;
    if b.len() > a.len() {
        bail!(
            "{} reports node {} but the reference has only {} nodes",
            other.display(),
            b.len() - 1,
            a.len()
        );
    }
    let mut c = Comparison {
        nodes: a.len(),
        differing: 0,
        max_abs_diff: 0.0,
        max_abs_reference: 0.0,
        first: Vec::new(),
    };
    let mut missing = Vec::new();
    for (n, ua) in a.iter().enumerate() {
        let Some(ua) = ua else { continue };
        let Some(ub) = b.get(n).copied().flatten() else {
            missing.push(n);
            continue;
        };
        for i in 0..3 {
            c.max_abs_reference = c.max_abs_reference.max(ua[i].abs());
            if ua[i].to_bits() != ub[i].to_bits() {
                c.differing += 1;
                c.max_abs_diff = c.max_abs_diff.max((ua[i] - ub[i]).abs());
                if c.first.len() < 10 {
                    c.first.push((n, i, ua[i], ub[i]));
                }
            }
        }
    }
    if !missing.is_empty() {
        bail!(
            "{}: {} nodes missing (first: {:?})",
            other.display(),
            missing.len(),
            &missing[..missing.len().min(10)]
        );
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A shorter field, one flipped bit, and -0.0 against 0.0 are all differences; the
    /// same field is not.
    #[test]
    fn bit_identical_checks_lengths_and_bits() {
        let a = vec![[1.0, -2.5e-4, 3.0], [0.0, 7.0, -1.0]];
        assert!(max_abs(&a) > 1.0, "not a field at rest");
        assert!(bit_identical(&a, &a.clone()).is_ok());
        let e = bit_identical(&a, &a[..1]).unwrap_err().to_string();
        assert!(e.contains("2 nodes against 1"), "{e}");
        let mut b = a.clone();
        b[1][2] = f64::from_bits((-1.0f64).to_bits() ^ 1);
        let e = bit_identical(&a, &b).unwrap_err().to_string();
        assert!(
            e.contains("1 of 6") && e.contains("node 1 component 2"),
            "{e}"
        );
        b = a.clone();
        b[1][0] = -0.0;
        assert!(bit_identical(&a, &b).is_err());
        assert_eq!(max_rel_diff(&a, &a[..1]), f64::INFINITY);
    }

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

    #[test]
    fn board_reports_compare_bitwise() {
        let d = std::env::temp_dir().join(format!("pe-fw-compare-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let csv = d.join("ref.csv");
        std::fs::write(
            &csv,
            "node,x_m,y_m,z_m,ux_m,uy_m,uz_m\n1,0,0,0,1.5e-3,0,-2.0e-4\n2,0,0,0,0,0,0\n",
        )
        .unwrap();
        // A nodes CSV of an earlier version (no units in the header) reads the same; a
        // header that is neither is refused rather than read by position.
        let legacy = d.join("legacy.csv");
        std::fs::write(
            &legacy,
            "node,x,y,z,ux,uy,uz\n1,0,0,0,1.5e-3,0,-2.0e-4\n2,0,0,0,0,0,0\n",
        )
        .unwrap();
        let (a, b) = (
            read_displacements(&csv).unwrap(),
            read_displacements(&legacy).unwrap(),
        );
        assert_eq!(a.len(), 2);
        assert_eq!(a[0], Some([1.5e-3, 0.0, -2.0e-4]), "non-zero row read");
        assert_eq!(a, b);
        let other = d.join("other.csv");
        std::fs::write(&other, "node,ux_m,uy_m,uz_m,x_m,y_m,z_m\n1,0,0,0,0,0,0\n").unwrap();
        let e = read_displacements(&other).unwrap_err().to_string();
        assert!(e.contains("other.csv:1: header"), "{e}");
        let bits = |v: f64| format!("{:016x}", v.to_bits());
        let log = |uz: f64| {
            format!(
                "pe-board: begin nodes\nu,1,{},{},{}\nu,0,{},{},{}\npe-board: end nodes\n",
                bits(0.0),
                bits(0.0),
                bits(0.0),
                bits(1.5e-3),
                bits(0.0),
                bits(uz)
            )
        };
        let same = d.join("same.txt");
        std::fs::write(&same, log(-2.0e-4)).unwrap();
        let c = compare(&csv, &same).unwrap();
        assert_eq!((c.nodes, c.differing), (2, 0));
        let off = d.join("off.txt");
        std::fs::write(&off, log(f64::from_bits((-2.0e-4f64).to_bits() + 1))).unwrap();
        let c = compare(&csv, &off).unwrap();
        assert_eq!(c.differing, 1);
        assert_eq!(c.first[0].0, 0);
        let cut = d.join("cut.txt");
        std::fs::write(&cut, "pe-board: begin nodes\n").unwrap();
        assert!(compare(&csv, &cut).is_err());
        let fault = d.join("fault.txt");
        std::fs::write(
            &fault,
            "pe-board: FAULT board (0,0,0) step 3: element 1 inverted\n",
        )
        .unwrap();
        assert!(compare(&csv, &fault)
            .unwrap_err()
            .to_string()
            .contains("inverted"));
        let _ = std::fs::remove_dir_all(&d);
    }
}
