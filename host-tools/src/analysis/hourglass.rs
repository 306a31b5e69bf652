//! Calibration of the hourglass coefficient (`[solver] hourglass`) against references that
//! do not depend on it: beam theory for MacNeal and Harder's straight cantilever (regular,
//! trapezoidal and parallelogram cells), the converged value of Cook's membrane, and the
//! closed form of a neo-Hookean block under homogeneous compression.
//!
//! The static solutions are those of the solver's own discrete problem: the tangent
//! stiffness is assembled from the elements' internal forces (the same kernels `pe solve`
//! runs) by central differences, probing all nodes of one colour of a distance-2 colouring
//! at once, and solved with a banded Cholesky factorisation (Newton iterations for the
//! large-strain block). The linear cases are the small-load limit of the solver's static
//! equilibrium, the state a damped explicit run settles to; `tests/solver/hourglass.rs` checks
//! one against a damped explicit run.
//!
//! `pe hourglass-study` prints the study's tables (`docs/measurements/hourglass-calibration.md`).

use std::collections::BTreeMap;

use anyhow::{anyhow, bail, Result};
use pe_firmware::image::Integration;
use pe_firmware::physics::MaterialLaw;

use crate::mesh::Mesh;
use crate::problem::elements::Elements;
use crate::problem::Problem;
use crate::scene::Scene;

/// The coefficients the study sweeps.
pub const COEFFICIENTS: [f64; 7] = [0.01, 0.03, 0.05, 0.1, 0.2, 0.3, 0.5];

/// A structured hexahedral grid of `n[0] x n[1] x n[2]` cells, the image of the unit cube
/// under a map. Nodes are numbered with `i` slowest, so the stiffness band is narrow when the
/// first direction is the long one.
pub struct Grid {
    pub n: [usize; 3],
    pub mesh: Mesh,
}

impl Grid {
    /// Grid of `n` cells; node `(i, j, k)` sits at `map([i/n0, j/n1, k/n2], [i, j, k])`.
    /// The map must keep the orientation (positive Jacobians).
    pub fn new(n: [usize; 3], map: impl Fn([f64; 3], [usize; 3]) -> [f64; 3]) -> Grid {
        let [nx, ny, nz] = n;
        let mut mesh = Mesh {
            source: format!("hourglass study grid {nx}x{ny}x{nz}"),
            ..Mesh::default()
        };
        for i in 0..=nx {
            for j in 0..=ny {
                for k in 0..=nz {
                    let s = [
                        i as f64 / nx as f64,
                        j as f64 / ny as f64,
                        k as f64 / nz as f64,
                    ];
                    mesh.nodes.push(map(s, [i, j, k]));
                }
            }
        }
        mesh.node_tags = (1..=mesh.nodes.len() as u64).collect();
        let g = Grid { n, mesh };
        let mut cells = Vec::with_capacity(nx * ny * nz);
        for i in 0..nx {
            for j in 0..ny {
                for k in 0..nz {
                    let a = |di: usize, dj: usize, dk: usize| g.node(i + di, j + dj, k + dk) as u32;
                    cells.push([
                        a(0, 0, 0),
                        a(1, 0, 0),
                        a(1, 1, 0),
                        a(0, 1, 0),
                        a(0, 0, 1),
                        a(1, 0, 1),
                        a(1, 1, 1),
                        a(0, 1, 1),
                    ]);
                }
            }
        }
        let mut g = g;
        g.mesh.cell_regions = vec![1; cells.len()];
        g.mesh.cells = cells;
        g.mesh.region_names.insert(1, "study".into());
        g
    }

    pub fn node(&self, i: usize, j: usize, k: usize) -> usize {
        let [_, ny, nz] = self.n;
        k + (nz + 1) * (j + (ny + 1) * i)
    }

    /// Nodes of the face `i = i0`.
    pub fn face_i(&self, i0: usize) -> Vec<usize> {
        let [_, ny, nz] = self.n;
        (0..=ny)
            .flat_map(|j| (0..=nz).map(move |k| (j, k)))
            .map(|(j, k)| self.node(i0, j, k))
            .collect()
    }

