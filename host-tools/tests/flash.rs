//! `pe flash`: the board map checked against the array before anything is written, the
//! probe-rs commands each board gets, and the read-back that must find what was written.
//! probe-rs itself is stood in for by a small program that keeps each probe's "flash" in a
//! directory: it writes what `download` gives it and answers `read` from what it holds, so
//! the flow runs end to end; an option makes one probe's writes fail silently, another
//! says which chip (unique ID) each probe is on.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

use pe_firmware::image::blob;

const PE: &str = env!("CARGO_BIN_EXE_pe");

fn temp_dir(tag: &str) -> common::TempDir {
    common::temp_dir(&format!("flash-{tag}"))
}

/// A 32-bit little-endian ELF with one loaded section at 0x0800_1000 holding the firmware's
/// identity record (board (0,0,0)) and the build record of an f64 reduced firmware for the
/// prototype (`stm32h743-uart`) with every part, between other bytes.
fn fake_firmware() -> Vec<u8> {
    let all = blob::BUILD_CONTACT | blob::BUILD_GRAPHICS | blob::BUILD_LOADS;
    fake_firmware_built(Some(blob::build_record(prototype_index(), all)))
}

/// The prototype's index in the profile registry.
fn prototype_index() -> u8 {
    pe_firmware::profile::profile_index("stm32h743-uart").expect("registered")
}

/// [`fake_firmware`] with another build record, or none.
fn fake_firmware_built(build: Option<[u8; blob::BUILD_LEN]>) -> Vec<u8> {
    let mut data = vec![0xAAu8; 64];
    data.extend_from_slice(&blob::identity_record([0, 0, 0]));
    data.extend(vec![0x55u8; 16]);
    data.extend(build.unwrap_or([0x55; blob::BUILD_LEN]));
    data.extend(vec![0x55u8; 16]);
    let data_off = 52u32;
    let shoff = data_off + data.len() as u32;
    let mut e = vec![0u8; 52];
    e[..4].copy_from_slice(b"\x7fELF");
    e[4] = 1; // 32-bit
    e[5] = 1; // little-endian
    e[6] = 1;
    e[0x10..0x12].copy_from_slice(&2u16.to_le_bytes()); // executable
    e[0x12..0x14].copy_from_slice(&40u16.to_le_bytes()); // ARM
    e[0x20..0x24].copy_from_slice(&shoff.to_le_bytes());
    e[0x28..0x2A].copy_from_slice(&52u16.to_le_bytes());
    e[0x2E..0x30].copy_from_slice(&40u16.to_le_bytes());
    e[0x30..0x32].copy_from_slice(&2u16.to_le_bytes());
    e.extend_from_slice(&data);
    e.extend(vec![0u8; 40]); // null section
    let mut sh = vec![0u8; 40];
    sh[4..8].copy_from_slice(&1u32.to_le_bytes()); // PROGBITS
    sh[0x0C..0x10].copy_from_slice(&0x0800_1000u32.to_le_bytes());
    sh[0x10..0x14].copy_from_slice(&data_off.to_le_bytes());
    sh[0x14..0x18].copy_from_slice(&(data.len() as u32).to_le_bytes());
    e.extend_from_slice(&sh);
    e
}

/// The stand-in probe-rs (python3): state per probe serial under $FAKE_PROBES;
/// FAKE_BROKEN=SERIAL makes that probe drop its writes; FAKE_UIDS="SERIAL=W0:W1:W2,..."
/// puts a probe on the chip with that unique ID (read at 0x1FF1E800, three little-endian
/// words; by default the probe's serial's bytes).
const FAKE_PROBE_RS: &str = r#"#!/usr/bin/env python3
import os, sys
args = sys.argv[1:]
state = os.environ["FAKE_PROBES"]
open(os.path.join(state, "log"), "a").write(" ".join(args) + "\n")
cmd = args[0]
probe = args[args.index("--probe") + 1]
mem = os.path.join(state, probe.replace(":", "_"))
os.makedirs(mem, exist_ok=True)
broken = os.environ.get("FAKE_BROKEN") == probe.split(":")[-1]
def region(addr):
    return os.path.join(mem, "%08x" % addr)
if cmd == "download":
    path = args[-1]
    data = open(path, "rb").read()
    if broken:
        sys.exit(0)
    if "--binary-format" in args:
        addr = int(args[args.index("--base-address") + 1], 16)
        open(region(addr), "wb").write(data)
    else:
        # ELF: every PROGBITS section at its address.
        import struct
        shoff, = struct.unpack_from("<I", data, 0x20)
        shnum, = struct.unpack_from("<H", data, 0x30)
        for k in range(shnum):
            kind, = struct.unpack_from("<I", data, shoff + 40 * k + 4)
            addr, off, size = struct.unpack_from("<III", data, shoff + 40 * k + 0x0C)
            if kind == 1:
                open(region(addr), "wb").write(data[off:off + size])
