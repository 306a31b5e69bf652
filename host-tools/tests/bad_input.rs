//! Bad input as a user meets it at the command line: every case exits non-zero before any
//! work, with a message naming the item (file, option, key), prints its cause chain and no
//! backtrace, and leaves nothing half-written.

use std::path::PathBuf;
use std::process::{Command, Output};

const PE: &str = env!("CARGO_BIN_EXE_pe");

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pe-bad-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
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
    let _ = std::fs::remove_dir_all(&d);
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

/// A scene's `[solver]` keys: both `steps` and `duration`, a zero `output_interval` and a
/// negative `damping` are refused naming the key (the last said "hourglass and damping >=
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
    ] {
        std::fs::write(&p, scene(solver)).unwrap();
        refused(&["solve", p.to_str().unwrap()], needles);
    }
    let _ = std::fs::remove_dir_all(&d);
}
