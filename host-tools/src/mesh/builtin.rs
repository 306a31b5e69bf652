//! The built-in scene's anatomy: a uterus with both fallopian tubes, generated procedurally
//! as a conforming linear hexahedral mesh at three resolutions.
//!
//! The scene is the one of Székely et al. (ETH Zürich, Fig. 3): a uterus with both tubes,
//! held at the cervical end, with a blunt probe pushing one tube. The proportions follow the
//! parametric reference mesh in `shared/meshes/uterus_scaffold_hex*.msh` ("Human 1"
//! parameters of the `scaffoldmaker` package), and the physical groups use its tags and
//! names: 1 `body_of_uterus`, 2 `fundus`, 3 `left_oviduct` (−y), 4 `right_oviduct` (+y),
//! 5 `vagina`.
//!
//! # Frame and geometry (millimetres here; the mesh itself is in metres)
//!
//! * x runs along the body from the fundus (x = −30) to the cervix, y is lateral (the tubes
//!   lie along ±y), z is antero-posterior; the vagina bends towards −z. Same frame as the
//!   reference mesh.
//! * **Wall.** The uterine wall is one thick hollow shell: a closed cap (the fundus) on a
//!   tapering tube that continues through the cervix into the vagina. Its midline is the
//!   x axis from x = 0 to x = 69.8, then a 35 mm radius arc turning 70° towards −z, then a
//!   straight 61.2 mm segment, ending at centre (123.6, 0, −80.5); 173.7 mm of midline in
//!   all. Cross-sections are perpendicular to the midline and elliptical; the half-axes are
//!   read off the reference mesh's rings (piecewise linear in between):
//!
//!   | s (mm along midline) | outer half-axes y, z | lumen half-axes y, z | wall y, z |
//!   |---|---|---|---|
//!   | 0 (fundus base) | 39, 30 | 24.5, 18.4 | 14.5, 11.6 |
//!   | 28.5 | 34.8, 28.5 | 19.3, 14.5 | 15.5, 14 |
//!   | 42.4 (mid-body) | 32.4, 26.5 | 14.3, 10.6 | 18.1, 15.9 |
//!   | 70 (start of bend) | 27.5, 19 | 4.1, 2.9 | 23.4, 16.1 |
//!   | 84.5 (cervix: body/vagina boundary, 24° into the bend) | 25, 15 | 3.4, 2.2 | 21.6, 12.8 |
//!   | 106 | 21.9, 13.5 | 17.5, 10.8 | 4.4, 2.7 |
//!   | 150 | 9.5, 7.7 | 7.6, 6.2 | 1.9, 1.5 |
//!   | 173.7 (vaginal end) | 6.2, 6.2 | 5, 5 | 1.2, 1.2 |
//!
//!   The fundus is a half-ellipsoidal cap on the s = 0 section, outer semi-axis 30 along
//!   the midline (pole at x = −30), lumen semi-axis 15 (the cavity ends at x = −15), so the
//!   wall is 15 mm thick at the pole.
//! * **Tubes.** Straight hollow cylinders along ±y, outer diameter 3.5 mm, lumen diameter
//!   1.75 mm, from the side of the fundus/body junction (axis at x = 2 mm (1.2 mm at the fine
//!   level), z = 0; root at |y| ≈ 38 mm) to |y| = 140 mm, so a tube region is about 103 mm
//!   long. The first 14 mm flare out (a smooth quadratic blend) to the 12 mm square patch of
//!   body surface the tube grows from, like the flared roots of the reference tubes. The
//!   tube lumen ends blind at the body surface (the intramural part is not modelled).
//!
//! # Mesh structure
//!
//! The wall is a structured "cubed-sphere" shell. The surface grid is an open box: a top
//! face (m_u × m_v quads, the pole of the fundus) and four side faces that form a ring of
//! 2(m_u + m_v) quads around the midline; the side rows above the equator are mapped onto
//! the fundus ellipsoid with the equiangular cube-to-sphere map, the rows below are placed
//! on the swept cross-sections. Each surface quad is extruded through the wall in `n_w`
//! straight layers between the lumen surface and the outer surface. Around the narrow
//! cervical canal (s = 42..100 mm) the lumen nodes drift from the outer surface's graded ring
//! angles towards uniform angles, so the narrow columns described below do not become
//! 0.3 mm edges on the 4 mm wide canal (they would set the explicit time step).
//!
//! Each tube is an O-grid-like ring: a P × P block of quads (P = 3, or 5 at the fine level)
//! with the centre quad left out as the lumen, mapped to an annulus (8 or 24 cells per
//! cross-section, 1 or 2 cells through the tube wall, 12 or 20 nodes around the outside).
//! The tube is conforming with the body: its root cross-section *is* a P × P patch of the
//! outer body surface (same node indices), centred at the equator of the ±y side faces. To
//! make that patch about 12 mm wide, the P central columns of the ±y side faces and the P
//! ring rows at the equator are narrow (12/P mm); because the grid is structured, those
//! narrow columns run along the whole body and over the fundus, and the narrow rows round
//! the whole circumference. Everything is built from index maps, so shared nodes are shared
//! by construction (no coordinate merging) and every interior face belongs to exactly two
//! cells.
//!
//! # Levels
//!
//! | level | cells | nodes | wall layers | tube cells per section | min scaled Jacobian | min edge |
//! |---|---|---|---|---|---|---|
//! | coarse | 319 | 656 | 1 | 8 | 0.46 | 0.67 mm |
//! | medium | 2032 | 3186 | 2 | 8 | 0.49 | 0.53 mm |
//! | fine | 19928 | 25670 | 4 | 24 | 0.31 | 0.22 mm |
//!
//! The worst cells are in the tubes: the four corner cells of the square-ring cross-section
//! have one corner on the round outer surface with an angle of 180° − 360°/(outer nodes),
//! i.e. 150° (12 nodes, scaled Jacobian 0.5) or 162° (20 nodes, 0.31). The wall itself stays
//! above 0.48. The reference meshes have 0.34 / 0.42 / 0.48 and minimum edges of
//! 0.67 / 0.34 / 0.17 mm.
//!
//! # Comparison with the reference mesh (`uterus_scaffold_hex2k.msh` / `_hex20k.msh`)
//!
//! | quantity | reference | generated (fine) |
//! |---|---|---|
//! | overall extent x × y × z (mm) | 159.5 × 280 × 112.7 | 159.4 × 280 × 112.6 |
//! | body_of_uterus extent x, z (mm) | 97.5, 60 | 90.2, 60 |
//! | fundus extent x × y × z (mm) | 30.5 × 89.7 × 59.8 | 30 × 77.9 × 60 |
//! | vagina extent x × y × z (mm) | 48 × 50 × 94 | 51.5 × 50 × 93.3 |
//! | tube region length (mm) | 99.5 | 102.8 |
//! | tube outer / lumen diameter (mm) | 3.5 / 1.75 | 3.5 / 1.75 |
//! | volume body / fundus / vagina (cm³) | 170.3 / 51.5 / 26.5 | 165.8 / 59.1 / 27.3 |
//! | volume per tube (cm³) | 1.06 | 1.27 (the longer flare) |
//! | total volume (cm³) | 250.4 | 254.7 (coarse 238.2, medium 250.4) |
//!
//! (The reference fundus's y extent includes the bulges around the tube roots; the
//! reference body region reaches 4 mm into the fundus side and its cervical face is
//! tilted, hence its larger x extent.)
//!
//! Cervix clamp: [`Anatomy::cervix_nodes`] are all nodes (every wall layer) of the last
//! cross-section, the lower (vaginal) end of the wall. Probe: [`ProbeSite`] is the top (+z)
//! point of the outer surface of the right tube at the node layer nearest the middle of
//! the tube, with push direction −z.

