//! Mesh import, validation, boundary extraction, box generation and ParaView output.
//!
//! The real-mesh tests read `../shared/meshes/` beside the repository and fail (never skip)
//! when it is absent.

use host_tools::compare::nan_max;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

mod common;

use common::TempDir;
use host_tools::mesh::grid::generate_box;
use host_tools::mesh::io::load_mesh;
use host_tools::mesh::{Mesh, MeshError};
use host_tools::output::vtk::{self, PointField, VtkSeriesWriter};

// ---------------------------------------------------------------------------------------
// helpers
// ---------------------------------------------------------------------------------------

fn meshes_dir() -> PathBuf {
    let dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/meshes"));
    assert!(
        dir.is_dir(),
        "shared mesh folder {} is absent: the real-mesh tests need ../shared/meshes beside \
         the repository",
        dir.display()
    );
    dir
}

fn load_shared(name: &str) -> Mesh {
    let path = meshes_dir().join(name);
    assert!(path.is_file(), "shared mesh {} is missing", path.display());
    match load_mesh(&path) {
        Ok(m) => m,
        Err(e) => panic!("loading {name} failed: {e}"),
    }
}

/// A fresh, empty directory for one test, removed when dropped ([`common::temp_dir`]).
fn temp_dir(tag: &str) -> TempDir {
    common::temp_dir(&format!("mesh-io-{tag}"))
}

/// Write `text` to `file` in a fresh temp dir; keep the returned guard alive while using it.
fn write_temp(tag: &str, file: &str, text: &str) -> (TempDir, PathBuf) {
    let dir = temp_dir(tag);
    let path = dir.join(file);
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Signed volume of a hexahedron as the sum of six tetrahedra around the 0-6 diagonal.
/// Independent of the library's Jacobian code; positive for a correctly ordered cell.
fn hex_volume(x: &[[f64; 3]; 8]) -> f64 {
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
            let (a, b, c, d) = (x[t[0]], x[t[1]], x[t[2]], x[t[3]]);
            dot(sub(b, a), cross(sub(c, a), sub(d, a))) / 6.0
        })
        .sum()
}

/// Volume enclosed by the boundary faces (divergence theorem, each quad as the average of its
/// two triangulations). Positive only if the faces are oriented outward.
fn enclosed_volume(mesh: &Mesh, faces: &[[u32; 4]]) -> f64 {
    let tri = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| dot(a, cross(b, c)) / 6.0;
    faces
        .iter()
        .map(|f| {
            let p = f.map(|i| mesh.nodes[i as usize]);
            0.5 * (tri(p[0], p[1], p[2])
                + tri(p[0], p[2], p[3])
                + tri(p[0], p[1], p[3])
                + tri(p[1], p[2], p[3]))
        })
        .sum()
}

fn total_volume(mesh: &Mesh) -> f64 {
    (0..mesh.cells.len())
        .map(|c| hex_volume(&mesh.cell_coords(c)))
        .sum()
}

/// Checks every imported mesh must pass: counts, consistency, positive cells, every node used,
/// and a closed outward boundary enclosing the mesh volume.
fn check_mesh(mesh: &Mesh, cells: usize, nodes: usize) {
    assert!(!mesh.source.is_empty(), "the mesh says where it came from");
    assert_eq!(mesh.cells.len(), cells, "{}: cell count", mesh.source);
    assert_eq!(mesh.nodes.len(), nodes, "{}: node count", mesh.source);
    assert_eq!(mesh.node_tags.len(), nodes);
    assert_eq!(mesh.cell_regions.len(), cells);
    mesh.validate().unwrap();
    for c in 0..mesh.cells.len() {
        let v = hex_volume(&mesh.cell_coords(c));
        assert!(v > 0.0, "{}: cell {c} has volume {v}", mesh.source);
    }
    let used: BTreeSet<u32> = mesh.cells.iter().flatten().copied().collect();
    assert_eq!(
        used.len(),
        nodes,
        "{}: every node belongs to a cell",
        mesh.source
    );
    let faces = mesh.boundary_faces();
    let (vb, vc) = (enclosed_volume(mesh, &faces), total_volume(mesh));
    assert!(
        (vb - vc).abs() < 1e-3 * vc,
        "{}: boundary encloses {vb}, cells sum to {vc}",
        mesh.source
    );
}

// ---------------------------------------------------------------------------------------
// real meshes
// ---------------------------------------------------------------------------------------

/// The coarse uterus: counts, the five named regions, positive cells, outward boundary, and
/// the README's minimum scaled Jacobian (our corner-based definition must agree with it).
#[test]
fn uterus_hex320_counts_regions_and_quality() {
    let m = load_shared("uterus_scaffold_hex320.msh");
    check_mesh(&m, 320, 674);
    let names: BTreeMap<i32, String> = [
        (1, "body_of_uterus"),
        (2, "fundus"),
        (3, "left_oviduct"),
        (4, "right_oviduct"),
        (5, "vagina"),
    ]
    .into_iter()
    .map(|(k, v)| (k, v.to_string()))
    .collect();
    assert_eq!(m.region_names, names);
    let used: BTreeSet<i32> = m.cell_regions.iter().copied().collect();
    assert_eq!(
        used,
        (1..=5).collect(),
        "every cell is in one of the five regions"
    );
    // Node tags in file order: this file numbers them 1..=674.
    assert_eq!(m.node_tags, (1..=674).collect::<Vec<u64>>());
    let msj = m.min_scaled_jacobian();
    assert!(
        (msj - 0.34).abs() < 0.01,
        "min scaled Jacobian {msj}, README says 0.34"
    );
}

