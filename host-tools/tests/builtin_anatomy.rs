//! Properties of the procedurally generated built-in anatomy (`host_tools::mesh::builtin`).
//!
//! Geometry checks here are computed independently of the generator (own volume split, own
//! corner Jacobians, own reader for the reference mesh), so they test the mesh, not the
//! generator's own helpers.

use std::collections::{BTreeMap, HashMap};
use std::sync::OnceLock;

use host_tools::mesh::builtin::{generate, Anatomy, Level};
use host_tools::mesh::Mesh;

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

/// The three levels, generated once (the fine level takes a moment).
fn anatomies() -> &'static [(Level, Anatomy)] {
    static ALL: OnceLock<Vec<(Level, Anatomy)>> = OnceLock::new();
    ALL.get_or_init(|| Level::ALL.iter().map(|&l| (l, generate(l))).collect())
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

/// (raw corner Jacobian determinant, scaled Jacobian) of every corner.
fn corner_jacobians(x: &[V3; 8]) -> [(f64, f64); 8] {
    core::array::from_fn(|c| {
        let e = CORNERS[c].map(|n| sub(x[n], x[c]));
        let j = det(e[0], e[1], e[2]);
        (j, j / (norm(e[0]) * norm(e[1]) * norm(e[2])))
    })
}

const FACES: [[usize; 4]; 6] = [
    [0, 1, 2, 3],
    [4, 5, 6, 7],
    [0, 1, 5, 4],
    [1, 2, 6, 5],
    [2, 3, 7, 6],
    [3, 0, 4, 7],
];

fn face_counts(m: &Mesh) -> HashMap<[u32; 4], usize> {
    let mut faces: HashMap<[u32; 4], usize> = HashMap::new();
    for c in &m.cells {
        for f in FACES {
            let mut k = f.map(|i| c[i]);
            k.sort_unstable();
            *faces.entry(k).or_default() += 1;
        }
    }
    faces
}

fn bbox<'a>(pts: impl Iterator<Item = &'a V3>) -> (V3, V3) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in pts {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

fn extent((lo, hi): (V3, V3)) -> V3 {
    [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]]
}

/// Nodes used by the cells of one region.
fn region_nodes(nodes: &[V3], cells: &[[u32; 8]], regions: &[i32], r: i32) -> Vec<V3> {
    let mut ids: Vec<u32> = cells
        .iter()
        .zip(regions)
        .filter(|(_, &g)| g == r)
        .flat_map(|(c, _)| c.iter().copied())
        .collect();
    ids.sort_unstable();
    ids.dedup();
    ids.into_iter().map(|i| nodes[i as usize]).collect()
}

// ---------------------------------------------------------------------------------------

/// Cell counts: each level must be within ±30 % of its nominal size (300 / 2000 / 20000),
/// because scenes and benchmarks pick a level by the cost they expect.
#[test]
fn cell_counts_near_nominal() {
    for (level, a) in anatomies() {
        let n = a.mesh.cells.len() as f64;
        let nominal = level.nominal_cells() as f64;
        println!(
            "{level}: {} cells, {} nodes",
            a.mesh.cells.len(),
            a.mesh.nodes.len()
        );
        assert!(
            (n / nominal - 1.0).abs() <= 0.3,
            "{level}: {n} cells, nominal {nominal}"
        );
        assert_eq!(a.mesh.cell_regions.len(), a.mesh.cells.len());
        assert_eq!(a.mesh.node_tags.len(), a.mesh.nodes.len());
    }
}

