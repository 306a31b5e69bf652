//! The right ovary added under the right tube (`host_tools::mesh::ovary`).
//!
//! Volumes and Jacobians are computed here independently of the generator (own 6-tet split,
//! own corner Jacobians), so the tests check the mesh, not the generator's helpers.

use host_tools::compare::nan_max;
use std::collections::HashMap;
use std::f64::consts::PI;
use std::sync::OnceLock;

use host_tools::mesh::builtin::{generate, Anatomy, Level, REGION_RIGHT_OVIDUCT};
use host_tools::mesh::ovary::{
    add_right_ovary, OvarySite, OVARY_GAP_M, OVARY_SEMI_AXES_M, REGION_RIGHT_OVARY,
};

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}
fn det(a: V3, b: V3, c: V3) -> f64 {
    dot(cross(a, b), c)
}

struct Case {
    level: Level,
    original: Anatomy,
    combined: Anatomy,
    site: OvarySite,
}

/// Every level: the anatomy as generated, and a copy with the ovary added.
fn cases() -> &'static [Case] {
    static ALL: OnceLock<Vec<Case>> = OnceLock::new();
    ALL.get_or_init(|| {
        Level::ALL
            .iter()
            .map(|&level| {
                let original = generate(level);
                let mut combined = original.clone();
                let site = add_right_ovary(&mut combined, level);
                Case {
                    level,
                    original,
                    combined,
                    site,
                }
            })
            .collect()
    })
}

/// Signed volume from the 6-tetrahedron split along the 0–6 diagonal.
fn hex_volume(x: &[V3; 8]) -> f64 {
    const TETS: [[usize; 4]; 6] = [
        [0, 1, 2, 6],
        [0, 2, 3, 6],
        [0, 3, 7, 6],
        [0, 7, 4, 6],
        [0, 4, 5, 6],
        [0, 5, 1, 6],
    ];
    TETS.iter()
        .map(|t| {
            det(
                sub(x[t[1]], x[t[0]]),
                sub(x[t[2]], x[t[0]]),
                sub(x[t[3]], x[t[0]]),
            ) / 6.0
        })
        .sum()
}

/// For each corner, its three edge neighbours in the right-handed (ξ, η, ζ) order.
const CORNERS: [[usize; 3]; 8] = [
    [1, 3, 4],
    [2, 0, 5],
    [3, 1, 6],
    [0, 2, 7],
    [7, 5, 0],
    [4, 6, 1],
    [5, 7, 2],
    [6, 4, 3],
];

/// Smallest scaled Jacobian over the eight corners.
fn scaled_jacobian(x: &[V3; 8]) -> f64 {
    (0..8)
        .map(|c| {
            let e = CORNERS[c].map(|n| sub(x[n], x[c]));
            det(e[0], e[1], e[2]) / (norm(e[0]) * norm(e[1]) * norm(e[2]))
        })
        .fold(f64::INFINITY, f64::min)
}

/// Sorted, de-duplicated nodes of the cells in `cells`.
fn nodes_of(cells: &[[u32; 8]]) -> Vec<u32> {
    let mut v: Vec<u32> = cells.iter().flatten().copied().collect();
    v.sort_unstable();
    v.dedup();
    v
}

fn ovary_nodes(c: &Case) -> Vec<u32> {
    nodes_of(&c.combined.mesh.cells[c.site.cells.clone()])
}

// ---------------------------------------------------------------------------------------

/// The combined mesh is a valid mesh, every cell (old and new) has a positive Jacobian, and
/// the uterus part is untouched: same nodes, tags, cells, regions, clamp and probe, so
/// everything addressed by index before (cervix clamp, probe, scene selections) still means
/// the same. Exact equality: appending must not move or renumber anything.
#[test]
fn combined_mesh_valid_and_original_unchanged() {
    for c in cases() {
        let (o, m) = (&c.original.mesh, &c.combined.mesh);
        let level = c.level;
        m.validate()
            .unwrap_or_else(|e| panic!("{level}: combined mesh invalid: {e}"));
        assert!(m.unused_nodes().is_empty(), "{level}: unused nodes");
        assert!(
            m.min_scaled_jacobian() > 0.0,
            "{level}: some cell is inverted"
        );
        let (n0, c0) = (o.nodes.len(), o.cells.len());
        assert_eq!(&m.nodes[..n0], &o.nodes[..], "{level}: nodes moved");
        assert_eq!(&m.node_tags[..n0], &o.node_tags[..], "{level}: node tags");
        assert_eq!(&m.cells[..c0], &o.cells[..], "{level}: cells renumbered");
        assert_eq!(&m.cell_regions[..c0], &o.cell_regions[..], "{level}");
        assert_eq!(c.combined.cervix_nodes, c.original.cervix_nodes);
        assert_eq!(c.combined.probe, c.original.probe);
        // Tags continue 1-based after the uterus's.
        let tags: Vec<u64> = (1..=m.nodes.len() as u64).collect();
        assert_eq!(m.node_tags, tags, "{level}: node tags not 1..=n");
        assert_eq!(c.site.cells, c0..m.cells.len(), "{level}: ovary cells");
        assert_eq!(
            m.region_names.get(&REGION_RIGHT_OVARY).map(String::as_str),
            Some("right_ovary")
        );
        for (k, v) in &o.region_names {
            assert_eq!(m.region_names.get(k), Some(v), "{level}: region {k}");
        }
        assert!(m.source.contains("ovary"), "{level}: source {:?}", m.source);
    }
}

