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