/// Element validity: every cell's signed volume (6-tet split) and every corner Jacobian must
/// be positive (an inverted or folded hexahedron breaks the explicit FEM), the scaled
/// Jacobian must stay ≥ 0.2 everywhere (no slivers, which would ruin accuracy and the
/// stable time step), and no edge may be shorter than 0.15 mm (the reference's finest mesh
/// has 0.17 mm; the shortest edge sets the explicit time step).
#[test]
fn cells_positive_and_well_shaped() {
    for (level, a) in anatomies() {
        let m = &a.mesh;
        let mut min_sj = f64::INFINITY;
        let mut min_edge = f64::INFINITY;
        for c in 0..m.cells.len() {
            let x = m.cell_coords(c);
            for (k, n) in CORNERS.iter().enumerate() {
                for &j in n {
                    min_edge = min_edge.min(norm(sub(x[j], x[k])));
                }
            }
            let v = hex_volume(&x);
            assert!(v > 0.0, "{level}: cell {c} volume {v}");
            for (k, (j, sj)) in corner_jacobians(&x).iter().enumerate() {
                assert!(*j > 0.0, "{level}: cell {c} corner {k} Jacobian {j}");
                min_sj = min_sj.min(*sj);
            }
        }
        println!(
            "{level}: min scaled Jacobian {min_sj:.3}, min edge {:.3} mm",
            min_edge * 1e3
        );
        assert!(min_sj >= 0.2, "{level}: min scaled Jacobian {min_sj}");
        assert!(min_edge >= 0.15e-3, "{level}: min edge {min_edge} m");
        let lib = m.min_scaled_jacobian();
        assert!(
            (lib - min_sj).abs() < 1e-12,
            "library {lib} vs test {min_sj}"
        );
    }
}

/// Conformity: every face belongs to one cell (boundary) or two (interior), never more; no
/// two distinct nodes coincide (a crack would show up as duplicated nodes); the boundary
/// surface is closed (every boundary edge is shared by exactly two boundary faces); every
/// node is used; and the mesh is one connected piece (union-find over the cells' nodes).
/// A non-conforming or cracked mesh lets the parts separate in the simulation.
#[test]
fn conforming_closed_and_connected() {
    for (level, a) in anatomies() {
        let m = &a.mesh;
        let faces = face_counts(m);
        let over: Vec<_> = faces.iter().filter(|(_, &n)| n > 2).collect();
        assert!(over.is_empty(), "{level}: faces in >2 cells: {over:?}");

        // Boundary edges: each in exactly two boundary faces.
        let mut edges: HashMap<[u32; 2], usize> = HashMap::new();
        for c in &m.cells {
            for f in FACES {
                let mut key = f.map(|i| c[i]);
                key.sort_unstable();
                if faces[&key] != 1 {
                    continue;
                }
                for e in 0..4 {
                    let (p, q) = (c[f[e]], c[f[(e + 1) % 4]]);
                    *edges.entry([p.min(q), p.max(q)]).or_default() += 1;
                }
            }
        }
        let open: Vec<_> = edges.iter().filter(|(_, &n)| n != 2).take(5).collect();
        assert!(open.is_empty(), "{level}: open boundary edges {open:?}");

        // No coincident nodes (grid hash on 1 µm cells, check neighbours exactly).
        let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, p) in m.nodes.iter().enumerate() {
            grid.entry(p.map(|x| (x * 1e6).floor() as i64))
                .or_default()
                .push(i);
        }
        for (i, p) in m.nodes.iter().enumerate() {
            let k = p.map(|x| (x * 1e6).floor() as i64);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        if let Some(v) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                            for &j in v {
                                assert!(
                                    j == i || norm(sub(m.nodes[j], *p)) > 1e-9,
                                    "{level}: nodes {i} and {j} coincide"
                                );
                            }
                        }
                    }
                }
            }
        }

        // Union-find.
        let n = m.nodes.len();
        let mut parent: Vec<usize> = (0..n).collect();
        fn find(p: &mut [usize], mut x: usize) -> usize {
            while p[x] != x {
                p[x] = p[p[x]];
                x = p[x];
            }
            x
        }
        let mut used = vec![false; n];
        for c in &m.cells {
            for &v in c {
                used[v as usize] = true;
                let (ra, rb) = (
                    find(&mut parent, c[0] as usize),
                    find(&mut parent, v as usize),
                );
                parent[ra] = rb;
            }
        }
        assert!(used.iter().all(|&u| u), "{level}: unused nodes");
        let root = find(&mut parent, 0);
        assert!(
            (0..n).all(|i| find(&mut parent, i) == root),
            "{level}: mesh is not one connected piece"
        );
    }
}