/// The ovary is a separate body: its cells use only new nodes, every new node is used, and
/// its boundary is a closed surface (every boundary edge in exactly two boundary faces),
/// i.e. a solid without cracks that touches the uterus only through contact.
#[test]
fn ovary_is_separate_closed_body() {
    for c in cases() {
        let m = &c.combined.mesh;
        let n0 = c.original.mesh.nodes.len() as u32;
        let nodes = ovary_nodes(c);
        assert_eq!(
            nodes,
            (n0..m.nodes.len() as u32).collect::<Vec<_>>(),
            "{}: the ovary must use exactly the new nodes",
            c.level
        );
        let sub = host_tools::mesh::Mesh {
            nodes: m.nodes.clone(),
            node_tags: m.node_tags.clone(),
            cells: m.cells[c.site.cells.clone()].to_vec(),
            cell_regions: m.cell_regions[c.site.cells.clone()].to_vec(),
            region_names: m.region_names.clone(),
            source: "ovary".into(),
            ..Default::default()
        };
        let mut edges: HashMap<[u32; 2], usize> = HashMap::new();
        for f in sub.boundary_faces() {
            for e in 0..4 {
                let (p, q) = (f[e], f[(e + 1) % 4]);
                *edges.entry([p.min(q), p.max(q)]).or_default() += 1;
            }
        }
        assert!(!edges.is_empty());
        let open: Vec<_> = edges.iter().filter(|(_, &n)| n != 2).take(5).collect();
        assert!(open.is_empty(), "{}: open ovary surface {open:?}", c.level);
    }
}

/// Region 6 on every ovary cell, and no sliver: the scaled Jacobian of each ovary cell
/// stays ≥ 0.25 (bad hexahedra would ruin accuracy and the explicit time step). The cell
/// count is roughly 5–10 % of the uterus's (4–11 % allowed: counts come in grid steps), so
/// the ovary does not dominate the cost.
#[test]
fn ovary_cells_tagged_and_well_shaped() {
    for c in cases() {
        let m = &c.combined.mesh;
        let mut min_sj = f64::INFINITY;
        let mut min_edge = f64::INFINITY;
        for i in c.site.cells.clone() {
            assert_eq!(
                m.cell_regions[i], REGION_RIGHT_OVARY,
                "{}: cell {i}",
                c.level
            );
            let x = m.cell_coords(i);
            min_sj = min_sj.min(scaled_jacobian(&x));
            for (k, n) in CORNERS.iter().enumerate() {
                for &j in n {
                    min_edge = min_edge.min(norm(sub(x[j], x[k])));
                }
            }
        }
        let n = c.site.cells.len();
        let share = n as f64 / c.original.mesh.cells.len() as f64;
        println!(
            "{}: ovary {n} cells ({:.1} % of the uterus), {} nodes, min scaled Jacobian \
             {min_sj:.3}, min edge {:.2} mm",
            c.level,
            100.0 * share,
            ovary_nodes(c).len(),
            min_edge * 1e3
        );
        assert!(min_sj >= 0.25, "{}: min scaled Jacobian {min_sj}", c.level);
        assert!(
            (0.04..=0.11).contains(&share),
            "{}: ovary share {share}",
            c.level
        );
    }
}

/// The volume is the ellipsoid's 4/3·π·abc within 8 % (coarse 15 %): the surface nodes lie
/// on the ellipsoid, so the faceted mesh is a bit smaller, the more so the coarser; the
/// volume must never exceed the ellipsoid's by more than rounding (the mesh is inscribed).
#[test]
fn ovary_volume_matches_ellipsoid() {
    let [a, b, cc] = OVARY_SEMI_AXES_M;
    let exact = 4.0 / 3.0 * PI * a * b * cc;
    for c in cases() {
        let m = &c.combined.mesh;
        let v: f64 = c
            .site
            .cells
            .clone()
            .map(|i| hex_volume(&m.cell_coords(i)))
            .sum();
        let tol = if c.level == Level::Coarse { 0.15 } else { 0.08 };
        println!(
            "{}: ovary volume {:.0} mm3 = {:.3} of the ellipsoid's {:.0} mm3",
            c.level,
            v * 1e9,
            v / exact,
            exact * 1e9
        );
        assert!(
            (v / exact - 1.0).abs() <= tol,
            "{}: volume {v} vs {exact}",
            c.level
        );
        assert!(
            v <= exact * (1.0 + 1e-9),
            "{}: larger than the ellipsoid",
            c.level
        );
    }
}

