//! ParaView output: a time series of XML unstructured-grid files (`frame_NNNNN.vtu`, ASCII)
//! plus a `series.pvd` collection that lists every frame with its time.
//!
//! Each frame holds the deformed points (initial positions + displacement), the hexahedra
//! (`VTK_HEXAHEDRON` = 12), the point vector "displacement", any extra point fields, the
//! cell data "region" and the time as field data "TimeValue". Open `series.pvd` in ParaView.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use crate::mesh::{Mesh, MeshError};

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
/// `DIR/series.pvd`. Existing files of those names in `DIR` are overwritten.
#[derive(Debug)]
pub struct VtkSeriesWriter {
    /// Reference positions: every mesh node; cells with their region sections.
    series: FrameSeries,
}

/// What a series of `.vtu` frames shares: the directory, the reference positions, the cell
/// sections (the same in every frame) and the frames written so far.
#[derive(Debug)]
struct FrameSeries {
    dir: PathBuf,
    reference: Vec<[f64; 3]>,
    /// Connectivity, offsets, types and cell data sections, the same in every frame.
    cells_xml: String,
    n_cells: usize,
    frames: Vec<(f64, String)>,
}

impl FrameSeries {
    /// Writes `DIR/{prefix}_NNNNN.vtu`: the reference positions + `displacement` (one per
    /// reference point), with the extra point data; returns its path.
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
            &self.cells_xml,
            self.n_cells,
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
            8,
            12,
            "region",
            mesh.cell_regions.iter().map(|r| r.to_string()),
        );
        Ok(VtkSeriesWriter {
            series: FrameSeries {
                dir: dir.to_path_buf(),
                reference: mesh.nodes.clone(),
                cells_xml: c,
                n_cells: mesh.cells.len(),
                frames: Vec::new(),
            },
        })
    }

    /// Number of frames written so far.
    pub fn frame_count(&self) -> usize {
        self.series.frames.len()
    }

    /// Write the next frame: points at initial position + `displacement` (one per node).
    /// Returns the path of the written `.vtu`.
    pub fn write_frame(
        &mut self,
        time_s: f64,
        displacement: &[[f64; 3]],
    ) -> Result<PathBuf, MeshError> {
        self.write_frame_with(time_s, displacement, &[])
    }

    /// Like [`write_frame`](Self::write_frame) with extra named point data (one value or
    /// vector per node each), e.g. `("von_mises", PointField::Scalar(&s))`.
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

/// The `<Cells>` and `<CellData>` sections (the same in every frame): connectivity of
/// `per_cell` nodes each, offsets, VTK type `vtk_type`, and one Int32 cell field `data_name`.
fn cells_xml<'a>(
    cells: impl ExactSizeIterator<Item = &'a [u32]>,
    per_cell: usize,
    vtk_type: u8,
    data_name: &str,
    data: impl Iterator<Item = String>,
) -> String {
    let n = cells.len();
    let mut c = String::new();
    let _ = writeln!(c, "      <Cells>");
    let _ = writeln!(
        c,
        "        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">"
    );
    for cell in cells {
        let line: Vec<String> = cell.iter().map(|i| i.to_string()).collect();
        let _ = writeln!(c, "          {}", line.join(" "));
    }
    let _ = writeln!(c, "        </DataArray>");
    let _ = writeln!(
        c,
        "        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">"
    );
    for chunk in (1..=n).collect::<Vec<_>>().chunks(16) {
        let line: Vec<String> = chunk.iter().map(|i| (per_cell * i).to_string()).collect();
        let _ = writeln!(c, "          {}", line.join(" "));
    }
    let _ = writeln!(c, "        </DataArray>");
    let _ = writeln!(
        c,
        "        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">"
    );
    let t = vtk_type.to_string();
    for k in (0..n).step_by(32) {
        let line = vec![t.as_str(); (n - k).min(32)];
        let _ = writeln!(c, "          {}", line.join(" "));
    }
    let _ = writeln!(c, "        </DataArray>");
    let _ = writeln!(c, "      </Cells>");
    let _ = writeln!(c, "      <CellData Scalars=\"{data_name}\">");
    let _ = writeln!(
        c,
        "        <DataArray type=\"Int32\" Name=\"{data_name}\" format=\"ascii\">"
    );
    let data: Vec<String> = data.collect();
    for chunk in data.chunks(32) {
        let _ = writeln!(c, "          {}", chunk.join(" "));
    }
    let _ = writeln!(c, "        </DataArray>");
    let _ = writeln!(c, "      </CellData>");
    c
}

