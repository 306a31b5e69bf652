//! The uterine wall of the built-in anatomy: the midline and its cross-section profile, the
//! structured surface grid (fundus cap and swept rows), the nodes through the wall and the
//! wall cells.

use std::f64::consts::{FRAC_PI_4, PI};

use super::{HexBuild, Params, REGION_BODY, REGION_FUNDUS, REGION_VAGINA};
use crate::geom::{add, lerp, scale, unit, V3};

// ---- dimensions, millimetres ----

/// Outer and lumen semi-axis of the fundus cap along the midline.
const POLE_OUT: f64 = 30.0;
const POLE_IN: f64 = 15.0;
/// Profile along the midline: arc length s, outer half-axes (y, z), lumen half-axes (y, z).
const PROFILE: [[f64; 5]; 11] = [
    [0.0, 39.0, 30.0, 24.5, 18.4],
    [15.6, 36.8, 29.7, 24.5, 18.5],
    [28.5, 34.8, 28.5, 19.3, 14.5],
    [42.4, 32.4, 26.5, 14.3, 10.6],
    [56.3, 29.9, 23.5, 9.2, 6.7],
    [70.0, 27.5, 19.0, 4.1, 2.9],
    [84.5, 25.0, 15.0, 3.4, 2.2],
    [106.0, 21.9, 13.5, 17.5, 10.8],
    [128.0, 15.8, 10.5, 12.6, 8.4],
    [150.0, 9.5, 7.7, 7.6, 6.2],
    [173.7, 6.2, 6.2, 5.0, 5.0],
];
/// Bend of the midline from the body into the vagina.
const BEND_RADIUS: f64 = 35.0;
const BEND_DEG: f64 = 70.0;
/// Centre of the vaginal end (x, z).
const END_X: f64 = 123.6;
const END_Z: f64 = -80.5;
/// How far into the bend the cervix (body/vagina boundary) lies.
const CERVIX_DEG: f64 = 24.0;
/// Width of the body-surface patch a tube grows from.
const TUBE_PATCH: f64 = 12.0;

/// The midline: straight along +x, a circular bend towards −z, straight to the end.
pub(super) struct Midline {
    x_bend: f64,
    arc_len: f64,
    total: f64,
}

impl Midline {
    pub(super) fn new() -> Self {
        let phi = BEND_DEG.to_radians();
        let straight = (-END_Z - BEND_RADIUS * (1.0 - phi.cos())) / phi.sin();
        let x_bend = END_X - BEND_RADIUS * phi.sin() - straight * phi.cos();
        let arc_len = BEND_RADIUS * phi;
        Midline {
            x_bend,
            arc_len,
            total: x_bend + arc_len + straight,
        }
    }

    /// Centre and in-plane normal (the rotated +z) at arc length `s`.
    pub(super) fn frame(&self, s: f64) -> (V3, V3) {
        if s <= self.x_bend {
            return ([s, 0.0, 0.0], [0.0, 0.0, 1.0]);
        }
        let a = ((s - self.x_bend) / BEND_RADIUS).min(BEND_DEG.to_radians());
        let c = [
            self.x_bend + BEND_RADIUS * a.sin(),
            0.0,
            -BEND_RADIUS * (1.0 - a.cos()),
        ];
        let n = [a.sin(), 0.0, a.cos()];
        let rest = s - self.x_bend - self.arc_len;
        if rest <= 0.0 {
            (c, n)
        } else {
            let t = [a.cos(), 0.0, -a.sin()];
            (add(c, scale(t, rest)), n)
        }
    }

    pub(super) fn s_cervix(&self) -> f64 {
        self.x_bend + BEND_RADIUS * CERVIX_DEG.to_radians()
    }
}

/// Outer (y, z) and lumen (y, z) half-axes at arc length `s` (piecewise linear).
fn profile(s: f64) -> [f64; 4] {
    let last = PROFILE[PROFILE.len() - 1];
    let mut prev = PROFILE[0];
    if s <= prev[0] {
        return [prev[1], prev[2], prev[3], prev[4]];
    }
    for row in PROFILE.iter().skip(1) {
        if s <= row[0] {
            let t = (s - prev[0]) / (row[0] - prev[0]);
            return core::array::from_fn(|k| prev[k + 1] + t * (row[k + 1] - prev[k + 1]));
        }
        prev = *row;
    }
    [last[1], last[2], last[3], last[4]]
}