elif cmd == "read":
    width, addr, n = args[-3], int(args[-2], 16), int(args[-1])
    out = []
    if addr == 0x1FF1E800:
        serial = probe.split(":")[-1]
        uids = dict(kv.split("=") for kv in os.environ.get("FAKE_UIDS", "").split(",") if kv)
        if serial in uids:
            import struct
            out = b"".join(struct.pack("<I", int(w, 16)) for w in uids[serial].split(":"))
        else:
            out = serial.encode().ljust(12, b"\0")[:12]
    for name in os.listdir(mem):
        base = int(name, 16)
        blob = open(os.path.join(mem, name), "rb").read()
        if base <= addr and addr + n <= base + len(blob):
            out = blob[addr - base: addr - base + n]
    if not out:
        out = bytes(n)  # erased flash reads as something; zeros here
    print(" ".join("%02x" % b for b in out))
elif cmd == "reset":
    pass
else:
    sys.exit("unknown command " + cmd)
"#;

struct Setup {
    dir: common::TempDir,
    images: PathBuf,
    probe_rs: PathBuf,
    state: PathBuf,
}

/// Runs a `pe` command that must succeed (its stderr shown if not).
fn pe_ok(cmd: &mut Command) {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn setup(tag: &str) -> Setup {
    let dir = temp_dir(tag);
    let compiled = dir.join("compiled");
    pe_ok(
        Command::new(PE)
            .args([
                "compile",
                "--builtin",
                "--level",
                "coarse",
                "--boards",
                "2x1x1",
            ])
            .args(["--profile", "stm32h743-uart", "--steps", "10", "-o"])
            .arg(&compiled),
    );
    let fw = dir.join("fake.elf");
    std::fs::write(&fw, fake_firmware()).unwrap();
    let images = dir.join("images");
    pe_ok(
        Command::new(PE)
            .arg("image")
            .arg(&compiled)
            .arg("-o")
            .arg(&images)
            .arg("--firmware")
            .arg(&fw),
    );
    let probe_rs = dir.join("probe-rs");
    std::fs::write(&probe_rs, FAKE_PROBE_RS).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&probe_rs, std::fs::Permissions::from_mode(0o755)).unwrap();
    let state = dir.join("probes");
    std::fs::create_dir_all(&state).unwrap();
    Setup {
        dir,
        images,
        probe_rs,
        state,
    }
}

fn map(dir: &Path, entries: &[([usize; 3], &str)]) -> PathBuf {
    let with_uids: Vec<_> = entries.iter().map(|&(p, probe)| (p, probe, None)).collect();
    map_with_uids(dir, &with_uids)
}

fn map_with_uids(dir: &Path, entries: &[([usize; 3], &str, Option<&str>)]) -> PathBuf {
    let mut t = String::new();
    for (p, probe, uid) in entries {
        t.push_str(&format!(
            "[[board]]\nposition = [{}, {}, {}]\nprobe = \"{probe}\"\n",
            p[0], p[1], p[2]
        ));
        if let Some(u) = uid {
            t.push_str(&format!("uid = \"{u}\"\n"));
        }
    }
    let p = dir.join("boards.toml");
    std::fs::write(&p, t).unwrap();
    p
}

fn flash(s: &Setup, map: &Path, extra: &[&str], broken: Option<&str>) -> (bool, String) {
    flash_on_chips(s, map, extra, broken, "")
}

/// [`flash`] with the probes on the chips `uids` names (`SERIAL=W0:W1:W2,...`).
fn flash_on_chips(
    s: &Setup,
    map: &Path,
    extra: &[&str],
    broken: Option<&str>,
    uids: &str,
) -> (bool, String) {
    let mut c = Command::new(PE);
    c.arg("flash")
        .arg(&s.images)
        .arg("--map")
        .arg(map)
        .arg("--probe-rs")
        .arg(&s.probe_rs)
        .args(extra)
        .env("FAKE_PROBES", &s.state)
        .env("FAKE_UIDS", uids)
        .env("RUST_BACKTRACE", "0");
    if let Some(b) = broken {
        c.env("FAKE_BROKEN", b);
    }
    let o = c.output().unwrap();
    (
        o.status.success(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        ),
    )
}

const A: &str = "0483:374e:AAAA0001";
const B: &str = "0483:374e:BBBB0002";

