//! The legacy VTK unstructured-grid reader: a structural walk of the text that locates
//! faults by line, then `vtkio` for the data.

use super::*;
use vtkio::model::{Attribute, CellType, Cells, DataSet, IOBuffer, Piece, UnstructuredGridPiece};

/// `VTK_HEXAHEDRON`.
const VTK_HEXAHEDRON: u8 = 12;

/// Names of cell data arrays taken as the region tag, in order of preference; otherwise the
/// first one-component integer cell array is used.
const REGION_ARRAY_NAMES: [&str; 5] = [
    "region",
    "Region",
    "gmsh:physical",
    "PhysicalGroup",
    "CellEntityIds",
];

/// Parse the bytes of a legacy VTK unstructured grid of `VTK_HEXAHEDRON` cells (ASCII or
/// big-endian binary, as the format prescribes). `path` is used for error messages only.
/// Region tags come from the integer cell array named `region` (or `Region`,
/// `gmsh:physical`, `PhysicalGroup`, `CellEntityIds`, else the first one-component integer
/// cell array); without one every cell is in region 0. Node tags are 1-based indices.
pub fn parse_vtk(path: &Path, bytes: &[u8]) -> Result<Mesh, MeshError> {
    // vtkio reports neither where nor what went wrong, and silently drops a cell data array
    // cut short by a truncated file, so walk the ASCII structure first: it finds those faults
    // with a line number.
    if std::str::from_utf8(bytes).is_ok() {
        walk_vtk(&mut Reader::new(path, bytes))?;
    }
    let piece = read_piece(path, bytes)?;
    let nodes = piece_nodes(path, piece.points)?;
    let node_tags: Vec<u64> = (1..=nodes.len() as u64).collect();
    let cells = piece_cells(path, piece.cells, nodes.len())?;
    let cell_regions = piece_regions(path, piece.data.cell, cells.len())?;

    let mesh = Mesh {
        nodes,
        node_tags,
        cells,
        cell_regions,
        region_names: BTreeMap::new(),
        source: path.display().to_string(),
    };
    mesh.validate()?;
    Ok(mesh)
}

/// A parse error of `path` (at `line` when known).
fn perr(path: &Path, line: Option<usize>, msg: String) -> MeshError {
    MeshError::Parse {
        path: path.to_path_buf(),
        line,
        msg,
    }
}

/// The one inline unstructured grid piece of the file, through vtkio.
fn read_piece(path: &Path, bytes: &[u8]) -> Result<UnstructuredGridPiece, MeshError> {
    let vtk = vtkio::Vtk::parse_legacy_be(bytes).map_err(|e| MeshError::Parse {
        path: path.to_path_buf(),
        line: None,
        msg: format!(
            "not a readable legacy VTK unstructured grid (vtkio: {})",
            match e {
                vtkio::Error::Unknown => "incomplete input".to_string(),
                other => other.to_string(),
            }
        ),
    })?;
    let pieces = match vtk.data {
        DataSet::UnstructuredGrid { pieces, .. } => pieces,
        _ => {
            return Err(perr(
                path,
                None,
                "dataset is not an UNSTRUCTURED_GRID".to_string(),
            ))
        }
    };
    if pieces.len() != 1 {
        return Err(perr(
            path,
            None,
            format!(
                "expected one unstructured grid piece, found {}",
                pieces.len()
            ),
        ));
    }
    match pieces.into_iter().next() {
        Some(Piece::Inline(p)) => Ok(*p),
        _ => Err(perr(
            path,
            None,
            "unstructured grid data is not inline".to_string(),
        )),
    }
}

/// The POINTS as finite 3-vectors.
fn piece_nodes(path: &Path, points: IOBuffer) -> Result<Vec<[f64; 3]>, MeshError> {
    let coords: Vec<f64> = match points {
        IOBuffer::F64(v) => v,
        IOBuffer::F32(v) => v.into_iter().map(f64::from).collect(),
        other => other.cast_into::<f64>().ok_or_else(|| {
            perr(
                path,
                None,
                "POINTS have an unsupported number type".to_string(),
            )
        })?,
    };
    if !coords.chunks_exact(3).remainder().is_empty() {
        return Err(perr(
            path,
            None,
            format!("POINTS hold {} numbers, not a multiple of 3", coords.len()),
        ));
    }
    let nodes: Vec<[f64; 3]> = coords.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    for (i, p) in nodes.iter().enumerate() {
        if !p.iter().all(|x| x.is_finite()) {
            return Err(MeshError::NonFiniteCoordinate {
                path: path.to_path_buf(),
                node: i as u64 + 1,
                coords: *p,
            });
        }
    }
    Ok(nodes)
}

