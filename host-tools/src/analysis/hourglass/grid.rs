//! The study's meshes and loads: structured grids mapped from the unit cube, consistent
//! traction loads, and a neo-Hookean problem on a mesh.

use std::collections::BTreeMap;

use anyhow::Result;
use pe_firmware::image::Integration;
use pe_firmware::physics::HourglassControl;

use crate::geom::{cross, norm};
use crate::mesh::grid::GridNumbering;
use crate::mesh::Mesh;
use crate::problem::Problem;
use crate::scene::Scene;

/// A structured hexahedral grid of `n[0] x n[1] x n[2]` cells, the image of the unit cube
/// under a map ([`GridNumbering`] with `i` slowest), so the stiffness band is narrow when
/// the first direction is the long one.
pub struct Grid {
    pub n: [usize; 3],
    pub mesh: Mesh,
}

impl Grid {
    /// Grid of `n` cells; node `(i, j, k)` sits at `map([i/n0, j/n1, k/n2], [i, j, k])`.
    /// The map must keep the orientation (positive Jacobians).
    pub fn new(n: [usize; 3], map: impl Fn([f64; 3], [usize; 3]) -> [f64; 3]) -> Grid {
        let [nx, ny, nz] = n;
        let mut mesh = Grid::numbering(n).mesh(|[i, j, k]| {
            let s = [
                i as f64 / nx as f64,
                j as f64 / ny as f64,
                k as f64 / nz as f64,
            ];
            map(s, [i, j, k])
        });
        mesh.source = format!("hourglass study grid {nx}x{ny}x{nz}");
        mesh.region_names.insert(1, "study".into());
        Grid { n, mesh }
    }

    /// Nodes and cells numbered with `i` slowest, `k` fastest.
    fn numbering(n: [usize; 3]) -> GridNumbering {
        GridNumbering {
            cells: n,
            order: [0, 1, 2],
        }
    }

    pub fn node(&self, i: usize, j: usize, k: usize) -> usize {
        Grid::numbering(self.n).node([i, j, k])
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
            let da = norm(cross(ta, tb));
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
    hourglass: HourglassControl,
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

/// Mean of component `c` of `u` over `nodes`.
pub fn mean(u: &[[f64; 3]], nodes: &[usize], c: usize) -> f64 {
    nodes.iter().map(|&a| u[a][c]).sum::<f64>() / nodes.len() as f64
}
