//! Image sets carry the id of their compilation: board-sim refuses a mixed, corrupted or
//! misplaced set at start, and the boards themselves refuse a mixed set with their
//! neighbours (the Hello frames before step 0) when the host's check is bypassed.

use std::path::{Path, PathBuf};
use std::time::Duration;

use board_sim::{run, SimFault, SimOptions};
use host_tools::compile::partition::Machine;
use host_tools::compile::{
    compilation_id, compile_images, decode_image, image_file_name, plan, read_manifest,
};
use host_tools::problem::Problem;
use host_tools::scene::builtin::builtin_scene;
use link_proto::machine::across;
use link_proto::FrameKind;
use pe_firmware::image::{stamp_compilation, CompilationId, ImageError};
use pe_firmware::runtime::FaultKind;
use system_tests::*;

/// The built-in coarse scene at `steps`, every material's Young's modulus times `scale`.
fn coarse(steps: u64, scale: f64) -> Problem {
    let mut sc = builtin_scene("coarse").expect("builtin scene");
    sc.solver.steps = Some(steps);
    for m in &mut sc.materials {
        m.youngs_modulus = m.youngs_modulus.map(|e| e * scale);
    }
    Problem::from_scene(&sc, Path::new(".")).expect("builtin problem")
}

/// A copy of the compiled set in `from` as a fresh directory.
fn copy_set(from: &Path, name: &str) -> TempDir {
    let d = temp_dir(name);
    for e in std::fs::read_dir(from).expect("set dir") {
        let e = e.expect("entry");
        std::fs::copy(e.path(), d.join(e.file_name())).expect("copy");
    }
    d
}

fn image(dir: &Path, b: [usize; 3]) -> PathBuf {
    dir.join(image_file_name(b))
}

fn manifest_id(dir: &Path) -> String {
    read_manifest(dir).expect("manifest").compilation
}

fn refusal(dir: &Path, opts: &SimOptions) -> String {
    match run(dir, opts, &mut |_, _| {}) {
        Ok(_) => panic!("{}: the set must be refused", dir.display()),
        Err(e) => {
            assert!(
                e.downcast_ref::<SimFault>().is_none(),
                "refused at start, before any board ran: {e}"
            );
            format!("{e:#}")
        }
    }
}

fn bypass() -> SimOptions {
    SimOptions {
        check_manifest: false,
        link_timeout: Duration::from_secs(5),
        workers: Some(2),
        ..Default::default()
    }
}

/// The header field: every image of a set carries the same non-zero id, the manifest
/// records it, it is the hash of the set with the field unset, stamping rewrites only its
/// 8 bytes and the CRC, and a changed modulus gives another id.
#[test]
fn the_compilation_id_is_the_hash_of_the_set() {
    let machine = Machine::parse("2x2x1").unwrap();
    let p = coarse(10, 1.0);
    let pl = plan(&p, machine).unwrap();
    let images = compile_images(&p, &pl).unwrap();
    assert_eq!(images.len(), 4, "one image per board");
    let id = images[0].header.compilation;
    assert_ne!(id, CompilationId::UNSET, "stamped");
    for im in &images {
        let d = decode_image(&im.bytes, Some(im.coords.map(|c| c as u8))).unwrap();
        assert_eq!(d.header.compilation, id, "board {:?}", im.coords);
    }
    // The same scene compiles to the same bytes and id; the hash is over the set unset.
    let again = compile_images(&p, &pl).unwrap();
    assert_eq!(again.len(), images.len());
    assert!(again.iter().zip(&images).all(|(a, b)| a.bytes == b.bytes));
    let mut unset = compile_images(&p, &pl).unwrap();
    for im in &mut unset {
        stamp_compilation(&mut im.bytes, CompilationId::UNSET).unwrap();
    }
    assert_eq!(
        compilation_id(&p, &unset),
        id,
        "the id excludes its own field"
    );
    // Stamping changes the 8 id bytes and the 4 CRC bytes, nothing else.
    let other = CompilationId::from_u64(0x0123_4567_89ab_cdef);
    let mut b = images[1].bytes.clone();
    stamp_compilation(&mut b, other).unwrap();
    assert_eq!(b.len(), images[1].bytes.len(), "same length");
    let changed = b
        .iter()
        .zip(&images[1].bytes)
        .filter(|(x, y)| x != y)
        .count();
    assert!(
        (1..=12).contains(&changed),
        "{changed} bytes changed: only the id and the CRC"
    );
    let d = decode_image(&b, Some([1, 0, 0])).unwrap();
    assert_eq!(d.header.compilation, other);
    assert_eq!(other.to_string(), "0123456789abcdef");
    // A changed modulus: another id.
    let q = coarse(10, 1.5);
    let stiffer = compile_images(&q, &plan(&q, machine).unwrap()).unwrap();
    assert_ne!(stiffer[0].header.compilation, id);
    // A flipped bit is refused by the image's CRC.
    let mut bad = images[2].bytes.clone();
    let k = bad.len() / 2;
    bad[k] ^= 0x10;
    assert!(matches!(
        decode_image(&bad, Some([0, 1, 0])),
        Err(ImageError::BadCrc { .. })
    ));
    // The Hello frame's wire code.
    assert_eq!(FrameKind::Hello.code(), 0x04);
    assert_eq!(FrameKind::from_code(0x04), FrameKind::Hello);
}