/// Regions: the five physical groups of the reference (same tags and names) are all present
/// at every level, so scenes can address them by tag or name; and the total volume
/// converges (coarse within 10 % of fine, medium closer), so the levels model the same
/// organ.
#[test]
fn regions_named_and_volume_converges() {
    let expected = BTreeMap::from([
        (1, "body_of_uterus"),
        (2, "fundus"),
        (3, "left_oviduct"),
        (4, "right_oviduct"),
        (5, "vagina"),
    ]);
    let mut volumes = Vec::new();
    for (level, a) in anatomies() {
        let m = &a.mesh;
        let names: BTreeMap<i32, &str> = m
            .region_names
            .iter()
            .map(|(k, v)| (*k, v.as_str()))
            .collect();
        assert_eq!(names, expected, "{level}");
        let mut per = BTreeMap::<i32, (usize, f64)>::new();
        for (c, &r) in m.cell_regions.iter().enumerate() {
            let e = per.entry(r).or_default();
            e.0 += 1;
            e.1 += hex_volume(&m.cell_coords(c));
        }
        assert_eq!(per.keys().copied().collect::<Vec<_>>(), vec![1, 2, 3, 4, 5]);
        for (r, (n, v)) in &per {
            println!(
                "{level}: region {r} {}: {n} cells, {:.0} mm3",
                expected[r],
                v * 1e9
            );
        }
        volumes.push(per.values().map(|x| x.1).sum::<f64>());
    }
    let fine = volumes[2];
    println!(
        "total volume mm3: {:?}",
        volumes.iter().map(|v| v * 1e9).collect::<Vec<_>>()
    );
    assert!((volumes[0] / fine - 1.0).abs() < 0.10, "coarse vs fine");
    assert!((volumes[1] / fine - 1.0).abs() < 0.05, "medium vs fine");
}

/// Minimal Gmsh MSH 4.1 ASCII reader: node coordinates by tag, and hexahedra (type 5) with
/// the physical tag of their volume entity.
struct Reference {
    nodes: Vec<V3>,
    cells: Vec<[u32; 8]>,
    regions: Vec<i32>,
}

fn read_reference(path: &str) -> Reference {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| {
        panic!(
            "reference mesh {path} is missing or unreadable ({e}); it lives in /work/shared/meshes"
        )
    });
    let lines: Vec<&str> = text.lines().collect();
    let nums = |l: &str| -> Vec<f64> {
        l.split_whitespace()
            .map(|t| t.parse::<f64>().expect("number in msh"))
            .collect()
    };
    let mut entity_phys: HashMap<i64, i32> = HashMap::new();
    let mut by_tag: HashMap<u64, V3> = HashMap::new();
    let mut raw_cells: Vec<([u64; 8], i32)> = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        match lines[i].trim() {
            "$Entities" => {
                let c = nums(lines[i + 1]);
                let skip = (c[0] + c[1] + c[2]) as usize;
                let mut j = i + 2 + skip;
                for _ in 0..c[3] as usize {
                    let v = nums(lines[j]);
                    let nphys = v[7] as usize;
                    if nphys > 0 {
                        entity_phys.insert(v[0] as i64, v[8] as i32);
                    }
                    j += 1;
                }
                i = j;
            }
            "$Nodes" => {
                let h = nums(lines[i + 1]);
                let mut j = i + 2;
                for _ in 0..h[0] as usize {
                    let b = nums(lines[j]);
                    let n = b[3] as usize;
                    for k in 0..n {
                        let tag = lines[j + 1 + k].trim().parse::<u64>().expect("node tag");
                        let x = nums(lines[j + 1 + n + k]);
                        by_tag.insert(tag, [x[0], x[1], x[2]]);
                    }
                    j += 1 + 2 * n;
                }
                i = j;
            }
            "$Elements" => {
                let h = nums(lines[i + 1]);
                let mut j = i + 2;
                for _ in 0..h[0] as usize {
                    let b = nums(lines[j]);
                    let n = b[3] as usize;
                    let phys = entity_phys.get(&(b[1] as i64)).copied().unwrap_or(0);
                    for k in 0..n {
                        if b[2] as i64 == 5 {
                            let v = nums(lines[j + 1 + k]);
                            raw_cells.push((core::array::from_fn(|a| v[a + 1] as u64), phys));
                        }
                    }
                    j += 1 + n;
                }
                i = j;
            }
            _ => i += 1,
        }
    }
    let mut tags: Vec<u64> = by_tag.keys().copied().collect();
    tags.sort_unstable();
    let index: HashMap<u64, u32> = tags
        .iter()
        .enumerate()
        .map(|(i, t)| (*t, i as u32))
        .collect();
    Reference {
        nodes: tags.iter().map(|t| by_tag[t]).collect(),
        cells: raw_cells
            .iter()
            .map(|(c, _)| c.map(|t| index[&t]))
            .collect(),
        regions: raw_cells.iter().map(|(_, r)| *r).collect(),
    }
}