    /// Quadrilaterals of the face `i = i0` (corner nodes in order around the face).
    pub fn face_i_quads(&self, i0: usize) -> Vec<[usize; 4]> {
        let [_, ny, nz] = self.n;
        let mut q = Vec::new();
        for j in 0..ny {
            for k in 0..nz {
                q.push([
                    self.node(i0, j, k),
                    self.node(i0, j + 1, k),
                    self.node(i0, j + 1, k + 1),
                    self.node(i0, j, k + 1),
                ]);
            }
        }
        q
    }
}

/// Consistent nodal forces of a traction `t(x)` (force per area) on quadrilateral faces
/// (bilinear, 2x2 Gauss points), added into `f`.
pub fn traction_loads(
    nodes: &[[f64; 3]],
    quads: &[[usize; 4]],
    t: impl Fn([f64; 3]) -> [f64; 3],
    f: &mut [[f64; 3]],
) {
    let g = 1.0 / 3f64.sqrt();
    for q in quads {
        let x: [[f64; 3]; 4] = q.map(|n| nodes[n]);
        for (a, b) in [(-g, -g), (g, -g), (g, g), (-g, g)] {
            let n = [
                (1.0 - a) * (1.0 - b) / 4.0,
                (1.0 + a) * (1.0 - b) / 4.0,
                (1.0 + a) * (1.0 + b) / 4.0,
                (1.0 - a) * (1.0 + b) / 4.0,
            ];
            let dna = [
                -(1.0 - b) / 4.0,
                (1.0 - b) / 4.0,
                (1.0 + b) / 4.0,
                -(1.0 + b) / 4.0,
            ];
            let dnb = [
                -(1.0 - a) / 4.0,
                -(1.0 + a) / 4.0,
                (1.0 + a) / 4.0,
                (1.0 - a) / 4.0,
            ];
            let mut p = [0.0; 3];
            let (mut ta, mut tb) = ([0.0; 3], [0.0; 3]);
            for c in 0..4 {
                for i in 0..3 {
                    p[i] += n[c] * x[c][i];
                    ta[i] += dna[c] * x[c][i];
                    tb[i] += dnb[c] * x[c][i];
                }
            }
            let cr = [
                ta[1] * tb[2] - ta[2] * tb[1],
                ta[2] * tb[0] - ta[0] * tb[2],
                ta[0] * tb[1] - ta[1] * tb[0],
            ];
            let da = (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt();
            let tr = t(p);
            for c in 0..4 {
                for i in 0..3 {
                    f[q[c]][i] += n[c] * tr[i] * da;
                }
            }
        }
    }
}

/// A neo-Hookean problem on `mesh` (E in Pa, ν) with the given integration and hourglass
/// coefficient; no constraints or loads (the static solver takes its own).
pub fn problem_on(
    mesh: Mesh,
    e: f64,
    nu: f64,
    integration: Integration,
    hourglass: f64,
) -> Result<Problem> {
    let text = format!(
        "[mesh]\ngenerate = {{ kind = \"box\", size = [1.0, 1.0, 1.0], cells = [1, 1, 1] }}\n\
         [material]\nlaw = \"neo-hookean\"\nyoungs_modulus = {e:e}\npoisson_ratio = {nu}\n\
         density = 1000.0\n[solver]\nduration = 1.0\n"
    );
    let mut scene = Scene::from_toml(&text)?;
    scene.solver.hourglass = hourglass;
    scene.solver.integration = integration;
    Problem::new(&scene, mesh, BTreeMap::new())
}

/// A symmetric positive definite band matrix (lower band stored), factorised in place.
struct Band {
    n: usize,
    w: usize,
    a: Vec<f64>,
}

impl Band {
    fn new(n: usize, w: usize) -> Band {
        Band {
            n,
            w,
            a: vec![0.0; n * (w + 1)],
        }
    }
    fn at(&mut self, r: usize, c: usize) -> &mut f64 {
        &mut self.a[r * (self.w + 1) + (r - c)]
    }
    fn get(&self, r: usize, c: usize) -> f64 {
        if r < c || r - c > self.w {
            0.0
        } else {
            self.a[r * (self.w + 1) + (r - c)]
        }
    }
    /// Cholesky `A = L Lᵀ`, `L` over `A`.
    fn factorise(&mut self) -> Result<()> {
        let (n, w) = (self.n, self.w);
        for j in 0..n {
            let lo = j.saturating_sub(w);
            let mut d = self.get(j, j);
            for k in lo..j {
                let l = self.get(j, k);
                d -= l * l;
            }
            if !(d > 0.0) {
                bail!("stiffness not positive definite at dof {j} (pivot {d:e})");
            }
            let d = d.sqrt();
            *self.at(j, j) = d;
            for i in j + 1..(j + w + 1).min(n) {
                let lo = i.saturating_sub(w);
                let mut s = self.get(i, j);
                for k in lo..j {
                    s -= self.get(i, k) * self.get(j, k);
                }
                *self.at(i, j) = s / d;
            }
        }
        Ok(())
    }
    /// Solves `L Lᵀ x = b` in place.
    fn solve(&self, b: &mut [f64]) {
        let (n, w) = (self.n, self.w);
        for i in 0..n {
            let mut s = b[i];
            for k in i.saturating_sub(w)..i {
                s -= self.get(i, k) * b[k];
            }
            b[i] = s / self.get(i, i);
        }
        for i in (0..n).rev() {
            let mut s = b[i];
            for k in i + 1..(i + w + 1).min(n) {
                s -= self.get(k, i) * b[k];
            }
            b[i] = s / self.get(i, i);
        }
    }
}

/// Static equilibrium of a problem's elements, with constraints per component.
pub struct Statics<'p> {
    problem: &'p Problem,
    elements: Elements<f64>,
    laws: Vec<MaterialLaw<f64>>,
    /// Nodes sharing a cell with each node (itself included).
    neighbours: Vec<Vec<usize>>,
    colour: Vec<usize>,
    colours: usize,
    /// Half-bandwidth in dofs.
    w: usize,
}

