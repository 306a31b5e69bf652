//! `pe bench`: host cost of one element-step (ns) for each precision and integration, and
//! the floating-point operation count of one element-step, counted with [`Counted`].

use std::cell::Cell;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};
use std::time::Instant;

use anyhow::{anyhow, Result};
use pe_firmware::image::{Integration, Precision};
use pe_firmware::physics::{Element, HexBox, HexCuboid, HexElement, HexReduced, Real};

use crate::problem::Problem;
use crate::scene::{builders, Scene};
use crate::solver::Model;

thread_local! {
    static FLOPS: Cell<[u64; 4]> = const { Cell::new([0; 4]) };
}

/// Operation classes counted: add/sub/neg, mul, div, sqrt/ln/cbrt.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FlopCount {
    pub add: u64,
    pub mul: u64,
    pub div: u64,
    pub special: u64,
}

impl FlopCount {
    pub fn total(&self) -> u64 {
        self.add + self.mul + self.div + self.special
    }
}

fn bump(k: usize) {
    FLOPS.with(|c| {
        let mut v = c.get();
        v[k] += 1;
        c.set(v);
    });
}

/// Resets and returns the counters of this thread.
pub fn take_flops() -> FlopCount {
    FLOPS.with(|c| {
        let v = c.replace([0; 4]);
        FlopCount {
            add: v[0],
            mul: v[1],
            div: v[2],
            special: v[3],
        }
    })
}

/// An `f64` that counts every arithmetic operation done on it.
#[derive(Clone, Copy, Debug, Default, PartialEq, PartialOrd)]
pub struct Counted(pub f64);

macro_rules! op {
    ($tr:ident, $f:ident, $k:expr, $op:tt) => {
        impl $tr for Counted {
            type Output = Counted;
            fn $f(self, o: Counted) -> Counted {
                bump($k);
                Counted(self.0 $op o.0)
            }
        }
    };
}
op!(Add, add, 0, +);
op!(Sub, sub, 0, -);
op!(Mul, mul, 1, *);
op!(Div, div, 2, /);
impl Neg for Counted {
    type Output = Counted;
    fn neg(self) -> Counted {
        Counted(-self.0)
    }
}
impl AddAssign for Counted {
    fn add_assign(&mut self, o: Counted) {
        *self = *self + o;
    }
}
impl SubAssign for Counted {
    fn sub_assign(&mut self, o: Counted) {
        *self = *self - o;
    }
}
impl MulAssign for Counted {
    fn mul_assign(&mut self, o: Counted) {
        *self = *self * o;
    }
}
impl Real for Counted {
    const ZERO: Self = Counted(0.0);
    const ONE: Self = Counted(1.0);
    const NAME: &'static str = "counted-f64";
    fn from_f64(x: f64) -> Self {
        Counted(x)
    }
    fn to_f64(self) -> f64 {
        self.0
    }
    fn sqrt(self) -> Self {
        bump(3);
        Counted(libm::sqrt(self.0))
    }
    /// As `f64`'s: the series near 1 (its operations counted), `libm` elsewhere.
    fn ln(self) -> Self {
        use pe_firmware::physics::real::{ln_near_one, LN_SERIES_RADIUS, LN_SERIES_TERMS_F64};
        let d = self - Counted(1.0);
        if d.0.abs() <= LN_SERIES_RADIUS {
            ln_near_one(d, LN_SERIES_TERMS_F64)
        } else {
            bump(3);
            Counted(libm::log(self.0))
        }
    }
    fn cbrt(self) -> Self {
        bump(3);
        Counted(libm::cbrt(self.0))
    }
    fn abs(self) -> Self {
        Counted(self.0.abs())
    }
    fn is_finite(self) -> bool {
        self.0.is_finite()
    }
}

/// The seed's case scaled to about `elements` cells: a 20 x 10 x 10 cm block of soft tissue
/// (3 kPa, ν = 0.45) in `2n x n x n` cells, clamped at x = 0, sagging under gravity with
/// damping, at the seed's step of 100 us. It stays stable however long it runs (it settles;
/// 30 000 steps of the 2000-cell block were run), so a timing can take as many steps as it needs.
pub fn bench_scene(
    elements: usize,
    integration: Integration,
    precision: Precision,
) -> Result<Scene> {
    let n = ((elements as f64 / 2.0).cbrt()).round().max(1.0) as usize;
    let mut scene = builders::box_cantilever([0.2, 0.1, 0.1], [2 * n, n, n], 3.0e3, 0.45, true);
    scene.gravity = Some(builders::gravity_down());
    scene.solver.precision = precision;
    scene.solver.integration = integration;
    scene.solver.damping = 20.0;
    // The seed's step (10 kHz), well below the critical one at rest (2.6 ms for 2000
    // cells), which the sag shrinks.
    scene.solver.dt = Some(1.0e-4);
    Ok(scene)
}

