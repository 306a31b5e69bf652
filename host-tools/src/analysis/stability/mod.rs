//! The stability suite (`pe stability`, `host-tools/tests/solver/stability.rs`): the solver at the
//! extremes of material, deformation, mesh quality, time step and run length. Every case
//! states its expected outcome, measures, and checks each figure against a bound whose reason
//! is given beside it; the tests assert [`Case::passed`], the report prints the same checks.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use pe_firmware::physics::{PhysicsError, Real};

use crate::geom::norm;
use crate::mesh::Mesh;
use crate::problem::{NodeKind, Path1, Problem};
use crate::scene::{builders, Scene, SolverSpec};
use crate::solver::{self, Model};
use pe_firmware::image::Integration;

mod material;
mod mesh_quality;
mod time_step;

pub use material::*;
pub use mesh_quality::*;
pub use time_step::*;

/// One checked figure of a case.
#[derive(Clone, Debug)]
pub struct Check {
    pub what: String,
    pub value: String,
    pub bound: String,
    pub ok: bool,
}

/// A case: what is expected, what was measured, whether every check held.
#[derive(Clone, Debug)]
pub struct Case {
    pub name: String,
    pub expected: String,
    pub checks: Vec<Check>,
    pub notes: Vec<String>,
    pub seconds: f64,
}

impl Case {
    fn new(name: &str, expected: &str) -> Case {
        Case {
            name: name.into(),
            expected: expected.into(),
            checks: vec![],
            notes: vec![],
            seconds: 0.0,
        }
    }

    /// `value < limit` (NaN fails).
    fn lt(&mut self, what: &str, value: f64, limit: f64) {
        self.checks.push(Check {
            what: what.into(),
            value: format!("{value:.3e}"),
            bound: format!("< {limit:.1e}"),
            ok: value < limit,
        });
    }

    /// `value > limit` (NaN fails).
    fn gt(&mut self, what: &str, value: f64, limit: f64) {
        self.checks.push(Check {
            what: what.into(),
            value: format!("{value:.3e}"),
            bound: format!("> {limit:.1e}"),
            ok: value > limit,
        });
    }

    fn is(&mut self, what: &str, ok: bool, value: impl Into<String>) {
        self.checks.push(Check {
            what: what.into(),
            value: value.into(),
            bound: "holds".into(),
            ok,
        });
    }

    fn note(&mut self, s: impl Into<String>) {
        self.notes.push(s.into());
    }

    pub fn passed(&self) -> bool {
        !self.checks.is_empty() && self.checks.iter().all(|c| c.ok)
    }

    /// Panics with the whole case when a check failed (for the tests).
    pub fn assert_passed(&self) {
        println!("{}", self.markdown());
        assert!(self.passed(), "stability case failed:\n{}", self.markdown());
    }

    pub fn markdown(&self) -> String {
        let mut s = format!(
            "### {} — {} ({:.1} s)\n\nExpected: {}\n\n| check | measured | bound | |\n|---|---|---|---|\n",
            self.name,
            if self.passed() { "PASS" } else { "FAIL" },
            self.seconds,
            self.expected
        );
        for c in &self.checks {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} |",
                c.what.replace('|', "\\|"),
                c.value.replace('|', "/"),
                c.bound.replace('|', "\\|"),
                if c.ok { "ok" } else { "**FAILED**" }
            );
        }
        for n in &self.notes {
            let _ = writeln!(s, "\n{n}");
        }
        s
    }
}

// ---------------------------------------------------------------------------------------
// Helpers

/// A box scene clamped at x = 0 (unless `clamp` is false), neo-Hookean, ρ = 1000
/// ([`builders::box_cantilever`]), with the case's `[solver]` settings (`solver` changes
/// the defaults); gravity and loads are added with the builder methods of [`Scene`].
fn box_scene(
    size: [f64; 3],
    cells: [usize; 3],
    e: f64,
    nu: f64,
    clamp: bool,
    solver: impl FnOnce(&mut SolverSpec),
) -> Scene {
    builders::box_cantilever(size, cells, e, nu, clamp).with_solver(solver)
}

