//! `pe flash OUT --map BOARDS.toml`: flashes every board of an array with probe-rs, each
//! through the debug probe the board map names, and checks afterwards what each board
//! holds.
//!
//! OUT is a `pe image` directory (per board the firmware ELF with its position written in,
//! and the schedule blob). The board map names one probe per board position:
//!
//! ```toml
//! # boards.toml: the probe on each board (probe-rs list shows VID:PID:SERIAL)
//! [[board]]
//! position = [0, 0, 0]
//! probe = "0483:374e:002C00283132510D33353533"
//! ```
//!
//! Before anything is written the map is checked against the array: every board has a
//! probe, no probe serves two boards, no position lies outside the machine. Each board
//! then gets `probe-rs download` of its ELF and of its schedule blob at the profile's image
//! address; after that the board's identity record and the head of its schedule region are
//! read back (`probe-rs read b8`) and must be the bytes written: its position and the
//! compilation's image. A probe plugged into the wrong board is named with both positions
//! (the identity it holds says where it is). Then every board is reset.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{anyhow, bail, Context, Result};
use serde::Deserialize;

use crate::firmware::{read_image_manifest, ImageManifest};
use pe_firmware::image::blob;

/// Bytes of the schedule region read back: the blob's length word and the image header
/// (magic, version, compilation id, position).
pub const SCHEDULE_HEAD_BYTES: usize = 64;

/// The board map file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BoardMap {
    board: Vec<MapEntry>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MapEntry {
    position: [usize; 3],
    /// `VID:PID:SERIAL` (or `VID:PID` for a single probe of its kind), as `probe-rs --probe`
    /// takes it.
    probe: String,
}

/// Reads a board map and checks it against a `machine`: position -> probe.
pub fn read_board_map(path: &Path, machine: [usize; 3]) -> Result<BTreeMap<[usize; 3], String>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let map: BoardMap = toml::from_str(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let mut out = BTreeMap::new();
    let mut seen: BTreeMap<String, [usize; 3]> = BTreeMap::new();
    for (k, e) in map.board.iter().enumerate() {
        let [x, y, z] = e.position;
        if (0..3).any(|a| e.position[a] >= machine[a]) {
            bail!(
                "{}: [[board]] {k}: position ({x},{y},{z}) is outside the {}x{}x{} machine",
                path.display(),
                machine[0],
                machine[1],
                machine[2]
            );
        }
        let probe = e.probe.trim().to_string();
        if probe.is_empty() || probe.contains(char::is_whitespace) {
            bail!(
                "{}: [[board]] {k}: probe {:?} is not VID:PID[:SERIAL]",
                path.display(),
                e.probe
            );
        }
        if let Some([a, b, c]) = seen.insert(probe.clone(), e.position) {
            bail!(
                "{}: probe {probe} is given to boards ({a},{b},{c}) and ({x},{y},{z}): one probe per board",
                path.display()
            );
        }
        if out.insert(e.position, probe).is_some() {
            bail!("{}: board ({x},{y},{z}) is listed twice", path.display());
        }
    }
    let missing: Vec<String> = (0..machine.iter().product::<usize>())
        .map(|b| {
            [
                b % machine[0],
                (b / machine[0]) % machine[1],
                b / (machine[0] * machine[1]),
            ]
        })
        .filter(|c| !out.contains_key(c))
        .map(|[x, y, z]| format!("({x},{y},{z})"))
        .collect();
    if !missing.is_empty() {
        bail!(
            "{}: no probe for board(s) {} of the {}x{}x{} machine",
            path.display(),
            missing.join(" "),
            machine[0],
            machine[1],
            machine[2]
        );
    }
    Ok(out)
}

