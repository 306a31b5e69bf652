//! A right ovary for the built-in anatomy: a separate solid body (not connected to the
//! uterus mesh) lying under the right fallopian tube at the probe site, so that the probe,
//! pushing the tube down (−z), presses it onto the ovary's curved top, where it slides.
//!
//! # Geometry
//!
//! An ellipsoid with semi-axes [`OVARY_SEMI_AXES_M`] = 15 × 9 × 6 mm: the long axis along
//! the tube's local axis at the probe site (made horizontal), the middle one horizontal
//! across the tube, the short one vertical. Its centre is directly below the probe's
//! contact point (the top of the tube), so its topmost point lies [`OVARY_GAP_M`] = 3 mm
//! below the bottom of the tube:
//! `centre = contact_point − (2·tube_radius + gap + c)·ẑ`.
//!
//! The tube's local axis is the principal direction (power iteration on the covariance)
//! of the right-oviduct nodes near the contact point: those within 8 mm, or within 16, 32,
//! … mm where the tube's node layers are farther apart than that (at the coarse and
//! medium levels the layer next to the contact point's is 22 mm and 9 mm away, and one
//! ring of nodes alone has no long axis). Its z component is dropped and the sign chosen
//! so that y > 0 (x > 0 if y = 0). For the built-in anatomy it is +y.
//!
//! # Mesh
//!
//! A structured hexahedral "cubed ball". Parameter points p of the cube [−1, 1]³ are mapped
//! to the unit ball by the standard cube-to-sphere map
//! `x' = x·√(1 − y²/2 − z²/2 + y²z²/3)` (and cyclically), then scaled by the semi-axes,
//! rotated and translated.
//!
//! * **Coarse:** the whole cube grid (4 × 4 × 2 cells) is mapped this way.
//! * **Medium and fine:** mapping the whole grid degrades the cells along the 12 cube edges
//!   and at the 8 corners (their corner nodes have all three edges in the curved surface),
//!   the more so the finer the grid. Measured minimum scaled Jacobians (corner / edge /
//!   face cells): 0.17 / 0.24 / 0.53 at 8 × 4 × 4 cells, 0.05 / 0.09 / 0.20 at
//!   16 × 10 × 8; so blending towards the cube near the corners alone would not do. These
//!   levels use an O-grid instead: a core cube grid, its nodes at
//!   `s·A·((1 − λ)·p + λ·ball(p))` (a rounded box, `s` = 0.4 or 0.5 of the semi-axes A,
//!   λ = 0.75), and `k` shell layers of cells between the core's surface and the
//!   ellipsoid, each core-surface node joined straight to its image on the ellipsoid. Every
//!   surface node has a radial edge, so the quality does not decay with refinement.
//!
//! | level | grid | cells | nodes | min scaled Jacobian | volume / ellipsoid |
//! |---|---|---|---|---|---|
//! | coarse | cube 4 × 4 × 2 | 32 | 75 | 0.31 | 0.875 |
//! | medium | core 4 × 4 × 4, 1 shell layer | 160 | 223 | 0.44 | 0.935 |
//! | fine | core 12 × 8 × 6, 2 shell layers | 1440 | 1687 | 0.38 | 0.982 |
//!
//! The cell counts are 10 %, 8 % and 7 % of the uterus's (319, 2032, 19928). The surface
//! nodes lie on the ellipsoid, so the faceted mesh is slightly smaller than it (the volume
//! column). All counts along the first two axes are even, so one surface node sits exactly
//! at the top pole: [`OvarySite::top_point`] is that node.
//!
//! The ovary's lower part (nodes below `centre.z − c/2`) is meant to be held fixed: the
//! ovary hangs from its ligaments and does not drop away when pressed from above.

use crate::geom::{add, cross, dot, lerp, norm, scale, sub, V3};
use crate::mesh::builtin::{Anatomy, Level, REGION_RIGHT_OVIDUCT};

/// Region (physical group) tag of the right ovary.
pub const REGION_RIGHT_OVARY: i32 = 6;
/// Region name of the right ovary.
const REGION_NAME: &str = "right_ovary";
/// Semi-axes (m) along the tube axis, across it (horizontal), and vertical.
pub const OVARY_SEMI_AXES_M: [f64; 3] = [0.015, 0.009, 0.006];
/// Gap (m) between the bottom of the tube and the top of the ovary at the probe site.
pub const OVARY_GAP_M: f64 = 0.003;