/// One frame's `.vtu` text: deformed points (`reference + displacement`), the fixed cell
/// sections, the point vector "displacement" and any extra point fields, the time as field
/// data "TimeValue".
fn frame_xml(
    time_s: f64,
    reference: &[[f64; 3]],
    displacement: &[[f64; 3]],
    cells_xml: &str,
    n_cells: usize,
    extra: &[(&str, PointField<'_>)],
) -> String {
    let n = reference.len();
    let mut s = String::with_capacity(128 * n + cells_xml.len() + 1024);
    s.push_str("<?xml version=\"1.0\"?>\n");
    s.push_str("<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n");
    s.push_str("  <UnstructuredGrid>\n");
    s.push_str("    <FieldData>\n");
    s.push_str(
        "      <DataArray type=\"Float64\" Name=\"TimeValue\" NumberOfTuples=\"1\" \
         format=\"ascii\">\n        ",
    );
    num(&mut s, time_s);
    s.push_str("\n      </DataArray>\n    </FieldData>\n");
    let _ = writeln!(
        s,
        "    <Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n_cells}\">"
    );
    s.push_str("      <Points>\n");
    s.push_str(
        "        <DataArray type=\"Float64\" Name=\"Points\" NumberOfComponents=\"3\" \
         format=\"ascii\">\n",
    );
    for (p, u) in reference.iter().zip(displacement) {
        vec3_line(&mut s, [p[0] + u[0], p[1] + u[1], p[2] + u[2]]);
    }
    s.push_str("        </DataArray>\n      </Points>\n");
    s.push_str(cells_xml);
    s.push_str("      <PointData Vectors=\"displacement\">\n");
    write_vectors(&mut s, "displacement", displacement);
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
/// Each frame holds the deformed points (reference + displacement), the quads
/// (`VTK_QUAD` = 9), the point vector "displacement", the cell data "group" and the time as
/// field data "TimeValue". Existing files of those names in `DIR` are overwritten.
#[derive(Debug)]
pub struct SurfaceSeriesWriter {
    /// Reference positions: the surface's nodes; quads with their group section.
    series: FrameSeries,
}

impl SurfaceSeriesWriter {
    /// `reference`: initial positions of the surface's nodes (surface-local numbering), `quads` in that numbering.
    ///
    /// Creates `dir` (and parents) if needed. The reference positions must be finite, every
    /// quad index must be below `reference.len()` and there must be one group per quad.
    pub fn new(
        dir: &Path,
        reference: Vec<[f64; 3]>,
        quads: Vec<[u32; 4]>,
        quad_groups: Vec<u8>,
    ) -> Result<Self, MeshError> {
        if quad_groups.len() != quads.len() {
            return Err(MeshError::LengthMismatch {
                path: dir.to_path_buf(),
                what: "quad_groups".into(),
                expected: quads.len(),
                got: quad_groups.len(),
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
            4,
            9,
            "group",
            quad_groups.iter().map(|g| g.to_string()),
        );
        Ok(SurfaceSeriesWriter {
            series: FrameSeries {
                dir: dir.to_path_buf(),
                reference,
                cells_xml: c,
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

    /// Two frames of a cube's surface read back with vtkio: 8 points, 6 quads, the groups,
    /// and the second frame's points are reference + displacement.
    #[test]
    fn surface_series_round_trip() {
        use vtkio::model::{Attribute, CellType, DataSet, Piece};

        let (nodes, quads) = cube();
        let groups = vec![0u8, 0, 1, 1, 2, 7];
        let dir = temp_dir("surface");
        let mut w =
            SurfaceSeriesWriter::new(&dir, nodes.clone(), quads.clone(), groups.clone()).unwrap();
        let zero = vec![[0.0; 3]; 8];
        let u: Vec<[f64; 3]> = nodes
            .iter()
            .enumerate()
            .map(|(i, p)| [0.1 * p[2], -1e-4 * i as f64, 3e-5])
            .collect();
        w.write_frame(0.0, &zero).unwrap();
        w.write_frame(0.002, &u).unwrap();
        assert_eq!(w.frame_count(), 2);

        let vtk = vtkio::Vtk::import(dir.join("surface_00001.vtu")).unwrap();
        let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
            panic!("not an unstructured grid")
        };
        let Some(Piece::Inline(p)) = pieces.into_iter().next() else {
            panic!("no inline piece")
        };
        let pts = p.points.cast_into::<f64>().unwrap();
        assert_eq!(pts.len(), 3 * 8, "8 points");
        for (i, (x, d)) in nodes.iter().zip(&u).enumerate() {
            for k in 0..3 {
                assert!((pts[3 * i + k] - (x[k] + d[k])).abs() <= 1e-12, "point {i}");
            }
        }
        assert_eq!(p.cells.types.len(), 6, "6 cells");
        assert!(p.cells.types.iter().all(|&t| t == CellType::Quad));
        let (conn, offsets) = p.cells.cell_verts.into_xml();
        let expect: Vec<u64> = quads.iter().flatten().map(|&i| i as u64).collect();
        assert_eq!(conn, expect);
        assert_eq!(offsets, [4, 8, 12, 16, 20, 24]);
        let group = p
            .data
            .cell
            .iter()
            .find_map(|a| match a {
                Attribute::DataArray(d) if d.name == "group" => Some(d.data.clone()),
                _ => None,
            })
            .expect("cell data group");
        let want: Vec<i32> = groups.iter().map(|&g| g as i32).collect();
        assert_eq!(group.cast_into::<i32>().unwrap(), want);
        let disp = match &p.data.point[0] {
            Attribute::DataArray(d) if d.name == "displacement" => {
                d.data.clone().cast_into::<f64>().unwrap()
            }
            _ => panic!("displacement is not the first point data array"),
        };
        assert_eq!(disp, u.iter().flatten().copied().collect::<Vec<f64>>());

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

    #[test]
    fn surface_series_rejects_bad_input() {
        let (nodes, quads) = cube();
        let dir = temp_dir("surface-bad");
        let e = SurfaceSeriesWriter::new(&dir, nodes.clone(), quads.clone(), vec![0; 5]);
        assert!(matches!(e, Err(MeshError::LengthMismatch { .. })), "{e:?}");
        let mut q = quads.clone();
        q[3][2] = 8;
        let e = SurfaceSeriesWriter::new(&dir, nodes.clone(), q, vec![0; 6]);
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
        let mut w = SurfaceSeriesWriter::new(&dir, nodes, quads, vec![0; 6]).unwrap();
        let e = w.write_frame(0.0, &[[0.0; 3]; 7]).unwrap_err();
        assert!(e.to_string().contains("surface_00000.vtu"), "{e}");
        assert!(w.write_frame(f64::NAN, &[[0.0; 3]; 8]).is_err());
        assert_eq!(w.frame_count(), 0);
        let _ = fs::remove_dir_all(&dir);
    }
}