use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_4, PI};
use std::fmt;
use std::str::FromStr;

use crate::geom::{add, cross, dot, lerp, scale, sub, unit, V3};
use crate::mesh::Mesh;

/// Physical group tag of the body of the uterus.
pub const REGION_BODY: i32 = 1;
/// Physical group tag of the fundus.
pub const REGION_FUNDUS: i32 = 2;
/// Physical group tag of the left fallopian tube (−y).
pub const REGION_LEFT_OVIDUCT: i32 = 3;
/// Physical group tag of the right fallopian tube (+y).
pub const REGION_RIGHT_OVIDUCT: i32 = 4;
/// Physical group tag of the vagina.
pub const REGION_VAGINA: i32 = 5;

/// Mesh resolution of the built-in anatomy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Level {
    /// About 300 hexahedra (319 cells, 656 nodes).
    Coarse,
    /// About 2000 hexahedra (2032 cells, 3186 nodes).
    Medium,
    /// About 20000 hexahedra (19928 cells, 25670 nodes).
    Fine,
}

impl Level {
    /// All levels, coarse to fine.
    pub const ALL: [Level; 3] = [Level::Coarse, Level::Medium, Level::Fine];

    /// The nominal cell count the level aims at (the generated count is within ±30 %).
    pub fn nominal_cells(self) -> usize {
        match self {
            Level::Coarse => 300,
            Level::Medium => 2000,
            Level::Fine => 20000,
        }
    }

