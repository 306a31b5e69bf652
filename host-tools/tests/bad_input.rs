//! Bad input as a user meets it at the command line: every case exits non-zero before any
//! work, with a message naming the item (file, option, key), prints its cause chain and no
//! backtrace, and leaves nothing half-written.

use std::path::PathBuf;
use std::process::{Command, Output};

const PE: &str = env!("CARGO_BIN_EXE_pe");

mod common;

/// A fresh scratch directory, removed when the test passes ([`common::temp_dir`]).
fn temp_dir(tag: &str) -> common::TempDir {
    common::temp_dir(&format!("bad-{tag}"))
}

fn run(args: &[&str]) -> Output {
    Command::new(PE)
        .args(args)
        .env("RUST_BACKTRACE", "1")
        .output()
        .unwrap()
}

/// Runs `pe ARGS` expecting a refusal; its stderr, asserted to contain every `needle` and
/// no backtrace (RUST_BACKTRACE=1 is set, as many Rust users have it).
fn refused(args: &[&str], needles: &[&str]) -> String {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "pe {args:?} was accepted: {err}");
    for n in needles {
        assert!(err.contains(n), "pe {args:?}: {n:?} not in {err}");
    }
    assert!(
        !err.contains("Stack backtrace") && !err.contains("stack backtrace"),
        "pe {args:?} printed a backtrace: {err}"
    );
    err
}

