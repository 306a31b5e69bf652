//! The XML text of the series: a frame's `.vtu` (points, cells, point and field data) and
//! the `series.pvd` collection, each number written to read back to the same value.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::{io_err, PointField, DISPLACEMENT, REGION, REGION_ID, REGION_NAME_PREFIX};
use crate::mesh::MeshError;

/// `f64` in a form that reads back to the same value (`{:e}` is shortest round-trip).
pub(super) fn num(out: &mut String, x: f64) {
    // Writing to a String cannot fail.
    let _ = write!(out, "{x:e}");
}

/// Escape the characters that may not appear in an XML attribute value.
pub(super) fn xml_attr(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A mesh cell as VTK writes it: a hexahedron (`VTK_HEXAHEDRON`, 12), a tetrahedron stored as
/// a degenerate hexahedron as a `VTK_TETRA` (10), a prism stored as a
/// degenerate hexahedron as a `VTK_WEDGE` (13) in VTK's order (the first triangle's normal
/// pointing away from the second); a surface quadrilateral (`VTK_QUAD`, 9), or a prism's
/// triangle (a quadrilateral with one node repeated) as a `VTK_TRIANGLE` (5).
pub(super) fn vtk_cell(nodes: &[u32]) -> (Vec<u32>, u8) {
    match nodes {
        [c0, c1, c2, c3, c4, c5, c6, c7] => {
            let c = [*c0, *c1, *c2, *c3, *c4, *c5, *c6, *c7];
            if let Some(t) = crate::mesh::as_tetrahedron(&c) {
                (t.to_vec(), 10)
            } else if crate::mesh::is_prism(&c) {
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
pub(super) fn cells_xml<'a>(
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

/// The region lookup of the field data: `region_id` (Int32), every region tag some cell
/// has, ascending; and per named region among them an Int32 array of one value, its tag,
/// named [`REGION_NAME_PREFIX`] + the name (a second region of the same name gets
/// ` (tag N)` after it). Numbers only: meshio refuses a `String` array ("Illegal data type"),
/// and ParaView shows the names as the arrays' names (*Information*, *Data Arrays*).
pub(super) fn region_lookup_xml(cell_regions: &[i32], names: &BTreeMap<i32, String>) -> String {
    let ids: std::collections::BTreeSet<i32> = cell_regions.iter().copied().collect();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "      <DataArray type=\"Int32\" Name=\"{REGION_ID}\" NumberOfTuples=\"{}\" format=\"ascii\">",
        ids.len()
    );
    let list: Vec<String> = ids.iter().map(i32::to_string).collect();
    for chunk in list.chunks(32) {
        let _ = writeln!(s, "        {}", chunk.join(" "));
    }
    s.push_str("      </DataArray>\n");
    let mut used = std::collections::BTreeSet::new();
    for id in &ids {
        let Some(name) = names.get(id).filter(|n| !n.is_empty()) else {
            continue;
        };
        let mut array = format!("{REGION_NAME_PREFIX}{name}");
        if !used.insert(array.clone()) {
            array = format!("{array} (tag {id})");
        }
        let _ = writeln!(
            s,
            "      <DataArray type=\"Int32\" Name=\"{}\" NumberOfTuples=\"1\" format=\"ascii\">\n        {id}\n      </DataArray>",
            xml_attr(&array)
        );
    }
    s
}

/// The parts of a frame that are the same in every frame.
pub(super) struct Sections<'a> {
    /// `<Cells>` and `<CellData>`.
    pub cells: &'a str,
    pub n_cells: usize,
    /// Field data arrays besides `TimeValue`.
    pub field: &'a str,
}

/// One frame's `.vtu` text: the reference points, the fixed cell sections, the point
/// vector `displacement_m` and any extra point fields, the time as field data `TimeValue`
/// next to the region lookup.
pub(super) fn frame_xml(
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
pub(super) fn write_pvd_file(dir: &Path, frames: &[(f64, String)]) -> Result<PathBuf, MeshError> {
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
    crate::output::file::write_bytes(&path, s.as_bytes()).map_err(io_err(&path))?;
    Ok(path)
}

pub(super) fn vec3_line(s: &mut String, v: [f64; 3]) {
    s.push_str("          ");
    num(s, v[0]);
    s.push(' ');
    num(s, v[1]);
    s.push(' ');
    num(s, v[2]);
    s.push('\n');
}

pub(super) fn write_vectors(s: &mut String, name: &str, v: &[[f64; 3]]) {
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