/// Tube length (extent along the tube, y) and diameter (x/z extent of the nodes in the
/// tube's far-end cross-section, which avoids the flared root).
fn tube_dims(pts: &[V3]) -> (f64, f64) {
    let (lo, hi) = bbox(pts.iter());
    let far = if hi[1].abs() > lo[1].abs() {
        hi[1]
    } else {
        lo[1]
    };
    let end: Vec<V3> = pts
        .iter()
        .copied()
        .filter(|p| (p[1] - far).abs() < 1e-6)
        .collect();
    let e = extent(bbox(end.iter()));
    (hi[1] - lo[1], 0.5 * (e[0] + e[2]))
}

/// Proportions: overall extents, per-region extents of body and fundus, and each tube's
/// length and diameter must be within 30 % of the reference mesh
/// (`uterus_scaffold_hex2k.msh`), so the built-in scene is the same anatomy at the same
/// scale. Reference (mm): overall 159.5 × 280 × 112.7, tubes 99.5 long, 3.5 across.
#[test]
fn proportions_match_reference() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/meshes/uterus_scaffold_hex2k.msh"
    );
    let r = read_reference(path);
    assert_eq!(r.cells.len(), 2560, "unexpected reference mesh");
    let close = |what: &str, got: f64, want: f64| {
        println!(
            "  {what}: generated {:.1} mm, reference {:.1} mm",
            got * 1e3,
            want * 1e3
        );
        assert!(
            (got / want - 1.0).abs() <= 0.3,
            "{what}: {got} vs reference {want}"
        );
    };
    let ref_ext = extent(bbox(r.nodes.iter()));
    let ref_reg = |g: i32| region_nodes(&r.nodes, &r.cells, &r.regions, g);
    for (level, a) in anatomies() {
        println!("{level}:");
        let m = &a.mesh;
        let ext = extent(m.bounding_box());
        for k in 0..3 {
            close(
                &format!("overall extent {}", ["x", "y", "z"][k]),
                ext[k],
                ref_ext[k],
            );
        }
        let reg = |g: i32| region_nodes(&m.nodes, &m.cells, &m.cell_regions, g);
        for (g, name) in [(1, "body_of_uterus"), (2, "fundus"), (5, "vagina")] {
            let (e, re) = (extent(bbox(reg(g).iter())), extent(bbox(ref_reg(g).iter())));
            for k in 0..3 {
                if g == 1 && k == 1 {
                    // The reference body's y extent includes its tube-root bulges.
                    continue;
                }
                close(
                    &format!("{name} extent {}", ["x", "y", "z"][k]),
                    e[k],
                    re[k],
                );
            }
        }
        for (g, name) in [(3, "left_oviduct"), (4, "right_oviduct")] {
            let (len, dia) = tube_dims(&reg(g));
            let (rlen, rdia) = tube_dims(&ref_reg(g));
            close(&format!("{name} length"), len, rlen);
            close(&format!("{name} diameter"), dia, rdia);
        }
    }
}