impl<'p> Statics<'p> {
    pub fn new(problem: &'p Problem) -> Statics<'p> {
        let n = problem.mesh.nodes.len();
        let mut neighbours: Vec<Vec<usize>> = (0..n).map(|a| vec![a]).collect();
        let mut w = 0;
        for c in &problem.mesh.cells {
            for &a in c {
                for &b in c {
                    let (a, b) = (a as usize, b as usize);
                    if !neighbours[a].contains(&b) {
                        neighbours[a].push(b);
                    }
                    w = w.max(3 * a.abs_diff(b) + 2);
                }
            }
        }
        // Distance-2 colouring: two nodes of one colour share no neighbour, so a probe of
        // every node of a colour leaves each node's force changed by one probed node only.
        let mut colour = vec![usize::MAX; n];
        let mut colours = 0;
        let mut used = Vec::new();
        for a in 0..n {
            used.clear();
            for &b in &neighbours[a] {
                for &c in &neighbours[b] {
                    if colour[c] != usize::MAX {
                        used.push(colour[c]);
                    }
                }
            }
            let c = (0..).find(|c| !used.contains(c)).unwrap_or(0);
            colour[a] = c;
            colours = colours.max(c + 1);
        }
        Statics {
            problem,
            elements: Elements::build(problem),
            laws: problem.laws.clone(),
            neighbours,
            colour,
            colours,
            w,
        }
    }

    /// Internal forces at `u`.
    pub fn forces(&self, u: &[[f64; 3]]) -> Result<Vec<[f64; 3]>> {
        let mut f = vec![[0.0; 3]; u.len()];
        self.elements
            .internal_forces(&self.laws, u, &mut f)
            .map_err(|e| anyhow!("{e}"))?;
        Ok(f)
    }

    /// Tangent stiffness at `u` by central differences of the internal forces, with the
    /// constrained dofs replaced by identity rows and columns.
    fn tangent(&self, u: &[[f64; 3]], fixed: &[[bool; 3]]) -> Result<Band> {
        let n = u.len();
        let scale = self
            .problem
            .reference
            .iter()
            .map(|r| r.characteristic_length)
            .fold(f64::INFINITY, f64::min);
        let eps = 1e-6 * scale;
        let mut k = Band::new(3 * n, self.w);
        for c in 0..self.colours {
            for i in 0..3 {
                let probe = |s: f64| -> Result<Vec<[f64; 3]>> {
                    let mut up = u.to_vec();
                    for (a, x) in up.iter_mut().enumerate() {
                        if self.colour[a] == c {
                            x[i] += s * eps;
                        }
                    }
                    self.forces(&up)
                };
                let (fp, fm) = (probe(1.0)?, probe(-1.0)?);
                for b in 0..n {
                    let Some(&a) = self.neighbours[b].iter().find(|&&a| self.colour[a] == c) else {
                        continue;
                    };
                    let col = 3 * a + i;
                    for j in 0..3 {
                        let row = 3 * b + j;
                        if row >= col {
                            let kv = (fp[b][j] - fm[b][j]) / (2.0 * eps);
                            // Symmetrise: half from each triangle.
                            *k.at(row, col) += 0.5 * kv;
                            if row == col {
                                *k.at(row, col) += 0.5 * kv;
                            }
                        } else {
                            let kv = (fp[b][j] - fm[b][j]) / (2.0 * eps);
                            *k.at(col, row) += 0.5 * kv;
                        }
                    }
                }
            }
        }
        for (a, fx) in fixed.iter().enumerate() {
            for i in 0..3 {
                if fx[i] {
                    let d = 3 * a + i;
                    for c in d.saturating_sub(self.w)..d {
                        *k.at(d, c) = 0.0;
                    }
                    for r in d + 1..(d + self.w + 1).min(3 * n) {
                        *k.at(r, d) = 0.0;
                    }
                    *k.at(d, d) = 1.0;
                }
            }
        }
        Ok(k)
    }

    /// Small-load static solution `K u = f` about the rest state, `u = 0` on `fixed`.
    pub fn linear(&self, fixed: &[[bool; 3]], f: &[[f64; 3]]) -> Result<Vec<[f64; 3]>> {
        let n = f.len();
        let u0 = vec![[0.0; 3]; n];
        let mut k = self.tangent(&u0, fixed)?;
        k.factorise()?;
        let mut b: Vec<f64> = (0..3 * n)
            .map(|d| {
                if fixed[d / 3][d % 3] {
                    0.0
                } else {
                    f[d / 3][d % 3]
                }
            })
            .collect();
        k.solve(&mut b);
        Ok((0..n)
            .map(|a| [b[3 * a], b[3 * a + 1], b[3 * a + 2]])
            .collect())
    }

    /// Large-strain static solution: the constrained dofs moved to `target` in `steps`
    /// equal increments, Newton iterations at each until the free residual is below `tol`
    /// of the largest internal force. No external load. The first iteration of a step uses
    /// the tangent of the last converged state (the jump of the constrained dofs alone can
    /// leave the elements next to them in a state whose tangent is indefinite); an
    /// iteration whose tangent is indefinite falls back to the last positive definite one.
    pub fn newton(
        &self,
        fixed: &[[bool; 3]],
        target: &[[f64; 3]],
        steps: usize,
        tol: f64,
    ) -> Result<Vec<[f64; 3]>> {
        let n = target.len();
        let mut u = vec![[0.0; 3]; n];
        let mut good = self.tangent(&u, fixed)?;
        good.factorise()?;
        for s in 1..=steps {
            let frac = s as f64 / steps as f64;
            for a in 0..n {
                for i in 0..3 {
                    if fixed[a][i] {
                        u[a][i] = frac * target[a][i];
                    }
                }
            }
            let mut converged = false;
            for it in 0..100 {
                let f = self.forces(&u)?;
                let fmax = f.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
                let mut r = vec![0.0; 3 * n];
                let mut rmax = 0.0f64;
                for a in 0..n {
                    for i in 0..3 {
                        if !fixed[a][i] {
                            r[3 * a + i] = -f[a][i];
                            rmax = rmax.max(f[a][i].abs());
                        }
                    }
                }
                if rmax <= tol * fmax {
                    converged = true;
                    break;
                }
                if it > 0 {
                    let mut k = self.tangent(&u, fixed)?;
                    if k.factorise().is_ok() {
                        good = k;
                    }
                }
                good.solve(&mut r);
                for a in 0..n {
                    for i in 0..3 {
                        u[a][i] += r[3 * a + i];
                    }
                }
            }
            if !converged {
                bail!("Newton did not converge at load step {s}/{steps}");
            }
            let mut k = self.tangent(&u, fixed)?;
            k.factorise()
                .map_err(|e| anyhow!("equilibrium at load step {s}/{steps} is unstable: {e}"))?;
            good = k;
        }
        Ok(u)
    }
}

/// Mean of component `c` of `u` over `nodes`.
pub fn mean(u: &[[f64; 3]], nodes: &[usize], c: usize) -> f64 {
    nodes.iter().map(|&a| u[a][c]).sum::<f64>() / nodes.len() as f64
}

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
    pub fn tip(&self, integration: Integration, hourglass: f64) -> Result<f64> {
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
pub fn cook_tip(m: usize, integration: Integration, hourglass: f64) -> Result<f64> {
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
pub fn block_compression(n: usize, e: f64, nu: f64, l: f64, hourglass: f64) -> Result<(f64, f64)> {
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

/// One row of a table: a case's name, its reference and its result at each coefficient
/// (and with full integration, which has no hourglass control).
pub struct Row {
    pub name: String,
    pub reference: f64,
    pub reduced: Vec<f64>,
    pub full: f64,
}

fn pct(v: f64, r: f64) -> String {
    format!("{:+.2}", 100.0 * (v / r - 1.0))
}

/// Markdown table of rows: error in % of the reference per coefficient.
pub fn table(title: &str, rows: &[Row], coefficients: &[f64]) -> String {
    let mut s = format!("#### {title}\n\n| case | reference |");
    for c in coefficients {
        s += &format!(" {c} |");
    }
    s += " full |\n|---|---|";
    for _ in coefficients {
        s += "---|";
    }
    s += "---|\n";
    for r in rows {
        s += &format!("| {} | {:.5e} |", r.name, r.reference);
        for v in &r.reduced {
            s += &format!(" {} |", pct(*v, r.reference));
        }
        s += &format!(" {} |\n", pct(r.full, r.reference));
    }
    s
}

fn sweep(
    coefficients: &[f64],
    name: String,
    reference: f64,
    run: impl Fn(Integration, f64) -> Result<f64>,
) -> Result<Row> {
    let reduced = coefficients
        .iter()
        .map(|&c| run(Integration::Reduced, c))
        .collect::<Result<Vec<_>>>()?;
    let full = run(Integration::Full, 0.0)?;
    eprintln!("  {name}: done");
    Ok(Row {
        name,
        reference,
        reduced,
        full,
    })
}

/// The whole study as markdown: error (%) of each case at each coefficient.
pub fn study(coefficients: &[f64]) -> Result<String> {
    let mut out = String::new();
    // (a) MacNeal-Harder cantilever.
    for load in [TipLoad::Shear, TipLoad::Moment] {
        let mut rows = Vec::new();
        for cells in [Cells::Regular, Cells::Trapezoidal, Cells::Parallelogram] {
            let depths: &[usize] = if cells == Cells::Regular {
                &[1, 2, 4, 8]
            } else {
                &[1, 2, 4]
            };
            for &ny in depths {
                let c = Cantilever::macneal_harder(ny, cells, load);
                let name = format!("{} {}x{}x{}", cells.name(), c.n[0], c.n[1], c.n[2]);
                rows.push(sweep(coefficients, name, c.reference(), |i, h| {
                    c.tip(i, h)
                })?);
            }
        }
        // Cubic cells (aspect 1) through the same depth; distorted: interfaces slanted at
        // 11° (45° would fold cubes against the square ends).
        for (cells, slant, depths) in [
            (Cells::Regular, 0.0, &[2usize, 4, 8][..]),
            (Cells::Parallelogram, 0.2, &[4][..]),
            (Cells::Trapezoidal, 0.2, &[4][..]),
        ] {
            for &ny in depths {
                let mut c = Cantilever::macneal_harder(ny, cells, load);
                c.n = [30 * ny, ny, (ny / 2).max(1)];
                c.slant = slant;
                let name = format!(
                    "{} cubes{} {}x{}x{}",
                    cells.name(),
                    if slant > 0.0 && slant < 1.0 {
                        " (±11°)"
                    } else {
                        ""
                    },
                    c.n[0],
                    c.n[1],
                    c.n[2]
                );
                rows.push(sweep(coefficients, name, c.reference(), |i, h| {
                    c.tip(i, h)
                })?);
            }
        }
        let title = match load {
            TipLoad::Shear => "MacNeal-Harder cantilever, tip shear (Timoshenko; MH's 0.1081)",
            TipLoad::Moment => "MacNeal-Harder cantilever, end moment (ML²/2EI)",
        };
        out += &table(title, &rows, coefficients);
        out += "\n";
    }
    // Soft slender cantilevers (L/h = 10, square section, cubic cells), ν = 0.3 and 0.49.
    let mut rows = Vec::new();
    for nu in [0.3, 0.49] {
        for n in [2, 4] {
            let c = Cantilever {
                l: 0.1,
                h: 0.01,
                b: 0.01,
                e: 5e3,
                nu,
                n: [10 * n, n, n],
                cells: Cells::Regular,
                slant: 0.0,
                load: TipLoad::Shear,
            };
            let name = format!("L/h=10 nu={nu} {}x{}x{}", c.n[0], c.n[1], c.n[2]);
            rows.push(sweep(coefficients, name, c.reference(), |i, h| {
                c.tip(i, h)
            })?);
        }
    }
    out += &table(
        "Square cantilever L/h = 10, E = 5 kPa, tip shear (Timoshenko, Cowper's κ)",
        &rows,
        coefficients,
    );
    out += "\n";
    // (b) Cook's membrane.
    let mut rows = Vec::new();
    for m in [2, 4, 8, 16, 32, 48] {
        rows.push(sweep(
            coefficients,
            format!("{m}x{m}x1"),
            COOK_REFERENCE,
            |i, h| cook_tip(m, i, h),
        )?);
    }
    out += &table(
        "Cook's membrane, top-right vertical displacement (plane stress, converged 25.18)",
        &rows,
        coefficients,
    );
    out += "\n";
    // (c) Block compression.
    let (e, nu, l) = (3000.0, 0.45, 0.8);
    let (t_ref, p_ref) = neo_hookean_uniaxial(e, nu, l);
    let mut rows_t = Vec::new();
    let mut rows_p = Vec::new();
    let mut ts = Vec::new();
    let mut ps = Vec::new();
    for &c in coefficients {
        let (t, p) = block_compression(4, e, nu, l, c)?;
        ts.push(t);
        ps.push(p);
    }
    rows_t.push(Row {
        name: "4x4x4 distorted, lateral stretch".into(),
        reference: t_ref,
        reduced: ts,
        full: f64::NAN,
    });
    rows_p.push(Row {
        name: "4x4x4 distorted, nominal stress (Pa)".into(),
        reference: p_ref,
        reduced: ps,
        full: f64::NAN,
    });
    rows_t.extend(rows_p);
    out += &table(
        "Block, 20% compression between frictionless faces (neo-Hookean E = 3 kPa, ν = 0.45)",
        &rows_t,
        coefficients,
    );
    Ok(out)
}