/// The memory address of file offset `offset` of a 32-bit little-endian ELF: from the
/// section (with file contents) that holds it.
pub fn elf_address(elf: &[u8], offset: usize) -> Option<u64> {
    let u16_at = |o: usize| Some(u16::from_le_bytes(elf.get(o..o + 2)?.try_into().ok()?));
    let u32_at = |o: usize| Some(u32::from_le_bytes(elf.get(o..o + 4)?.try_into().ok()?));
    if elf.get(..4)? != b"\x7fELF" || *elf.get(4)? != 1 || *elf.get(5)? != 1 {
        return None; // not ELF32 little-endian
    }
    let (shoff, shentsize, shnum) = (
        u32_at(0x20)? as usize,
        u16_at(0x2E)? as usize,
        u16_at(0x30)?,
    );
    for k in 0..shnum as usize {
        let h = shoff + k * shentsize;
        let (kind, addr, off, size) = (
            u32_at(h + 4)?,
            u32_at(h + 0x0C)?,
            u32_at(h + 0x10)?,
            u32_at(h + 0x14)?,
        );
        const SHT_NOBITS: u32 = 8;
        if kind != SHT_NOBITS
            && addr != 0
            && (off as usize..(off + size) as usize).contains(&offset)
        {
            return Some(addr as u64 + (offset - off as usize) as u64);
        }
    }
    None
}

/// Hex bytes as probe-rs prints them: its plain form (`00 1f 2a ...`, byte width) or a
/// table of lines `ADDRESS: BYTES` with an optional `|ASCII|` column, which is dropped.
fn parse_hex_bytes(text: &str) -> Vec<u8> {
    text.lines()
        .flat_map(|line| {
            let line = line.split('|').next().unwrap_or("");
            let line = line.rsplit_once(':').map_or(line, |(_, rest)| rest);
            line.split(|c: char| c.is_whitespace() || c == ',' || c == '[' || c == ']')
                .filter_map(|t| {
                    let t = t.trim().trim_start_matches("0x");
                    (t.len() == 2)
                        .then(|| u8::from_str_radix(t, 16).ok())
                        .flatten()
                })
                .collect::<Vec<u8>>()
        })
        .collect()
}

/// One board's flashing, for the report.
#[derive(Clone, Debug)]
pub struct FlashedBoard {
    pub board: [usize; 3],
    pub probe: String,
    /// The probe-rs command lines run (or, dry, to run).
    pub commands: Vec<Vec<String>>,
}

