//! The study's cases and the closed forms they are held to: MacNeal and Harder's
//! cantilever (Timoshenko and Euler-Bernoulli beams), Cook's membrane, a neo-Hookean block
//! under uniaxial compression.

use anyhow::Result;
use pe_firmware::image::Integration;
use pe_firmware::physics::HourglassControl;

use super::{mean, problem_on, traction_loads, Grid, Statics};

/// Shear correction of a rectangular section (Cowper): `κ = 10(1+ν)/(12+11ν)`.
pub fn cowper_rectangle(nu: f64) -> f64 {
    10.0 * (1.0 + nu) / (12.0 + 11.0 * nu)
}

/// Timoshenko tip deflection of a cantilever (length `l`, depth `h` in the load direction,
/// width `b`) under a tip shear `p`: `pl³/(3EI) + pl/(κGA)`.
pub fn timoshenko_tip_shear(p: f64, l: f64, h: f64, b: f64, e: f64, nu: f64) -> f64 {
    let i = b * h.powi(3) / 12.0;
    let g = e / (2.0 * (1.0 + nu));
    p * l.powi(3) / (3.0 * e * i) + p * l / (cowper_rectangle(nu) * g * b * h)
}

/// Euler-Bernoulli tip deflection under an end moment `m`: `ml²/(2EI)` (exact in beam
/// theory: pure bending has no shear).
pub fn tip_moment_deflection(m: f64, l: f64, h: f64, b: f64, e: f64) -> f64 {
    m * l * l / (2.0 * e * b * h.powi(3) / 12.0)
}

/// How MacNeal and Harder's straight cantilever's cells are shaped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cells {
    /// Rectangular boxes.
    Regular,
    /// Interfaces slanted at ±45° in the bending plane, alternately.
    Trapezoidal,
    /// Interfaces all slanted at 45° in the bending plane.
    Parallelogram,
}

impl Cells {
    pub fn name(self) -> &'static str {
        match self {
            Cells::Regular => "regular",
            Cells::Trapezoidal => "trapezoidal",
            Cells::Parallelogram => "parallelogram",
        }
    }
}

/// The tip load of a cantilever case.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TipLoad {
    /// Uniform shear traction in the bending direction (+y).
    Shear,
    /// Linear axial traction: a pure end moment bending towards +y.
    Moment,
}

/// A cantilever along x (length `l`), depth `h` in y (the bending direction), width `b`
/// in z, clamped at x = 0, with `n` cells; its mean tip deflection in y over the small-load
/// limit, and the beam-theory value. MacNeal and Harder: l = 6, h = 0.2, b = 0.1,
/// E = 1e7, ν = 0.3 ("in-plane shear": 0.1081).
#[derive(Clone, Copy, Debug)]
pub struct Cantilever {
    pub l: f64,
    pub h: f64,
    pub b: f64,
    pub e: f64,
    pub nu: f64,
    pub n: [usize; 3],
    pub cells: Cells,
    /// Slant of the distorted interfaces: x shifted by `slant · (y − h/2)` (1: 45°).
    pub slant: f64,
    pub load: TipLoad,
}

impl Cantilever {
    /// MacNeal-Harder's straight cantilever with `ny` cells through the depth (bending
    /// direction), `6 ny` along and `max(1, ny/2)` across (cells 1/ny x 0.2/ny x 0.1/nz).
    pub fn macneal_harder(ny: usize, cells: Cells, load: TipLoad) -> Cantilever {
        Cantilever {
            l: 6.0,
            h: 0.2,
            b: 0.1,
            e: 1e7,
            nu: 0.3,
            n: [6 * ny, ny, (ny / 2).max(1)],
            cells,
            slant: 1.0,
            load,
        }
    }

    pub fn grid(&self) -> Grid {
        let (l, h, b, nx) = (self.l, self.h, self.b, self.n[0]);
        let (cells, slant) = (self.cells, self.slant);
        Grid::new(self.n, move |s, [i, _, _]| {
            let y = s[1] * h;
            // 45° interfaces: x shifted by ±(y − h/2); the ends stay square.
            let shift = if i == 0 || i == nx {
                0.0
            } else {
                match cells {
                    Cells::Regular => 0.0,
                    Cells::Parallelogram => slant * (y - h / 2.0),
                    Cells::Trapezoidal => {
                        if i % 2 == 0 {
                            slant * (y - h / 2.0)
                        } else {
                            slant * (h / 2.0 - y)
                        }
                    }
                }
            };
            [s[0] * l + shift, y, s[2] * b]
        })
    }

    /// The beam-theory tip deflection for a unit load (shear 1 N, or moment 1 N m).
    pub fn reference(&self) -> f64 {
        match self.load {
            TipLoad::Shear => timoshenko_tip_shear(1.0, self.l, self.h, self.b, self.e, self.nu),
            TipLoad::Moment => tip_moment_deflection(1.0, self.l, self.h, self.b, self.e),
        }
    }

    /// Mean tip deflection (y) of the small-load static solution for a unit load.
    pub fn tip(&self, integration: Integration, hourglass: HourglassControl) -> Result<f64> {
        let g = self.grid();
        let nodes = g.mesh.nodes.clone();
        let p = problem_on(g.mesh.clone(), self.e, self.nu, integration, hourglass)?;
        let s = Statics::new(&p);
        let mut fixed = vec![[false; 3]; nodes.len()];
        for a in g.face_i(0) {
            fixed[a] = [true; 3];
        }
        let mut f = vec![[0.0; 3]; nodes.len()];
        let quads = g.face_i_quads(self.n[0]);
        let (h, b) = (self.h, self.b);
        match self.load {
            TipLoad::Shear => traction_loads(&nodes, &quads, |_| [0.0, 1.0 / (h * b), 0.0], &mut f),
            TipLoad::Moment => {
                let i = b * h.powi(3) / 12.0;
                traction_loads(
                    &nodes,
                    &quads,
                    |x| [-(x[1] - h / 2.0) / i, 0.0, 0.0],
                    &mut f,
                )
            }
        }
        let u = s.linear(&fixed, &f)?;
        Ok(mean(&u, &g.face_i(self.n[0]), 1))
    }
}