/// The hand-written MSH parser must agree with the independent `mshio` crate on the same file
/// (node coordinates and hexahedron connectivity, mapped through node tags).
#[test]
fn msh_parser_agrees_with_mshio() {
    let path = meshes_dir().join("uterus_scaffold_hex320.msh");
    let ours = load_mesh(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let theirs = mshio::parse_msh_bytes(&bytes).unwrap();
    let nodes = theirs.data.nodes.as_ref().unwrap();
    let coords: Vec<[f64; 3]> = nodes
        .node_blocks
        .iter()
        .flat_map(|b| b.nodes.iter().map(|n| [n.x, n.y, n.z]))
        .collect();
    assert_eq!(ours.nodes, coords);
    // Tags in this file are dense 1..=N in order, so mshio's element node tags are index + 1.
    let cells: Vec<[u32; 8]> = theirs
        .data
        .elements
        .as_ref()
        .unwrap()
        .element_blocks
        .iter()
        .filter(|b| b.element_type == mshio::ElementType::Hex8)
        .flat_map(|b| b.elements.iter())
        .map(|e| core::array::from_fn(|a| (e.nodes[a] - 1) as u32))
        .collect();
    assert_eq!(ours.cells, cells);
}

/// Number of cells per region.
fn region_counts(m: &Mesh) -> BTreeMap<i32, usize> {
    let mut c = BTreeMap::new();
    for &r in &m.cell_regions {
        *c.entry(r).or_insert(0) += 1;
    }
    c
}

/// Sorted (cell, region) pairs: the .msh and .vtk list the same cells in different orders.
fn sorted_cells(m: &Mesh) -> Vec<([u32; 8], i32)> {
    let mut v: Vec<_> = m
        .cells
        .iter()
        .copied()
        .zip(m.cell_regions.iter().copied())
        .collect();
    v.sort_unstable();
    v
}

/// The refined uterus as .msh and .vtk must be the same mesh: same nodes in the same order,
/// the same cells with the same regions (the .vtk carries them as cell data "region").
#[test]
fn uterus_hex2k_msh_and_vtk_agree() {
    let msh = load_shared("uterus_scaffold_hex2k.msh");
    let vtk = load_shared("uterus_scaffold_hex2k.vtk");
    check_mesh(&msh, 2560, 3945);
    check_mesh(&vtk, 2560, 3945);
    assert_eq!(msh.nodes, vtk.nodes);
    assert_eq!(sorted_cells(&msh), sorted_cells(&vtk));
    // Cells per region, cross-checked independently with meshio 5.3.5's reader.
    let expect: BTreeMap<i32, usize> = [(1, 1024), (2, 256), (3, 320), (4, 320), (5, 640)].into();
    assert_eq!(region_counts(&vtk), expect, "the .vtk region data was read");
    let msj = msh.min_scaled_jacobian();
    assert!(
        (msj - 0.42).abs() < 0.01,
        "min scaled Jacobian {msj}, README says 0.42"
    );
}

/// Voxel liver: .msh and .vtk give the same geometry; the .vtk has no region data, so its
/// cells get region 0, while the .msh puts all of them in group 1 "tissue". Voxels are cubes.
#[test]
fn liver_hex2k_msh_and_vtk_agree() {
    let msh = load_shared("sofaenv_liver_hex2k.msh");
    let vtk = load_shared("sofaenv_liver_hex2k.vtk");
    check_mesh(&msh, 1997, 2736);
    check_mesh(&vtk, 1997, 2736);
    assert_eq!(msh.nodes, vtk.nodes);
    let mut a = msh.cells.clone();
    let mut b = vtk.cells.clone();
    a.sort_unstable();
    b.sort_unstable();
    assert_eq!(a, b);
    assert!(msh.cell_regions.iter().all(|&r| r == 1));
    assert!(vtk.cell_regions.iter().all(|&r| r == 0));
    assert_eq!(msh.region_names.get(&1).map(String::as_str), Some("tissue"));
    assert!((msh.min_scaled_jacobian() - 1.0).abs() < 1e-6);
}

/// Voxel gallbladder: counts and consistency.
#[test]
fn gallbladder_hex2k() {
    let m = load_shared("sofaenv_gallbladder_hex2k.msh");
    check_mesh(&m, 1997, 2839);
}

/// The two 20k meshes: counts and consistency at the size the solver will really run.
#[test]
fn large_meshes_hex20k() {
    let liver = load_shared("sofaenv_liver_hex20k.msh");
    check_mesh(&liver, 19995, 23413);
    let uterus = load_shared("uterus_scaffold_hex20k.msh");
    check_mesh(&uterus, 20480, 25955);
    let used: BTreeSet<i32> = uterus.cell_regions.iter().copied().collect();
    assert_eq!(used, (1..=5).collect());
    let msj = uterus.min_scaled_jacobian();
    assert!(
        (msj - 0.48).abs() < 0.01,
        "min scaled Jacobian {msj}, README says 0.48"
    );
}

// ---------------------------------------------------------------------------------------
// generated box, validation, boundary
// ---------------------------------------------------------------------------------------

/// The generated box has the expected counts, extent, tags and region, cube-shaped cells of
/// the right volume, and the closed-form boundary face and node counts.
#[test]
fn generated_box_counts_and_boundary() {
    let (nx, ny, nz) = (3usize, 4usize, 5usize);
    let size = [0.03, 0.02, 0.05];
    let m = generate_box(size, [nx, ny, nz]);
    check_mesh(&m, nx * ny * nz, (nx + 1) * (ny + 1) * (nz + 1));
    assert_eq!(m.bounding_box(), ([0.0; 3], size));
    assert_eq!(m.node_tags.first(), Some(&1));
    assert!(m.cell_regions.iter().all(|&r| r == 1));
    assert_eq!(m.region_names.get(&1).map(String::as_str), Some("box"));
    let cell_vol = size[0] * size[1] * size[2] / (nx * ny * nz) as f64;
    for c in 0..m.cells.len() {
        assert!((hex_volume(&m.cell_coords(c)) - cell_vol).abs() < 1e-12 * cell_vol.max(1.0));
    }
    assert!((m.min_scaled_jacobian() - 1.0).abs() < 1e-12);
    let faces = m.boundary_faces();
    assert_eq!(faces.len(), 2 * (nx * ny + ny * nz + nx * nz));
    let interior = (nx - 1) * (ny - 1) * (nz - 1);
    assert_eq!(m.boundary_nodes().len(), m.nodes.len() - interior);
    let vol = size[0] * size[1] * size[2];
    assert!((enclosed_volume(&m, &faces) - vol).abs() < 1e-12);
}

/// Each boundary face of a box lies on one side of the box and its normal points away from
/// the box centre: a per-face check of the outward orientation.
#[test]
fn box_boundary_faces_point_outward() {
    let size = [1.0, 2.0, 3.0];
    let m = generate_box(size, [2, 2, 2]);
    let centre = [0.5, 1.0, 1.5];
    for f in m.boundary_faces() {
        let p = f.map(|i| m.nodes[i as usize]);
        let n = cross(sub(p[2], p[0]), sub(p[3], p[1]));
        let c = [0, 1, 2].map(|k| p.iter().map(|q| q[k]).sum::<f64>() / 4.0);
        assert!(dot(n, sub(c, centre)) > 0.0, "face {f:?} points inward");
    }
}

/// A single cell is all boundary: six faces, eight nodes.
#[test]
fn single_cell_boundary() {
    let m = generate_box([1.0; 3], [1, 1, 1]);
    assert_eq!(m.boundary_faces().len(), 6);
    assert_eq!(m.boundary_nodes(), (0..8).collect::<Vec<u32>>());
}

/// `validate` catches each topological defect and names it.
#[test]
fn validate_rejects_broken_topology() {
    let good = generate_box([1.0; 3], [2, 1, 1]);
    good.validate().unwrap();

    let mut m = good.clone();
    m.cells[1][3] = m.cells[1][0];
    let e = m.validate().unwrap_err().to_string();
    assert!(matches!(m.validate(), Err(MeshError::RepeatedNode { .. })));
    assert!(e.contains("cell 1"), "{e}");

    let mut m = good.clone();
    m.cells[0][5] = 99;
    let e = m.validate().unwrap_err().to_string();
    assert!(e.contains("cell 0") && e.contains("99"), "{e}");

    let mut m = good.clone();
    m.cell_regions.pop();
    let e = m.validate().unwrap_err().to_string();
    assert!(
        e.contains("cell_regions") && e.contains('1') && e.contains('2'),
        "{e}"
    );

    let mut m = good;
    m.nodes[4][1] = f64::NAN;
    let e = m.validate().unwrap_err().to_string();
    assert!(e.contains("node 5"), "node tags are 1-based: {e}");
}

/// An inverted (mirrored) cell has a negative scaled Jacobian.
#[test]
fn scaled_jacobian_detects_inversion() {
    let mut m = generate_box([1.0; 3], [1, 1, 1]);
    for p in &mut m.nodes {
        p[2] = -p[2];
    }
    assert!(m.min_scaled_jacobian() < 0.0);
}

// ---------------------------------------------------------------------------------------
// small MSH files, good and broken
// ---------------------------------------------------------------------------------------

/// A unit cube as MSH 4.1 with a quad boundary element, nodes given with `tags` in file order
/// (coordinates follow the tags, so any permutation describes the same cube).
fn cube_msh(tags: [u64; 8], element_nodes: &str) -> String {
    let corner = |t: u64| match t {
        1 => "0 0 0",
        2 => "1 0 0",
        3 => "1 1 0",
        4 => "0 1 0",
        5 => "0 0 1",
        6 => "1 0 1",
        7 => "1 1 1",
        _ => "0 1 1",
    };
    let mut s = String::from(
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n2\n2 3 \"skin\"\n\
         3 7 \"liver tissue\"\n$EndPhysicalNames\n$Entities\n0 0 1 1\n\
         1 0 0 0 1 1 0 1 3 0\n1 0 0 0 1 1 1 1 7 1 1\n$EndEntities\n$Nodes\n1 8 1 8\n3 1 0 8\n",
    );
    for t in tags {
        s += &format!("{t}\n");
    }
    for t in tags {
        s += corner(t);
        s += "\n";
    }
    s += "$EndNodes\n$Elements\n2 2 1 2\n2 1 3 1\n1 1 2 3 4\n3 1 5 1\n";
    s += &format!("2 {element_nodes}\n$EndElements\n");
    s
}

/// A minimal valid file: one hex in region 7 with its name (spaces kept), the quad ignored.
#[test]
fn msh_minimal_cube() {
    let (_tmp, path) = write_temp(
        "cube",
        "cube.msh",
        &cube_msh([1, 2, 3, 4, 5, 6, 7, 8], "1 2 3 4 5 6 7 8"),
    );
    let m = load_mesh(&path).unwrap();
    assert_eq!(m.cells, vec![[0, 1, 2, 3, 4, 5, 6, 7]]);
    assert_eq!(m.cell_regions, vec![7]);
    assert_eq!(
        m.region_names.get(&7).map(String::as_str),
        Some("liver tissue")
    );
    assert_eq!(
        m.region_names.len(),
        1,
        "only volume (dim 3) names are kept"
    );
    assert!((hex_volume(&m.cell_coords(0)) - 1.0).abs() < 1e-15);
    assert_eq!(m.source, path.display().to_string());
}

/// Node tags listed in a permuted order must be mapped through the tags, not assumed to be
/// 1..N in order (the case `mshio` 0.4 gets wrong); node_tags keeps the file order.
#[test]
fn msh_permuted_node_tags() {
    let tags = [8, 7, 6, 5, 4, 3, 2, 1];
    let (_tmp, path) = write_temp("perm", "perm.msh", &cube_msh(tags, "1 2 3 4 5 6 7 8"));
    let m = load_mesh(&path).unwrap();
    assert_eq!(m.node_tags, tags.to_vec());
    assert_eq!(m.cells, vec![[7, 6, 5, 4, 3, 2, 1, 0]]);
    assert_eq!(m.cell_coords(0)[0], [0.0, 0.0, 0.0]);
    assert_eq!(m.cell_coords(0)[6], [1.0, 1.0, 1.0]);
    assert!((hex_volume(&m.cell_coords(0)) - 1.0).abs() < 1e-15);
}

fn err_text(path: &Path) -> String {
    match load_mesh(path) {
        Ok(_) => panic!("{} loaded but should have failed", path.display()),
        Err(e) => {
            eprintln!("{e}");
            e.to_string()
        }
    }
}

/// A missing file is reported as such, with its name.
#[test]
fn error_missing_file() {
    let dir = temp_dir("missing");
    let path = dir.join("no_such_mesh.msh");
    let e = load_mesh(&path).unwrap_err();
    assert!(matches!(e, MeshError::NotFound { .. }));
    assert!(e.to_string().contains("no_such_mesh.msh"), "{e}");
    assert!(e.to_string().contains("not found"), "{e}");
}

/// An unknown extension is rejected before reading, naming the file and the extension.
#[test]
fn error_unsupported_extension() {
    let (_tmp, path) = write_temp("ext", "organ.stl", "solid x\nendsolid x\n");
    let e = err_text(&path);
    assert!(e.contains("organ.stl") && e.contains("\"stl\""), "{e}");
}

/// A file cut off inside $Nodes reports the end of file and the last line number.
#[test]
fn error_truncated_msh() {
    let full = cube_msh([1, 2, 3, 4, 5, 6, 7, 8], "1 2 3 4 5 6 7 8");
    let cut: String = full.lines().take(24).map(|l| format!("{l}\n")).collect();
    let (_tmp, path) = write_temp("trunc", "truncated.msh", &cut);
    let e = err_text(&path);
    assert!(e.contains("truncated.msh:24:"), "file and line: {e}");
    assert!(e.contains("end of file"), "{e}");
    assert!(e.contains("coordinate of node"), "what was being read: {e}");
}

/// An element referring to an undefined node tag names the element, the node and the line.
#[test]
fn error_unknown_node() {
    let (_tmp, path) = write_temp(
        "unknown",
        "unknown_node.msh",
        &cube_msh([1, 2, 3, 4, 5, 6, 7, 8], "1 2 3 4 5 6 7 99"),
    );
    let e = err_text(&path);
    assert!(e.contains("unknown_node.msh:"), "{e}");
    assert!(e.contains("element 2") && e.contains("node tag 99"), "{e}");
}

/// A collapsed hexahedron (node used twice) names the element and the node.
#[test]
fn error_repeated_node() {
    let (_tmp, path) = write_temp(
        "repeat",
        "repeated.msh",
        &cube_msh([1, 2, 3, 4, 5, 6, 7, 8], "1 2 3 4 5 6 3 8"),
    );
    let e = err_text(&path);
    assert!(e.contains("repeated.msh") && e.contains("element 2"), "{e}");
    assert!(e.contains("node 3"), "{e}");
}

/// A NaN coordinate is caught at import and names the node tag.
#[test]
fn error_nan_coordinate() {
    let text =
        cube_msh([1, 2, 3, 4, 5, 6, 7, 8], "1 2 3 4 5 6 7 8").replace("\n1 1 1\n", "\n1 nan 1\n");
    let (_tmp, path) = write_temp("nan", "nan.msh", &text);
    let e = err_text(&path);
    assert!(e.contains("nan.msh") && e.contains("node 7"), "{e}");
}

/// A non-numeric value names the file, the line and what was expected there.
#[test]
fn error_garbage_number() {
    let text =
        cube_msh([1, 2, 3, 4, 5, 6, 7, 8], "1 2 3 4 5 6 7 8").replace("\n1 0 1\n", "\n1 zero 1\n");
    let line = text.lines().position(|l| l == "1 zero 1").unwrap() + 1;
    let (_tmp, path) = write_temp("garbage", "garbage.msh", &text);
    let e = err_text(&path);
    assert!(e.contains(&format!("garbage.msh:{line}:")), "{e}");
    assert!(e.contains("\"zero\"") && e.contains("node 6"), "{e}");
}

/// A one-tetrahedron mesh loads as one tetrahedron (listed the wrong way round, turned
/// over, said in a note); a pyramid is refused naming the type and the count; a file with
/// only lower-dimensional elements has no volume cells: say so and list what it has.
#[test]
fn error_no_hexahedra() {
    let text = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n\
                0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n$Elements\n1 1 1 1\n3 1 4 1\n1 1 3 2 4\n\
                $EndElements\n";
    let (_tmp, path) = write_temp("tet", "tet.msh", text);
    let m = load_mesh(&path).expect("a tetrahedron loads");
    assert_eq!(
        m.cells,
        vec![[0, 1, 2, 2, 3, 3, 3, 3]],
        "turned over, stored degenerate"
    );
    assert!(
        m.notes
            .iter()
            .any(|n| n.contains("1 tetrahedra") && n.contains("1 given in the other orientation")),
        "{:?}",
        m.notes
    );
    let pyramid = text
        .replace(
            "$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n",
            "$Nodes\n1 5 1 5\n3 1 0 5\n1\n2\n3\n4\n5\n",
        )
        .replace("0 0 1\n$EndNodes", "1 1 0\n0.5 0.5 1\n$EndNodes")
        .replace("3 1 4 1\n1 1 3 2 4", "3 1 7 1\n1 1 2 4 3 5");
    let (_tmp, path) = write_temp("pyr", "pyr.msh", &pyramid);
    let e = load_mesh(&path).unwrap_err();
    assert!(matches!(e, MeshError::UnsupportedCells { .. }), "{e}");
    let e = e.to_string();
    assert!(
        e.contains("pyr.msh") && e.contains("1 pyramids (Gmsh type 7)"),
        "{e}"
    );
    let tri = text.replace("3 1 4 1\n1 1 3 2 4", "2 1 2 1\n1 1 2 3");
    let (_tmp, path) = write_temp("tri", "tri.msh", &tri);
    let e = load_mesh(&path).unwrap_err();
    assert!(matches!(e, MeshError::NoHexahedra { .. }), "{e}");
    let e = e.to_string();
    assert!(
        e.contains("tri.msh") && e.contains("only boundary cells (1 triangles (Gmsh type 2))"),
        "{e}"
    );
}

/// MSH versions other than 4.1 and 2.2 are refused with a message saying which are read.
#[test]
fn error_old_msh_version() {
    let text = "$MeshFormat\n3.0 0 8\n$EndMeshFormat\n";
    let (_tmp, path) = write_temp("v30", "old.msh", text);
    let e = err_text(&path);
    assert!(
        e.contains("old.msh:2:") && e.contains("3.0") && e.contains("4.1") && e.contains("2.2"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------------
// small VTK files
// ---------------------------------------------------------------------------------------

fn cube_vtk(cell_type: u32, extra_cell_data: &str) -> String {
    format!(
        "# vtk DataFile Version 4.2\ncube\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 8 double\n\
         0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\nCELLS 1 9\n8 0 1 2 3 4 5 6 7\n\
         CELL_TYPES 1\n{cell_type}\n{extra_cell_data}"
    )
}

/// A one-cell VTK file with an int cell array "region" gives that region.
#[test]
fn vtk_minimal_cube_with_region() {
    let (_tmp, path) = write_temp(
        "vtkcube",
        "cube.vtk",
        &cube_vtk(
            12,
            "CELL_DATA 1\nSCALARS region int 1\nLOOKUP_TABLE default\n4\n",
        ),
    );
    let m = load_mesh(&path).unwrap();
    assert_eq!(m.cells, vec![[0, 1, 2, 3, 4, 5, 6, 7]]);
    assert_eq!(m.cell_regions, vec![4]);
    assert_eq!(m.node_tags, (1..=8).collect::<Vec<u64>>());
}

/// A VTK volume cell the solver has no element for is refused naming its type and count.
#[test]
fn error_vtk_unsupported_cell() {
    let (_tmp, path) = write_temp("vtkvoxel", "voxel.vtk", &cube_vtk(11, ""));
    let e = load_mesh(&path).unwrap_err();
    assert!(matches!(e, MeshError::UnsupportedCells { .. }), "{e}");
    let e = e.to_string();
    assert!(
        e.contains("voxel.vtk") && e.contains("1 VTK_VOXEL (11)"),
        "{e}"
    );
}

/// Unreadable VTK content is a parse error naming the file, the line and the bad token.
#[test]
fn error_vtk_garbage() {
    let (_tmp, path) = write_temp(
        "vtkbad",
        "bad.vtk",
        "# vtk DataFile Version 4.2\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS two double\n",
    );
    let e = load_mesh(&path).unwrap_err();
    assert!(matches!(e, MeshError::Parse { .. }), "{e}");
    let e = e.to_string();
    assert!(e.contains("bad.vtk:5:") && e.contains("\"two\""), "{e}");
}

// ---------------------------------------------------------------------------------------
// ParaView output
// ---------------------------------------------------------------------------------------

/// Frames written by `VtkSeriesWriter` read back with vtkio's XML reader give the reference
/// points in every frame (ParaView's Warp By Vector on `displacement_m` adds the motion, so
/// the points must not carry it too), the same connectivity, hex cell types, the regions
/// with their names in the field data, and `displacement_m` then the extra field; the .pvd
/// lists every frame with its time. Numbers are written shortest-round-trip, so they read
/// back exactly.
#[test]
fn vtu_series_round_trip() {
    use vtkio::model::{Attribute, CellType, DataSet, Piece};

    let mesh = generate_box([0.02, 0.01, 0.03], [2, 3, 4]);
    let dir = temp_dir("vtu");
    let mut w = VtkSeriesWriter::new(&dir, &mesh).unwrap();
    let times = [0.0, 0.0025, 0.005];
    for (f, &t) in times.iter().enumerate() {
        let u: Vec<[f64; 3]> = mesh
            .nodes
            .iter()
            .map(|p| [1e-3 * f as f64 * p[2], 0.0, -1e-7 * f as f64])
            .collect();
        let s: Vec<f64> = (0..mesh.nodes.len()).map(|i| i as f64 * 0.5).collect();
        let path = w
            .write_frame_with(t, &u, &[("stress_pa", PointField::Scalar(&s))])
            .unwrap();
        assert_eq!(path, dir.join(format!("frame_{f:05}.vtu")));

        let vtk = vtkio::Vtk::import(&path).unwrap();
        let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
            panic!("not an unstructured grid")
        };
        let Some(Piece::Inline(p)) = pieces.into_iter().next() else {
            panic!("no inline piece")
        };
        if f > 0 {
            // Moved frames: "points = reference" below is then a real check.
            assert!(u.iter().flatten().map(|x| x.abs()).fold(0.0, nan_max) > 1e-6);
        }
        let pts = p.points.cast_into::<f64>().unwrap();
        assert_eq!(pts.len(), 3 * mesh.nodes.len());
        assert_eq!(
            pts,
            mesh.nodes.iter().flatten().copied().collect::<Vec<f64>>(),
            "frame {f}: the points are the reference positions"
        );
        let (conn, offsets) = p.cells.cell_verts.into_xml();
        let expect: Vec<u64> = mesh.cells.iter().flatten().map(|&i| i as u64).collect();
        assert_eq!(conn, expect);
        assert_eq!(
            offsets,
            (1..=mesh.cells.len() as u64)
                .map(|c| 8 * c)
                .collect::<Vec<_>>()
        );
        assert!(p.cells.types.iter().all(|&t| t == CellType::Hexahedron));
        assert_eq!(p.cells.types.len(), mesh.cells.len());
        let region = p
            .data
            .cell
            .iter()
            .find_map(|a| match a {
                Attribute::DataArray(d) if d.name == "region" => Some(d.data.clone()),
                _ => None,
            })
            .expect("cell data region");
        assert_eq!(region.cast_into::<i32>().unwrap(), mesh.cell_regions);
        let names: Vec<&str> = p.data.point.iter().map(|a| a.name()).collect();
        assert_eq!(names, [vtk::DISPLACEMENT, "stress_pa"]);
        let disp = match &p.data.point[0] {
            Attribute::DataArray(d) => d.data.clone().cast_into::<f64>().unwrap(),
            _ => panic!("displacement_m is not a data array"),
        };
        let text = std::fs::read_to_string(&path).unwrap();
        let used: BTreeSet<i32> = mesh.cell_regions.iter().copied().collect();
        let want: std::collections::BTreeMap<i32, String> = used
            .iter()
            .filter_map(|r| Some((*r, mesh.region_names.get(r)?.clone())))
            .collect();
        assert_eq!(vtk::region_names(&text), Some(want));
        assert_eq!(disp, u.iter().flatten().copied().collect::<Vec<f64>>());
    }
    assert_eq!(w.frame_count(), 3);
    let pvd = w.finish().unwrap();
    let text = std::fs::read_to_string(&pvd).unwrap();
    assert!(text.contains("<VTKFile type=\"Collection\""), "{text}");
    let entries: Vec<&str> = text.lines().filter(|l| l.contains("<DataSet ")).collect();
    assert_eq!(entries.len(), times.len());
    for (f, (line, t)) in entries.iter().zip(times).enumerate() {
        assert!(
            line.contains(&format!("file=\"frame_{f:05}.vtu\"")),
            "{line}"
        );
        let ts: f64 = line
            .split("timestep=\"")
            .nth(1)
            .and_then(|r| r.split('"').next())
            .unwrap()
            .parse()
            .unwrap();
        assert_eq!(ts, t);
        assert!(dir.join(format!("frame_{f:05}.vtu")).is_file());
    }
}

/// A displacement array of the wrong length, or a NaN time, is refused (and no frame is
/// counted, so the numbering stays contiguous).
#[test]
fn vtu_rejects_wrong_displacement_length() {
    let mesh = generate_box([1.0; 3], [1, 1, 1]);
    let dir = temp_dir("vtulen");
    let mut w = VtkSeriesWriter::new(&dir, &mesh).unwrap();
    let e = w.write_frame(0.0, &[[0.0; 3]; 7]).unwrap_err().to_string();
    assert!(
        e.contains("displacement") && e.contains('7') && e.contains('8'),
        "{e}"
    );
    let e = w.write_frame(f64::NAN, &[[0.0; 3]; 8]).unwrap_err();
    assert!(matches!(e, MeshError::InvalidInput { .. }), "{e}");
    assert_eq!(w.frame_count(), 0);
}

/// A real mesh writes and reads back too: sizes match, the points stay at the reference
/// positions under a non-zero displacement, and its five named regions (the .msh file's
/// physical names) are the lookup, in tag order.
#[test]
fn vtu_real_mesh_round_trip() {
    use vtkio::model::{DataSet, Piece};
    let mesh = load_shared("uterus_scaffold_hex320.msh");
    let dir = temp_dir("vtureal");
    let mut w = VtkSeriesWriter::new(&dir, &mesh).unwrap();
    let path = w
        .write_frame(0.1, &vec![[1e-3, -2e-3, 5e-4]; mesh.nodes.len()])
        .unwrap();
    w.finish().unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let names = vtk::region_names(&text).expect("region name lookup");
    assert_eq!(names.len(), 5, "{names:?}");
    assert!(names.values().all(|n| !n.is_empty()), "{names:?}");
    assert_eq!(names, mesh.region_names);
    let vtk = vtkio::Vtk::import(&path).unwrap();
    let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
        panic!("not an unstructured grid")
    };
    let Some(Piece::Inline(p)) = pieces.into_iter().next() else {
        panic!("no inline piece")
    };
    assert_eq!(
        p.points.cast_into::<f64>().unwrap(),
        mesh.nodes.iter().flatten().copied().collect::<Vec<_>>()
    );
    assert_eq!(p.cells.types.len(), 320);
}

/// A VTK file cut off inside POINTS is located: file, line, and what was being read.
#[test]
fn error_vtk_truncated() {
    let full = cube_vtk(12, "");
    let cut: String = full.lines().take(8).map(|l| format!("{l}\n")).collect();
    let (_tmp, path) = write_temp("vtktrunc", "cut.vtk", &cut);
    let e = err_text(&path);
    assert!(e.contains("cut.vtk:8:"), "{e}");
    assert!(e.contains("end of file") && e.contains("point 3"), "{e}");
}

/// A CELLS header whose list size disagrees with the cells is located at the CELLS line.
#[test]
fn error_vtk_bad_cells_size() {
    let text = cube_vtk(12, "").replace("CELLS 1 9", "CELLS 1 10");
    let (_tmp, path) = write_temp("vtksize", "size.vtk", &text);
    let e = err_text(&path);
    assert!(
        e.contains("size.vtk:14:") && e.contains("10") && e.contains('9'),
        "{e}"
    );
}

/// A file cut off inside the region cell data must not load with the regions silently
/// dropped (vtkio alone would return the mesh without them): it is an error at that line.
#[test]
fn error_vtk_truncated_cell_data() {
    let text = cube_vtk(
        12,
        "CELL_DATA 1\nSCALARS region int 1\nLOOKUP_TABLE default\n",
    );
    let (_tmp, path) = write_temp("vtkcd", "cd.vtk", &text);
    let e = err_text(&path);
    assert!(e.contains("cd.vtk:20:") && e.contains("end of file"), "{e}");
    assert!(e.contains("value 0 of SCALARS \"region\""), "{e}");
}

// ---------------------------------------------------------------------------------------
// binary MSH
// ---------------------------------------------------------------------------------------

/// Write `m` as binary MSH 4.1 in the given byte order: one volume entity per region
/// (entity tag 10 + region), one hex block per region in cell order, plus a quad block on a
/// surface entity that the reader must skip.
fn msh_binary(m: &Mesh, big: bool) -> Vec<u8> {
    let mut b: Vec<u8> = Vec::new();
    let sz = |b: &mut Vec<u8>, v: u64| {
        b.extend(if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        })
    };
    let int = |b: &mut Vec<u8>, v: i32| {
        b.extend(if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        })
    };
    let fl = |b: &mut Vec<u8>, v: f64| {
        b.extend(if big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        })
    };
    b.extend(b"$MeshFormat\n4.1 1 8\n");
    int(&mut b, 1);
    b.extend(b"\n$EndMeshFormat\n$PhysicalNames\n");
    b.extend(format!("{}\n", m.region_names.len()).as_bytes());
    for (t, name) in &m.region_names {
        b.extend(format!("3 {t} \"{name}\"\n").as_bytes());
    }
    b.extend(b"$EndPhysicalNames\n$Entities\n");
    let regions: Vec<i32> = region_counts(m).into_keys().collect();
    for n in [0, 0, 1, regions.len() as u64] {
        sz(&mut b, n);
    }
    int(&mut b, 1); // the surface
    for _ in 0..6 {
        fl(&mut b, 0.0);
    }
    sz(&mut b, 0);
    sz(&mut b, 0);
    for &r in &regions {
        int(&mut b, 10 + r);
        for _ in 0..6 {
            fl(&mut b, 0.0);
        }
        sz(&mut b, 1);
        int(&mut b, r);
        sz(&mut b, 0);
    }
    b.extend(b"\n$EndEntities\n$Nodes\n");
    let tags = &m.node_tags;
    for n in [1, tags.len() as u64, tags[0], *tags.last().unwrap()] {
        sz(&mut b, n);
    }
    int(&mut b, 3);
    int(&mut b, 1);
    int(&mut b, 0);
    sz(&mut b, tags.len() as u64);
    for &t in tags {
        sz(&mut b, t);
    }
    for p in &m.nodes {
        for x in p {
            fl(&mut b, *x);
        }
    }
    b.extend(b"\n$EndNodes\n$Elements\n");
    let total = m.cells.len() as u64 + 1;
    for n in [regions.len() as u64 + 1, total, 1, total] {
        sz(&mut b, n);
    }
    // The quad block.
    int(&mut b, 2);
    int(&mut b, 1);
    int(&mut b, 3);
    sz(&mut b, 1);
    sz(&mut b, total);
    for a in 0..4 {
        sz(&mut b, tags[m.cells[0][a] as usize]);
    }
    for &r in &regions {
        let cells: Vec<usize> = (0..m.cells.len())
            .filter(|&c| m.cell_regions[c] == r)
            .collect();
        int(&mut b, 3);
        int(&mut b, 10 + r);
        int(&mut b, 5);
        sz(&mut b, cells.len() as u64);
        for c in cells {
            sz(&mut b, c as u64 + 1);
            for &i in &m.cells[c] {
                sz(&mut b, tags[i as usize]);
            }
        }
    }
    b.extend(b"\n$EndElements\n");
    b
}