    fn params(self) -> Params {
        match self {
            Level::Coarse => Params {
                m_u: 3,
                m_v: 5,
                n_cap: 2,
                n_axial: 12,
                n_wall: 1,
                patch: 3,
                n_tube: 5,
                n_flare: 1,
            },
            Level::Medium => Params {
                m_u: 4,
                m_v: 9,
                n_cap: 4,
                n_axial: 30,
                n_wall: 2,
                patch: 3,
                n_tube: 12,
                n_flare: 2,
            },
            Level::Fine => Params {
                m_u: 12,
                m_v: 19,
                n_cap: 8,
                n_axial: 59,
                n_wall: 4,
                patch: 5,
                n_tube: 50,
                n_flare: 4,
            },
        }
    }
}

impl fmt::Display for Level {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Level::Coarse => "coarse",
            Level::Medium => "medium",
            Level::Fine => "fine",
        })
    }
}

/// Error for a mesh level name that is not one of the known ones.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown mesh level {0:?}: expected coarse, medium or fine (or 300, 2000, 20000)")]
pub struct ParseLevelError(pub String);

impl FromStr for Level {
    type Err = ParseLevelError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "coarse" | "300" => Ok(Level::Coarse),
            "medium" | "2000" => Ok(Level::Medium),
            "fine" | "20000" => Ok(Level::Fine),
            _ => Err(ParseLevelError(s.to_string())),
        }
    }
}

/// Where the blunt probe touches a fallopian tube.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeSite {
    /// Region tag of the tube that is pushed ([`REGION_RIGHT_OVIDUCT`]).
    pub tube_region: i32,
    /// A point on the outer surface of the tube, halfway along it, in metres.
    pub contact_point: [f64; 3],
    /// Unit vector pointing into the tube, perpendicular to the tube axis.
    pub push_direction: [f64; 3],
    /// Outer radius of the tube, in metres.
    pub tube_radius_m: f64,
}

/// The generated anatomy: mesh, clamped nodes and probe site.
#[derive(Clone, Debug, PartialEq)]
pub struct Anatomy {
    pub mesh: Mesh,
    /// 0-based indices of the nodes at the cervical (vaginal, lower) end, to clamp; sorted.
    pub cervix_nodes: Vec<u32>,
    pub probe: ProbeSite,
}

/// Resolution parameters of one level.
#[derive(Clone, Copy, Debug)]
struct Params {
    /// Top-face quads along y (ring quads on each ±z side face).
    m_u: usize,
    /// Top-face quads along z (ring quads on each ±y side face); `m_v - patch` even.
    m_v: usize,
    /// Side rows on the fundus cap (above the equator).
    n_cap: usize,
    /// Rows along the swept part (body and vagina).
    n_axial: usize,
    /// Cell layers through the wall.
    n_wall: usize,
    /// Tube root patch size P (odd, ≥ 3): P × P surface quads minus the centre one.
    patch: usize,
    /// Cell layers along each tube.
    n_tube: usize,
    /// Of which in the flared root.
    n_flare: usize,
}

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
/// Tubes.
const TUBE_END_Y: f64 = 140.0;
const TUBE_R_OUT: f64 = 1.75;
const TUBE_R_IN: f64 = 0.875;
const TUBE_FLARE: f64 = 14.0;
/// Width of the body-surface patch a tube grows from.
const TUBE_PATCH: f64 = 12.0;

/// The midline: straight along +x, a circular bend towards −z, straight to the end.
struct Midline {
    x_bend: f64,
    arc_len: f64,
    total: f64,
}