/// Where the ovary was placed and how it is held.
#[derive(Clone, Debug, PartialEq)]
pub struct OvarySite {
    pub centre: [f64; 3],
    /// Unit vector of the ovary's long axis (the tube's local axis at the probe site, made horizontal).
    pub axis: [f64; 3],
    /// Topmost point of the ovary surface (directly under the probe contact point).
    pub top_point: [f64; 3],
    /// Nodes (0-based, in the combined mesh) held fixed: the ovary's lower part (z below centre − 0.5·c), held by its ligaments; sorted.
    pub fixed_nodes: Vec<u32>,
    /// Cells of the ovary in the combined mesh: first..end.
    pub cells: std::ops::Range<usize>,
}

/// Radius (m) of the first search for tube nodes around the contact point.
const AXIS_SEARCH_M: f64 = 0.008;
/// Largest search radius (m) tried before giving up.
const AXIS_SEARCH_MAX_M: f64 = 0.128;
/// Share of the nodes' total variance the principal direction must carry to count as the
/// tube's axis (a single ring of nodes gives about 0.5; three layers well over 0.9).
const AXIS_DOMINANCE: f64 = 0.8;

/// Mesh parameters of one level.
#[derive(Clone, Copy, Debug)]
struct Params {
    /// Core grid cells along the long, middle and vertical axes (first two even).
    core: [usize; 3],
    /// Shell layers between the core and the ellipsoid (0: the core is the whole ball).
    shell: usize,
    /// Core size as a fraction of the semi-axes (1 without a shell).
    core_scale: f64,
    /// Blend of the core from a box (0) to the mapped ball (1).
    core_round: f64,
}

fn params(level: Level) -> Params {
    match level {
        Level::Coarse => Params {
            core: [4, 4, 2],
            shell: 0,
            core_scale: 1.0,
            core_round: 1.0,
        },
        Level::Medium => Params {
            core: [4, 4, 4],
            shell: 1,
            core_scale: 0.4,
            core_round: 0.75,
        },
        Level::Fine => Params {
            core: [12, 8, 6],
            shell: 2,
            core_scale: 0.5,
            core_round: 0.75,
        },
    }
}

/// The standard cube-to-ball map: [−1, 1]³ onto the unit ball, cube faces onto the sphere.
fn cube_to_ball(p: V3) -> V3 {
    let [x, y, z] = p;
    let (x2, y2, z2) = (x * x, y * y, z * z);
    [
        x * (1.0 - y2 / 2.0 - z2 / 2.0 + y2 * z2 / 3.0).sqrt(),
        y * (1.0 - z2 / 2.0 - x2 / 2.0 + z2 * x2 / 3.0).sqrt(),
        z * (1.0 - x2 / 2.0 - y2 / 2.0 + x2 * y2 / 3.0).sqrt(),
    ]
}

/// Principal direction and its share of the total variance of a point set.
fn principal_direction(pts: &[V3]) -> (V3, f64) {
    let n = pts.len() as f64;
    let mean = scale(pts.iter().fold([0.0; 3], |acc, &p| add(acc, p)), 1.0 / n);
    let mut cov = [[0.0; 3]; 3];
    for p in pts {
        let d = sub(*p, mean);
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += d[i] * d[j] / n;
            }
        }
    }
    let trace = cov[0][0] + cov[1][1] + cov[2][2];
    if !(trace > 0.0) {
        return ([0.0; 3], 0.0);
    }
    // Start from the column of the largest diagonal entry: never orthogonal to the
    // dominant eigenvector of a covariance matrix.
    let k = (0..3)
        .max_by(|&a, &b| cov[a][a].total_cmp(&cov[b][b]))
        .unwrap_or(0);
    let mut v = cov[k];
    for _ in 0..200 {
        let w: V3 = core::array::from_fn(|i| dot(cov[i], v));
        let l = norm(w);
        if !(l > 0.0) {
            break;
        }
        v = scale(w, 1.0 / l);
    }
    let cv: V3 = core::array::from_fn(|i| dot(cov[i], v));
    (v, dot(v, cv) / trace)
}