/// Both boards flashed through their own probes: each probe first read the unique ID of
/// its chip, then got the board's ELF and its schedule at the profile's address, read back
/// the identity and the schedule head, and was reset; the probes now hold different
/// identities (each its board's). A map without uids gets each board's printed.
#[test]
fn every_board_is_flashed_through_its_probe_and_read_back() {
    let s = setup("ok");
    let m = map(&s.dir, &[([0, 0, 0], A), ([1, 0, 0], B)]);
    let (ok, text) = flash(&s, &m, &[], None);
    assert!(ok, "{text}");
    assert!(
        text.contains("2 boards flashed, checked and reset"),
        "{text}"
    );
    // The stand-in's chips: each probe's serial as the ID's bytes ("AAAA0001" + zeros).
    assert!(
        text.contains("position = [0, 0, 0]  uid = \"41414141:31303030:00000000\""),
        "{text}"
    );
    let log = std::fs::read_to_string(s.state.join("log")).unwrap();
    let lines: Vec<&str> = log.lines().collect();
    assert_eq!(lines.len(), 2 * 6, "{log}");
    // Both chips are read before anything is written.
    assert!(lines[0].contains(" b8 0x1ff1e800 12") && lines[1].contains(" b8 0x1ff1e800 12"));
    for (probe, board) in [(A, "board-0-0-0"), (B, "board-1-0-0")] {
        let mine: Vec<&&str> = lines.iter().filter(|l| l.contains(probe)).collect();
        assert_eq!(mine.len(), 6, "{log}");
        assert!(mine[0].starts_with("read") && mine[0].contains(" b8 0x1ff1e800 12"));
        assert!(mine[1].starts_with("download") && mine[1].ends_with(&format!("{board}.elf")));
        assert!(
            mine[2].contains("--base-address 0x08100000")
                && mine[2].ends_with(&format!("{board}.sched"))
        );
        assert!(
            mine[3].starts_with("read") && mine[3].contains(" b8 0x08001040 16"),
            "{log}"
        );
        assert!(
            mine[4].starts_with("read") && mine[4].contains(" b8 0x08100000 64"),
            "{log}"
        );
        assert!(mine[5].starts_with("reset"));
    }
    // Resets come after every board was flashed and checked.
    let first_reset = lines.iter().position(|l| l.starts_with("reset")).unwrap();
    assert_eq!(first_reset, 10, "{log}");
    // What each fake board holds at the identity address is its own position's record.
    for (probe, pos) in [(A, [0u8, 0, 0]), (B, [1, 0, 0])] {
        let held = std::fs::read(s.state.join(probe.replace(':', "_")).join("08001000")).unwrap();
        assert_eq!(&held[64..80], &blob::identity_record(pos));
    }
}

/// The board map knows each board by its chip: probes swapped at the array (each on the
/// other's board) are refused naming both positions, before any board is written; with the
/// probes where the map says, the chips are reported as mapped.
#[test]
fn a_probe_on_the_wrong_board_is_refused_before_anything_is_written() {
    let s = setup("swapped");
    let (u0, u1) = ("003A0028:31385104:33333439", "00290041:3137510B:36383830");
    let m = map_with_uids(
        &s.dir,
        &[([0, 0, 0], A, Some(u0)), ([1, 0, 0], B, Some(u1))],
    );
    let swapped = format!("AAAA0001={u1},BBBB0002={u0}");
    let (ok, text) = flash_on_chips(&s, &m, &[], None, &swapped);
    assert!(!ok, "{text}");
    assert!(
        text.contains(&format!("board (0,0,0): probe {A} is on the chip with unique ID {u1}, which the board map gives board (1,0,0): the probes of boards (0,0,0) and (1,0,0) look swapped")),
        "{text}"
    );
    let log = std::fs::read_to_string(s.state.join("log")).unwrap();
    assert!(!log.contains("download"), "written before the check: {log}");
    assert_eq!(
        log.lines().count(),
        2,
        "both chips read, nothing else: {log}"
    );
    // A uid that is no unique ID is refused naming the entry.
    let bad = map_with_uids(
        &s.dir,
        &[([0, 0, 0], A, Some("12:34")), ([1, 0, 0], B, None)],
    );
    let (ok, text) = flash(&s, &bad, &[], None);
    assert!(
        !ok && text.contains("[[board]] 0 (0,0,0): uid \"12:34\" is not a 96-bit unique ID"),
        "{text}"
    );
    // In their places, the same map flashes, and says each chip is the mapped one.
    let m = map_with_uids(
        &s.dir,
        &[([0, 0, 0], A, Some(u0)), ([1, 0, 0], B, Some(u1))],
    );
    let (ok, text) = flash_on_chips(&s, &m, &[], None, &format!("AAAA0001={u0},BBBB0002={u1}"));
    assert!(ok, "{text}");
    assert!(
        text.contains(&format!("board (1,0,0): chip {u1} as mapped")),
        "{text}"
    );
    assert!(!text.contains("add each board's uid"), "{text}");
}

