//! The VTK unstructured-grid readers: legacy VTK (versions up to 5.1, ASCII or binary) and
//! XML `.vtu` (ASCII, binary or appended base64 data, zlib or LZ4 compressed; raw appended data is refused), both through
//! `vtkio`. For ASCII legacy files a structural walk of the text first locates faults by
//! line (vtkio's own errors carry no position, and it silently drops a cell data array cut
//! short by truncation).
//!
//! What the cells become is [`CellCollector`]'s rule: hexahedra and wedges are the cells,
//! boundary cells (vertices, lines, triangles, quads) tagged in the region array give node
//! sets named "ARRAY VALUE" (e.g. "gmsh:physical 2"), other volume cells are refused.
//! One-component integer point data gives the node set of its non-zero nodes, named as the
//! array.

use super::*;

mod grid;
mod walk;
mod xml;

use grid::grid_mesh;
use walk::walk_vtk;
use xml::{check_compressed_sizes, refuse_raw_appended};

/// Parse the bytes of a legacy VTK unstructured grid (any version up to 5.1, ASCII or
/// big-endian binary, as the format prescribes). `path` is used for error messages only.
/// Region tags come from the integer cell array named `region` (or `Region`,
/// `gmsh:physical`, `PhysicalGroup`, `CellEntityIds`, else the first one-component integer
/// cell array, as plain data or in a FIELD), of any integer type; without one every cell is
/// in region 0. Node tags are 1-based indices.
pub fn parse_vtk(path: &Path, bytes: &[u8]) -> Result<Mesh, MeshError> {
    // vtkio reports neither where nor what went wrong, and silently drops a cell data array
    // cut short by a truncated file, so walk the ASCII structure first: it finds those faults
    // with a line number.
    if std::str::from_utf8(bytes).is_ok() {
        walk_vtk(&mut Reader::new(path, bytes))?;
    }
    let bytes = legacy_type_names(bytes);
    let vtk = vtkio_guarded(path, "legacy VTK", || {
        vtkio::Vtk::parse_legacy_be(&bytes[..])
    })?
    .map_err(|e| {
        perr(
            path,
            None,
            format!(
                "not a readable legacy VTK unstructured grid (vtkio: {})",
                vtkio_message(e)
            ),
        )
    })?;
    grid_mesh(path, vtk.data, "legacy VTK")
}

/// Parse the bytes of an XML VTK unstructured grid (`.vtu`): one piece, data inline (ASCII
/// or base64) or appended base64, uncompressed, zlib or LZ4; raw appended data is refused
/// (vtkio 0.7 does not read it). Regions, node sets and node tags as
/// for [`parse_vtk`].
pub fn parse_vtu(path: &Path, bytes: &[u8]) -> Result<Mesh, MeshError> {
    refuse_raw_appended(path, bytes)?;
    check_compressed_sizes(path, bytes)?;
    let vtk = vtkio_guarded(path, "VTK XML", || vtkio::Vtk::parse_xml(bytes))?.map_err(|e| {
        perr(
            path,
            None,
            format!(
                "not a readable VTK XML unstructured grid (vtkio: {})",
                vtkio_message(e)
            ),
        )
    })?;
    grid_mesh(path, vtk.data, "VTU")
}

/// Runs a vtkio parse, turning a panic inside vtkio (it indexes by lengths read from the
/// file: a damaged VTU header length panics in its decompressor) into an error naming the
/// file, instead of a crash of the host tool.
fn vtkio_guarded<R>(path: &Path, format: &str, parse: impl FnOnce() -> R) -> Result<R, MeshError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(parse)).map_err(|_| {
        perr(
            path,
            None,
            format!(
                "not a readable {format} file: its data lengths do not fit the file (vtkio failed)"
            ),
        )
    })
}

/// VTK 5.1's data type names (`vtktypeint64`, ...) on FIELD array and attribute header
/// lines replaced by the legacy names vtkio knows (`long`, ...): VTK and meshio write them,
/// vtkio 0.7 reads them only in OFFSETS/CONNECTIVITY. Only a text line whose last token is
/// such a name and that has the shape of a header (`NAME COMPONENTS TUPLES TYPE`, or
/// `SCALARS|VECTORS|NORMALS|TENSORS NAME TYPE [N]`) is changed, so binary data is left alone.
fn legacy_type_names(bytes: &[u8]) -> std::borrow::Cow<'_, [u8]> {
    const NAMES: [(&str, &str); 9] = [
        ("vtktypeint8", "char"),
        ("vtktypeuint8", "unsigned_char"),
        ("vtktypeint16", "short"),
        ("vtktypeint32", "int"),
        ("vtktypeuint32", "unsigned_int"),
        ("vtktypeint64", "long"),
        ("vtktypeuint64", "unsigned_long"),
        ("vtktypefloat32", "float"),
        ("vtktypefloat64", "double"),
    ];
    if !bytes.windows(7).any(|w| w == b"vtktype") {
        return std::borrow::Cow::Borrowed(bytes);
    }
    let mut out = Vec::with_capacity(bytes.len());
    for (k, line) in bytes.split(|&b| b == b'\n').enumerate() {
        if k > 0 {
            out.push(b'\n');
        }
        let replaced = std::str::from_utf8(line).ok().and_then(|text| {
            let mut t: Vec<&str> = text.split_whitespace().collect();
            let ty_at = match t.as_slice() {
                ["SCALARS", _, _] | ["SCALARS", _, _, _] => 2,
                ["VECTORS" | "NORMALS" | "TENSORS", _, _] => 2,
                [_, c, n, _] if c.parse::<u32>().is_ok() && n.parse::<u64>().is_ok() => 3,
                _ => return None,
            };
            t[ty_at] = NAMES.iter().find(|(n, _)| *n == t[ty_at])?.1;
            Some(t.join(" "))
        });
        match replaced {
            Some(r) => out.extend_from_slice(r.as_bytes()),
            None => out.extend_from_slice(line),
        }
    }
    std::borrow::Cow::Owned(out)
}

fn vtkio_message(e: vtkio::Error) -> String {
    match e {
        vtkio::Error::Unknown => "incomplete input".to_string(),
        other => other.to_string(),
    }
}

/// A parse error of `path` (at `line` when known).
fn perr(path: &Path, line: Option<usize>, msg: String) -> MeshError {
    MeshError::Parse {
        path: path.to_path_buf(),
        line,
        msg,
    }
}