/// Flops of one element's internal-force evaluation (the element kernel of one step) at a
/// generic deformed state, per kernel ("cuboid", "parallelepiped" and "general" for
/// reduced integration, "full"), and of one node update. The bench cell is a cuboid; the
/// parallelepiped kernel is counted on a copy turned by 30° about z, the general one on a
/// distorted copy.
pub fn element_step_flops(
    integration: Integration,
) -> Result<(Vec<(&'static str, FlopCount)>, FlopCount)> {
    let scene = bench_scene(32, integration, Precision::F64)?;
    let p = Problem::from_scene(&scene, std::path::Path::new("."))?;
    let law = p.laws[0].cast::<Counted>();
    let u: [[Counted; 3]; 8] = core::array::from_fn(|a| {
        core::array::from_fn(|i| Counted(1e-4 * ((a * 3 + i) as f64).sin()))
    });
    let mut x: [[f64; 3]; 8] = p.mesh.cells[0].map(|n| p.mesh.nodes[n as usize]);
    let cell = pe_firmware::physics::ReferenceHex::new(&x).map_err(|e| anyhow!("{e}"))?;
    let (s, c) = (0.5f64, 0.75f64.sqrt());
    let turned = x.map(|p| [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]);
    let turned = pe_firmware::physics::ReferenceHex::new(&turned).map_err(|e| anyhow!("{e}"))?;
    x[6][0] += 0.1 * cell.characteristic_length;
    let distorted = pe_firmware::physics::ReferenceHex::new(&x).map_err(|e| anyhow!("{e}"))?;
    let hourglass = pe_firmware::physics::Hourglass::of_law(&p.laws[0], p.solver.hourglass);
    let connectivity = pe_firmware::physics::Connectivity {
        nodes: p.mesh.cells[0],
        material: 0,
    };
    let (nodes, m) = (p.mesh.cells[0], 0);
    let mut out = Vec::new();
    take_flops();
    if integration == Integration::Full {
        let _ = cell.full::<Counted>(nodes, m).internal_forces(&law, &u);
        out.push(("full", take_flops()));
    } else {
        let _ = HexCuboid::<Counted>::from_reference(&cell, connectivity, hourglass)
            .internal_forces(&law, &u);
        out.push(("cuboid", take_flops()));
        let _ = HexBox::<Counted>::from_reference(&turned, connectivity, hourglass)
            .internal_forces(&law, &u);
        out.push(("parallelepiped", take_flops()));
        let _ = HexReduced::<Counted>::from_reference(&distorted, connectivity, hourglass)
            .internal_forces(&law, &u);
        out.push(("general", take_flops()));
    }
    let cd = pe_firmware::physics::CentralDifference::<Counted>::new(1e-4, 20.0);
    let r = [Counted(1.0); 3];
    let _ = cd.advance(&r, &r, Counted(0.1), &r);
    Ok((out, take_flops()))
}

/// One configuration's timing: ns per element-step of whole steps (forces, assembly,
/// update), median, least and most over the runs.
#[derive(Clone, Copy, Debug)]
pub struct Timing {
    pub elements: usize,
    pub nodes: usize,
    pub threads: usize,
    pub steps_per_run: u64,
    pub ns_median: f64,
    pub ns_min: f64,
    pub ns_max: f64,
}

/// Times whole steps of the bench scene: `runs` runs, each from rest (20 steps to warm
/// up) for at least `seconds`.
pub fn time_steps(
    elements: usize,
    integration: Integration,
    precision: Precision,
    threads: usize,
    seconds: f64,
    runs: usize,
) -> Result<Timing> {
    let scene = bench_scene(elements, integration, precision)?;
    let p = Problem::from_scene(&scene, std::path::Path::new("."))?;
    let timed = timed_runs(&p, threads, seconds, runs)?;
    let ns = timed.iter().map(|r| r.ns_per_element_step(&p)).collect();
    let steps_per_run = timed.last().map_or(0, |r| r.steps);
    Ok(Timing::of(&p, threads, steps_per_run, ns))
}

/// One timed run of whole steps.
struct Run {
    steps: u64,
    wall_s: f64,
    /// Of it, in contact evaluations (s).
    contact_s: f64,
    /// Steps in which a tool touched the tissue.
    touching: u64,
}

impl Run {
    fn ns_per_element_step(&self, p: &Problem) -> f64 {
        self.wall_s * 1e9 / (p.mesh.cells.len() as f64 * self.steps as f64)
    }
}

/// `runs` runs of `p` in its precision on `threads` threads, each from rest: 20 steps to
/// warm up, then whole steps for at least `seconds` (a multiple of 16).
fn timed_runs(p: &Problem, threads: usize, seconds: f64, runs: usize) -> Result<Vec<Run>> {
    fn one<T: Real>(p: &Problem, threads: usize, seconds: f64) -> Result<Run> {
        let mut m = Model::<T>::new(p, p.time_step.dt_s);
        m.set_threads(threads)?;
        for _ in 0..20 {
            m.advance()?;
        }
        let contact_s = |m: &Model<T>| m.contact.as_ref().map_or(0.0, |c| c.evaluate_s);
        let c0 = contact_s(&m);
        let t = Instant::now();
        let (mut steps, mut touching) = (0u64, 0u64);
        loop {
            for _ in 0..16 {
                m.advance()?;
                touching += u64::from(m.contact.as_ref().is_some_and(|c| c.stats.active > 0));
            }
            steps += 16;
            let wall_s = t.elapsed().as_secs_f64();
            if wall_s >= seconds {
                let contact_s = contact_s(&m) - c0;
                return Ok(Run {
                    steps,
                    wall_s,
                    contact_s,
                    touching,
                });
            }
        }
    }
    (0..runs.max(1))
        .map(|_| match p.solver.precision {
            Precision::F32 => one::<f32>(p, threads, seconds),
            Precision::F64 => one::<f64>(p, threads, seconds),
        })
        .collect()
}

impl Timing {
    /// The figures of `ns` (one ns per element-step per run, at least one) on `p`'s mesh.
    fn of(p: &Problem, threads: usize, steps_per_run: u64, mut ns: Vec<f64>) -> Timing {
        ns.sort_by(f64::total_cmp);
        Timing {
            elements: p.mesh.cells.len(),
            nodes: p.mesh.nodes.len(),
            threads,
            steps_per_run,
            ns_median: ns[ns.len() / 2],
            ns_min: ns[0],
            ns_max: ns[ns.len() - 1],
        }
    }

    /// The columns both of `pe bench`'s tables start with (heads: [`columns_head`]).
    fn columns(&self, integration: Integration, precision: Precision) -> String {
        format!(
            "{:<8} {:<5} {:>8} {:>7} {:>12.1} {:>17} {:>10}",
            integration.to_string(),
            precision.to_string(),
            self.elements,
            self.threads,
            self.ns_median,
            format!("({:.1} .. {:.1})", self.ns_min, self.ns_max),
            self.steps_per_run,
        )
    }
}

/// The heads of [`Timing::columns`].
fn columns_head() -> String {
    format!(
        "{:<8} {:<5} {:>8} {:>7} {:>12} {:>17} {:>10}",
        "integr.", "prec.", "elements", "threads", "ns/elem-step", "(min .. max)", "steps/run"
    )
}

/// The built-in anatomy's timing: whole steps from rest, the general kernel (every cell of
/// the anatomy is general) and contact included.
#[derive(Clone, Copy, Debug)]
pub struct AnatomyTiming {
    pub steps: Timing,
    /// Contact evaluation (check, search, forces) per step, µs: median over the runs.
    pub contact_us_per_step: f64,
    /// Steps of the last run in which the probe touched the tissue, of `steps_per_run`.
    pub steps_in_contact: u64,
}

/// Times whole steps of the built-in scene at `level` in its own precision and
/// integration: `runs` runs from rest, each 20 steps then at least `seconds` (the probe's
/// path starts on its way to the tube, so the first second holds few contacts at the
/// medium level).
pub fn time_anatomy(
    level: &str,
    threads: usize,
    seconds: f64,
    runs: usize,
) -> Result<AnatomyTiming> {
    let scene = crate::scene::builtin::builtin_scene(level)?;
    let p = Problem::from_scene(&scene, std::path::Path::new("."))?;
    let timed = timed_runs(&p, threads, seconds, runs)?;
    let ns = timed.iter().map(|r| r.ns_per_element_step(&p)).collect();
    let mut contact_us: Vec<f64> = timed
        .iter()
        .map(|r| r.contact_s * 1e6 / r.steps as f64)
        .collect();
    let (steps_per_run, touching) = timed.last().map_or((0, 0), |r| (r.steps, r.touching));
    contact_us.sort_by(f64::total_cmp);
    Ok(AnatomyTiming {
        steps: Timing::of(&p, threads, steps_per_run, ns),
        contact_us_per_step: contact_us[contact_us.len() / 2],
        steps_in_contact: touching,
    })
}

/// The built-in medium scene's rows: the general kernel the anatomy uses, and contact (in
/// the scene's precision and integration, which the filters must allow).
fn anatomy_rows(thread_counts: &[usize], seconds: f64, runs: usize, only: Only) -> Result<()> {
    let scene = crate::scene::builtin::builtin_scene("medium")?;
    let (prec, integ) = (scene.solver.precision, scene.solver.integration);
    if only.precision.is_some_and(|p| p != prec) || only.integration.is_some_and(|i| i != integ) {
        return Ok(());
    }
    println!("\nthe built-in medium scene (anatomy: every cell on the general kernel; the probe's contact), whole steps from rest, median of {runs} runs of >= {seconds} s:");
    println!(
        "{} {:>16} {:>11}",
        columns_head(),
        "contact us/step",
        "touching"
    );
    for &threads in thread_counts {
        let a = time_anatomy("medium", threads, seconds, runs)?;
        println!(
            "{} {:>16.1} {:>11}",
            a.steps.columns(integ, prec),
            a.contact_us_per_step,
            format!("{} steps", a.steps_in_contact)
        );
    }
    Ok(())
}

/// Times whole steps of the bench box ([`bench_scene`] with about `elements / 6` cells)
/// split into about `elements` tetrahedra ([`crate::mesh::grid::split_into_tetrahedra`]),
/// in `form` and `precision`.
pub fn time_tetrahedra(
    elements: usize,
    form: pe_firmware::physics::TetPressure,
    precision: Precision,
    threads: usize,
    seconds: f64,
    runs: usize,
) -> Result<Timing> {
    let mut scene = bench_scene(elements.div_ceil(6), Integration::Reduced, precision)?;
    scene.solver.tetrahedron = form;
    let (mesh, sets) = crate::scene::mesh_source::load(&scene.mesh, std::path::Path::new("."))?;
    let p = Problem::new(
        &scene,
        crate::mesh::grid::split_into_tetrahedra(&mesh),
        sets,
    )?;
    let timed = timed_runs(&p, threads, seconds, runs)?;
    let ns = timed.iter().map(|r| r.ns_per_element_step(&p)).collect();
    let steps_per_run = timed.last().map_or(0, |r| r.steps);
    Ok(Timing::of(&p, threads, steps_per_run, ns))
}

/// The tetrahedra's rows: the bench box split into about `elements` tetrahedra, both forms,
/// whole steps (the tetrahedra run scalar, on one thread, after the hexahedra).
fn tetrahedra_rows(
    elements: usize,
    thread_counts: &[usize],
    seconds: f64,
    runs: usize,
    only: Only,
) -> Result<()> {
    if only.integration.is_some_and(|i| i != Integration::Reduced) {
        return Ok(());
    }
    println!("
the seed's box split into tetrahedra (six per cell), whole steps from rest, median of {runs} runs of >= {seconds} s (ns per tetrahedron-step):");
    println!("{:<16} {}", "form", columns_head());
    for form in [
        pe_firmware::physics::TetPressure::Nodal,
        pe_firmware::physics::TetPressure::Element,
    ] {
        for prec in [Precision::F64, Precision::F32] {
            if only.precision.is_some_and(|p| p != prec) {
                continue;
            }
            for &threads in thread_counts {
                let t = time_tetrahedra(elements, form, prec, threads, seconds, runs)?;
                println!(
                    "{:<16} {}",
                    form.name(),
                    t.columns(Integration::Reduced, prec)
                );
            }
        }
    }
    Ok(())
}

/// The CPU's clock (GHz) as the kernel reports it, if it does.
fn clock_ghz() -> Option<f64> {
    let info = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("cpu MHz"))?;
    line.split(':')
        .nth(1)?
        .trim()
        .parse::<f64>()
        .ok()
        .map(|m| m / 1e3)
}

/// The CPU's model name as the kernel reports it, if it does.
fn cpu_model() -> Option<String> {
    let info = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("model name"))?;
    Some(line.split_once(':')?.1.trim().to_string())
}