/// --dry-run prints the same commands and runs none.
#[test]
fn a_dry_run_prints_the_commands_and_runs_nothing() {
    let s = setup("dry");
    let m = map(&s.dir, &[([1, 0, 0], B), ([0, 0, 0], A)]);
    let (ok, text) = flash(&s, &m, &["--dry-run"], None);
    assert!(ok, "{text}");
    assert_eq!(
        text.lines().filter(|l| l.contains(" download ")).count(),
        4,
        "{text}"
    );
    assert_eq!(
        text.lines().filter(|l| l.contains(" reset ")).count(),
        2,
        "{text}"
    );
    assert!(!s.state.join("log").exists());
}

/// A map that does not fit the array is refused before any probe is used: a board
/// without a probe, one probe for two boards, a board outside the machine.
#[test]
fn a_wrong_board_map_is_refused_before_anything_is_written() {
    let s = setup("map");
    for (entries, want) in [
        (vec![([0, 0, 0], A)], "no probe for board(s) (1,0,0)"),
        (
            vec![([0, 0, 0], A), ([1, 0, 0], A)],
            "probe 0483:374e:AAAA0001 is given to boards (0,0,0) and (1,0,0)",
        ),
        (
            vec![
                ([0, 0, 0], A),
                ([1, 0, 0], B),
                ([2, 0, 0], "0483:374e:CCCC"),
            ],
            "position (2,0,0) is outside the 2x1x1 machine",
        ),
    ] {
        let m = map(&s.dir, &entries);
        let (ok, text) = flash(&s, &m, &[], None);
        assert!(!ok, "{text}");
        assert!(text.contains(want), "expected {want:?}:\n{text}");
        assert!(!s.state.join("log").exists(), "a probe was used: {text}");
    }
}

/// A probe whose writes do not take: the read-back names the board and the probe, and no
/// board is reset.
#[test]
fn a_write_that_did_not_take_is_named() {
    let s = setup("broken");
    let m = map(&s.dir, &[([0, 0, 0], A), ([1, 0, 0], B)]);
    let (ok, text) = flash(&s, &m, &[], Some("BBBB0002"));
    assert!(!ok, "{text}");
    assert!(
        text.contains("board (1,0,0): probe 0483:374e:BBBB0002 reads back 16 bytes that are no identity record"),
        "{text}"
    );
    let log = std::fs::read_to_string(s.state.join("log")).unwrap();
    assert!(!log.contains("reset"), "{log}");
}

/// `pe image --firmware` reads what the ELF was built for from its build record and refuses,
/// before writing anything, one built for another board profile, another precision, without
/// a part the images need, or without a build record; the manifest records the features the
/// ELF has (here every part, more than the images need).
#[test]
fn an_elf_built_for_something_else_is_refused() {
    let s = setup("elf-check");
    let compiled = s.dir.join("compiled");
    let qemu = pe_firmware::profile::profile_index("qemu-mps2-an500").expect("registered");
    let all = blob::BUILD_CONTACT | blob::BUILD_GRAPHICS | blob::BUILD_LOADS;
    let proto = prototype_index();
    for (build, want) in [
        (
            Some(blob::build_record(qemu, all)),
            "built for the board profile qemu-mps2-an500, the images for stm32h743-uart",
        ),
        (
            Some(blob::build_record(proto, all | blob::BUILD_F32)),
            "built for f32 reduced, the images are f64 reduced",
        ),
        (
            Some(blob::build_record(proto, blob::BUILD_LOADS)),
            "built without contact, graphics, which the images need",
        ),
        (None, "holds 0 build records"),
    ] {
        let fw = s.dir.join("other.elf");
        std::fs::write(&fw, fake_firmware_built(build)).unwrap();
        let out_dir = s.dir.join("refused");
        let out = Command::new(PE)
            .arg("image")
            .arg(&compiled)
            .arg("-o")
            .arg(&out_dir)
            .arg("--firmware")
            .arg(&fw)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "accepted: {want}");
        assert!(text.contains(want), "expected {want:?}:\n{text}");
        assert!(text.contains("other.elf"), "the ELF is named: {text}");
        assert!(!out_dir.exists(), "{want}: wrote {}", out_dir.display());
    }
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(s.images.join("manifest.json")).unwrap())
            .unwrap();
    let features: Vec<&str> = m["firmware_features"]
        .as_array()
        .expect("features")
        .iter()
        .filter_map(|v| v.as_str())
        .collect();
    assert_eq!(
        features,
        ["stm32h743", "defmt", "contact", "graphics", "loads"],
        "the ELF's features"
    );
}