/// No overlap with the tube: every ovary node is at least half the gap (1.5 mm) from every
/// right-oviduct node. The designed clearance is the full 3 mm gap under the tube; half of
/// it leaves room for faceting and still catches any misplacement by a tube radius.
#[test]
fn ovary_clear_of_tube() {
    for c in cases() {
        let m = &c.combined.mesh;
        let tube: Vec<[u32; 8]> = m
            .cells
            .iter()
            .zip(&m.cell_regions)
            .filter(|(_, &r)| r == REGION_RIGHT_OVIDUCT)
            .map(|(x, _)| *x)
            .collect();
        let tube = nodes_of(&tube);
        assert!(!tube.is_empty());
        let mut min = f64::INFINITY;
        for &i in &ovary_nodes(c) {
            for &j in &tube {
                min = min.min(norm(sub(m.nodes[i as usize], m.nodes[j as usize])));
            }
        }
        println!(
            "{}: ovary to tube nodes: {:.2} mm (gap {} mm)",
            c.level,
            min * 1e3,
            OVARY_GAP_M * 1e3
        );
        assert!(min >= 0.5 * OVARY_GAP_M, "{}: distance {min}", c.level);
    }
}

/// Placement: the top of the ovary is directly under the probe, one tube diameter plus the
/// gap below the contact point, within 0.2 mm horizontally and vertically (allowance for the
/// faceting of the ellipsoid; with a node at the pole it is exact up to rounding). The top
/// point is the highest ovary node (nothing of the ovary reaches above it, so the tube
/// meets it first), the centre lies c below it, and the long axis is horizontal and along
/// the tube: +y for the built-in tube, which is straight along +y (1e-6: rounding only).
#[test]
fn ovary_placed_under_probe() {
    let c_axis = OVARY_SEMI_AXES_M[2];
    for c in cases() {
        let level = c.level;
        let p = &c.combined.probe;
        let cp = p.contact_point;
        let want = [cp[0], cp[1], cp[2] - 2.0 * p.tube_radius_m - OVARY_GAP_M];
        let t = c.site.top_point;
        let horiz = ((t[0] - want[0]).powi(2) + (t[1] - want[1]).powi(2)).sqrt();
        assert!(
            horiz <= 0.2e-3,
            "{level}: top {t:?} off the vertical by {horiz}"
        );
        assert!(
            (t[2] - want[2]).abs() <= 0.2e-3,
            "{level}: top at z {} instead of {}",
            t[2],
            want[2]
        );
        let m = &c.combined.mesh;
        let z_max = ovary_nodes(c)
            .iter()
            .map(|&i| m.nodes[i as usize][2])
            .fold(f64::NEG_INFINITY, nan_max);
        assert!(
            z_max <= t[2] + 1e-12,
            "{level}: ovary node above the top point"
        );
        let centre = c.site.centre;
        assert!(norm(sub(centre, [cp[0], cp[1], want[2] - c_axis])) <= 1e-12);
        let ax = c.site.axis;
        assert!(
            (norm(ax) - 1.0).abs() <= 1e-12 && ax[2] == 0.0,
            "{level}: {ax:?}"
        );
        assert!(
            norm(sub(ax, [0.0, 1.0, 0.0])) <= 1e-6,
            "{level}: axis {ax:?}"
        );
        // The long axis really lies along `axis`: the extent along it is 2a.
        let ext = |d: V3| {
            let s: Vec<f64> = ovary_nodes(c)
                .iter()
                .map(|&i| dot(sub(m.nodes[i as usize], centre), d))
                .collect();
            s.iter().copied().fold(f64::NEG_INFINITY, nan_max)
                - s.iter().copied().fold(f64::INFINITY, f64::min)
        };
        let along = ext(ax);
        assert!(
            (along - 2.0 * OVARY_SEMI_AXES_M[0]).abs() <= 1e-9,
            "{level}: length {along}"
        );
    }
}

/// Ligaments: the fixed nodes are exactly the ovary nodes below centre − c/2 (sorted, not
/// empty), so the lower part is held and the top is free to be pressed.
#[test]
fn fixed_nodes_are_lower_part() {
    for c in cases() {
        let m = &c.combined.mesh;
        let level = c.level;
        let f = &c.site.fixed_nodes;
        assert!(!f.is_empty(), "{level}: no fixed nodes");
        assert!(f.windows(2).all(|w| w[0] < w[1]), "{level}: not sorted");
        let z_cut = c.site.centre[2] - 0.5 * OVARY_SEMI_AXES_M[2];
        let want: Vec<u32> = ovary_nodes(c)
            .into_iter()
            .filter(|&i| m.nodes[i as usize][2] < z_cut)
            .collect();
        assert_eq!(f, &want, "{level}: fixed nodes");
        assert!(f.iter().all(|&i| m.nodes[i as usize][2] < c.site.centre[2]));
        println!("{level}: {} fixed ovary nodes", f.len());
    }
}