/// `pe compare` on a result of NaN against finite values, in either order and with or
/// without a tolerance: refused as not a result (before, `--tolerance` printed "within
/// ... max |diff| 0" and exited 0, as `f64::max` dropped the NaN).
#[test]
fn compare_refuses_nan_in_either_file() {
    let d = temp_dir("nan");
    let head = "node,x_m,y_m,z_m,ux_m,uy_m,uz_m\n";
    let finite = d.join("finite.csv");
    std::fs::write(
        &finite,
        format!("{head}1,0,0,0,1e-3,2e-3,-3e-3\n2,1,0,0,4e-3,0,0\n"),
    )
    .unwrap();
    let nan = d.join("nan.csv");
    std::fs::write(
        &nan,
        format!("{head}1,0,0,0,NaN,NaN,NaN\n2,1,0,0,NaN,NaN,NaN\n"),
    )
    .unwrap();
    let (f, n) = (finite.to_str().unwrap(), nan.to_str().unwrap());
    for (a, b) in [(f, n), (n, f)] {
        for tol in [&["--tolerance", "0.5"][..], &[]] {
            let mut args = vec!["compare", a, b];
            args.extend_from_slice(tol);
            refused(&args, &["not finite", "node 1 component 0", "nan.csv"]);
        }
    }
    // The control: the same file against itself passes.
    let out = run(&["compare", f, f]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Every option's domain is checked as it is parsed, naming the option: 0, negatives, NaN
/// and infinities never reach a run (each of these was accepted silently, or ran into
/// NaN/inf figures, before `host_tools::domain`).
#[test]
fn option_domains_are_checked_before_work() {
    for (args, option) in [
        (&["solve", "--builtin", "--threads", "0"][..], "--threads"),
        (&["solve", "--builtin", "--steps", "0"], "--steps"),
        (&["bench", "--runs", "0"], "--runs"),
        (&["bench", "--seconds", "NaN"], "--seconds"),
        (&["bench", "--elements=-5"], "--elements"),
        (
            &["compare", "a.csv", "b.csv", "--tolerance=-1e-3"],
            "--tolerance",
        ),
        (
            &["compare", "a.csv", "b.csv", "--min-displacement", "inf"],
            "--min-displacement",
        ),
        (
            &["live", "--builtin", "--graphics-hz", "0"],
            "--graphics-hz",
        ),
        (&["live", "--builtin", "--threads", "0"], "--threads"),
    ] {
        refused(args, &[option, "invalid value"]);
    }
    refused(
        &["plan", "--builtin", "--budget", "2", "-o", "/tmp/pe-never"],
        &["--budget", "200%", "write 2%"],
    );
}

/// A scene's `[solver]` keys: both `steps` and `duration`, a zero `output_interval`, a
/// negative `damping` and a negative or misspelt `hourglass` are refused naming the key (the last said "hourglass and damping >=
/// 0" without saying which). The control scene, with none of them, is accepted.
#[test]
fn scene_solver_keys_are_named() {
    let d = temp_dir("keys");
    let scene = |solver: &str| {
        format!(
            "[mesh]\ngenerate = {{ kind = \"box\", size = [0.02, 0.01, 0.01], cells = [2, 1, 1] }}\n\
             [material]\nlaw = \"neo-hookean\"\nyoungs_modulus = 3.0e3\npoisson_ratio = 0.45\ndensity = 1000.0\n\
             [[fixed]]\nbox = [[-1.0, -1.0, -1.0], [1e-9, 1.0, 1.0]]\n\
             [gravity]\nacceleration = [0.0, 0.0, -9.81]\n\
             [solver]\n{solver}"
        )
    };
    let p = d.join("scene.toml");
    std::fs::write(&p, scene("steps = 10\n")).unwrap();
    let ok = run(&["solve", p.to_str().unwrap()]);
    assert!(
        ok.status.success(),
        "control: {}",
        String::from_utf8_lossy(&ok.stderr)
    );
    for (solver, needles) in [
        (
            "steps = 10\nduration = 0.5\n",
            &["steps = 10", "duration = 0.5", "give one"][..],
        ),
        (
            "steps = 10\noutput_interval = 0.0\n",
            &["output_interval must be > 0"],
        ),
        ("steps = 10\ndamping = -1.0\n", &["damping must be >= 0"]),
        (
            "steps = 10\nhourglass = -0.1\n",
            &[
                "hourglass must be \"physical\" or a coefficient >= 0, got -0.1",
                "line 14",
            ],
        ),
        (
            "steps = 10\nhourglass = \"phys\"\n",
            &["hourglass \"phys\": expected \"physical\"", "line 14"],
        ),
    ] {
        std::fs::write(&p, scene(solver)).unwrap();
        refused(&["solve", p.to_str().unwrap()], needles);
    }
}

/// A box of `cells` scene that runs `steps` steps.
fn box_scene(dir: &std::path::Path, cells: [usize; 3], steps: u64) -> PathBuf {
    let p = dir.join("box.toml");
    let [x, y, z] = cells;
    std::fs::write(
        &p,
        format!(
            "[mesh]\ngenerate = {{ kind = \"box\", size = [{sx}, {sy}, {sz}], cells = [{x}, {y}, {z}] }}\n\
             [material]\nlaw = \"neo-hookean\"\nyoungs_modulus = 3.0e3\npoisson_ratio = 0.45\ndensity = 1000.0\n\
             [[fixed]]\nbox = [[-1.0, -1.0, -1.0], [1e-9, 1.0, 1.0]]\n\
             [gravity]\nacceleration = [0.0, 0.0, -9.81]\n\
             [solver]\nsteps = {steps}\noutput_interval = 1e-4\n",
            sx = 0.01 * x as f64,
            sy = 0.01 * y as f64,
            sz = 0.01 * z as f64
        ),
    )
    .unwrap();
    p
}

/// An output path in a directory that does not exist is named before the run starts (the
/// run's first line, its element count, is never printed); nothing is written.
#[test]
fn output_paths_are_checked_before_the_run() {
    let d = temp_dir("paths");
    let scene = box_scene(&d, [4, 1, 1], 10);
    let s = scene.to_str().unwrap();
    for flag in ["--output-nodes", "--report", "--tool-force"] {
        let typo = d.join("no-such-dir/out.csv");
        let err = refused(
            &["solve", s, flag, typo.to_str().unwrap()],
            &[flag, "does not exist"],
        );
        assert!(!err.contains("elements,"), "{flag}: the run started: {err}");
    }
    let file = d.join("a-file");
    std::fs::write(&file, "").unwrap();
    refused(
        &["solve", s, "--vtk", file.to_str().unwrap()],
        &["--vtk", "is a file"],
    );
}

/// Two `pe solve` runs writing the same nodes CSV at once (one of 5 steps, one of 6, so the
/// files differ) leave exactly one of the two files, and no temporary file behind. Before
/// writes went through a temporary file and a rename, this test failed (the file held
/// neither: one truncated it while the other wrote).
#[test]
fn concurrent_runs_leave_a_whole_file() {
    let d = temp_dir("race");
    // 4961 nodes: a CSV of about 600 kB, written in many pieces.
    let scenes = [5, 6].map(|steps| {
        let p = box_scene(&d, [40, 10, 10], steps);
        let q = d.join(format!("box-{steps}.toml"));
        std::fs::rename(&p, &q).unwrap();
        q
    });
    let solve = |scene: &PathBuf, out: &PathBuf| {
        Command::new(PE)
            .args([
                "solve",
                scene.to_str().unwrap(),
                "--quiet",
                "--output-nodes",
            ])
            .arg(out)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap()
    };
    let alone: Vec<Vec<u8>> = scenes
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let out = d.join(format!("alone-{k}.csv"));
            assert!(solve(s, &out).wait().unwrap().success());
            std::fs::read(&out).unwrap()
        })
        .collect();
    assert!(
        alone[0].len() > 500_000 && alone[0] != alone[1],
        "two different, long files"
    );
    let out = d.join("nodes.csv");
    for trial in 0..10 {
        let runs = [solve(&scenes[0], &out), solve(&scenes[1], &out)];
        for mut r in runs {
            assert!(r.wait().unwrap().success(), "trial {trial}");
        }
        let got = std::fs::read(&out).unwrap();
        assert!(
            got == alone[0] || got == alone[1],
            "trial {trial}: the file ({} bytes) is neither run's ({} or {} bytes)",
            got.len(),
            alone[0].len(),
            alone[1].len()
        );
    }
    let names: Vec<String> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        names.iter().all(|n| !n.ends_with(".tmp")),
        "temporaries left: {names:?}"
    );
}