/// Probe site: the contact point is on the outer surface of the pushed tube (within 1 mm of
/// its surface nodes, at the tube radius from its axis, away from the ends), and the push
/// direction is a unit vector perpendicular to the tube axis (1e-9), pointing at the axis.
#[test]
fn probe_site_on_tube() {
    for (level, a) in anatomies() {
        let m = &a.mesh;
        let p = &a.probe;
        assert_eq!(p.tube_region, 4, "the right tube");
        let tube = region_nodes(&m.nodes, &m.cells, &m.cell_regions, p.tube_region);
        let (lo, hi) = bbox(tube.iter());
        // Axis: through the centroids of the far-end section and of the contact's section.
        let centroid = |f: &dyn Fn(&V3) -> bool| {
            let sel: Vec<&V3> = tube.iter().filter(|q| f(q)).collect();
            assert!(!sel.is_empty());
            let n = sel.len() as f64;
            let s = sel
                .iter()
                .fold([0.0; 3], |a, q| [a[0] + q[0], a[1] + q[1], a[2] + q[2]]);
            s.map(|x| x / n)
        };
        let c_end = centroid(&|q| (q[1] - hi[1]).abs() < 1e-9);
        let c_mid = centroid(&|q| (q[1] - p.contact_point[1]).abs() < 1e-4);
        let axis = sub(c_end, c_mid);
        let axis = axis.map(|x| x / norm(axis));
        let d = p.push_direction;
        assert!((norm(d) - 1.0).abs() < 1e-12, "{level}: push not unit");
        assert!(
            dot(d, axis).abs() < 1e-9,
            "{level}: push·axis = {}",
            dot(d, axis)
        );
        // Radial distance of the contact point from the axis = tube radius; push points inward.
        let rel = sub(p.contact_point, c_mid);
        let radial = sub(rel, axis.map(|x| x * dot(rel, axis)));
        assert!(
            (norm(radial) - p.tube_radius_m).abs() < 1e-4,
            "{level}: not on surface"
        );
        assert!(dot(radial, d) < 0.0, "{level}: push points outward");
        // Near the tube's outer-surface nodes (those at the tube radius from the axis).
        let on_surface = |q: &V3| {
            let rel = sub(*q, c_mid);
            let radial = sub(rel, axis.map(|x| x * dot(rel, axis)));
            (norm(radial) - p.tube_radius_m).abs() < 1e-5
        };
        let nearest = tube
            .iter()
            .filter(|q| on_surface(q))
            .map(|q| norm(sub(*q, p.contact_point)))
            .fold(f64::INFINITY, f64::min);
        println!(
            "{level}: probe {:?}, nearest tube node {:.3} mm",
            p.contact_point,
            nearest * 1e3
        );
        assert!(
            nearest < 1e-3,
            "{level}: contact point {nearest} m from tube nodes"
        );
        // Roughly halfway along the tube, not at an end.
        let t = (p.contact_point[1] - lo[1]) / (hi[1] - lo[1]);
        assert!(
            (0.25..=0.75).contains(&t),
            "{level}: contact at fraction {t}"
        );
        assert!(p.tube_radius_m > 1e-3 && p.tube_radius_m < 3e-3);
    }
}

/// Cervix clamp: the clamped set is non-empty, valid, free of duplicates, and lies at the
/// lower (vaginal) end: every clamped node is in the lowest 10 % of the mesh's height and
/// in the vagina region, so fixing them holds the organ at its cervical end only.
#[test]
fn cervix_nodes_at_lower_end() {
    for (level, a) in anatomies() {
        let m = &a.mesh;
        let c = &a.cervix_nodes;
        assert!(!c.is_empty(), "{level}");
        assert!(
            c.windows(2).all(|w| w[0] < w[1]),
            "{level}: not sorted/unique"
        );
        assert!(c.iter().all(|&i| (i as usize) < m.nodes.len()));
        let (lo, hi) = m.bounding_box();
        let limit = lo[2] + 0.1 * (hi[2] - lo[2]);
        assert!(
            c.iter().all(|&i| m.nodes[i as usize][2] <= limit),
            "{level}"
        );
        let vagina = region_nodes(&m.nodes, &m.cells, &m.cell_regions, 5);
        assert!(c.iter().all(|&i| vagina.contains(&m.nodes[i as usize])));
        // The lowest node of the whole mesh is clamped.
        let lowest = (0..m.nodes.len())
            .min_by(|&x, &y| m.nodes[x][2].total_cmp(&m.nodes[y][2]))
            .unwrap();
        assert!(c.contains(&(lowest as u32)), "{level}");
    }
}

/// Levels parse from their names and nominal sizes, round-trip through Display, and reject
/// anything else (user input from the command line).
#[test]
fn level_parsing() {
    for (s, l) in [
        ("coarse", Level::Coarse),
        ("Medium", Level::Medium),
        (" fine ", Level::Fine),
        ("300", Level::Coarse),
        ("2000", Level::Medium),
        ("20000", Level::Fine),
    ] {
        assert_eq!(s.parse::<Level>(), Ok(l));
    }
    for l in Level::ALL {
        assert_eq!(l.to_string().parse::<Level>(), Ok(l));
    }
    for bad in ["", "ultra", "301", "-1"] {
        assert!(bad.parse::<Level>().is_err(), "{bad:?}");
    }
}

/// Determinism: generating the same level twice gives bit-identical anatomy, so scenes and
/// recorded runs are reproducible.
#[test]
fn deterministic() {
    assert_eq!(generate(Level::Medium), generate(Level::Medium));
}