/// The cells, all hexahedra of eight distinct nodes among the `n_nodes`.
fn piece_cells(path: &Path, cells: Cells, n_nodes: usize) -> Result<Vec<[u32; 8]>, MeshError> {
    let types = cells.types;
    let (connectivity, offsets) = cells.cell_verts.into_xml();
    if offsets.len() != types.len() {
        return Err(perr(
            path,
            None,
            format!("{} cells but {} CELL_TYPES", offsets.len(), types.len()),
        ));
    }
    if types.is_empty() {
        return Err(MeshError::NoHexahedra {
            path: path.to_path_buf(),
            detail: "the file has no cells".to_string(),
        });
    }
    let mut cells = Vec::with_capacity(types.len());
    let mut start = 0usize;
    for (ci, (&ty, &end)) in types.iter().zip(&offsets).enumerate() {
        if ty != CellType::Hexahedron {
            return Err(MeshError::NonHexCell {
                path: path.to_path_buf(),
                cell: ci,
                cell_type: format!("{} ({ty:?})", ty as u8),
            });
        }
        let end = end as usize;
        let verts = connectivity.get(start..end).ok_or_else(|| {
            perr(
                path,
                None,
                format!("cell {ci}: connectivity offsets out of range"),
            )
        })?;
        if verts.len() != 8 {
            return Err(perr(
                path,
                None,
                format!(
                    "cell {ci} is VTK_HEXAHEDRON ({VTK_HEXAHEDRON}) but has {} points",
                    verts.len()
                ),
            ));
        }
        let mut cell = [0u32; 8];
        for (a, &v) in verts.iter().enumerate() {
            if v as usize >= n_nodes {
                return Err(MeshError::NodeIndexOutOfRange {
                    path: path.to_path_buf(),
                    cell: ci,
                    index: u32::try_from(v).unwrap_or(u32::MAX),
                    nodes: n_nodes,
                });
            }
            if cell[..a].contains(&(v as u32)) {
                return Err(MeshError::RepeatedNode {
                    path: path.to_path_buf(),
                    item: format!("cell {ci}"),
                    node: v + 1,
                });
            }
            cell[a] = v as u32;
        }
        cells.push(cell);
        start = end;
    }
    Ok(cells)
}

/// Region tags from an integer cell data array (see [`REGION_ARRAY_NAMES`]); 0 for every
/// cell without one.
fn piece_regions(
    path: &Path,
    cell_data: Vec<Attribute>,
    n_cells: usize,
) -> Result<Vec<i32>, MeshError> {
    let arrays: Vec<_> = cell_data
        .into_iter()
        .filter_map(|a| match a {
            Attribute::DataArray(d) => Some(d),
            Attribute::Field { .. } => None,
        })
        .collect();
    let is_int = |b: &IOBuffer| {
        matches!(
            b,
            IOBuffer::I8(_)
                | IOBuffer::U8(_)
                | IOBuffer::I16(_)
                | IOBuffer::U16(_)
                | IOBuffer::I32(_)
                | IOBuffer::U32(_)
                | IOBuffer::I64(_)
                | IOBuffer::U64(_)
        )
    };
    let chosen = REGION_ARRAY_NAMES
        .iter()
        .find_map(|n| arrays.iter().find(|a| a.name == *n))
        .or_else(|| {
            arrays
                .iter()
                .find(|a| is_int(&a.data) && a.data.len() == n_cells)
        });
    let Some(a) = chosen else {
        return Ok(vec![0; n_cells]);
    };
    let name = a.name.clone();
    let vals = a
        .data
        .clone()
        .cast_into::<i64>()
        .ok_or_else(|| perr(path, None, format!("cell data {name:?} is not numeric")))?;
    if vals.len() != n_cells {
        return Err(MeshError::LengthMismatch {
            path: path.to_path_buf(),
            what: format!("cell data {name:?}"),
            expected: n_cells,
            got: vals.len(),
        });
    }
    vals.into_iter()
        .map(|v| {
            i32::try_from(v).map_err(|_| perr(path, None, format!("region {v} out of i32 range")))
        })
        .collect()
}