/// Cook's membrane: the tapered panel (0,0), (48,44), (48,60), (0,44), clamped at x = 0,
/// a total shear force 1 spread uniformly over the right edge, E = 1, ν = 1/3, extruded to
/// a thickness 1 with one cell through it and free faces (plane stress). Reference: the
/// top right corner's vertical displacement of the plane-stress problem, 25.18, computed
/// independently of this code (`docs/measurements/cook_q8.py`: 2D serendipity quadrilaterals,
/// 3x3 Gauss, 8..32 cells a side: 24.908, 25.065, 25.110, 25.132, extrapolated). The often
/// quoted 23.96 is not this problem's plane-stress value (nor plane strain's 22.6, which the
/// same script gives, matching CoFEA's 32.27 for E = 70, F = 100); see the study.
pub const COOK_REFERENCE: f64 = 25.18;

/// Cook's membrane on `m x m` cells: the top right corner's vertical displacement.
pub fn cook_tip(m: usize, integration: Integration, hourglass: HourglassControl) -> Result<f64> {
    let g = Grid::new([m, m, 1], |s, _| {
        let x = 48.0 * s[0];
        let (y0, y1) = (44.0 * s[0], 44.0 + 16.0 * s[0]);
        [x, y0 + s[1] * (y1 - y0), s[2]]
    });
    let nodes = g.mesh.nodes.clone();
    let p = problem_on(g.mesh.clone(), 1.0, 1.0 / 3.0, integration, hourglass)?;
    let s = Statics::new(&p);
    let mut fixed = vec![[false; 3]; nodes.len()];
    for a in g.face_i(0) {
        fixed[a] = [true; 3];
    }
    let mut f = vec![[0.0; 3]; nodes.len()];
    traction_loads(
        &nodes,
        &g.face_i_quads(m),
        |_| [0.0, 1.0 / 16.0, 0.0],
        &mut f,
    );
    let u = s.linear(&fixed, &f)?;
    let corner = [g.node(m, m, 0), g.node(m, m, 1)];
    Ok(mean(&u, &corner, 1))
}

/// Uniaxial stress of the compressible neo-Hookean law `P = μF + (λ ln J − μ) F⁻ᵀ`
/// (`σ = μ/J (b − I) + λ ln J / J I`) at axial stretch `l`: the lateral stretch `t` (lateral
/// stress zero, by bisection) and the nominal axial stress `P₁₁ = σ₁₁ t²` (force per
/// reference area).
pub fn neo_hookean_uniaxial(e: f64, nu: f64, l: f64) -> (f64, f64) {
    let mu = e / (2.0 * (1.0 + nu));
    let lam = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let sigma = |t: f64, lk: f64| {
        let j = l * t * t;
        mu / j * (lk * lk - 1.0) + lam * j.ln() / j
    };
    let (mut lo, mut hi) = (0.5, 2.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        // Lateral stress increases with t.
        if sigma(mid, mid) > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let t = 0.5 * (lo + hi);
    (t, sigma(t, l) * t * t)
}

/// A unit cube of `n³` cells with its interior nodes moved (a fixed pseudo-random pattern,
/// up to 0.3 of a cell), compressed to stretch `l` between frictionless faces (each of the
/// faces x = 0, y = 0, z = 0 held in its normal direction, the top moved down, the other
/// faces free): the lateral stretch (mean over the face x = 1) and the nominal stress
/// (the top face's reaction over the reference area).
pub fn block_compression(
    n: usize,
    e: f64,
    nu: f64,
    l: f64,
    hourglass: HourglassControl,
) -> Result<(f64, f64)> {
    let g = Grid::new([n, n, n], |s, [i, j, k]| {
        let interior = [i, j, k].iter().all(|&c| c > 0 && c < n);
        if !interior {
            return s;
        }
        let h = 0.3 / n as f64;
        let r = |m: usize| (((i * 7 + j * 13 + k * 29 + m * 5) as f64) * 0.618_034).fract() - 0.5;
        [s[0] + h * r(0), s[1] + h * r(1), s[2] + h * r(2)]
    });
    let nodes = g.mesh.nodes.clone();
    let p = problem_on(g.mesh.clone(), e, nu, Integration::Reduced, hourglass)?;
    let s = Statics::new(&p);
    let mut fixed = vec![[false; 3]; nodes.len()];
    let mut target = vec![[0.0; 3]; nodes.len()];
    let top: Vec<usize> = (0..nodes.len())
        .filter(|&a| nodes[a][2] > 1.0 - 1e-9)
        .collect();
    for (a, x) in nodes.iter().enumerate() {
        for i in 0..3 {
            if x[i].abs() < 1e-9 {
                fixed[a][i] = true;
            }
        }
    }
    for &a in &top {
        fixed[a][2] = true;
        target[a][2] = l - 1.0;
    }
    let u = s.newton(&fixed, &target, 8, 1e-10)?;
    let f = s.forces(&u)?;
    let reaction: f64 = top.iter().map(|&a| f[a][2]).sum();
    let side = g.face_i(n);
    let t = 1.0 + mean(&u, &side, 0);
    Ok((t, reaction))
}