/// The finding of issue 18: one board's image from a recompile with another modulus. The
/// host refuses the set naming exactly that board and both ids; with the host's check
/// bypassed (and also with the recompile's manifest) the boards refuse it themselves on the
/// first exchange, naming the board and the link; a clean set runs and moves.
#[test]
fn a_mixed_set_is_refused_by_the_host_and_by_the_boards() {
    // 1000 steps: the probe has pressed the tube, so a clean run's displacements are far
    // from zero.
    let a = compile(&coarse(1000, 1.0), "builtin:coarse", "4x4x4", "set-a");
    let b = compile(&coarse(1000, 1.5), "builtin:coarse", "4x4x4", "set-b");
    let (id_a, id_b) = (manifest_id(&a), manifest_id(&b));
    assert_ne!(id_a, id_b, "a changed modulus is another compilation");
    let odd = [1usize, 2, 0];
    let mixed = copy_set(&a, "set-mixed");
    std::fs::copy(image(&b, odd), image(&mixed, odd)).unwrap();

    // The host: exactly that board, its file and both ids.
    let e = refusal(&mixed, &SimOptions::default());
    assert!(e.contains("board (1,2,0)"), "{e}");
    assert_eq!(e.matches("board (").count(), 1, "only the odd board: {e}");
    assert!(e.contains(&image_file_name(odd)), "{e}");
    assert!(e.contains(&id_a) && e.contains(&id_b), "{e}");
    assert!(e.contains("63 other boards"), "{e}");

    // The boards: every mismatch reported is on a link of the odd board, between the two
    // ids.
    let check_boards = |dir: &Path| {
        let f = match run(dir, &bypass(), &mut |_, _| {}) {
            Ok(_) => panic!("a mixed set must not run"),
            Err(e) => e.downcast::<SimFault>().expect("a fault report"),
        };
        println!("{f}");
        let root = &f.observed[f.cause.detected].fault;
        let FaultKind::CompilationMismatch { face, ours, theirs } = root.kind else {
            panic!("the root cause is the mismatch, not a timeout: {f}");
        };
        let other = across(root.board.map(usize::from), face).expect("a neighbour");
        assert!(root.board.map(usize::from) == odd || other == odd, "{root}");
        let mut ids = [ours.to_string(), theirs.to_string()];
        ids.sort();
        let mut want = [id_a.clone(), id_b.clone()];
        want.sort();
        assert_eq!(ids, want, "{root}");
        assert!(root.to_string().contains(&format!("{face:?}")), "{root}");
        for x in f.observed.iter().map(|o| &o.fault) {
            if let FaultKind::CompilationMismatch { face, .. } = x.kind {
                let n = across(x.board.map(usize::from), face).expect("a neighbour");
                assert!(x.board.map(usize::from) == odd || n == odd, "{x}");
            }
        }
        assert_eq!(root.step, 0, "before step 0's exchange");
    };
    check_boards(&mixed);
    // The recompile's manifest too: the host names the 63 boards not from it; the boards
    // still refuse the set.
    std::fs::copy(b.join("manifest.json"), mixed.join("manifest.json")).unwrap();
    let e = refusal(&mixed, &SimOptions::default());
    assert!(
        e.contains("only 1 of 64") && e.contains("board (1,2,0)"),
        "{e}"
    );
    assert_eq!(e.matches("board (").count(), 1, "only the odd board: {e}");
    check_boards(&mixed);

    // A clean set runs, and moves.
    let clean = SimOptions {
        workers: Some(2),
        ..Default::default()
    };
    let out = run(&a, &clean, &mut |_, _| {}).expect("a clean set runs");
    assert_eq!(out.steps, 1000);
    assert_eq!(out.displacements.len(), coarse(1, 1.0).mesh.nodes.len());
    let u_max = host_tools::compare::max_abs(&out.displacements);
    assert!(
        u_max > 1e-4,
        "the probe has moved the tube: max |u| {u_max} m"
    );
}

