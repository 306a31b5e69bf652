//! The static equilibrium of a problem's elements: the tangent stiffness by central
//! differences of the internal forces (a distance-2 colouring probes many nodes at once),
//! a banded Cholesky factorisation over the nodes in reverse Cuthill-McKee order (Gmsh
//! numbers a tetrahedral mesh's nodes by entity, which leaves the band the whole matrix),
//! linear and Newton solutions. A node's force depends on the nodes of its cells, and with
//! the tetrahedra's averaged nodal pressure on those of its neighbours' cells too (two
//! rings): the colouring and the band follow what the forces depend on.

use anyhow::{anyhow, bail, Result};
use pe_firmware::physics::real::nan_max;
use pe_firmware::physics::{MaterialLaw, TetPressure};

use crate::problem::elements::Elements;
use crate::problem::Problem;

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
    /// The nodes whose displacements each node's force depends on (itself included): the
    /// nodes of its cells, or two rings of them with nodal-pressure tetrahedra.
    neighbours: Vec<Vec<usize>>,
    /// Each node's place in the band (reverse Cuthill-McKee).
    order: Vec<usize>,
    colour: Vec<usize>,
    colours: usize,
    /// Half-bandwidth in dofs.
    w: usize,
}

impl<'p> Statics<'p> {
    pub fn new(problem: &'p Problem) -> Statics<'p> {
        let elements = Elements::build(problem);
        let two_rings = !elements.tets.is_empty() && elements.tets.form == TetPressure::Nodal;
        let neighbours = dependencies(&problem.mesh.cells, problem.mesh.nodes.len(), two_rings);
        let n = neighbours.len();
        let order = reverse_cuthill_mckee(&neighbours);
        let mut w = 0;
        for (a, around) in neighbours.iter().enumerate() {
            for &b in around {
                w = w.max(3 * order[a].abs_diff(order[b]) + 2);
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
            elements,
            laws: problem.laws.clone(),
            neighbours,
            order,
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
            .map(|r| r.characteristic_length())
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
                    let col = 3 * self.order[a] + i;
                    for j in 0..3 {
                        let row = 3 * self.order[b] + j;
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
                    let d = 3 * self.order[a] + i;
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
        let mut b = vec![0.0; 3 * n];
        for a in 0..n {
            for i in 0..3 {
                if !fixed[a][i] {
                    b[3 * self.order[a] + i] = f[a][i];
                }
            }
        }
        k.solve(&mut b);
        Ok((0..n)
            .map(|a| core::array::from_fn(|i| b[3 * self.order[a] + i]))
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
                // `nan_max`: a NaN force is never dropped (`f64::max` would drop it and
                // let a NaN state pass for converged).
                let fmax = f.iter().flatten().fold(0.0f64, |m, v| nan_max(m, v.abs()));
                let mut r = vec![0.0; 3 * n];
                let mut rmax = 0.0f64;
                for a in 0..n {
                    for i in 0..3 {
                        if !fixed[a][i] {
                            r[3 * self.order[a] + i] = -f[a][i];
                            rmax = nan_max(rmax, f[a][i].abs());
                        }
                    }
                }
                if rmax.is_nan() || fmax.is_nan() {
                    bail!("Newton at load step {s}/{steps}, iteration {it}: the forces are NaN");
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
                        u[a][i] += r[3 * self.order[a] + i];
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

/// For each of `n` nodes, the nodes sharing a cell with it (itself included), sorted; with
/// `two_rings`, also the nodes sharing a cell with those.
fn dependencies(cells: &[[u32; 8]], n: usize, two_rings: bool) -> Vec<Vec<usize>> {
    let mut ring: Vec<Vec<usize>> = (0..n).map(|a| vec![a]).collect();
    for c in cells {
        for &a in c {
            ring[a as usize].extend(c.iter().map(|&b| b as usize));
        }
    }
    for r in &mut ring {
        r.sort_unstable();
        r.dedup();
    }
    if !two_rings {
        return ring;
    }
    (0..n)
        .map(|a| {
            let mut v: Vec<usize> = ring[a]
                .iter()
                .flat_map(|&b| ring[b].iter().copied())
                .collect();
            v.sort_unstable();
            v.dedup();
            v
        })
        .collect()
}

/// Each node's position in the reverse Cuthill-McKee order of the graph `adjacent` (each
/// component from a node of least degree, neighbours in increasing degree): a narrow band.
fn reverse_cuthill_mckee(adjacent: &[Vec<usize>]) -> Vec<usize> {
    let n = adjacent.len();
    let degree = |a: usize| adjacent[a].len();
    let mut visited = vec![false; n];
    let mut sequence = Vec::with_capacity(n);
    let mut by_degree: Vec<usize> = (0..n).collect();
    by_degree.sort_by_key(|&a| (degree(a), a));
    for &start in &by_degree {
        if visited[start] {
            continue;
        }
        visited[start] = true;
        let mut head = sequence.len();
        sequence.push(start);
        while head < sequence.len() {
            let a = sequence[head];
            head += 1;
            let mut next: Vec<usize> = adjacent[a]
                .iter()
                .copied()
                .filter(|&b| !visited[b])
                .collect();
            next.sort_by_key(|&b| (degree(b), b));
            for b in next {
                visited[b] = true;
                sequence.push(b);
            }
        }
    }
    let mut order = vec![0; n];
    for (place, &a) in sequence.iter().rev().enumerate() {
        order[a] = place;
    }
    order
}