/// Binary MSH 4.1 in either byte order reads back to exactly the mesh the ASCII file gives
/// (this file lists its cells grouped by region, the order the writer above keeps).
#[test]
fn msh_binary_matches_ascii() {
    let ascii = load_shared("uterus_scaffold_hex320.msh");
    for big in [false, true] {
        let (_tmp, path) = write_temp("bin", "bin.msh", "");
        std::fs::write(&path, msh_binary(&ascii, big)).unwrap();
        let bin = load_mesh(&path).unwrap();
        assert_eq!(bin.nodes, ascii.nodes, "big endian: {big}");
        assert_eq!(bin.node_tags, ascii.node_tags);
        assert_eq!(bin.cells, ascii.cells);
        assert_eq!(bin.cell_regions, ascii.cell_regions);
        assert_eq!(bin.region_names, ascii.region_names);
    }
}

/// A truncated binary file reports the byte offset and what was being read.
#[test]
fn error_truncated_binary_msh() {
    let bytes = msh_binary(&generate_box([1.0; 3], [2, 2, 2]), false);
    let cut = &bytes[..bytes.len() - 30];
    let e = host_tools::mesh::io::parse_msh(Path::new("cut_binary.msh"), cut).unwrap_err();
    let e = e.to_string();
    assert!(e.contains("cut_binary.msh") && e.contains("at byte"), "{e}");
    assert!(e.contains("element 8") && e.contains("end of file"), "{e}");
}