/// How far (0..1) the lumen nodes of the swept part move from the graded ring angles of the
/// outer surface to uniform angles, as a function of arc length: 1 around the narrow
/// cervical canal (s = 70..86 mm, lumen 2–4 mm across), so that the narrow columns made for
/// the tube roots do not turn into 0.3 mm edges there (the stable time step); 0 where the
/// lumen is wide relative to the wall (fundus, upper body, thin-walled vagina), so the
/// through-wall edges stay radial.
fn lumen_uniformity(s: f64) -> f64 {
    let smooth = |t: f64| {
        let t = t.clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    };
    smooth((s - 42.0) / 28.0) * (1.0 - smooth((s - 86.0) / 14.0))
}

/// `n` cell sizes summing to `total`, growing geometrically (ratio 1.25) from `first` up to
/// a cap, or uniform if the cells cannot be larger than `first`.
fn graded(first: f64, n: usize, total: f64) -> Vec<f64> {
    const RATIO: f64 = 1.25;
    if n == 0 {
        return Vec::new();
    }
    let uniform = total / n as f64;
    if uniform <= first * RATIO {
        return vec![uniform; n];
    }
    let sizes = |cap: f64| -> Vec<f64> {
        let mut g = first;
        (0..n)
            .map(|_| {
                g *= RATIO;
                g.min(cap)
            })
            .collect()
    };
    let (mut lo, mut hi) = (first * RATIO, total);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if sizes(mid).iter().sum::<f64>() > total {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let mut out = sizes(0.5 * (lo + hi));
    // Remove the bisection residue so the sizes add up exactly.
    let err = total - out.iter().sum::<f64>();
    if let Some(l) = out.last_mut() {
        *l += err;
    }
    out
}

/// Node coordinates from cumulative sizes, starting at `start`.
fn cumulative(start: f64, sizes: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(sizes.len() + 1);
    let mut x = start;
    out.push(x);
    for s in sizes {
        x += s;
        out.push(x);
    }
    out
}

/// Which side face a ring index lies on, and the face coordinate there.
enum RingPos {
    PlusY(f64),
    PlusZ(f64),
    MinusY(f64),
    MinusZ(f64),
}

/// The structured surface grid of the wall: top face and side ring, rows along the
/// midline.
pub(super) struct Grid {
    pub(super) p: Params,
    /// Top face node coordinates in [-1, 1] (y direction, uniform).
    u: Vec<f64>,
    /// Top face node coordinates in [-1, 1] (z direction, narrow in the middle).
    v: Vec<f64>,
    /// Cap row elevation, row 0 = top edge (1) to row n_cap = equator (0).
    w: Vec<f64>,
    /// Arc length of the swept rows (row n_cap + j has s[j]).
    s: Vec<f64>,
    pub(super) ring: usize,
}

impl Grid {
    pub(super) fn new(p: Params, mid: &Midline) -> Self {
        assert!(p.patch % 2 == 1 && p.patch >= 3 && p.m_v >= p.patch);
        assert!((p.m_v - p.patch) & 1 == 0 && p.n_cap > p.patch / 2);
        let narrow = TUBE_PATCH / p.patch as f64;
        let half = p.patch / 2;

        let u = (0..=p.m_u)
            .map(|i| -1.0 + 2.0 * i as f64 / p.m_u as f64)
            .collect();

        // v: patch columns of physical width `narrow` at the ±y equator (arc speed a_z).
        let a0 = profile(0.0);
        let dv = 4.0 / PI * narrow / a0[1];
        let side = graded(dv, (p.m_v - p.patch) / 2, 1.0 - dv * p.patch as f64 / 2.0);
        let mut sizes: Vec<f64> = side.iter().rev().copied().collect();
        sizes.extend(std::iter::repeat_n(dv, p.patch));
        sizes.extend(side.iter().copied());
        let mut v = cumulative(-1.0, &sizes);
        // Exact symmetry and end points.
        let m = v.len() - 1;
        for i in 0..=m / 2 {
            let a = 0.5 * (v[m - i] - v[i]);
            v[i] = -a;
            v[m - i] = a;
        }

        // w: `half` narrow rows above the equator (arc speed POLE_OUT).
        let dw = 4.0 / PI * narrow / POLE_OUT;
        let mut wsizes = vec![dw; half];
        wsizes.extend(graded(dw, p.n_cap - half, 1.0 - dw * half as f64));
        let mut w: Vec<f64> = cumulative(0.0, &wsizes);
        w.reverse();
        w[0] = 1.0;
        w[p.n_cap] = 0.0;

        // s: half + 1 narrow rows below the equator, then graded to the end.
        let mut ssizes = vec![narrow; half + 1];
        let used = narrow * (half + 1) as f64;
        ssizes.extend(graded(narrow, p.n_axial - half - 1, mid.total - used));
        let mut s = cumulative(0.0, &ssizes);
        s[p.n_axial] = mid.total;

        Grid {
            p,
            u,
            v,
            w,
            s,
            ring: 2 * (p.m_u + p.m_v),
        }
    }

    pub(super) fn rows(&self) -> usize {
        self.p.n_cap + self.p.n_axial
    }

    fn ring_pos(&self, i: usize) -> RingPos {
        let (mu, mv) = (self.p.m_u, self.p.m_v);
        let i = i % self.ring;
        if i <= mv {
            RingPos::PlusY(self.v[i])
        } else if i <= mv + mu {
            RingPos::PlusZ(self.u[mu - (i - mv)])
        } else if i <= 2 * mv + mu {
            RingPos::MinusY(self.v[mv - (i - mv - mu)])
        } else {
            RingPos::MinusZ(self.u[i - 2 * mv - mu])
        }
    }

    /// Unnormalised (y, z) direction of ring index `i` (cube face point).
    fn ring_dir(&self, i: usize) -> (f64, f64) {
        let t = tan_quarter;
        match self.ring_pos(i) {
            RingPos::PlusY(v) => (1.0, t(v)),
            RingPos::PlusZ(u) => (t(u), 1.0),
            RingPos::MinusY(v) => (-1.0, t(v)),
            RingPos::MinusZ(u) => (t(u), -1.0),
        }
    }

    /// Surface node id of side-grid node (ring i, row r).
    pub(super) fn side(&self, i: usize, r: usize) -> usize {
        r * self.ring + i % self.ring
    }

    /// Surface node id of top-face node (iu, iv).
    fn top(&self, iu: usize, iv: usize) -> usize {
        let (mu, mv) = (self.p.m_u, self.p.m_v);
        if iu == mu {
            self.side(iv, 0)
        } else if iv == mv {
            self.side(mv + (mu - iu), 0)
        } else if iu == 0 {
            self.side(mv + mu + (mv - iv), 0)
        } else if iv == 0 {
            self.side(2 * mv + mu + iu, 0)
        } else {
            (self.rows() + 1) * self.ring + (iu - 1) * (mv - 1) + (iv - 1)
        }
    }

    fn surface_nodes(&self) -> usize {
        (self.rows() + 1) * self.ring + (self.p.m_u - 1) * (self.p.m_v - 1)
    }

    /// Node id of wall layer `k` (0 lumen .. `n_wall` outer surface) under surface node `sn`.
    pub(super) fn wall_id(&self, sn: usize, k: usize) -> u32 {
        (sn * (self.p.n_wall + 1) + k) as u32
    }
}

fn cap_point(d: V3, a: [f64; 4]) -> (V3, V3) {
    let d = unit(d);
    let outer = [-POLE_OUT * d[0], a[0] * d[1], a[1] * d[2]];
    let inner = [-POLE_IN * d[0], a[2] * d[1], a[3] * d[2]];
    (outer, inner)
}

/// `tan(π/4 · x)`: the equiangular cube-to-sphere map of a face coordinate in [-1, 1].
pub(super) fn tan_quarter(x: f64) -> f64 {
    (FRAC_PI_4 * x).tan()
}

/// The (outer, lumen) position of every surface node.
fn surface_points(g: &Grid, mid: &Midline) -> Vec<(V3, V3)> {
    let p = g.p;
    let a0 = profile(0.0);
    let tan = tan_quarter;
    let ns = g.surface_nodes();
    let mut surf: Vec<(V3, V3)> = vec![([0.0; 3], [0.0; 3]); ns];
    for r in 0..=g.rows() {
        for i in 0..g.ring {
            let (ry, rz) = g.ring_dir(i);
            surf[g.side(i, r)] = if r < p.n_cap {
                cap_point([tan(g.w[r]), ry, rz], a0)
            } else {
                let s = g.s[r - p.n_cap];
                let (c, nz) = mid.frame(s);
                let a = profile(s);
                // Outer nodes at the graded ring angles; lumen nodes drift towards uniform
                // angles where the lumen is narrow (see `lumen_uniformity`).
                let th_out = rz.atan2(ry);
                let th_unif = 2.0 * PI * (i as f64 - p.m_v as f64 / 2.0) / g.ring as f64;
                let diff = (th_unif - th_out + PI).rem_euclid(2.0 * PI) - PI;
                let th_in = th_out + lumen_uniformity(s) * diff;
                let at = |hy: f64, hz: f64, th: f64| {
                    add(c, add([0.0, hy * th.cos(), 0.0], scale(nz, hz * th.sin())))
                };
                (at(a[0], a[1], th_out), at(a[2], a[3], th_in))
            };
        }
    }
    for iu in 1..p.m_u {
        for iv in 1..p.m_v {
            surf[g.top(iu, iv)] = cap_point([1.0, tan(g.u[iu]), tan(g.v[iv])], a0);
        }
    }
    surf
}

/// The wall: `n_wall` straight layers of nodes and cells between the lumen and the outer
/// surface under every surface node and quad (node ids from [`Grid::wall_id`]).
pub(super) fn wall(g: &Grid, mid: &Midline) -> HexBuild {
    let p = g.p;
    let surf = surface_points(g, mid);
    let nw = p.n_wall;
    let mut nodes: Vec<V3> = Vec::with_capacity(surf.len() * (nw + 1));
    for (outer, inner) in &surf {
        for k in 0..=nw {
            nodes.push(lerp(*inner, *outer, k as f64 / nw as f64));
        }
    }

    let mut cells: Vec<[u32; 8]> = Vec::new();
    let mut regions: Vec<i32> = Vec::new();
    let mut push_wall = |q: [usize; 4], region: i32| {
        for k in 0..nw {
            cells.push([
                g.wall_id(q[0], k),
                g.wall_id(q[1], k),
                g.wall_id(q[2], k),
                g.wall_id(q[3], k),
                g.wall_id(q[0], k + 1),
                g.wall_id(q[1], k + 1),
                g.wall_id(q[2], k + 1),
                g.wall_id(q[3], k + 1),
            ]);
            regions.push(region);
        }
    };
    for iu in 0..p.m_u {
        for iv in 0..p.m_v {
            let q = [
                g.top(iu, iv),
                g.top(iu + 1, iv),
                g.top(iu + 1, iv + 1),
                g.top(iu, iv + 1),
            ];
            push_wall(q, REGION_FUNDUS);
        }
    }
    let s_cervix = mid.s_cervix();
    for r in 0..g.rows() {
        let region = if r < p.n_cap {
            REGION_FUNDUS
        } else {
            let j = r - p.n_cap;
            if 0.5 * (g.s[j] + g.s[j + 1]) < s_cervix {
                REGION_BODY
            } else {
                REGION_VAGINA
            }
        };
        for i in 0..g.ring {
            let q = [
                g.side(i, r),
                g.side(i + 1, r),
                g.side(i + 1, r + 1),
                g.side(i, r + 1),
            ];
            push_wall(q, region);
        }
    }
    HexBuild {
        nodes,
        cells,
        regions,
    }
}