/// The tube's local axis at the probe site, horizontal, with y > 0 (x > 0 if y = 0).
fn tube_axis(anatomy: &Anatomy) -> V3 {
    let mesh = &anatomy.mesh;
    let mut on_tube = vec![false; mesh.nodes.len()];
    for (c, &r) in mesh.cells.iter().zip(&mesh.cell_regions) {
        if r == REGION_RIGHT_OVIDUCT {
            for &i in c {
                on_tube[i as usize] = true;
            }
        }
    }
    let cp = anatomy.probe.contact_point;
    let mut radius = AXIS_SEARCH_M;
    loop {
        let pts: Vec<V3> = mesh
            .nodes
            .iter()
            .zip(&on_tube)
            .filter(|(p, &t)| t && norm(sub(**p, cp)) <= radius)
            .map(|(p, _)| *p)
            .collect();
        let (v, share) = principal_direction(&pts);
        if pts.len() >= 2 && share >= AXIS_DOMINANCE {
            let h = [v[0], v[1], 0.0];
            let l = norm(h);
            assert!(
                l > 1e-6,
                "the right tube is vertical at the probe site; no horizontal axis for the ovary"
            );
            let sign = if h[1] < 0.0 || (h[1] == 0.0 && h[0] < 0.0) {
                -1.0
            } else {
                1.0
            };
            return scale(h, sign / l);
        }
        radius *= 2.0;
        assert!(
            radius <= AXIS_SEARCH_MAX_M,
            "no elongated set of right-oviduct nodes within {AXIS_SEARCH_MAX_M} m of the \
             probe contact point {cp:?}"
        );
    }
}

/// The ovary mesh in local coordinates (metres; x along the long axis, z up), cells with
/// positive Jacobian, and the index of the node at the top pole.
fn ovary_mesh(p: Params) -> (Vec<V3>, Vec<[u32; 8]>, usize) {
    let [m0, m1, m2] = p.core;
    assert!(m0 % 2 == 0 && m1 % 2 == 0 && m2 >= 1);
    let a = OVARY_SEMI_AXES_M;
    let k = p.shell;
    let param = |i: usize, m: usize| -1.0 + 2.0 * i as f64 / m as f64;
    let ellipsoid = |q: V3| -> V3 {
        let b = cube_to_ball(q);
        core::array::from_fn(|d| a[d] * b[d])
    };
    let core_pos = |q: V3| -> V3 {
        let r = lerp(q, cube_to_ball(q), p.core_round);
        core::array::from_fn(|d| p.core_scale * a[d] * r[d])
    };
    let core_id = |i: usize, j: usize, l: usize| (i * (m1 + 1) + j) * (m2 + 1) + l;

    let mut nodes: Vec<V3> = Vec::new();
    for i in 0..=m0 {
        for j in 0..=m1 {
            for l in 0..=m2 {
                nodes.push(core_pos([param(i, m0), param(j, m1), param(l, m2)]));
            }
        }
    }
    // Shell: node `layer` (1..=k) above core-surface node `c` (layer 0 is `c` itself).
    let mut shell_base = vec![usize::MAX; nodes.len()];
    if k > 0 {
        for i in 0..=m0 {
            for j in 0..=m1 {
                for l in 0..=m2 {
                    if i % m0 != 0 && j % m1 != 0 && l % m2 != 0 {
                        continue;
                    }
                    let q = [param(i, m0), param(j, m1), param(l, m2)];
                    let (inner, outer) = (core_pos(q), ellipsoid(q));
                    shell_base[core_id(i, j, l)] = nodes.len();
                    for layer in 1..=k {
                        nodes.push(lerp(inner, outer, layer as f64 / k as f64));
                    }
                }
            }
        }
    }
    let shell = |c: usize, layer: usize| -> u32 {
        if layer == 0 {
            c as u32
        } else {
            (shell_base[c] + layer - 1) as u32
        }
    };

    let mut cells: Vec<[u32; 8]> = Vec::new();
    for i in 0..m0 {
        for j in 0..m1 {
            for l in 0..m2 {
                let id = |di: usize, dj: usize, dl: usize| core_id(i + di, j + dj, l + dl) as u32;
                cells.push([
                    id(0, 0, 0),
                    id(1, 0, 0),
                    id(1, 1, 0),
                    id(0, 1, 0),
                    id(0, 0, 1),
                    id(1, 0, 1),
                    id(1, 1, 1),
                    id(0, 1, 1),
                ]);
            }
        }
    }
    // Shell cells: every quad of every core face, extruded through the k layers.
    let m = p.core;
    for d in 0..3 {
        let (e1, e2) = ((d + 1) % 3, (d + 2) % 3);
        for side in [0, m[d]] {
            for u in 0..m[e1] {
                for v in 0..m[e2] {
                    let at = |du: usize, dv: usize| {
                        let mut idx = [0usize; 3];
                        idx[d] = side;
                        idx[e1] = u + du;
                        idx[e2] = v + dv;
                        core_id(idx[0], idx[1], idx[2])
                    };
                    let q = [at(0, 0), at(1, 0), at(1, 1), at(0, 1)];
                    for layer in 0..k {
                        cells.push([
                            shell(q[0], layer),
                            shell(q[1], layer),
                            shell(q[2], layer),
                            shell(q[3], layer),
                            shell(q[0], layer + 1),
                            shell(q[1], layer + 1),
                            shell(q[2], layer + 1),
                            shell(q[3], layer + 1),
                        ]);
                    }
                }
            }
        }
    }
    // Orientation: make every cell's Jacobian positive (as in `builtin`).
    for c in &mut cells {
        let x: [V3; 8] = core::array::from_fn(|n| nodes[c[n] as usize]);
        let e = |from: [usize; 4], to: [usize; 4]| {
            (0..4).fold([0.0; 3], |acc, n| add(acc, sub(x[to[n]], x[from[n]])))
        };
        let d1 = e([0, 3, 4, 7], [1, 2, 5, 6]);
        let d2 = e([0, 1, 4, 5], [3, 2, 7, 6]);
        let d3 = e([0, 1, 2, 3], [4, 5, 6, 7]);
        if dot(cross(d1, d2), d3) < 0.0 {
            *c = [c[0], c[3], c[2], c[1], c[4], c[7], c[6], c[5]];
        }
    }
    let pole = shell(core_id(m0 / 2, m1 / 2, m2), k) as usize;
    (nodes, cells, pole)
}