/// A hex block on a volume entity that $Entities does not list is refused (its physical
/// group, so the tissue label, would be a guess), naming the entity and the line.
#[test]
fn error_unlisted_volume_entity() {
    let text =
        cube_msh([1, 2, 3, 4, 5, 6, 7, 8], "1 2 3 4 5 6 7 8").replace("3 1 5 1\n", "3 4 5 1\n");
    let (_tmp, path) = write_temp("entity", "entity.msh", &text);
    let e = err_text(&path);
    assert!(
        e.contains("entity.msh:") && e.contains("volume entity 4"),
        "{e}"
    );
}

/// `write_pvd` during a run lists the frames so far, so a partial series can be opened.
#[test]
fn pvd_can_be_written_mid_run() {
    let mesh = generate_box([1.0; 3], [1, 1, 1]);
    let dir = temp_dir("pvdmid");
    let mut w = VtkSeriesWriter::new(&dir, &mesh).unwrap();
    w.write_frame(0.5, &[[0.0; 3]; 8]).unwrap();
    let text = std::fs::read_to_string(w.write_pvd().unwrap()).unwrap();
    assert_eq!(text.matches("<DataSet ").count(), 1);
    w.write_frame(1.0, &[[0.0; 3]; 8]).unwrap();
    let text = std::fs::read_to_string(w.finish().unwrap()).unwrap();
    assert_eq!(text.matches("<DataSet ").count(), 2);
    assert!(text.contains("timestep=\"1e0\" group=\"\" part=\"0\" file=\"frame_00001.vtu\""));
}

