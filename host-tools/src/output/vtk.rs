//! ParaView output: a time series of XML unstructured-grid files (`frame_NNNNN.vtu`, ASCII)
//! plus a `series.pvd` collection that lists every frame with its time.
//!
//! Conventions, the same in every frame `pe solve` and board-sim write (volume and surface):
//!
//! - The points are the **reference (initial) positions**, the same in every frame; the
//!   motion is the point vector `displacement_m`. ParaView's *Warp By Vector* on
//!   `displacement_m` (scale 1) therefore shows the deformed shape, once.
//! - **Units are in the array names**, as the suffix of the SI unit: `displacement_m` (m),
//!   `velocity_m_per_s` (m/s; `pe solve` only: the central difference's velocity over the
//!   last step, `(u_n − u_{n−1})/dt`; board-sim's boards send displacements only). Extra
//!   point fields are named by their writer the same way. Ids and counts have no unit.
//!   The one exception is the field data `TimeValue` (s), the name ParaView reads a frame's
//!   time from.
//! - Cell data `region` (Int32): the mesh's region (physical group) tag of each cell; on a
//!   surface, the region of the cell the face bounds. Its names are a lookup in the field
//!   data: `region_id` (Int32) and `region_name` (String, empty when the mesh names none),
//!   in the same order, one entry per region present (ParaView: *Spreadsheet View*,
//!   *Field Data*).
//!
//! Hexahedra are `VTK_HEXAHEDRON` (12), prisms `VTK_WEDGE` (13), surface quads `VTK_QUAD` (9)
//! (a prism's triangles `VTK_TRIANGLE`, 5). Open `series.pvd` in ParaView.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use crate::mesh::{Mesh, MeshError};

/// Point vector: displacement from the reference position (m).
pub const DISPLACEMENT: &str = "displacement_m";
/// Point vector: velocity (m/s).
pub const VELOCITY: &str = "velocity_m_per_s";
/// Cell data: region tag of each cell (or of the cell a surface face bounds).
pub const REGION: &str = "region";
/// Field data: the region tags of the lookup, in the order of [`REGION_NAME`].
pub const REGION_ID: &str = "region_id";
/// Field data: the name of each region of [`REGION_ID`] (String array).
pub const REGION_NAME: &str = "region_name";

/// Extra per-node data for a frame.
#[derive(Clone, Copy, Debug)]
pub enum PointField<'a> {
    /// One value per node.
    Scalar(&'a [f64]),
    /// One 3-vector per node.
    Vector(&'a [[f64; 3]]),
}

impl PointField<'_> {
    fn len(&self) -> usize {
        match self {
            PointField::Scalar(v) => v.len(),
            PointField::Vector(v) => v.len(),
        }
    }
}

/// Writes `DIR/frame_00000.vtu`, `DIR/frame_00001.vtu`, ... and, on
/// [`finish`](VtkSeriesWriter::finish) (or [`write_pvd`](VtkSeriesWriter::write_pvd)),
/// `DIR/series.pvd`. Existing files of those names in `DIR` are overwritten. The arrays
/// follow the module's conventions.
#[derive(Debug)]
pub struct VtkSeriesWriter {
    /// Reference positions: every mesh node; cells with their region sections.
    series: FrameSeries,
}

/// What a series of `.vtu` frames shares: the directory, the reference positions, the cell
/// sections and region lookup (the same in every frame) and the frames written so far.
#[derive(Debug)]
struct FrameSeries {
    dir: PathBuf,
    reference: Vec<[f64; 3]>,
    /// Connectivity, offsets, types and cell data sections, the same in every frame.
    cells_xml: String,
    /// The region lookup arrays of the field data, the same in every frame.
    field_xml: String,
    n_cells: usize,
    frames: Vec<(f64, String)>,
}

