//! A cube cut into Kuhn tetrahedra: the patch the tetrahedron's tests and its cost
//! measurement share (allocation-free: the caller owns the arrays).
//!
//! `n³` cells of side `h` on the `(n+1)³` grid (node `i + (n+1)(j + (n+1)k)`), each cell
//! cut into the six tetrahedra around its diagonal from corner `000` to `111`, one per order
//! of the three axes (conforming: neighbouring cells cut a shared face along the same
//! diagonal), each listed with a positive volume. Inner nodes may be moved by a fixed
//! fraction of `h` (`jitter`), so the tetrahedra are not all alike.

use super::super::super::vec3;

/// Nodes of an `n`-cell cube: `(n+1)³`.
pub const fn node_count(n: usize) -> usize {
    (n + 1) * (n + 1) * (n + 1)
}

/// Tetrahedra of an `n`-cell cube: `6n³`.
pub const fn tet_count(n: usize) -> usize {
    6 * n * n * n
}

/// The six paths from corner `000` to `111` along the cube's edges: one tetrahedron each.
const PATHS: [[usize; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];

/// Writes the nodes of an `n`-cell cube of side `n h` into `x` (the first
/// [`node_count`]`(n)`; `x` shorter: nothing written, `None`), inner nodes moved by
/// `jitter · (0.31, −0.23, 0.17) h`. Returns the count written.
pub fn nodes(n: usize, h: f64, jitter: f64, x: &mut [[f64; 3]]) -> Option<usize> {
    let count = node_count(n);
    let x = x.get_mut(..count)?;
    let mut out = x.iter_mut();
    for k in 0..=n {
        for j in 0..=n {
            for i in 0..=n {
                let inner = [i, j, k].iter().all(|&c| c > 0 && c < n);
                let wiggle = |s: f64| if inner { jitter * s * h } else { 0.0 };
                if let Some(p) = out.next() {
                    *p = [
                        i as f64 * h + wiggle(0.31),
                        j as f64 * h + wiggle(-0.23),
                        k as f64 * h + wiggle(0.17),
                    ];
                }
            }
        }
    }
    Some(count)
}

/// Writes the `6n³` tetrahedra of an `n`-cell cube whose nodes are `x` (from [`nodes`])
/// into `tets`, each turned so that its volume is positive (`tets` shorter than
/// [`tet_count`]`(n)` or `x` shorter than [`node_count`]`(n)`: `None`). Returns the count.
pub fn tetrahedra(n: usize, x: &[[f64; 3]], tets: &mut [[u32; 4]]) -> Option<usize> {
    let count = tet_count(n);
    let tets = tets.get_mut(..count)?;
    x.get(..node_count(n))?;
    let id = |c: [usize; 3]| (c[0] + (n + 1) * (c[1] + (n + 1) * c[2])) as u32;
    let mut out = tets.iter_mut();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                for p in PATHS {
                    let mut c = [i, j, k];
                    let mut t = [id(c); 4];
                    for (s, &axis) in p.iter().enumerate() {
                        c[axis] += 1;
                        t[s + 1] = id(c);
                    }
                    let xs = t.map(|a| x[a as usize]);
                    let e = [1, 2, 3].map(|a| vec3::sub(xs[a], xs[0]));
                    if vec3::dot(e[0], vec3::cross(e[1], e[2])) < 0.0 {
                        t.swap(1, 2);
                    }
                    if let Some(slot) = out.next() {
                        *slot = t;
                    }
                }
            }
        }
    }
    Some(count)
}