fn problem(scene: &Scene) -> Result<Problem> {
    Problem::from_scene(scene, Path::new("."))
}

/// Node nearest to `x`.
fn node_near(p: &Problem, x: [f64; 3]) -> usize {
    let d = |n: usize| norm(core::array::from_fn(|i| p.mesh.nodes[n][i] - x[i]));
    (0..p.mesh.nodes.len())
        .min_by(|&a, &b| d(a).total_cmp(&d(b)))
        .unwrap_or(0)
}

/// Every boundary node follows its own path `u(X, t)`, given at the times `times`.
fn prescribe_boundary(
    p: &mut Problem,
    times: &[f64],
    u: impl Fn([f64; 3], f64) -> [f64; 3],
) -> Result<()> {
    for n in p.mesh.boundary_nodes() {
        let x = p.mesh.nodes[n as usize];
        p.node_kind[n as usize] = NodeKind::Prescribed(p.paths.len() as u32);
        p.paths
            .push(Path1::linear(times.iter().map(|&t| (t, u(x, t))).collect()));
    }
    p.update_time_step()
}

/// Runs `steps` steps, sampling the energies every `every` steps from step `from` on:
/// (min total, max total, max stored). The stored energy is evaluated in f64 whatever the
/// model's precision: in f32 the strain energy of small strains cancels catastrophically
/// (W ~ ε² from terms ~ ε), which would measure the evaluation, not the trajectory.
fn energy_band<T: Real>(
    m: &mut Model<'_, T>,
    steps: u64,
    every: u64,
    from: u64,
) -> Result<(f64, f64, f64)> {
    let ev = crate::problem::elements::Elements::<f64>::build(m.problem);
    let (mut lo, mut hi, mut smax) = (f64::MAX, f64::MIN, 0.0f64);
    for k in 0..steps {
        m.advance()
            .map_err(|e| anyhow!("{}", solver::describe_step_error(m.problem, &e)))?;
        if k >= from && k % every == 0 {
            let up: Vec<[f64; 3]> = m.previous_displacements();
            let stored = ev
                .stored_energy(&m.problem.laws, &up)
                .map_err(|e| anyhow!("{e}"))?;
            let g = m.gravity_m_per_s2();
            let gravity: f64 = up
                .iter()
                .zip(&m.problem.mass)
                .map(|(u, mass)| -mass * (0..3).map(|i| g[i] * u[i]).sum::<f64>())
                .sum();
            let total = m.kinetic_energy + stored + gravity;
            lo = lo.min(total);
            hi = hi.max(total);
            smax = smax.max(stored);
        }
    }
    Ok((lo, hi, smax))
}