/// An image of another scene is refused at start with a clear message (not a timeout), and
/// by the boards with the host's check bypassed; a misplaced, a corrupted image and one
/// whose CRC is not the manifest's are refused naming the board.
#[test]
fn foreign_misplaced_and_corrupted_images_are_refused() {
    let a = compile(&coarse(20, 1.0), "builtin:coarse", "4x4x4", "set-c");
    let mut seed_box = repo_scene("seed-box.toml");
    seed_box.solver.steps = Some(20);
    let other = compile(&seed_box, "scenes/seed-box.toml", "4x4x4", "set-box");
    let b0 = [0usize, 0, 0];

    let foreign = copy_set(&a, "set-foreign");
    std::fs::copy(image(&other, [2, 1, 1]), image(&foreign, [2, 1, 1])).unwrap();
    let e = refusal(&foreign, &SimOptions::default());
    assert!(
        e.contains("board (2,1,1)") && e.contains(&manifest_id(&other)),
        "{e}"
    );
    let f = match run(&foreign, &bypass(), &mut |_, _| {}) {
        Ok(_) => panic!("a foreign image must not run"),
        Err(e) => e.downcast::<SimFault>().expect("a fault report"),
    };
    assert!(
        matches!(
            f.observed[f.cause.detected].fault.kind,
            FaultKind::CompilationMismatch { .. } | FaultKind::Image(_)
        ),
        "named at start, not a timeout: {f}"
    );

    // Board (1,0,0)'s image where (0,0,0)'s belongs.
    let moved = copy_set(&a, "set-moved");
    std::fs::copy(image(&a, [1, 0, 0]), image(&moved, b0)).unwrap();
    let e = refusal(&moved, &bypass());
    assert!(
        e.contains("board (0,0,0)") && e.contains("image is for board (1,0,0)"),
        "{e}"
    );

    // A flipped bit.
    let corrupt = copy_set(&a, "set-corrupt");
    let p = image(&corrupt, [3, 1, 2]);
    let mut bytes = std::fs::read(&p).unwrap();
    let k = bytes.len() / 3;
    bytes[k] ^= 0x01;
    std::fs::write(&p, bytes).unwrap();
    let e = refusal(&corrupt, &bypass());
    assert!(e.contains("board (3,1,2)") && e.contains("CRC"), "{e}");

    // A file whose own CRC holds but is not the one the manifest recorded.
    let edited = copy_set(&a, "set-edited");
    let p = image(&edited, [2, 3, 1]);
    let mut bytes = std::fs::read(&p).unwrap();
    // One bit of the last record flipped and the image's own CRC renewed: a hand edit.
    let n = bytes.len();
    bytes[n - 20] ^= 0x01;
    let crc = link_proto::frame::crc32(&bytes[..n - 4]);
    bytes[n - 4..].copy_from_slice(&crc.to_le_bytes());
    std::fs::write(&p, bytes).unwrap();
    let e = refusal(&edited, &SimOptions::default());
    assert!(
        e.contains("board (2,3,1)") && e.contains("manifest.json records"),
        "{e}"
    );
}

/// A header whose counts claim more records than the image has bytes (a damaged or forged
/// header behind a valid CRC) is refused before anyone sizes storage from it: by the
/// reader, the host decoder and the firmware's loader; the genuine image passes.
#[test]
fn counts_beyond_the_image_are_refused_before_allocation() {
    use pe_firmware::image::{ImageReader, MAGIC};
    let machine = Machine::parse("2x1x1").unwrap();
    let p = coarse(10, 1.0);
    let pl = plan(&p, machine).unwrap();
    let images = compile_images(&p, &pl).unwrap();
    let good = &images[0].bytes;
    let header = ImageReader::new(good, None)
        .expect("a genuine image")
        .header;
    let header_len = postcard::to_allocvec(&header).expect("header").len();
    let body = &good[MAGIC.len() + header_len..good.len() - 4];
    // Not trivial: the genuine image holds thousands of records in fewer bytes than that
    // bound allows (each record at least one byte).
    assert!(
        header.counts.records() > 1000 && header.counts.records() <= body.len() as u64,
        "{} records in {} bytes",
        header.counts.records(),
        body.len()
    );
    let board = header.board;
    assert!(board_sim::load_check(good, board, board_sim::StorageSizing::Exact).is_ok());
    let forge = |edit: &dyn Fn(&mut pe_firmware::image::Counts)| {
        let mut h = header;
        edit(&mut h.counts);
        let mut img = MAGIC.to_vec();
        img.extend(postcard::to_allocvec(&h).expect("header"));
        img.extend_from_slice(body);
        let crc = link_proto::frame::crc32(&img);
        img.extend(crc.to_le_bytes());
        img
    };
    let bytes = body.len() as u32;
    type Edit<'a> = (&'a str, &'a dyn Fn(&mut pe_firmware::image::Counts));
    let edits: [Edit; 4] = [
        ("receives", &|c| c.recvs = u32::MAX),
        ("elements", &|c| c.elements += bytes),
        ("contact nodes", &|c| c.contact_nodes = u32::MAX / 2),
        ("sends", &|c| c.sends = bytes),
    ];
    for (what, edit) in edits {
        let img = forge(edit);
        match ImageReader::new(&img, None) {
            Err(ImageError::Malformed { record }) => {
                assert!(record.contains("header counts"), "{what}: {record}")
            }
            other => panic!(
                "{what}: refused as malformed counts, got {:?}",
                other.map(|r| r.header.counts)
            ),
        }
        assert!(
            decode_image(&img, None).is_err(),
            "{what}: the host decoder refuses it"
        );
        assert!(
            board_sim::load_check(&img, board, board_sim::StorageSizing::Exact).is_err(),
            "{what}: the loader refuses it"
        );
    }
}
