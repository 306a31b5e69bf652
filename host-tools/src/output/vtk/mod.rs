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
//!   data: `region_id` (Int32), the tags present, and per named region an Int32 array
//!   `region:NAME` holding its tag (ParaView: *Information*, *Data Arrays*; meshio:
//!   `mesh.field_data`). Only numeric arrays: the frames load in ParaView, VTK and pyvista
//!   and in meshio, which refuses `String` arrays.
//!
//! Hexahedra are `VTK_HEXAHEDRON` (12), prisms `VTK_WEDGE` (13), surface quads `VTK_QUAD` (9)
//! (a prism's triangles `VTK_TRIANGLE`, 5). Open `series.pvd` in ParaView.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use crate::mesh::{Mesh, MeshError};

mod xml;

use xml::{cells_xml, frame_xml, region_lookup_xml, write_pvd_file, Sections};

/// Point vector: displacement from the reference position (m).
pub const DISPLACEMENT: &str = "displacement_m";
/// Point vector: velocity (m/s).
pub const VELOCITY: &str = "velocity_m_per_s";
/// Cell data: region tag of each cell (or of the cell a surface face bounds).
pub const REGION: &str = "region";
/// Field data: the region tags present (Int32).
pub const REGION_ID: &str = "region_id";
/// Field data: a named region's Int32 array (one value, its tag) is named this prefix and
/// the region's name.
pub const REGION_NAME_PREFIX: &str = "region:";

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
        crate::output::file::write_bytes(&path, s.as_bytes()).map_err(io_err(&path))?;
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

/// Removes the files an earlier series left in `dir` (`PREFIX_NNNNN.vtu` and `series.pvd`),
/// so a reused directory holds this run's frames only (not this run's frames and, after
/// them, an earlier and longer run's).
fn remove_earlier_series(dir: &Path, prefix: &str) -> Result<(), MeshError> {
    let owned = |name: &str| {
        name == "series.pvd"
            || name
                .strip_prefix(prefix)
                .and_then(|n| n.strip_suffix(".vtu"))
                .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()))
    };
    crate::output::file::remove_owned(dir, owned)
        .map(|_| ())
        .map_err(|e| io_err(dir)(std::io::Error::other(format!("{e:#}"))))
}

impl VtkSeriesWriter {
    /// Create `dir` (and parents) if needed and prepare to write frames of `mesh`.
    /// The mesh must pass [`Mesh::validate`].
    pub fn new(dir: &Path, mesh: &Mesh) -> Result<Self, MeshError> {
        mesh.validate()?;
        fs::create_dir_all(dir).map_err(io_err(dir))?;
        remove_earlier_series(dir, "frame_")?;
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

/// ParaView series of a surface (quads): `DIR/surface_NNNNN.vtu` + `DIR/series.pvd`.
///
/// Each frame holds the reference points, the quads (`VTK_QUAD` = 9), the point vector
/// `displacement_m`, the cell data `region` with its `region_id` and `region:NAME` lookup and
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
        remove_earlier_series(dir, "surface_")?;
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

/// The region names of a `.vtu` text written here: tag -> name, from the field data's
/// [`REGION_NAME_PREFIX`] arrays (XML entities decoded). None without field data or when
/// such an array does not hold one integer.
pub fn region_names(vtu: &str) -> Option<BTreeMap<i32, String>> {
    let field = vtu
        .split("<FieldData>")
        .nth(1)?
        .split("</FieldData>")
        .next()?;
    let prefix = format!("Name=\"{REGION_NAME_PREFIX}");
    let mut out = BTreeMap::new();
    for (attrs, rest) in field.split("<DataArray").filter_map(|a| a.split_once('>')) {
        let Some((_, name)) = attrs.split_once(&prefix) else {
            continue;
        };
        let name = name.split('"').next()?;
        let name = name
            .replace("&lt;", "<")
            .replace("&gt;", ">")
            .replace("&quot;", "\"")
            .replace("&amp;", "&");
        let values: Vec<&str> = rest
            .split("</DataArray>")
            .next()?
            .split_whitespace()
            .collect();
        let [tag] = values[..] else { return None };
        out.insert(tag.parse().ok()?, name);
    }
    Some(out)
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
            region_names(&text).unwrap(),
            BTreeMap::from([(1, "uterus".to_string()), (3, "right tube".to_string())])
        );
        assert!(
            !text.contains("type=\"String\""),
            "meshio refuses String arrays"
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

    /// Names become array names, XML-escaped, and read back: non-ASCII, markup characters
    /// and a repeated name (told apart by its tag); an unnamed or unused region has none.
    #[test]
    fn region_names_are_numeric_field_arrays() {
        let names: BTreeMap<i32, String> = [
            (1, "ovary é"),
            (2, "tube <left> & \"right\""),
            (3, "tube <left> & \"right\""),
            (5, ""),
            (9, "unused"),
        ]
        .map(|(r, n)| (r, n.to_string()))
        .into();
        let xml = format!(
            "<FieldData>\n{}</FieldData>",
            region_lookup_xml(&[2, 1, 3, 5, 2], &names)
        );
        assert!(
            xml.contains("Name=\"region:tube &lt;left&gt; &amp; &quot;right&quot;\""),
            "{xml}"
        );
        assert!(!xml.contains("String"), "{xml}");
        let read = region_names(&xml).unwrap();
        assert_eq!(read.len(), 3, "{read:?}");
        assert_eq!(read[&1], "ovary é");
        assert_eq!(read[&2], "tube <left> & \"right\"");
        assert_eq!(read[&3], "tube <left> & \"right\" (tag 3)");
        assert!(
            xml.contains(&format!(
                "Name=\"{REGION_ID}\" NumberOfTuples=\"4\" format=\"ascii\">\n        1 2 3 5\n"
            )),
            "{xml}"
        );
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