/// A `--vtk` directory reused by a shorter run holds the shorter run's frames only: the
/// earlier run's later frames are removed, and other files are left alone.
#[test]
fn a_reused_frame_directory_holds_this_runs_frames_only() {
    let d = temp_dir("frames");
    let frames = d.join("frames");
    let count = |steps: u64| {
        let scene = box_scene(&d, [4, 1, 1], steps);
        let out = run(&[
            "solve",
            scene.to_str().unwrap(),
            "--quiet",
            "--vtk",
            frames.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        std::fs::read_dir(&frames)
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .starts_with("frame_")
            })
            .count()
    };
    let long = count(60);
    std::fs::write(frames.join("notes.txt"), "mine").unwrap();
    let short = count(10);
    assert!(long > short && short >= 2, "frames: {long} then {short}");
    let pvd = std::fs::read_to_string(frames.join("series.pvd")).unwrap();
    assert_eq!(
        pvd.matches("<DataSet").count(),
        short,
        "series.pvd lists what is there"
    );
    assert!(
        frames.join("notes.txt").exists(),
        "a file the series does not own stays"
    );
}

/// A recompile into an old directory for a smaller machine leaves only the new machine's
/// images (the old one's extra images stayed, and `pe inspect` showed them without a word).
#[test]
fn a_recompile_leaves_no_stale_images() {
    let d = temp_dir("recompile");
    let scene = box_scene(&d, [8, 2, 2], 10);
    let out = d.join("compiled");
    let images = |boards: &str| {
        let o = run(&[
            "compile",
            scene.to_str().unwrap(),
            "--boards",
            boards,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let mut names: Vec<String> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("board-") && n.ends_with(".bin"))
            .collect();
        names.sort();
        names
    };
    assert_eq!(images("2x1x1"), ["board-0-0-0.bin", "board-1-0-0.bin"]);
    assert_eq!(images("1x1x1"), ["board-0-0-0.bin"]);
}

/// A generated box too large for this machine's memory is refused before any allocation,
/// naming the key and the memory (250^3 cells passed the former cell-count check and
/// aborted allocating 34 GB).
#[test]
fn a_box_larger_than_memory_is_refused_before_allocation() {
    let d = temp_dir("huge");
    let avail = host_tools::scene::mesh_source::available_memory_bytes();
    // A box of twice the available memory (or of the fixed limit where memory is unknown).
    let budget = avail.unwrap_or(
        host_tools::scene::mesh_source::MAX_GENERATED_CELLS
            * host_tools::scene::mesh_source::BYTES_PER_CELL,
    );
    let side = (2.0 * budget / host_tools::scene::mesh_source::BYTES_PER_CELL)
        .cbrt()
        .ceil() as usize;
    let scene = box_scene(&d, [side; 3], 1);
    refused(
        &["solve", scene.to_str().unwrap()],
        &["[mesh] generate", "GB of memory"],
    );
}

/// `BYTES_PER_CELL`, the estimate the memory check relies on, bounds the peak resident
/// memory of a `pe solve` run of 80 000 cells in the dearest configuration (full
/// integration, f64) from above, and is not more than 4x the peak of the cheapest (reduced
/// integration). The peak counts the process's fixed part too (binary, buffers).
/// Re-measured at every test run: a change that makes cells dearer fails here.
#[test]
fn the_memory_estimate_bounds_a_runs_peak() {
    let d = temp_dir("memory");
    let cells = [50, 40, 40];
    let n = (cells[0] * cells[1] * cells[2]) as f64;
    let estimate = host_tools::scene::mesh_source::BYTES_PER_CELL;
    let mut per_cell = Vec::new();
    for integration in ["reduced", "full"] {
        let scene = box_scene(&d, cells, 2);
        let text = std::fs::read_to_string(&scene).unwrap();
        std::fs::write(&scene, format!("{text}integration = \"{integration}\"\n")).unwrap();
        // Waited for by wait4 below, which also returns the child's peak memory.
        #[allow(clippy::zombie_processes)]
        let child = Command::new(PE)
            .args([
                "solve",
                scene.to_str().unwrap(),
                "--quiet",
                "--threads",
                "1",
            ])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let pid = child.id() as libc::pid_t;
        let mut status = 0;
        // SAFETY: rusage is plain data; wait4 fills it for this child, which nothing else
        // waits on.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        let got = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
        assert_eq!(got, pid, "waited for the run");
        assert!(
            libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0,
            "the {integration} run failed: {status}"
        );
        let b = usage.ru_maxrss as f64 * 1024.0 / n;
        println!(
            "{integration}: peak {} kB, {b:.0} bytes per cell (estimate {estimate:.0})",
            usage.ru_maxrss
        );
        per_cell.push(b);
    }
    assert!(
        per_cell[1] <= estimate && per_cell[0] >= estimate / 4.0,
        "{per_cell:.0?} bytes per cell measured (reduced, full), {estimate:.0} estimated"
    );
}
