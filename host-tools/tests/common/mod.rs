//! Helpers shared by the solver tests.
#![allow(dead_code)]

use host_tools::problem::Problem;
use host_tools::scene::Scene;

mod scratch;
pub use scratch::TempDir;

/// A box scene with a neo-Hookean material, clamped at x = 0; `extra` is appended TOML
/// (more tables, e.g. [gravity] or [[load]]) and `solver` goes into [solver].
pub fn box_scene(
    size: [f64; 3],
    cells: [usize; 3],
    e: f64,
    nu: f64,
    solver: &str,
    extra: &str,
) -> Scene {
    let text = format!(
        r#"
[mesh]
generate = {{ kind = "box", size = [{}, {}, {}], cells = [{}, {}, {}] }}
[material]
law = "neo-hookean"
youngs_modulus = {e}
poisson_ratio = {nu}
density = 1000.0
[[fixed]]
box = [[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]
{extra}
[solver]
{solver}
"#,
        size[0], size[1], size[2], cells[0], cells[1], cells[2]
    );
    Scene::from_toml(&text).expect("test scene parses")
}

pub fn problem(scene: &Scene) -> Problem {
    Problem::from_scene(scene, std::path::Path::new(".")).expect("test scene resolves")
}

/// Node nearest to `p`.
pub fn node_near(p: &Problem, x: [f64; 3]) -> usize {
    (0..p.mesh.nodes.len())
        .min_by(|&a, &b| {
            let d = |n: usize| {
                (0..3)
                    .map(|i| (p.mesh.nodes[n][i] - x[i]).powi(2))
                    .sum::<f64>()
            };
            d(a).total_cmp(&d(b))
        })
        .expect("mesh has nodes")
}

/// A fresh, empty directory `<temp>/host-tools-<name>-<process>-<n>` (`n` counts this
/// process's directories, so parallel tests never share one).
pub fn temp_dir(name: &str) -> TempDir {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static N: AtomicUsize = AtomicUsize::new(0);
    TempDir::fresh(&format!(
        "host-tools-{name}-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ))
}