impl Midline {
    fn new() -> Self {
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
    fn frame(&self, s: f64) -> (V3, V3) {
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

    fn s_cervix(&self) -> f64 {
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

struct Grid {
    p: Params,
    /// Top face node coordinates in [-1, 1] (y direction, uniform).
    u: Vec<f64>,
    /// Top face node coordinates in [-1, 1] (z direction, narrow in the middle).
    v: Vec<f64>,
    /// Cap row elevation, row 0 = top edge (1) to row n_cap = equator (0).
    w: Vec<f64>,
    /// Arc length of the swept rows (row n_cap + j has s[j]).
    s: Vec<f64>,
    ring: usize,
}

impl Grid {
    fn new(p: Params, mid: &Midline) -> Self {
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

    fn rows(&self) -> usize {
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
        let t = |x: f64| (FRAC_PI_4 * x).tan();
        match self.ring_pos(i) {
            RingPos::PlusY(v) => (1.0, t(v)),
            RingPos::PlusZ(u) => (t(u), 1.0),
            RingPos::MinusY(v) => (-1.0, t(v)),
            RingPos::MinusZ(u) => (t(u), -1.0),
        }
    }

    /// Surface node id of side-grid node (ring i, row r).
    fn side(&self, i: usize, r: usize) -> usize {
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
}

fn cap_point(d: V3, a: [f64; 4]) -> (V3, V3) {
    let d = unit(d);
    let outer = [-POLE_OUT * d[0], a[0] * d[1], a[1] * d[2]];
    let inner = [-POLE_IN * d[0], a[2] * d[1], a[3] * d[2]];
    (outer, inner)
}

/// Generate the built-in uterus-and-tubes anatomy at the given level.
pub fn generate(level: Level) -> Anatomy {
    let p = level.params();
    let mid = Midline::new();
    let g = Grid::new(p, &mid);
    let a0 = profile(0.0);
    let tan = |x: f64| (FRAC_PI_4 * x).tan();

    // ---- surface nodes: (outer, lumen) positions ----
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

    // ---- wall nodes ----
    let nw = p.n_wall;
    let wall_id = |sn: usize, k: usize| (sn * (nw + 1) + k) as u32;
    let mut nodes: Vec<V3> = Vec::with_capacity(ns * (nw + 1));
    for (outer, inner) in &surf {
        for k in 0..=nw {
            nodes.push(lerp(*inner, *outer, k as f64 / nw as f64));
        }
    }

    // ---- wall cells ----
    let mut cells: Vec<[u32; 8]> = Vec::new();
    let mut regions: Vec<i32> = Vec::new();
    let mut push_wall = |q: [usize; 4], region: i32| {
        for k in 0..nw {
            cells.push([
                wall_id(q[0], k),
                wall_id(q[1], k),
                wall_id(q[2], k),
                wall_id(q[3], k),
                wall_id(q[0], k + 1),
                wall_id(q[1], k + 1),
                wall_id(q[2], k + 1),
                wall_id(q[3], k + 1),
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

    // ---- tubes ----
    let pp = p.patch;
    let half = pp / 2;
    let r0 = p.n_cap - half;
    let mut probe = None;
    for (sign, region, i0) in [
        (1.0, REGION_RIGHT_OVIDUCT, (p.m_v - pp) / 2),
        (-1.0, REGION_LEFT_OVIDUCT, p.m_v + p.m_u + (p.m_v - pp) / 2),
    ] {
        let root = |a: usize, b: usize| wall_id(g.side(i0 + a, r0 + b), nw);
        let pos = |id: u32| nodes[id as usize];
        let axis = [0.0, sign, 0.0];
        let origin = scale(
            [half, half + 1]
                .iter()
                .flat_map(|&a| [half, half + 1].map(|b| pos(root(a, b))))
                .fold([0.0; 3], add),
            0.25,
        );
        let length = TUBE_END_Y - sign * origin[1];
        let flatten = |x: V3| sub(x, scale(axis, dot(x, axis)));
        let mut ea = [0.0; 3];
        let mut eb = [0.0; 3];
        for k in 0..=pp {
            ea = add(ea, sub(pos(root(pp, k)), pos(root(0, k))));
            eb = add(eb, sub(pos(root(k, pp)), pos(root(k, 0))));
        }
        let ea = unit(flatten(ea));
        let eb = unit(flatten(sub(eb, scale(ea, dot(eb, ea)))));

        let dist = |k: usize| -> f64 {
            if k <= p.n_flare {
                TUBE_FLARE * k as f64 / p.n_flare as f64
            } else {
                TUBE_FLARE
                    + (length - TUBE_FLARE) * (k - p.n_flare) as f64 / (p.n_tube - p.n_flare) as f64
            }
        };
        // ids[k][a][b]
        let mut ids = vec![vec![vec![0u32; pp + 1]; pp + 1]; p.n_tube + 1];
        for (a, col) in ids[0].iter_mut().enumerate() {
            for (b, id) in col.iter_mut().enumerate() {
                *id = root(a, b);
            }
        }
        for (k, layer) in ids.iter_mut().enumerate().skip(1) {
            let d = dist(k);
            let beta = (1.0 - d / TUBE_FLARE).max(0.0).powi(2);
            for (a, col) in layer.iter_mut().enumerate() {
                for (b, id) in col.iter_mut().enumerate() {
                    let x = a as f64 - pp as f64 / 2.0;
                    let y = b as f64 - pp as f64 / 2.0;
                    let rho = x.abs().max(y.abs());
                    let rad = TUBE_R_IN + (rho - 0.5) / half as f64 * (TUBE_R_OUT - TUBE_R_IN);
                    let phi = tan(y / rho).atan2(tan(x / rho));
                    let circle = add(
                        origin,
                        add(scale(ea, rad * phi.cos()), scale(eb, rad * phi.sin())),
                    );
                    let rootp = nodes[root(a, b) as usize];
                    let q = add(
                        scale(axis, d),
                        add(scale(rootp, beta), scale(circle, 1.0 - beta)),
                    );
                    *id = nodes.len() as u32;
                    nodes.push(q);
                }
            }
        }
        for k in 0..p.n_tube {
            for qa in 0..pp {
                for qb in 0..pp {
                    if qa == half && qb == half {
                        continue; // the lumen
                    }
                    let (l0, l1) = (&ids[k], &ids[k + 1]);
                    cells.push([
                        l0[qa][qb],
                        l0[qa + 1][qb],
                        l0[qa + 1][qb + 1],
                        l0[qa][qb + 1],
                        l1[qa][qb],
                        l1[qa + 1][qb],
                        l1[qa + 1][qb + 1],
                        l1[qa][qb + 1],
                    ]);
                    regions.push(region);
                }
            }
        }
        if region == REGION_RIGHT_OVIDUCT {
            let k_mid = (1..=p.n_tube)
                .min_by(|&x, &y| {
                    (dist(x) - 0.5 * length)
                        .abs()
                        .total_cmp(&(dist(y) - 0.5 * length).abs())
                })
                .unwrap_or(p.n_tube);
            let centre = add(origin, scale(axis, dist(k_mid)));
            // +z, made exactly perpendicular to the axis.
            let up = unit(flatten([0.0, 0.0, 1.0]));
            probe = Some((add(centre, scale(up, TUBE_R_OUT)), scale(up, -1.0)));
        }
    }

    // ---- orientation: make every cell's Jacobian positive ----
    for c in &mut cells {
        let x: [V3; 8] = core::array::from_fn(|a| nodes[c[a] as usize]);
        let e = |a: [usize; 4], b: [usize; 4]| {
            scale(
                (0..4).fold([0.0; 3], |acc, k| add(acc, sub(x[b[k]], x[a[k]]))),
                0.25,
            )
        };
        let d1 = e([0, 3, 4, 7], [1, 2, 5, 6]);
        let d2 = e([0, 1, 4, 5], [3, 2, 7, 6]);
        let d3 = e([0, 1, 2, 3], [4, 5, 6, 7]);
        if dot(cross(d1, d2), d3) < 0.0 {
            *c = [c[0], c[3], c[2], c[1], c[4], c[7], c[6], c[5]];
        }
    }

    let cervix_nodes: Vec<u32> = {
        let mut v: Vec<u32> = (0..g.ring)
            .flat_map(|i| (0..=nw).map(move |k| (i, k)))
            .map(|(i, k)| wall_id(g.side(i, g.rows()), k))
            .collect();
        v.sort_unstable();
        v
    };

    let (contact, push) = probe.unwrap_or(([0.0; 3], [0.0, 0.0, -1.0]));
    let mm = 1e-3;
    let mesh = Mesh {
        node_tags: (1..=nodes.len() as u64).collect(),
        nodes: nodes.into_iter().map(|x| scale(x, mm)).collect(),
        cells,
        cell_regions: regions,
        region_names: BTreeMap::from([
            (REGION_BODY, "body_of_uterus".to_string()),
            (REGION_FUNDUS, "fundus".to_string()),
            (REGION_LEFT_OVIDUCT, "left_oviduct".to_string()),
            (REGION_RIGHT_OVIDUCT, "right_oviduct".to_string()),
            (REGION_VAGINA, "vagina".to_string()),
        ]),
        source: format!("builtin uterus with fallopian tubes ({level})"),
    };
    Anatomy {
        mesh,
        cervix_nodes,
        probe: ProbeSite {
            tube_region: REGION_RIGHT_OVIDUCT,
            contact_point: scale(contact, mm),
            push_direction: push,
            tube_radius_m: TUBE_R_OUT * mm,
        },
    }
}