/// Walk the sections of an ASCII legacy VTK file (POINTS, CELLS, CELL_TYPES,
/// CELL_DATA/POINT_DATA with SCALARS, VECTORS, NORMALS, FIELD), checking the counts and that
/// every value is a number. Stops without error at the first keyword it does not know.
fn walk_vtk(r: &mut Reader<'_>) -> Result<(), MeshError> {
    walk_vtk_header(r)?;
    let mut attr_count = 0usize;
    loop {
        let (kw, l) = match r.token("keyword") {
            Ok(t) => t,
            Err(_) => return Ok(()),
        };
        match kw {
            "POINTS" => {
                let n: usize = r.num("number of points")?;
                r.token("POINTS number type")?;
                for i in 0..3 * n {
                    let _: f64 = r.num(&format!("coordinate {} of point {}", i % 3, i / 3))?;
                }
            }
            "CELLS" => {
                let n: usize = r.num("number of cells")?;
                let size: usize = r.num("CELLS list size")?;
                let mut read = 0usize;
                for c in 0..n {
                    let (tok, tl) = r.token(&format!("point count of cell {c}"))?;
                    if c == 0 && tok == "OFFSETS" {
                        // VTK 5.x offsets/connectivity layout: beyond this check.
                        return Ok(());
                    }
                    let k: usize = tok.parse().map_err(|_| {
                        r.err(
                            Some(tl),
                            format!("expected point count of cell {c}, found {tok:?}"),
                        )
                    })?;
                    for _ in 0..k {
                        let _: u64 = r.num(&format!("point index of cell {c}"))?;
                    }
                    read += k + 1;
                }
                if read != size {
                    return Err(r.err(
                        Some(l),
                        format!("CELLS announces list size {size}, the cells hold {read}"),
                    ));
                }
            }
            "CELL_TYPES" => {
                let n: usize = r.num("number of cell types")?;
                for c in 0..n {
                    let _: u8 = r.num(&format!("type of cell {c}"))?;
                }
            }
            "CELL_DATA" | "POINT_DATA" => attr_count = r.num("number of data values")?,
            "SCALARS" => {
                let (name, _) = r.token("SCALARS name")?;
                r.token("SCALARS type")?;
                let comps = match r.rest_of_line("") {
                    Ok((rest, _)) => rest.parse::<usize>().map_err(|_| {
                        r.err(
                            Some(l),
                            format!("expected SCALARS component count, found {rest:?}"),
                        )
                    })?,
                    Err(_) => 1,
                };
                let (lt, _) = r.token("LOOKUP_TABLE")?;
                if lt != "LOOKUP_TABLE" {
                    return Err(r.err(Some(l), format!("expected LOOKUP_TABLE, found {lt:?}")));
                }
                r.token("lookup table name")?;
                for i in 0..attr_count * comps {
                    let _: f64 = r.num(&format!("value {i} of SCALARS {name:?}"))?;
                }
            }
            "VECTORS" | "NORMALS" => {
                let (name, _) = r.token("array name")?;
                r.token("array type")?;
                for i in 0..3 * attr_count {
                    let _: f64 = r.num(&format!("value {i} of {kw} {name:?}"))?;
                }
            }
            "FIELD" => {
                r.token("FIELD name")?;
                let arrays: usize = r.num("number of FIELD arrays")?;
                for _ in 0..arrays {
                    let (name, _) = r.token("FIELD array name")?;
                    let comps: usize = r.num("FIELD array component count")?;
                    let tuples: usize = r.num("FIELD array tuple count")?;
                    r.token("FIELD array type")?;
                    for i in 0..comps * tuples {
                        let _: f64 = r.num(&format!("value {i} of FIELD array {name:?}"))?;
                    }
                }
            }
            // Anything else (METADATA, TENSORS, ...) is beyond this check: stop here.
            _ => return Ok(()),
        }
    }
}

/// The four header lines: version, title, ASCII, `DATASET UNSTRUCTURED_GRID`.
fn walk_vtk_header(r: &mut Reader<'_>) -> Result<(), MeshError> {
    let (l, head) = r.next_line().ok_or_else(|| r.err(Some(1), "empty file"))?;
    if !head.starts_with("# vtk DataFile Version") {
        return Err(r.err(
            Some(l),
            format!(
                "expected \"# vtk DataFile Version x.y\", found {:?}",
                truncate(head)
            ),
        ));
    }
    // The title line may be blank, so take it raw.
    r.raw_line();
    let (l, enc) = r
        .next_line()
        .ok_or_else(|| r.err(Some(r.eof_line()), "file ends after the title"))?;
    if enc != "ASCII" {
        return Err(r.err(
            Some(l),
            format!("expected ASCII, found {:?}", truncate(enc)),
        ));
    }
    let (l, ds) = r
        .next_line()
        .ok_or_else(|| r.err(Some(r.eof_line()), "no DATASET line"))?;
    if ds.split_whitespace().collect::<Vec<_>>() != ["DATASET", "UNSTRUCTURED_GRID"] {
        return Err(r.err(
            Some(l),
            format!(
                "expected DATASET UNSTRUCTURED_GRID, found {:?}",
                truncate(ds)
            ),
        ));
    }
    Ok(())
}