/// Advances until `probe(model)` changes by less than `tol` (relative) over 500 steps.
fn settle<T: Real>(
    m: &mut Model<'_, T>,
    max_steps: u64,
    tol: f64,
    probe: impl Fn(&Model<'_, T>) -> f64,
) -> Result<f64> {
    let mut last = f64::NAN;
    for k in 0..max_steps {
        m.advance()
            .map_err(|e| anyhow!("{}", solver::describe_step_error(m.problem, &e)))?;
        if k % 500 == 499 {
            let w = probe(m);
            if (w - last).abs() < tol * w.abs() {
                return Ok(w);
            }
            last = w;
        }
    }
    bail!("did not settle to {tol:e} in {max_steps} steps")
}

/// Shear modulus μ of material 0 (Pa).
fn mu(p: &Problem) -> f64 {
    p.laws[0].shear_modulus()
}

fn total_volume(p: &Problem) -> f64 {
    p.reference.iter().map(|r| r.volume()).sum()
}

fn timed(name: &str, f: impl FnOnce(&mut Case) -> Result<()>, expected: &str) -> Result<Case> {
    let t = Instant::now();
    let mut c = Case::new(name, expected);
    f(&mut c).with_context(|| format!("stability case {name}"))?;
    c.seconds = t.elapsed().as_secs_f64();
    Ok(c)
}

// ---------------------------------------------------------------------------------------
// Cases

/// A case to run: its name, whether it is slow (not in CI), and the function.
pub struct CaseFn {
    pub name: &'static str,
    pub slow: bool,
    pub run: fn() -> Result<Case>,
}

/// Every case, in report order.
pub fn cases() -> Vec<CaseFn> {
    let c = |name, slow, run| CaseFn { name, slow, run };
    vec![
        c("poisson_0.49", false, || poisson(0.49)),
        c("poisson_0.499", false, || poisson(0.499)),
        c("poisson_0.4999", false, || poisson(0.4999)),
        c("compression_50", false, compression_50),
        c("rigid_rotation", false, rigid_rotation),
        c("dt_0.5", false, || dt_fraction(0.5)),
        c("dt_0.9", false, || dt_fraction(0.9)),
        c("dt_0.99", false, || dt_fraction(0.99)),
        c("dt_1.01", false, || dt_fraction(1.01)),
        c("dt_1.1", false, || dt_fraction(1.1)),
        c("long_run_1e6", false, || long_run(1_000_000)),
        c("long_run_1e7", true, || long_run(10_000_000)),
        c("load_cycles_100", false, || load_cycles(100)),
        c("soft_stiff_1000", false, soft_stiff),
        c("distorted_aspect_10", false, distorted_aspect),
        c("distorted_skew", false, distorted_skew),
        c("sagging_cantilever_dt", false, sagging_cantilever),
        c("sudden_gravity_soft_cantilever", false, sudden_gravity),
        c("f32_statics", false, f32_statics),
        c("runtime_guards", false, guards),
    ]
}

/// `pe stability`: runs the cases (the slow ones with `long`), prints a summary, writes the
/// markdown report. Fails when a case fails.
pub fn run_cli(out: Option<&Path>, long: bool, only: Option<&str>) -> Result<()> {
    let mut report = String::from(
        "# Stability report\n\nEach case states its expected outcome; every check has its bound (reasons in `host-tools/src/analysis/stability/`).\n\n",
    );
    let mut summary = String::from("| case | result | time (s) |\n|---|---|---|\n");
    let mut body = String::new();
    let mut failed = Vec::new();
    for case in cases() {
        if only.is_some_and(|o| !case.name.contains(o)) {
            continue;
        }
        if case.slow && !long {
            let _ = writeln!(summary, "| {} | skipped (slow: --long) | |", case.name);
            continue;
        }
        eprintln!("running {} ...", case.name);
        let r = match (case.run)() {
            Ok(r) => r,
            Err(e) => {
                let mut r = Case::new(case.name, "runs");
                r.is("case ran", false, format!("{e:#}"));
                r
            }
        };
        eprintln!(
            "  {} in {:.1} s",
            if r.passed() { "PASS" } else { "FAIL" },
            r.seconds
        );
        if !r.passed() {
            failed.push(case.name);
        }
        let _ = writeln!(
            summary,
            "| {} | {} | {:.1} |",
            r.name,
            if r.passed() { "PASS" } else { "**FAIL**" },
            r.seconds
        );
        body.push_str(&r.markdown());
        body.push('\n');
    }
    report.push_str(&summary);
    report.push('\n');
    report.push_str(&body);
    println!("{summary}");
    if let Some(p) = out {
        if let Some(d) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
        }
        crate::output::file::write_atomic(p, &report)?;
        println!("report: {}", p.display());
    } else {
        println!("{body}");
    }
    if !failed.is_empty() {
        bail!("stability cases failed: {failed:?}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A check named with `|u|` stays one cell: every row of the table has the header's
    /// four columns (the report's rows once had six, read as a broken table).
    #[test]
    fn a_bar_in_a_check_name_keeps_the_table_whole() {
        let mut c = Case::new("case", "expected");
        c.lt("max |u| after unloading / peak", 1e-15, 1e-9);
        c.lt("plain", 1.0, 2.0);
        let md = c.markdown();
        let rows: Vec<&str> = md.lines().filter(|l| l.starts_with('|')).collect();
        assert_eq!(rows.len(), 4, "{md}");
        for row in rows {
            let cells = row.replace("\\|", "").matches('|').count() - 1;
            assert_eq!(cells, 4, "{row}");
        }
        assert!(md.contains("max \\|u\\| after unloading"), "{md}");
    }
}