/// Appends the ovary to the anatomy's mesh (new nodes and cells after the existing ones; existing numbering untouched; node_tags continue 1-based; region name registered; `source` mentions the ovary).
///
/// Node tags continue after the largest existing tag (for the built-in mesh, whose tags are
/// 1..=n, the new node i gets tag i + 1).
///
/// # Panics
///
/// If the anatomy has no right-oviduct nodes near its probe contact point, or the tube is
/// vertical there.
pub fn add_right_ovary(anatomy: &mut Anatomy, level: Level) -> OvarySite {
    let axis = tube_axis(anatomy);
    let up = [0.0, 0.0, 1.0];
    let across = cross(up, axis);
    let c = OVARY_SEMI_AXES_M[2];
    let cp = anatomy.probe.contact_point;
    let centre = [
        cp[0],
        cp[1],
        cp[2] - 2.0 * anatomy.probe.tube_radius_m - OVARY_GAP_M - c,
    ];
    let to_world = |x: V3| {
        add(
            centre,
            add(scale(axis, x[0]), add(scale(across, x[1]), scale(up, x[2]))),
        )
    };

    let (local, cells, pole) = ovary_mesh(params(level));
    let mesh = &mut anatomy.mesh;
    let base = mesh.nodes.len();
    let first_cell = mesh.cells.len();
    let next_tag = mesh.node_tags.iter().copied().max().unwrap_or(0) + 1;
    let z_fixed = centre[2] - 0.5 * c;
    let mut fixed_nodes = Vec::new();
    for (i, x) in local.iter().enumerate() {
        let w = to_world(*x);
        if w[2] < z_fixed {
            fixed_nodes.push((base + i) as u32);
        }
        mesh.nodes.push(w);
        mesh.node_tags.push(next_tag + i as u64);
    }
    let n_cells = cells.len();
    mesh.cells
        .extend(cells.into_iter().map(|cell| cell.map(|n| n + base as u32)));
    mesh.cell_regions
        .extend(std::iter::repeat_n(REGION_RIGHT_OVARY, n_cells));
    mesh.region_names
        .insert(REGION_RIGHT_OVARY, REGION_NAME.to_string());
    mesh.source = format!("{} with right ovary", mesh.source);
    fixed_nodes.sort_unstable();
    OvarySite {
        centre,
        axis,
        top_point: mesh.nodes[base + pole],
        fixed_nodes,
        cells: first_cell..first_cell + n_cells,
    }
}