/// Runs (or with `dry_run` lists) the commands that flash and check every board of OUT.
pub fn flash_array(
    out: &Path,
    map: &Path,
    probe_rs: &Path,
    dry_run: bool,
) -> Result<Vec<FlashedBoard>> {
    let m: ImageManifest = read_image_manifest(out)?;
    let profile = pe_firmware::profile::profile(&m.profile)
        .with_context(|| format!("{}: unknown profile {:?}", out.display(), m.profile))?;
    if profile.probe_chip.is_empty() {
        bail!(
            "{}: images of the {} profile run under emulation (board-sim qemu), not on a probe",
            out.display(),
            m.profile
        );
    }
    let probes = read_board_map(map, m.machine)?;
    let chip = profile.probe_chip;
    let run = |args: &[String], what: &str| -> Result<String> {
        let o = Command::new(probe_rs)
            .args(args)
            .output()
            .with_context(|| format!("{what}: running {}", probe_rs.display()))?;
        if !o.status.success() {
            bail!(
                "{what}: {} {} failed ({}): {}",
                probe_rs.display(),
                args.join(" "),
                o.status,
                String::from_utf8_lossy(&o.stderr).trim()
            );
        }
        Ok(String::from_utf8_lossy(&o.stdout).into_owned())
    };
    let mut done = Vec::new();
    // What every board must hold: its identity record where the ELF has it, and the head
    // of its schedule blob.
    let mut expected = Vec::new();
    for b in &m.boards {
        let elf_path = out.join(&b.elf);
        let elf =
            std::fs::read(&elf_path).with_context(|| format!("reading {}", elf_path.display()))?;
        let hits: Vec<usize> = blob::find_identity(&elf).collect();
        let [at] = hits[..] else {
            bail!(
                "{}: {} identity records (expected one)",
                elf_path.display(),
                hits.len()
            );
        };
        let id_addr = elf_address(&elf, at).with_context(|| {
            format!(
                "{}: the identity record lies in no loaded section",
                elf_path.display()
            )
        })?;
        let record = elf[at..at + blob::IDENTITY_LEN].to_vec();
        if record != blob::identity_record(b.board.map(|v| v as u8)) {
            bail!(
                "{}: its identity record is not board {:?}'s",
                elf_path.display(),
                b.board
            );
        }
        let sched = out.join(&b.schedule);
        let head: Vec<u8> = std::fs::read(&sched)
            .with_context(|| format!("reading {}", sched.display()))?
            .into_iter()
            .take(SCHEDULE_HEAD_BYTES)
            .collect();
        expected.push((id_addr, record, head));
    }
    for (b, (id_addr, record, head)) in m.boards.iter().zip(&expected) {
        let [x, y, z] = b.board;
        let who = format!("board ({x},{y},{z})");
        let probe = probes.get(&b.board).cloned().unwrap_or_default();
        let base = |cmd: &str| -> Vec<String> {
            vec![
                cmd.into(),
                "--chip".into(),
                chip.into(),
                "--probe".into(),
                probe.clone(),
            ]
        };
        let dir = |f: &str| out.join(f).display().to_string();
        let mut cmds = vec![
            [base("download"), vec![dir(&b.elf)]].concat(),
            [
                base("download"),
                vec![
                    "--binary-format".into(),
                    "bin".into(),
                    "--base-address".into(),
                    b.schedule_address.clone(),
                    dir(&b.schedule),
                ],
            ]
            .concat(),
        ];
        let read_id = [
            base("read"),
            vec![
                "b8".into(),
                format!("{id_addr:#010x}"),
                blob::IDENTITY_LEN.to_string(),
            ],
        ]
        .concat();
        let read_head = [
            base("read"),
            vec![
                "b8".into(),
                b.schedule_address.clone(),
                head.len().to_string(),
            ],
        ]
        .concat();
        cmds.push(read_id.clone());
        cmds.push(read_head.clone());
        if !dry_run {
            run(
                &cmds[0],
                &format!("{who} (probe {probe}): flashing the firmware"),
            )?;
            run(
                &cmds[1],
                &format!("{who} (probe {probe}): flashing the schedule"),
            )?;
            let got = parse_hex_bytes(&run(&read_id, &format!("{who}: reading its identity"))?);
            if got != *record {
                let holds = (got.len() == blob::IDENTITY_LEN)
                    .then(|| <[u8; blob::IDENTITY_LEN]>::try_from(&got[..]).ok())
                    .flatten()
                    .and_then(|r| blob::identity_position(&r));
                bail!(
                    "{who}: probe {probe} reads back {}, not the identity just written: {}",
                    match holds {
                        Some([a, b, c]) => format!("board ({a},{b},{c})'s identity"),
                        None => format!("{} bytes that are no identity record", got.len()),
                    },
                    "the write did not take (a protected flash, a probe that lost the board)"
                );
            }
            let got = parse_hex_bytes(&run(&read_head, &format!("{who}: reading its schedule"))?);
            if got != *head {
                bail!(
                    "{who}: probe {probe}: the schedule region does not hold the compilation {} image just written ({} of {} bytes read back differ)",
                    m.compilation,
                    got.iter().zip(head.iter()).filter(|(a, b)| a != b).count() + got.len().abs_diff(head.len()),
                    head.len()
                );
            }
        }
        done.push(FlashedBoard {
            board: b.board,
            probe,
            commands: cmds,
        });
    }
    // Every board flashed and checked: start them together.
    for f in &mut done {
        let reset = vec![
            "reset".into(),
            "--chip".into(),
            chip.into(),
            "--probe".into(),
            f.probe.clone(),
        ];
        if !dry_run {
            let [x, y, z] = f.board;
            run(&reset, &format!("board ({x},{y},{z}): reset"))?;
        }
        f.commands.push(reset);
    }
    Ok(done)
}

/// `probe-rs` from PATH unless given.
pub fn probe_rs_path(given: Option<PathBuf>) -> PathBuf {
    given.unwrap_or_else(|| PathBuf::from("probe-rs"))
}

#[cfg(test)]
mod tests {
    use super::parse_hex_bytes;

    /// Both of probe-rs's forms give the bytes, and only them.
    #[test]
    fn probe_rs_read_output_parses_in_either_form() {
        assert_eq!(parse_hex_bytes("00 1f 2a ff\n"), [0x00, 0x1f, 0x2a, 0xff]);
        let table = "0x08100000: 50 45 2d 42 |PE-B|\n0x08100004: 4f 41 |OA|\n";
        assert_eq!(parse_hex_bytes(table), [0x50, 0x45, 0x2d, 0x42, 0x4f, 0x41]);
        assert_eq!(parse_hex_bytes("[0x01, 0x02]"), [1, 2]);
        assert!(parse_hex_bytes("Error: no probe").is_empty());
    }
}