impl FrameSeries {
    /// Writes `DIR/{prefix}_NNNNN.vtu`: the reference positions, `displacement_m` (one per
    /// reference point) and the extra point data; returns its path.
    fn write_frame(
        &mut self,
        prefix: &str,
        time_s: f64,
        displacement: &[[f64; 3]],
        extra: &[(&str, PointField<'_>)],
    ) -> Result<PathBuf, MeshError> {
        let name = format!("{prefix}_{:05}.vtu", self.frames.len());
        let path = self.dir.join(&name);
        let n = self.reference.len();
        if displacement.len() != n {
            return Err(MeshError::LengthMismatch {
                path,
                what: "displacement".into(),
                expected: n,
                got: displacement.len(),
            });
        }
        for (fname, field) in extra {
            if field.len() != n {
                return Err(MeshError::LengthMismatch {
                    path,
                    what: format!("point data {fname:?}"),
                    expected: n,
                    got: field.len(),
                });
            }
        }
        if !time_s.is_finite() {
            return Err(MeshError::InvalidInput {
                path,
                msg: format!("frame time {time_s} is not finite"),
            });
        }
        let s = frame_xml(
            time_s,
            &self.reference,
            displacement,
            &Sections {
                cells: &self.cells_xml,
                n_cells: self.n_cells,
                field: &self.field_xml,
            },
            extra,
        );
        fs::write(&path, s).map_err(io_err(&path))?;
        self.frames.push((time_s, name));
        Ok(path)
    }

    /// Writes (or rewrites) `DIR/series.pvd` listing the frames so far; returns its path.
    fn write_pvd(&self) -> Result<PathBuf, MeshError> {
        write_pvd_file(&self.dir, &self.frames)
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> MeshError + '_ {
    move |source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// `f64` in a form that reads back to the same value (`{:e}` is shortest round-trip).
fn num(out: &mut String, x: f64) {
    // Writing to a String cannot fail.
    let _ = write!(out, "{x:e}");
}

/// Escape the characters that may not appear in an XML attribute value.
fn xml_attr(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

impl VtkSeriesWriter {
    /// Create `dir` (and parents) if needed and prepare to write frames of `mesh`.
    /// The mesh must pass [`Mesh::validate`].
    pub fn new(dir: &Path, mesh: &Mesh) -> Result<Self, MeshError> {
        mesh.validate()?;
        fs::create_dir_all(dir).map_err(io_err(dir))?;
        let c = cells_xml(
            mesh.cells.iter().map(|c| &c[..]),
            mesh.cell_regions.iter().map(|r| r.to_string()),
        );
        Ok(VtkSeriesWriter {
            series: FrameSeries {
                dir: dir.to_path_buf(),
                reference: mesh.nodes.clone(),
                cells_xml: c,
                field_xml: region_lookup_xml(&mesh.cell_regions, &mesh.region_names),
                n_cells: mesh.cells.len(),
                frames: Vec::new(),
            },
        })
    }

    /// Number of frames written so far.
    pub fn frame_count(&self) -> usize {
        self.series.frames.len()
    }

    /// Write the next frame: the reference points with `displacement_m` (one per node).
    /// Returns the path of the written `.vtu`.
    pub fn write_frame(
        &mut self,
        time_s: f64,
        displacement: &[[f64; 3]],
    ) -> Result<PathBuf, MeshError> {
        self.write_frame_with(time_s, displacement, &[])
    }

    /// Like [`write_frame`](Self::write_frame) with extra named point data (one value or
    /// vector per node each), e.g. `(VELOCITY, PointField::Vector(&v))`. Name a field with
    /// its unit, as the module's conventions say (`von_mises_pa`).
    pub fn write_frame_with(
        &mut self,
        time_s: f64,
        displacement: &[[f64; 3]],
        extra: &[(&str, PointField<'_>)],
    ) -> Result<PathBuf, MeshError> {
        self.series
            .write_frame("frame", time_s, displacement, extra)
    }

    /// Write (or rewrite) `DIR/series.pvd` listing the frames written so far with their
    /// times; returns its path. Call it now and then during a long run to be able to open
    /// the series before the run ends.
    pub fn write_pvd(&self) -> Result<PathBuf, MeshError> {
        self.series.write_pvd()
    }

    /// Write `DIR/series.pvd` listing every frame with its time and close the series;
    /// returns the `.pvd` path (the file to open in ParaView).
    pub fn finish(self) -> Result<PathBuf, MeshError> {
        self.write_pvd()
    }
}

/// A mesh cell as VTK writes it: a hexahedron (`VTK_HEXAHEDRON`, 12), a prism stored as a
/// degenerate hexahedron as a `VTK_WEDGE` (13) in VTK's order (the first triangle's normal
/// pointing away from the second); a surface quadrilateral (`VTK_QUAD`, 9), or a prism's
/// triangle (a quadrilateral with one node repeated) as a `VTK_TRIANGLE` (5).
fn vtk_cell(nodes: &[u32]) -> (Vec<u32>, u8) {
    match nodes {
        [c0, c1, c2, c3, c4, c5, c6, c7] => {
            let c = [*c0, *c1, *c2, *c3, *c4, *c5, *c6, *c7];
            if crate::mesh::is_prism(&c) {
                (vec![c[0], c[2], c[1], c[4], c[6], c[5]], 13)
            } else {
                (c.to_vec(), 12)
            }
        }
        [_, _, _, _] => {
            let mut distinct: Vec<u32> = Vec::with_capacity(4);
            for (k, &n) in nodes.iter().enumerate() {
                if n != nodes[(k + 3) % 4] {
                    distinct.push(n);
                }
            }
            if distinct.len() == 3 {
                (distinct, 5)
            } else {
                (nodes.to_vec(), 9)
            }
        }
        _ => (nodes.to_vec(), 0),
    }
}

/// The `<Cells>` and `<CellData>` sections (the same in every frame): each cell's
/// connectivity, offsets and VTK type (see [`vtk_cell`]), and the Int32 cell data `region`.
fn cells_xml<'a>(
    cells: impl ExactSizeIterator<Item = &'a [u32]>,
    regions: impl Iterator<Item = String>,
) -> String {
    let cells: Vec<(Vec<u32>, u8)> = cells.map(vtk_cell).collect();
    let mut c = String::new();
    let _ = writeln!(c, "      <Cells>");
    let _ = writeln!(
        c,
        "        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">"
    );
    for (cell, _) in &cells {
        let line: Vec<String> = cell.iter().map(|i| i.to_string()).collect();
        let _ = writeln!(c, "          {}", line.join(" "));
    }
    let _ = writeln!(c, "        </DataArray>");
    let _ = writeln!(
        c,
        "        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">"
    );
    let offsets: Vec<String> = cells
        .iter()
        .scan(0usize, |end, (cell, _)| {
            *end += cell.len();
            Some(end.to_string())
        })
        .collect();
    for chunk in offsets.chunks(16) {
        let _ = writeln!(c, "          {}", chunk.join(" "));
    }
    let _ = writeln!(c, "        </DataArray>");
    let _ = writeln!(
        c,
        "        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">"
    );
    let types: Vec<String> = cells.iter().map(|(_, t)| t.to_string()).collect();
    for chunk in types.chunks(32) {
        let _ = writeln!(c, "          {}", chunk.join(" "));
    }
    let _ = writeln!(c, "        </DataArray>");
    let _ = writeln!(c, "      </Cells>");
    let _ = writeln!(c, "      <CellData Scalars=\"{REGION}\">");
    let _ = writeln!(
        c,
        "        <DataArray type=\"Int32\" Name=\"{REGION}\" format=\"ascii\">"
    );
    let data: Vec<String> = regions.collect();
    for chunk in data.chunks(32) {
        let _ = writeln!(c, "          {}", chunk.join(" "));
    }
    let _ = writeln!(c, "        </DataArray>");
    let _ = writeln!(c, "      </CellData>");
    c
}

/// The region lookup of the field data: `region_id` (Int32) and `region_name` (String),
/// one entry per region tag that some cell has, ascending, named from `names` (empty when
/// unnamed).
fn region_lookup_xml(cell_regions: &[i32], names: &BTreeMap<i32, String>) -> String {
    let ids: std::collections::BTreeSet<i32> = cell_regions.iter().copied().collect();
    let names: Vec<&str> = ids
        .iter()
        .map(|r| names.get(r).map_or("", String::as_str))
        .collect();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "      <DataArray type=\"Int32\" Name=\"{REGION_ID}\" NumberOfTuples=\"{}\" format=\"ascii\">",
        ids.len()
    );
    let ids: Vec<String> = ids.iter().map(i32::to_string).collect();
    for chunk in ids.chunks(32) {
        let _ = writeln!(s, "        {}", chunk.join(" "));
    }
    s.push_str("      </DataArray>\n");
    let _ = writeln!(
        s,
        "      <DataArray type=\"String\" Name=\"{REGION_NAME}\" NumberOfTuples=\"{}\" format=\"ascii\">",
        names.len()
    );
    for name in names {
        let _ = writeln!(s, "        {}", ascii_string(name));
    }
    s.push_str("      </DataArray>\n");
    s
}

/// A string as VTK's XML writer spells it in an ASCII `String` array: each byte as a
/// (signed char) number, then the terminating 0.
fn ascii_string(name: &str) -> String {
    let mut v: Vec<String> = name.bytes().map(|b| (b as i8).to_string()).collect();
    v.push("0".into());
    v.join(" ")
}

/// The parts of a frame that are the same in every frame.
struct Sections<'a> {
    /// `<Cells>` and `<CellData>`.
    cells: &'a str,
    n_cells: usize,
    /// Field data arrays besides `TimeValue`.
    field: &'a str,
}

/// One frame's `.vtu` text: the reference points, the fixed cell sections, the point
/// vector `displacement_m` and any extra point fields, the time as field data `TimeValue`
/// next to the region lookup.
fn frame_xml(
    time_s: f64,
    reference: &[[f64; 3]],
    displacement: &[[f64; 3]],
    fixed: &Sections<'_>,
    extra: &[(&str, PointField<'_>)],
) -> String {
    let n = reference.len();
    let mut s = String::with_capacity(128 * n + fixed.cells.len() + fixed.field.len() + 1024);
    s.push_str("<?xml version=\"1.0\"?>\n");
    s.push_str("<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n");
    s.push_str("  <UnstructuredGrid>\n");
    s.push_str("    <FieldData>\n");
    s.push_str(
        "      <DataArray type=\"Float64\" Name=\"TimeValue\" NumberOfTuples=\"1\" \
         format=\"ascii\">\n        ",
    );
    num(&mut s, time_s);
    s.push_str("\n      </DataArray>\n");
    s.push_str(fixed.field);
    s.push_str("    </FieldData>\n");
    let _ = writeln!(
        s,
        "    <Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{}\">",
        fixed.n_cells
    );
    s.push_str("      <Points>\n");
    s.push_str(
        "        <DataArray type=\"Float64\" Name=\"Points\" NumberOfComponents=\"3\" \
         format=\"ascii\">\n",
    );
    for p in reference {
        vec3_line(&mut s, *p);
    }
    s.push_str("        </DataArray>\n      </Points>\n");
    s.push_str(fixed.cells);
    let _ = writeln!(s, "      <PointData Vectors=\"{DISPLACEMENT}\">");
    write_vectors(&mut s, DISPLACEMENT, displacement);
    for (fname, field) in extra {
        match field {
            PointField::Vector(v) => write_vectors(&mut s, fname, v),
            PointField::Scalar(v) => {
                let _ = writeln!(
                    s,
                    "        <DataArray type=\"Float64\" Name=\"{}\" format=\"ascii\">",
                    xml_attr(fname)
                );
                for chunk in v.chunks(8) {
                    s.push_str("          ");
                    for (i, x) in chunk.iter().enumerate() {
                        if i > 0 {
                            s.push(' ');
                        }
                        num(&mut s, *x);
                    }
                    s.push('\n');
                }
                s.push_str("        </DataArray>\n");
            }
        }
    }
    s.push_str("      </PointData>\n");
    s.push_str("    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n");
    s
}

/// Writes `DIR/series.pvd` listing `frames` (time, file name); returns its path.
fn write_pvd_file(dir: &Path, frames: &[(f64, String)]) -> Result<PathBuf, MeshError> {
    let path = dir.join("series.pvd");
    let mut s = String::new();
    s.push_str("<?xml version=\"1.0\"?>\n");
    s.push_str("<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n");
    s.push_str("  <Collection>\n");
    for (t, file) in frames {
        s.push_str("    <DataSet timestep=\"");
        num(&mut s, *t);
        let _ = writeln!(s, "\" group=\"\" part=\"0\" file=\"{}\"/>", xml_attr(file));
    }
    s.push_str("  </Collection>\n</VTKFile>\n");
    fs::write(&path, s).map_err(io_err(&path))?;
    Ok(path)
}

fn vec3_line(s: &mut String, v: [f64; 3]) {
    s.push_str("          ");
    num(s, v[0]);
    s.push(' ');
    num(s, v[1]);
    s.push(' ');
    num(s, v[2]);
    s.push('\n');
}

fn write_vectors(s: &mut String, name: &str, v: &[[f64; 3]]) {
    let _ = writeln!(
        s,
        "        <DataArray type=\"Float64\" Name=\"{}\" NumberOfComponents=\"3\" format=\"ascii\">",
        xml_attr(name)
    );
    for u in v {
        vec3_line(s, *u);
    }
    s.push_str("        </DataArray>\n");
}

/// ParaView series of a surface (quads): `DIR/surface_NNNNN.vtu` + `DIR/series.pvd`.
///
/// Each frame holds the reference points, the quads (`VTK_QUAD` = 9), the point vector
/// `displacement_m`, the cell data `region` with its `region_id`/`region_name` lookup and
/// the time as field data `TimeValue` (the module's conventions). Existing files of those
/// names in `DIR` are overwritten.
#[derive(Debug)]
pub struct SurfaceSeriesWriter {
    /// Reference positions: the surface's nodes; quads with their region section.
    series: FrameSeries,
}

impl SurfaceSeriesWriter {
    /// `reference`: initial positions of the surface's nodes (surface-local numbering),
    /// `quads` in that numbering, `quad_regions` the region tag of each quad (of the cell
    /// it bounds) and `region_names` the names of the tags (a mesh's `region_names`).
    ///
    /// Creates `dir` (and parents) if needed. The reference positions must be finite, every
    /// quad index must be below `reference.len()` and there must be one region per quad.
    pub fn new(
        dir: &Path,
        reference: Vec<[f64; 3]>,
        quads: Vec<[u32; 4]>,
        quad_regions: Vec<i32>,
        region_names: &BTreeMap<i32, String>,
    ) -> Result<Self, MeshError> {
        if quad_regions.len() != quads.len() {
            return Err(MeshError::LengthMismatch {
                path: dir.to_path_buf(),
                what: "quad_regions".into(),
                expected: quads.len(),
                got: quad_regions.len(),
            });
        }
        for (i, p) in reference.iter().enumerate() {
            if !p.iter().all(|x| x.is_finite()) {
                return Err(MeshError::NonFiniteCoordinate {
                    path: dir.to_path_buf(),
                    node: i as u64,
                    coords: *p,
                });
            }
        }
        for (c, q) in quads.iter().enumerate() {
            if let Some(&index) = q.iter().find(|&&i| i as usize >= reference.len()) {
                return Err(MeshError::NodeIndexOutOfRange {
                    path: dir.to_path_buf(),
                    cell: c,
                    index,
                    nodes: reference.len(),
                });
            }
        }
        fs::create_dir_all(dir).map_err(io_err(dir))?;
        let c = cells_xml(
            quads.iter().map(|q| &q[..]),
            quad_regions.iter().map(|g| g.to_string()),
        );
        Ok(SurfaceSeriesWriter {
            series: FrameSeries {
                dir: dir.to_path_buf(),
                reference,
                cells_xml: c,
                field_xml: region_lookup_xml(&quad_regions, region_names),
                n_cells: quads.len(),
                frames: Vec::new(),
            },
        })
    }

    /// Number of frames written so far.
    pub fn frame_count(&self) -> usize {
        self.series.frames.len()
    }

    /// One frame: displacement per surface node (same numbering), time in s.
    pub fn write_frame(&mut self, time_s: f64, displacement: &[[f64; 3]]) -> Result<(), MeshError> {
        self.series
            .write_frame("surface", time_s, displacement, &[])?;
        Ok(())
    }

    /// Write (or rewrite) `DIR/series.pvd` listing the frames written so far; returns its
    /// path.
    pub fn write_pvd(&self) -> Result<PathBuf, MeshError> {
        self.series.write_pvd()
    }

    /// Writes series.pvd, returns its path.
    pub fn finish(self) -> Result<PathBuf, MeshError> {
        self.write_pvd()
    }
}

/// Reads the field data String array `name` of a `.vtu` text written here (or by VTK in
/// ASCII): the strings in order. None when the array is absent or not a String array of
/// byte values.
pub fn field_strings(vtu: &str, name: &str) -> Option<Vec<String>> {
    let field = vtu
        .split("<FieldData>")
        .nth(1)?
        .split("</FieldData>")
        .next()?;
    let tag = format!("Name=\"{}\"", xml_attr(name));
    let (_, rest) = field
        .split("<DataArray")
        .filter_map(|a| a.split_once('>'))
        .find(|(attrs, _)| attrs.contains(&tag) && attrs.contains("type=\"String\""))?;
    let mut out = Vec::new();
    let mut cur = Vec::new();
    for t in rest.split("</DataArray>").next()?.split_whitespace() {
        match t.parse::<i16>().ok()? {
            0 => out.push(String::from_utf8(std::mem::take(&mut cur)).ok()?),
            // A signed char's bits are the byte.
            b => cur.push(b as u8),
        }
    }
    cur.is_empty().then_some(out)
}

#[cfg(test)]
mod surface_series_tests {
    use super::*;

    fn temp_dir(tag: &str) -> PathBuf {
        static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let k = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        std::env::temp_dir().join(format!("pe-vtk-{tag}-{}-{k}", std::process::id()))
    }

    fn cube() -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
        crate::mesh::cube_surface(0.01)
    }

    /// Two frames of a cube's surface read back with vtkio: 8 points, 6 quads, the regions
    /// with their names in the field data, and the second frame's points are the reference
    /// positions (not moved: Warp By Vector on `displacement_m` moves them, once) with the
    /// displacement as `displacement_m`. Coordinates and displacements are written
    /// shortest-round-trip, so they read back exactly.
    #[test]
    fn surface_series_round_trip() {
        use vtkio::model::{Attribute, CellType, DataSet, Piece};

        let (nodes, quads) = cube();
        let regions = vec![3, 3, 1, 1, 2, 7];
        let names: BTreeMap<i32, String> = [(1, "uterus"), (3, "right tube"), (9, "unused")]
            .map(|(r, n)| (r, n.to_string()))
            .into();
        let dir = temp_dir("surface");
        let mut w =
            SurfaceSeriesWriter::new(&dir, nodes.clone(), quads.clone(), regions.clone(), &names)
                .unwrap();
        let zero = vec![[0.0; 3]; 8];
        let u: Vec<[f64; 3]> = nodes
            .iter()
            .enumerate()
            .map(|(i, p)| [0.1 * p[2], -1e-4 * i as f64, 3e-5])
            .collect();
        // The displacement is far from zero, so "points = reference" is a real check.
        assert!(u.iter().flatten().map(|x| x.abs()).sum::<f64>() > 1e-4);
        w.write_frame(0.0, &zero).unwrap();
        w.write_frame(0.002, &u).unwrap();
        assert_eq!(w.frame_count(), 2);

        let path = dir.join("surface_00001.vtu");
        let vtk = vtkio::Vtk::import(&path).unwrap();
        let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
            panic!("not an unstructured grid")
        };
        let Some(Piece::Inline(p)) = pieces.into_iter().next() else {
            panic!("no inline piece")
        };
        let pts = p.points.cast_into::<f64>().unwrap();
        assert_eq!(pts.len(), 3 * 8, "8 points");
        assert_eq!(pts, nodes.iter().flatten().copied().collect::<Vec<f64>>());
        assert_eq!(p.cells.types.len(), 6, "6 cells");
        assert!(p.cells.types.iter().all(|&t| t == CellType::Quad));
        let (conn, offsets) = p.cells.cell_verts.into_xml();
        let expect: Vec<u64> = quads.iter().flatten().map(|&i| i as u64).collect();
        assert_eq!(conn, expect);
        assert_eq!(offsets, [4, 8, 12, 16, 20, 24]);
        let region = p
            .data
            .cell
            .iter()
            .find_map(|a| match a {
                Attribute::DataArray(d) if d.name == REGION => Some(d.data.clone()),
                _ => None,
            })
            .expect("cell data region");
        assert_eq!(region.cast_into::<i32>().unwrap(), regions);
        let names_read: Vec<&str> = p.data.point.iter().map(|a| a.name()).collect();
        assert_eq!(names_read, [DISPLACEMENT]);
        let disp = match &p.data.point[0] {
            Attribute::DataArray(d) => d.data.clone().cast_into::<f64>().unwrap(),
            _ => panic!("displacement_m is not a data array"),
        };
        assert_eq!(disp, u.iter().flatten().copied().collect::<Vec<f64>>());

        // The lookup: one entry per region present (1, 2, 3, 7), named where the mesh
        // names it; the unused name 9 is left out.
        let text = fs::read_to_string(&path).unwrap();
        assert_eq!(
            field_strings(&text, REGION_NAME).unwrap(),
            ["uterus", "", "right tube", ""]
        );
        assert!(
            text.contains(&format!(
                "Name=\"{REGION_ID}\" NumberOfTuples=\"4\" format=\"ascii\">\n        1 2 3 7\n"
            )),
            "{text}"
        );

        let pvd = w.finish().unwrap();
        assert_eq!(pvd, dir.join("series.pvd"));
        let text = fs::read_to_string(&pvd).unwrap();
        assert!(text.contains("file=\"surface_00000.vtu\""), "{text}");
        assert!(
            text.contains("timestep=\"2e-3\" group=\"\" part=\"0\" file=\"surface_00001.vtu\""),
            "{text}"
        );
        let _ = fs::remove_dir_all(&dir);
    }

    /// A name is spelt as VTK's writer spells an ASCII String array: its bytes (as signed
    /// chars), then 0; the reader takes back what the writer wrote, non-ASCII included.
    #[test]
    fn string_array_spelling() {
        assert_eq!(ascii_string("ab"), "97 98 0");
        assert_eq!(ascii_string(""), "0");
        let names: BTreeMap<i32, String> =
            [(1, "ovary é".to_string()), (2, "tube".to_string())].into();
        let xml = format!(
            "<FieldData>\n{}</FieldData>",
            region_lookup_xml(&[2, 1, 2], &names)
        );
        assert!(xml.contains("-61 -87 0"), "é is the bytes C3 A9: {xml}");
        assert_eq!(
            field_strings(&xml, REGION_NAME).unwrap(),
            ["ovary é", "tube"]
        );
        assert_eq!(field_strings(&xml, REGION_ID), None, "not a String array");
    }

    #[test]
    fn surface_series_rejects_bad_input() {
        let (nodes, quads) = cube();
        let dir = temp_dir("surface-bad");
        let none = BTreeMap::new();
        let e = SurfaceSeriesWriter::new(&dir, nodes.clone(), quads.clone(), vec![0; 5], &none);
        assert!(matches!(e, Err(MeshError::LengthMismatch { .. })), "{e:?}");
        let mut q = quads.clone();
        q[3][2] = 8;
        let e = SurfaceSeriesWriter::new(&dir, nodes.clone(), q, vec![0; 6], &none);
        assert!(
            matches!(
                e,
                Err(MeshError::NodeIndexOutOfRange {
                    cell: 3,
                    index: 8,
                    ..
                })
            ),
            "{e:?}"
        );
        let mut w = SurfaceSeriesWriter::new(&dir, nodes, quads, vec![0; 6], &none).unwrap();
        let e = w.write_frame(0.0, &[[0.0; 3]; 7]).unwrap_err();
        assert!(e.to_string().contains("surface_00000.vtu"), "{e}");
        assert!(w.write_frame(f64::NAN, &[[0.0; 3]; 8]).is_err());
        assert_eq!(w.frame_count(), 0);
        let _ = fs::remove_dir_all(&dir);
    }
}
