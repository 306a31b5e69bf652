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
//! A board may also give its MCU's unique ID (`uid = "003A0028:31385104:33333439"`, the
//! three words at the profile's `unique_id_address`; `pe flash` prints each board's).
//!
//! Before anything is written the map is checked against the array: every board has a
//! probe, no probe serves two boards, no position lies outside the machine; then every
//! probe reads the unique ID of the chip it is on ([`identity`]): a probe on another
//! board than the map says (two probes swapped), two probes on one chip, or a chip the map
//! does not know is refused naming the positions, before any board is written. Each board
//! then gets `probe-rs download` of its ELF and of its schedule blob at the profile's image
//! address; after that the board's identity record and the head of its schedule region are
//! read back (`probe-rs read b8`) and must be the bytes written: its position and the
//! compilation's image. Then every board is reset.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{anyhow, bail, Context, Result};
use serde::Deserialize;

use crate::firmware::{read_image_manifest, ImageBoard, ImageManifest};
use identity::{check_unique_ids, UniqueId, UNIQUE_ID_BYTES};
use link_proto::machine::Coords;
use link_proto::Machine;
use pe_firmware::image::blob;

pub mod identity;

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
    /// The board's MCU unique ID ([`UniqueId::parse`]).
    uid: Option<String>,
}

/// A board map checked against the machine.
#[derive(Debug, Default)]
pub struct MappedBoards {
    /// Position -> probe, every board.
    pub probes: BTreeMap<Coords, String>,
    /// Position -> unique ID, the boards that give one.
    pub uids: BTreeMap<Coords, UniqueId>,
}