/// A node no cell uses (it would get zero lumped mass) is found, and removing it keeps the
/// geometry of every cell and the tags of the remaining nodes.
#[test]
fn unused_nodes_found_and_removed() {
    let mut m = generate_box([1.0; 3], [2, 1, 1]);
    assert!(m.unused_nodes().is_empty());
    // Insert a stray node at index 3 and shift the cell indices past it.
    m.nodes.insert(3, [9.0; 3]);
    m.node_tags.insert(3, 1000);
    for c in &mut m.cells {
        for i in c.iter_mut() {
            if *i >= 3 {
                *i += 1;
            }
        }
    }
    m.validate().unwrap();
    assert_eq!(m.unused_nodes(), vec![3]);
    let before: Vec<_> = (0..m.cells.len()).map(|c| m.cell_coords(c)).collect();
    assert_eq!(m.remove_unused_nodes(), 1);
    m.validate().unwrap();
    assert_eq!(
        m,
        generate_box([1.0; 3], [2, 1, 1]),
        "back to the original box"
    );
    let after: Vec<_> = (0..m.cells.len()).map(|c| m.cell_coords(c)).collect();
    assert_eq!(before, after);
    assert!(!m.node_tags.contains(&1000));
}

// ---------------------------------------------------------------------------------------
// the MSH 2.2 writer (`pe plan`'s reduced meshes)
// ---------------------------------------------------------------------------------------