/// The configurations `pe bench` times: None times every one.
#[derive(Clone, Copy, Debug, Default)]
pub struct Only {
    pub precision: Option<Precision>,
    pub integration: Option<Integration>,
    pub threads: Option<usize>,
}

/// `pe bench`: the table of ns per element-step, reduced/full x f64/f32 x one thread/all
/// threads (or the ones `only` names), with the fraction of the machine's peak, and the flop
/// counts.
pub fn run_cli(elements: usize, seconds: f64, runs: usize, only: Only) -> Result<()> {
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    if only.threads == Some(0) {
        return Err(anyhow!("--threads 0: at least one thread is needed"));
    }
    let thread_counts = match only.threads {
        Some(n) => vec![n],
        None if all > 1 => vec![1, all],
        None => vec![1],
    };
    let ghz = clock_ghz();
    let isa = crate::problem::batched::Isa::detect();
    println!(
        "CPU: {}, {all} hardware thread(s); element loops: {isa:?} lanes{}",
        cpu_model().unwrap_or_else(|| "unknown model".into()),
        if std::env::var_os("PE_ISA").is_some() {
            " (capped by PE_ISA)"
        } else {
            ""
        }
    );
    println!(
        "host cost of one element-step (whole steps of the seed's box / elements), median of {runs} runs of >= {seconds} s each, {isa:?} lanes:"
    );
    println!("{} {:>9}", columns_head(), "% peak");
    let mut flops = Vec::new();
    for integ in [Integration::Reduced, Integration::Full] {
        let (kernels, node) = element_step_flops(integ)?;
        flops.push((integ, kernels, node));
    }
    for (integ, kernels, node) in &flops {
        if only.integration.is_some_and(|i| i != *integ) {
            continue;
        }
        // The bench scene is all cuboids (reduced) or all full elements: the first
        // kernel counted, plus a node update per node.
        let element = kernels.first().map_or(0, |k| k.1.total()) as f64;
        for prec in [Precision::F64, Precision::F32] {
            if only.precision.is_some_and(|p| p != prec) {
                continue;
            }
            for &threads in &thread_counts {
                let t = time_steps(elements, *integ, prec, threads, seconds, runs)?;
                let per_step =
                    element + t.nodes as f64 / t.elements.max(1) as f64 * node.total() as f64;
                // Peak: 2 FMA units x 256 bits per core per cycle (16 f64 or 32 f32 flops).
                let lanes = if prec == Precision::F32 { 32.0 } else { 16.0 };
                let peak = ghz.map(|g| {
                    let achieved = per_step / t.ns_median; // flops per ns
                    format!("{:.1}", 100.0 * achieved / (lanes * g * threads as f64))
                });
                println!(
                    "{} {:>9}",
                    t.columns(*integ, prec),
                    peak.unwrap_or_else(|| "?".into())
                );
            }
        }
    }
    anatomy_rows(&thread_counts, seconds, runs, only)?;
    tetrahedra_rows(elements, &thread_counts, seconds, runs, only)?;
    match ghz {
        Some(g) => println!(
            "% peak: flops per element-step (below) over {g:.2} GHz x 16 (f64) or 32 (f32) flops per cycle per thread (two 256-bit FMA units); the kernels use no FMA (the board's bits), so half of it is their ceiling"
        ),
        None => println!("% peak: the clock is unknown here"),
    }
    println!("\nfloating-point operations of one element's internal force (neo-Hookean):");
    for (integ, kernels, node) in flops {
        for (kind, e) in kernels {
            println!(
                "{integ:<8} {kind:<15} element: {} (add {}, mul {}, div {}, sqrt/ln/cbrt {}); node update: {}",
                e.total(),
                e.add,
                e.mul,
                e.div,
                e.special,
                node.total()
            );
        }
    }
    println!("seed's budget: ~700 flops per element-step (reduced integration)");
    Ok(())
}
