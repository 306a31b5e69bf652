//! Interpolation of the reference configuration's displacement field at another mesh's
//! nodes: the reference cell holding a point, found by inverting the trilinear cell map.

use super::*;

/// Trilinear interpolation of a nodal field of `mesh` at arbitrary points.
pub struct Interpolator<'m> {
    mesh: &'m Mesh,
    lo: [f64; 3],
    h: [f64; 3],
    n: [usize; 3],
    bins: Vec<Vec<u32>>,
}

impl<'m> Interpolator<'m> {
    pub fn new(mesh: &'m Mesh) -> Self {
        let (lo, hi) = mesh.bounding_box();
        let k = ((mesh.cells.len() as f64).cbrt().ceil() as usize).max(1);
        let n = [k; 3];
        let h: [f64; 3] = core::array::from_fn(|i| ((hi[i] - lo[i]) / k as f64).max(1e-300));
        let mut bins = vec![Vec::new(); k * k * k];
        for c in 0..mesh.cells.len() {
            let x = mesh.cell_coords(c);
            let (mut a, mut b) = ([f64::MAX; 3], [f64::MIN; 3]);
            for p in &x {
                for i in 0..3 {
                    a[i] = a[i].min(p[i]);
                    b[i] = b[i].max(p[i]);
                }
            }
            // Pad by a quarter of the cell so nodes just outside still find it.
            let pad: [f64; 3] = core::array::from_fn(|i| 0.25 * (b[i] - a[i]));
            let r =
                |v: f64, i: usize| (((v - lo[i]) / h[i]).floor().max(0.0) as usize).min(n[i] - 1);
            for ix in r(a[0] - pad[0], 0)..=r(b[0] + pad[0], 0) {
                for iy in r(a[1] - pad[1], 1)..=r(b[1] + pad[1], 1) {
                    for iz in r(a[2] - pad[2], 2)..=r(b[2] + pad[2], 2) {
                        bins[ix + n[0] * (iy + n[1] * iz)].push(c as u32);
                    }
                }
            }
        }
        Interpolator {
            mesh,
            lo,
            h,
            n,
            bins,
        }
    }

    /// Natural coordinates of `p` in cell `c` (Newton on the trilinear map).
    fn natural(&self, c: usize, p: [f64; 3]) -> [f64; 3] {
        let x = self.mesh.cell_coords(c);
        let mut xi = [0.0; 3];
        for _ in 0..20 {
            let n = shape(xi);
            let g = pe_firmware::physics::element::hex::natural_gradients(xi);
            let mut r = [0.0; 3];
            let mut j = [[0.0; 3]; 3];
            for a in 0..8 {
                for i in 0..3 {
                    r[i] += n[a] * x[a][i];
                    for k in 0..3 {
                        j[i][k] += x[a][i] * g[a][k];
                    }
                }
            }
            let d: [f64; 3] = core::array::from_fn(|i| p[i] - r[i]);
            let Some(s) = solve3(j, d) else { break };
            for i in 0..3 {
                xi[i] += s[i];
            }
            if s.iter().map(|v| v.abs()).fold(0.0, f64::max) < 1e-12 {
                break;
            }
        }
        xi
    }

    /// The field `u` at `p`, or `None` when `p` lies more than a quarter cell outside the
    /// mesh (natural coordinate beyond ±1.5; inside that, the coordinates are clamped).
    pub fn at(&self, u: &[[f64; 3]], p: [f64; 3]) -> Option<[f64; 3]> {
        let b: [usize; 3] = core::array::from_fn(|i| {
            (((p[i] - self.lo[i]) / self.h[i]).floor().max(0.0) as usize).min(self.n[i] - 1)
        });
        let mut best: Option<(f64, usize, [f64; 3])> = None;
        for &c in &self.bins[b[0] + self.n[0] * (b[1] + self.n[1] * b[2])] {
            let xi = self.natural(c as usize, p);
            let out = xi.iter().map(|v| v.abs()).fold(0.0, f64::max);
            if !out.is_finite() {
                continue;
            }
            if best.is_none_or(|(o, _, _)| out < o) {
                best = Some((out, c as usize, xi));
            }
            if out <= 1.0 + 1e-9 {
                break;
            }
        }
        let (out, c, xi) = best?;
        if out > 1.5 {
            return None;
        }
        let n = shape(xi.map(|v| v.clamp(-1.0, 1.0)));
        let cell = self.mesh.cells[c];
        Some(core::array::from_fn(|i| {
            (0..8).map(|a| n[a] * u[cell[a] as usize][i]).sum()
        }))
    }
}

fn shape(xi: [f64; 3]) -> [f64; 8] {
    core::array::from_fn(|a| {
        let q = pe_firmware::physics::element::hex::NODE_XI[a];
        0.125 * (1.0 + q[0] * xi[0]) * (1.0 + q[1] * xi[1]) * (1.0 + q[2] * xi[2])
    })
}

fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    if !(det.abs() > 0.0) {
        return None;
    }
    let col = |k: usize| {
        let mut m = a;
        for i in 0..3 {
            m[i][k] = b[i];
        }
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    Some([col(0) / det, col(1) / det, col(2) / det])
}