/// A mesh written by `to_msh22` reads back as the same mesh: coordinates bit for bit,
/// cells (prisms as prisms), regions and their names, and the node sets given, on the
/// shared uterus (five named regions), the built-in anatomy with its node sets, and Gmsh's
/// hex-and-prism beam.
#[test]
fn a_written_msh22_reads_back_as_the_same_mesh() {
    use host_tools::mesh::io::{parse_msh, to_msh22};
    let builtin = host_tools::scene::builtin::builtin_scene("coarse").expect("builtin");
    let (b, b_sets) =
        host_tools::scene::mesh_source::load(&builtin.mesh, Path::new(".")).expect("builtin mesh");
    let beam = load_mesh(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/meshes/beam_mixed.msh"),
    )
    .expect("beam");
    let uterus = load_shared("uterus_scaffold_hex320.msh");
    let mut uterus_sets = BTreeMap::new();
    uterus_sets.insert(
        "every_seventh".to_string(),
        (0..uterus.nodes.len() as u32)
            .step_by(7)
            .collect::<Vec<_>>(),
    );
    let beam_sets = beam.node_sets.clone();
    for (what, mesh, sets) in [
        ("uterus", uterus, uterus_sets),
        ("builtin coarse", b, b_sets),
        ("beam", beam, beam_sets),
    ] {
        assert!(
            !sets.is_empty() && sets.values().all(|s| !s.is_empty()),
            "{what}: sets to write"
        );
        assert!(!mesh.region_names.is_empty(), "{what}: named regions");
        let text = to_msh22(&mesh, &sets);
        let back = parse_msh(Path::new("written.msh"), text.as_bytes()).expect("reads back");
        assert_eq!(back.nodes.len(), mesh.nodes.len(), "{what}: nodes");
        for (a, c) in mesh.nodes.iter().zip(&back.nodes) {
            assert_eq!(
                a.map(f64::to_bits),
                c.map(f64::to_bits),
                "{what}: coordinates bit for bit"
            );
        }
        assert_eq!(back.cells, mesh.cells, "{what}: cells");
        assert_eq!(back.cell_regions, mesh.cell_regions, "{what}: regions");
        assert_eq!(back.region_names, mesh.region_names, "{what}: region names");
        assert_eq!(back.node_sets, sets, "{what}: node sets");
    }
}
