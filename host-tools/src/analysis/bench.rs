//! `pe bench`: host cost of one element-step (ns) for each precision and integration, and
//! the floating-point operation count of one element-step, counted with [`Counted`].

use std::cell::Cell;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};
use std::time::Instant;

use anyhow::{anyhow, Result};
use pe_firmware::image::{Integration, Precision};
use pe_firmware::physics::{HexElement, Real};

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
    fn ln(self) -> Self {
        bump(3);
        Counted(libm::log(self.0))
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

/// A box scene of about `elements` cells, clamped at x = 0, under gravity.
pub fn bench_scene(
    elements: usize,
    integration: Integration,
    precision: Precision,
) -> Result<Scene> {
    let n = ((elements as f64 / 4.0).cbrt()).round().max(1.0) as usize;
    let mut scene = builders::box_cantilever([0.1, 0.025, 0.025], [4 * n, n, n], 3.0e3, 0.45, true);
    scene.gravity = Some(builders::gravity_down());
    scene.solver.precision = precision;
    scene.solver.integration = integration;
    scene.solver.damping = 20.0;
    Ok(scene)
}

/// Flops of one element's internal-force evaluation (the element kernel of one step) at a
/// generic deformed state, per kernel ("parallelepiped" and "general" for reduced
/// integration, "full"), and of one node update. The general kernel is counted on a
/// distorted copy of the bench cell.
pub fn element_step_flops(
    integration: Integration,
) -> Result<(Vec<(&'static str, FlopCount)>, FlopCount)> {
    let scene = bench_scene(32, integration, Precision::F64)?;
    let p = Problem::from_scene(&scene, std::path::Path::new("."))?;
    let law = p.laws[0].cast::<Counted>();
    let modulus = p.laws[0].hourglass_modulus();
    let u: [[Counted; 3]; 8] = core::array::from_fn(|a| {
        core::array::from_fn(|i| Counted(1e-4 * ((a * 3 + i) as f64).sin()))
    });
    let mut x: [[f64; 3]; 8] = p.mesh.cells[0].map(|n| p.mesh.nodes[n as usize]);
    let cell = pe_firmware::physics::ReferenceHex::new(&x).map_err(|e| anyhow!("{e}"))?;
    x[6][0] += 0.1 * cell.characteristic_length;
    let distorted = pe_firmware::physics::ReferenceHex::new(&x).map_err(|e| anyhow!("{e}"))?;
    let (nodes, m, k) = (p.mesh.cells[0], 0, p.solver.hourglass);
    let mut out = Vec::new();
    take_flops();
    if integration == Integration::Full {
        let _ = cell.full::<Counted>(nodes, m).internal_forces(&law, &u);
        out.push(("full", take_flops()));
    } else {
        let _ = cell
            .parallelepiped::<Counted>(nodes, m, modulus, k)
            .internal_forces(&law, &u);
        out.push(("parallelepiped", take_flops()));
        let _ = distorted
            .reduced::<Counted>(nodes, m, modulus, k)
            .internal_forces(&law, &u);
        out.push(("general", take_flops()));
    }
    let cd = pe_firmware::physics::CentralDifference::<Counted>::new(1e-4, 20.0);
    let r = [Counted(1.0); 3];
    let _ = cd.advance(&r, &r, Counted(0.1), &r);
    Ok((out, take_flops()))
}

/// ns per element-step of a whole serial step (forces, assembly, update) for one config.
pub fn ns_per_element_step(
    elements: usize,
    steps: u64,
    integration: Integration,
    precision: Precision,
) -> Result<(usize, f64)> {
    let scene = bench_scene(elements, integration, precision)?;
    let p = Problem::from_scene(&scene, std::path::Path::new("."))?;
    let dt = p.time_step.dt_s;
    fn time<T: Real>(p: &Problem, dt: f64, steps: u64) -> Result<f64> {
        let mut m = Model::<T>::new(p, dt);
        for _ in 0..10 {
            m.advance()?;
        }
        let t = Instant::now();
        for _ in 0..steps {
            m.advance()?;
        }
        Ok(t.elapsed().as_secs_f64())
    }
    let secs = if precision == Precision::F32 {
        time::<f32>(&p, dt, steps)?
    } else {
        time::<f64>(&p, dt, steps)?
    };
    let n = p.mesh.cells.len();
    Ok((n, secs * 1e9 / (n as f64 * steps as f64)))
}

pub fn run_cli(elements: usize, steps: u64) -> Result<()> {
    println!("host cost of one element-step (whole serial step / elements), one thread:");
    println!(
        "{:<10} {:<6} {:>9} {:>14}",
        "integr.", "prec.", "elements", "ns/elem-step"
    );
    for integ in [Integration::Reduced, Integration::Full] {
        for prec in [Precision::F64, Precision::F32] {
            let (n, ns) = ns_per_element_step(elements, steps, integ, prec)?;
            println!("{integ:<10} {prec:<6} {n:>9} {ns:>14.1}");
        }
    }
    println!("\nfloating-point operations of one element's internal force (neo-Hookean):");
    for integ in [Integration::Reduced, Integration::Full] {
        let (kernels, node) = element_step_flops(integ)?;
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
