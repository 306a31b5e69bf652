//! Shared helpers for the system tests.
#![allow(clippy::needless_range_loop)]

use std::path::{Path, PathBuf};

use host_tools::compile::compile_to_dir;
use host_tools::compile::partition::Machine;
use host_tools::problem::Problem;
use host_tools::scene::builtin::builtin_scene;
use host_tools::scene::Scene;

/// `../shared/meshes` beside the checkout (tests read the organ meshes from there).
pub fn shared_meshes_dir() -> PathBuf {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/meshes");
    assert!(
        d.is_dir(),
        "the shared meshes are missing: expected {} beside the checkout",
        d.display()
    );
    d
}

pub fn scenes_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes")
}

/// A test's scratch directory (images, manifests, reports), removed when the test ends
/// unless it fails: host-tools' test helper, the one home of it.
#[path = "../../host-tools/tests/common/scratch.rs"]
mod scratch;
pub use scratch::TempDir;

/// A fresh temporary directory for one test.
pub fn temp_dir(name: &str) -> TempDir {
    TempDir::fresh(&format!("pe-systest-{}-{name}", std::process::id()))
}

/// The built-in scene at `level`, cut to `steps`.
pub fn builtin_problem(level: &str, steps: u64) -> Problem {
    let mut sc = builtin_scene(level).expect("builtin scene");
    sc.solver.steps = Some(steps);
    Problem::from_scene(&sc, Path::new(".")).expect("builtin problem")
}

/// A scene file from tests/scenes.
pub fn file_problem(name: &str) -> (Problem, String) {
    let p = scenes_dir().join(name);
    let sc = Scene::from_file(&p).expect("scene parses");
    let dir = p.parent().expect("dir").to_path_buf();
    (
        Problem::from_scene(&sc, &dir).expect("scene resolves"),
        p.display().to_string(),
    )
}

/// A scene of the repository's `scenes/` folder.
pub fn repo_scene(name: &str) -> Problem {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(name);
    let sc = Scene::from_file(&path).expect("scene parses");
    Problem::from_scene(&sc, path.parent().unwrap_or(Path::new("."))).expect("scene resolves")
}

/// Compiles `problem` for `machine` into a fresh directory. Machines of at most two boards
/// along each axis are compiled for the emulation profile (QEMU mps2-an500: the frames'
/// 1024 nodes a board, so the test scenes fit one or two boards); larger ones, whose middle
/// boards link five or six faces, for the PE board (512 nodes a board in its AXI SRAM,
/// six links). The profiles' own limits are tested in `capacity.rs` and `schedule.rs`.
pub fn compile(problem: &Problem, source: &str, machine: &str, name: &str) -> TempDir {
    let dir = temp_dir(name);
    let m = Machine::parse(machine).expect("machine");
    let profile = if m.dims().iter().all(|&d| d <= 2) {
        pe_firmware::profile::QEMU_MPS2_AN500
    } else {
        pe_firmware::profile::PE_BOARD
    };
    compile_to_dir(name, source, problem, m, &profile, &dir).expect("compiles");
    dir
}

pub use host_tools::compare::{max_abs, max_rel_diff};

/// Asserts that `a` and `b` are bit-identical and of the same length (the one home of that
/// check for the system tests: `host_tools::compare::bit_identical`).
pub fn assert_bit_identical(a: &[[f64; 3]], b: &[[f64; 3]], what: &str) {
    if let Err(e) = host_tools::compare::bit_identical(a, b) {
        panic!("{what}: {e}");
    }
}
