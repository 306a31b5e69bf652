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
use std::fmt;
use std::str::FromStr;

use crate::geom::{add, cross, dot, scale, sub, V3};
use crate::mesh::Mesh;

mod body;
mod tubes;

use body::{Grid, Midline};

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
pub(super) struct Params {
    /// Top-face quads along y (ring quads on each ±z side face).
    pub(super) m_u: usize,
    /// Top-face quads along z (ring quads on each ±y side face); `m_v - patch` even.
    pub(super) m_v: usize,
    /// Side rows on the fundus cap (above the equator).
    pub(super) n_cap: usize,
    /// Rows along the swept part (body and vagina).
    pub(super) n_axial: usize,
    /// Cell layers through the wall.
    pub(super) n_wall: usize,
    /// Tube root patch size P (odd, ≥ 3): P × P surface quads minus the centre one.
    pub(super) patch: usize,
    /// Cell layers along each tube.
    pub(super) n_tube: usize,
    /// Of which in the flared root.
    pub(super) n_flare: usize,
}

/// The hexahedral mesh as it is built, in millimetres.
pub(super) struct HexBuild {
    pub(super) nodes: Vec<V3>,
    pub(super) cells: Vec<[u32; 8]>,
    pub(super) regions: Vec<i32>,
}

/// Generate the built-in uterus-and-tubes anatomy at the given level.
pub fn generate(level: Level) -> Anatomy {
    let p = level.params();
    let mid = Midline::new();
    let g = Grid::new(p, &mid);
    let mut b = body::wall(&g, &mid);
    let mut probe = None;
    for (sign, region, i0) in [
        (1.0, REGION_RIGHT_OVIDUCT, (p.m_v - p.patch) / 2),
        (
            -1.0,
            REGION_LEFT_OVIDUCT,
            p.m_v + p.m_u + (p.m_v - p.patch) / 2,
        ),
    ] {
        let site = tubes::add_tube(&mut b, &g, sign, region, i0);
        if region == REGION_RIGHT_OVIDUCT {
            probe = Some(site);
        }
    }
    orient_cells(&b.nodes, &mut b.cells);

    // The cervix: every wall layer of the last cross-section.
    let mut cervix_nodes: Vec<u32> = (0..g.ring)
        .flat_map(|i| (0..=p.n_wall).map(move |k| (i, k)))
        .map(|(i, k)| g.wall_id(g.side(i, g.rows()), k))
        .collect();
    cervix_nodes.sort_unstable();

    let (contact, push) = probe.unwrap_or(([0.0; 3], [0.0, 0.0, -1.0]));
    let mm = 1e-3;
    let HexBuild {
        nodes,
        cells,
        regions,
    } = b;
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
        ..Mesh::default()
    };
    Anatomy {
        mesh,
        cervix_nodes,
        probe: ProbeSite {
            tube_region: REGION_RIGHT_OVIDUCT,
            contact_point: scale(contact, mm),
            push_direction: push,
            tube_radius_m: tubes::TUBE_R_OUT * mm,
        },
    }
}

/// Make every cell's Jacobian positive (mirror the node order of those that are not).
fn orient_cells(nodes: &[V3], cells: &mut [[u32; 8]]) {
    for c in cells {
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
}