/// Reads a board map and checks it against a machine of `dims` boards.
pub fn read_board_map(path: &Path, dims: [usize; 3]) -> Result<MappedBoards> {
    let machine = Machine::new(dims).with_context(|| {
        format!(
            "{}: a {}x{}x{} machine: 1..{} boards per axis",
            path.display(),
            dims[0],
            dims[1],
            dims[2],
            Machine::AXIS_MAX
        )
    })?;
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let map: BoardMap = toml::from_str(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let mut out = BTreeMap::new();
    let mut uids: BTreeMap<Coords, UniqueId> = BTreeMap::new();
    let mut seen: BTreeMap<String, [usize; 3]> = BTreeMap::new();
    for (k, e) in map.board.iter().enumerate() {
        let [x, y, z] = e.position;
        if !machine.contains(e.position) {
            bail!(
                "{}: [[board]] {k}: position ({x},{y},{z}) is outside the {machine} machine",
                path.display()
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
        if let Some(text) = &e.uid {
            let uid = UniqueId::parse(text).with_context(|| {
                format!(
                    "{}: [[board]] {k} ({x},{y},{z}): uid {text:?} is not a 96-bit unique ID (24 hex digits, e.g. \"003A0028:31385104:33333439\")",
                    path.display()
                )
            })?;
            if let Some((&[a, b, c], _)) = uids.iter().find(|(_, u)| **u == uid) {
                bail!(
                    "{}: uid {uid} is given to boards ({a},{b},{c}) and ({x},{y},{z}): one chip per board",
                    path.display()
                );
            }
            uids.insert(e.position, uid);
        }
    }
    let missing: Vec<String> = machine
        .boards()
        .filter(|c| !out.contains_key(c))
        .map(|[x, y, z]| format!("({x},{y},{z})"))
        .collect();
    if !missing.is_empty() {
        bail!(
            "{}: no probe for board(s) {} of the {machine} machine",
            path.display(),
            missing.join(" ")
        );
    }
    Ok(MappedBoards { probes: out, uids })
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
    pub board: Coords,
    pub probe: String,
    /// The unique ID its probe read (none on a dry run or a profile without one).
    pub uid: Option<UniqueId>,
    /// Whether the board map gave it.
    pub uid_in_map: bool,
    /// The probe-rs command lines run (or, dry, to run).
    pub commands: Vec<Vec<String>>,
}

/// What a board must hold after flashing: its identity record at the address the ELF
/// puts it, and the head of its schedule blob.
struct Expected {
    id_addr: u64,
    record: Vec<u8>,
    head: Vec<u8>,
}

/// Board `b`'s [`Expected`] contents, from its ELF (the one identity record, its address
/// and that it names `b`) and its schedule blob in OUT.
fn expected_of(out: &Path, b: &ImageBoard) -> Result<Expected> {
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
    Ok(Expected {
        id_addr,
        record,
        head,
    })
}

/// The probe-rs program and the chip every command names.
struct ProbeRs<'a> {
    program: &'a Path,
    chip: &'static str,
}

impl ProbeRs<'_> {
    /// `probe-rs CMD --chip CHIP --probe PROBE`.
    fn command(&self, cmd: &str, probe: &str) -> Vec<String> {
        vec![
            cmd.into(),
            "--chip".into(),
            self.chip.into(),
            "--probe".into(),
            probe.into(),
        ]
    }

    /// Runs `args`; its standard output, or an error saying `what` failed and why.
    fn run(&self, args: &[String], what: &str) -> Result<String> {
        let o = Command::new(self.program)
            .args(args)
            .output()
            .with_context(|| format!("{what}: running {}", self.program.display()))?;
        if !o.status.success() {
            bail!(
                "{what}: {} {} failed ({}): {}",
                self.program.display(),
                args.join(" "),
                o.status,
                String::from_utf8_lossy(&o.stderr).trim()
            );
        }
        Ok(String::from_utf8_lossy(&o.stdout).into_owned())
    }
}

/// One board's commands: download its ELF, download its schedule blob at the profile's
/// image address, read back its identity record, read back its schedule's head.
fn board_commands(
    probe_rs: &ProbeRs,
    out: &Path,
    b: &ImageBoard,
    probe: &str,
    e: &Expected,
) -> [Vec<String>; 4] {
    let file = |f: &str| out.join(f).display().to_string();
    let with = |cmd: &str, rest: Vec<String>| [probe_rs.command(cmd, probe), rest].concat();
    [
        with("download", vec![file(&b.elf)]),
        with(
            "download",
            vec![
                "--binary-format".into(),
                "bin".into(),
                "--base-address".into(),
                b.schedule_address.clone(),
                file(&b.schedule),
            ],
        ),
        with(
            "read",
            vec![
                "b8".into(),
                format!("{:#010x}", e.id_addr),
                blob::IDENTITY_LEN.to_string(),
            ],
        ),
        with(
            "read",
            vec![
                "b8".into(),
                b.schedule_address.clone(),
                e.head.len().to_string(),
            ],
        ),
    ]
}

/// Runs one board's [`board_commands`] and checks what it reads back: the identity just
/// written (else which board's identity the probe found, or that it found none: a probe
/// plugged into another board) and the schedule's head (compilation `compilation`).
fn flash_and_check(
    probe_rs: &ProbeRs,
    board: Coords,
    probe: &str,
    cmds: &[Vec<String>; 4],
    e: &Expected,
    compilation: &str,
) -> Result<()> {
    let [x, y, z] = board;
    let who = format!("board ({x},{y},{z})");
    let [elf, schedule, read_id, read_head] = cmds;
    probe_rs.run(
        elf,
        &format!("{who} (probe {probe}): flashing the firmware"),
    )?;
    probe_rs.run(
        schedule,
        &format!("{who} (probe {probe}): flashing the schedule"),
    )?;
    let got = parse_hex_bytes(&probe_rs.run(read_id, &format!("{who}: reading its identity"))?);
    if got != e.record {
        let holds = <[u8; blob::IDENTITY_LEN]>::try_from(&got[..])
            .ok()
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
    let got = parse_hex_bytes(&probe_rs.run(read_head, &format!("{who}: reading its schedule"))?);
    if got != e.head {
        bail!(
            "{who}: probe {probe}: the schedule region does not hold the compilation {compilation} image just written ({} of {} bytes read back differ)",
            got.iter().zip(e.head.iter()).filter(|(a, b)| a != b).count() + got.len().abs_diff(e.head.len()),
            e.head.len()
        );
    }
    Ok(())
}

/// Runs (or with `dry_run` lists) the commands that flash and check every board of OUT:
/// the set and the board map checked, every board's expected contents read from OUT,
/// then each board flashed and read back, then every board reset together.
pub fn flash_array(
    out: &Path,
    map: &Path,
    probe_rs: &Path,
    dry_run: bool,
) -> Result<Vec<FlashedBoard>> {
    let m: ImageManifest = read_image_manifest(out)?;
    if m.profile.probe_chip.is_empty() {
        bail!(
            "{}: images of the {} profile run under emulation (board-sim qemu), not on a probe",
            out.display(),
            m.profile.name
        );
    }
    let mapped = read_board_map(map, m.machine)?;
    let probe_rs = ProbeRs {
        program: probe_rs,
        chip: m.profile.probe_chip,
    };
    // What every board must hold, from OUT, before any board is written.
    let expected = (m.boards.iter())
        .map(|b| expected_of(out, b))
        .collect::<Result<Vec<_>>>()?;
    let mut done: Vec<FlashedBoard> = (m.boards.iter())
        .map(|b| FlashedBoard {
            board: b.board,
            probe: mapped.probes.get(&b.board).cloned().unwrap_or_default(),
            uid: None,
            uid_in_map: mapped.uids.contains_key(&b.board),
            commands: Vec::new(),
        })
        .collect();
    // Every board's chip, through its probe, before any board is written.
    if m.profile.unique_id_address != 0 {
        let mut read = BTreeMap::new();
        for f in &mut done {
            let cmd = [
                probe_rs.command("read", &f.probe),
                vec![
                    "b8".into(),
                    format!("{:#010x}", m.profile.unique_id_address),
                    UNIQUE_ID_BYTES.to_string(),
                ],
            ]
            .concat();
            if !dry_run {
                let [x, y, z] = f.board;
                let who = format!("board ({x},{y},{z}) (probe {})", f.probe);
                let bytes =
                    parse_hex_bytes(&probe_rs.run(&cmd, &format!("{who}: reading its unique ID"))?);
                let uid = UniqueId::from_bytes(&bytes).with_context(|| {
                    format!(
                        "{who}: its unique ID read back as {} bytes, not {UNIQUE_ID_BYTES}",
                        bytes.len()
                    )
                })?;
                read.insert(f.board, uid);
                f.uid = Some(uid);
            }
            f.commands.push(cmd);
        }
        check_unique_ids(&read, &mapped.uids, &mapped.probes)?;
    }
    for ((b, e), f) in m.boards.iter().zip(&expected).zip(&mut done) {
        let cmds = board_commands(&probe_rs, out, b, &f.probe, e);
        if !dry_run {
            flash_and_check(&probe_rs, b.board, &f.probe, &cmds, e, &m.compilation)?;
        }
        f.commands.extend(cmds);
    }
    // Every board flashed and checked: start them together.
    for f in &mut done {
        let reset = probe_rs.command("reset", &f.probe);
        if !dry_run {
            let [x, y, z] = f.board;
            probe_rs.run(&reset, &format!("board ({x},{y},{z}): reset"))?;
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
    use super::*;
    use crate::firmware::{patch_identity, ImageBoard};
    use pe_firmware::image::{Integration, Precision};

    /// Both of probe-rs's forms give the bytes, and only them.
    #[test]
    fn probe_rs_read_output_parses_in_either_form() {
        assert_eq!(parse_hex_bytes("00 1f 2a ff\n"), [0x00, 0x1f, 0x2a, 0xff]);
        let table = "0x08100000: 50 45 2d 42 |PE-B|\n0x08100004: 4f 41 |OA|\n";
        assert_eq!(parse_hex_bytes(table), [0x50, 0x45, 0x2d, 0x42, 0x4f, 0x41]);
        assert_eq!(parse_hex_bytes("[0x01, 0x02]"), [1, 2]);
        assert!(parse_hex_bytes("Error: no probe").is_empty());
    }

    /// A 32-bit little-endian ELF whose one loaded section (at 0x2000_0000, file offset
    /// 0x40, 0x40 bytes) holds board (0,0,0)'s identity record at offset 0x50.
    fn elf_with_identity() -> Vec<u8> {
        let mut e = vec![0u8; 0x100 + 40];
        e[..6].copy_from_slice(b"\x7fELF\x01\x01");
        e[0x20..0x24].copy_from_slice(&0x100u32.to_le_bytes());
        e[0x2E..0x30].copy_from_slice(&40u16.to_le_bytes());
        e[0x30..0x32].copy_from_slice(&1u16.to_le_bytes());
        let h = 0x100;
        e[h + 4..h + 8].copy_from_slice(&1u32.to_le_bytes()); // PROGBITS
        e[h + 0x0C..h + 0x10].copy_from_slice(&0x2000_0000u32.to_le_bytes());
        e[h + 0x10..h + 0x14].copy_from_slice(&0x40u32.to_le_bytes());
        e[h + 0x14..h + 0x18].copy_from_slice(&0x40u32.to_le_bytes());
        e[0x50..0x50 + blob::IDENTITY_LEN].copy_from_slice(&blob::identity_record([0; 3]));
        e
    }

    /// A dry run of a 2x1x1 array lists, per board and in order, the downloads of its ELF
    /// and of its schedule at the image address, the reads of its identity record (at the
    /// address its ELF section gives it: 0x2000_0010) and of its schedule's head (64
    /// bytes), each through the board's probe; then one reset per board. A board map that
    /// leaves a board out, or places one outside the machine, is refused naming it.
    #[test]
    fn a_dry_run_lists_every_boards_commands() {
        let out = std::env::temp_dir().join(format!("pe-flash-dry-{}", std::process::id()));
        std::fs::create_dir_all(&out).unwrap();
        let template = elf_with_identity();
        assert_eq!(elf_address(&template, 0x50), Some(0x2000_0010));
        let mut boards = Vec::new();
        for x in 0..2 {
            let (elf, sched) = (format!("board-{x}-0-0.elf"), format!("board-{x}-0-0.sched"));
            let patched = patch_identity(&template, [x as u8, 0, 0]).unwrap();
            std::fs::write(out.join(&elf), patched).unwrap();
            std::fs::write(out.join(&sched), vec![x as u8 + 1; 100]).unwrap();
            boards.push(ImageBoard {
                board: [x, 0, 0],
                elf,
                schedule: sched,
                schedule_address: "0x08100000".into(),
                schedule_bytes: 100,
                flash: Vec::new(),
            });
        }
        let m = ImageManifest {
            scene: "test".into(),
            compilation: "0123456789abcdef".into(),
            machine: [2, 1, 1],
            profile: &pe_firmware::profile::PE_BOARD,
            precision: Precision::F64,
            integration: Integration::Reduced,
            steps: 1,
            firmware: "fw.elf".into(),
            firmware_features: Vec::new(),
            boards,
        };
        std::fs::write(
            out.join("manifest.json"),
            serde_json::to_string(&m).unwrap(),
        )
        .unwrap();
        let map = out.join("boards.toml");
        let entry = |x: usize, probe: &str| {
            format!("[[board]]\nposition = [{x}, 0, 0]\nprobe = \"{probe}\"\n")
        };
        std::fs::write(&map, entry(0, "p0") + &entry(1, "p1")).unwrap();
        let done = flash_array(&out, &map, Path::new("probe-rs"), true).unwrap();
        assert_eq!(done.len(), 2);
        for (x, f) in done.iter().enumerate() {
            let probe = format!("p{x}");
            let file = |n: &str| out.join(n).display().to_string();
            let head = ["--chip", "STM32H743ZITx", "--probe", &probe];
            let cmd = |c: &str, rest: &[&str]| {
                let mut v = vec![c.to_string()];
                v.extend(head.iter().chain(rest).map(|s| s.to_string()));
                v
            };
            let (elf, sched) = (
                file(&format!("board-{x}-0-0.elf")),
                file(&format!("board-{x}-0-0.sched")),
            );
            assert_eq!((f.board, f.probe.as_str()), ([x, 0, 0], probe.as_str()));
            assert_eq!(
                f.commands,
                vec![
                    cmd("read", &["b8", "0x1ff1e800", "12"]),
                    cmd("download", &[&elf]),
                    cmd(
                        "download",
                        &[
                            "--binary-format",
                            "bin",
                            "--base-address",
                            "0x08100000",
                            &sched
                        ]
                    ),
                    cmd("read", &["b8", "0x20000010", "16"]),
                    cmd("read", &["b8", "0x08100000", "64"]),
                    cmd("reset", &[]),
                ]
            );
        }
        std::fs::write(&map, entry(0, "p0")).unwrap();
        let e = flash_array(&out, &map, Path::new("probe-rs"), true)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no probe for board(s) (1,0,0) of the 2x1x1 machine"),
            "{e}"
        );
        std::fs::write(&map, entry(0, "p0") + &entry(2, "p1")).unwrap();
        let e = flash_array(&out, &map, Path::new("probe-rs"), true)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("position (2,0,0) is outside the 2x1x1 machine"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&out);
    }
}
