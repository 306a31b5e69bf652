//! A vtkio data set into the common [`Mesh`]: one inline unstructured grid piece, its
//! points, its cells through [`CellCollector`], the region array and the point tags.

use super::super::cells::{vtk_type, CellCollector, CellKind};
use super::*;
use vtkio::model::{Attribute, Cells, DataSet, IOBuffer, Piece, UnstructuredGridPiece};

/// Names of cell data arrays taken as the region tag, in order of preference; otherwise the
/// first one-component integer cell array is used.
const REGION_ARRAY_NAMES: [&str; 5] = [
    "region",
    "Region",
    "gmsh:physical",
    "PhysicalGroup",
    "CellEntityIds",
];

/// The mesh of a data set that must be one inline unstructured grid piece.
pub(super) fn grid_mesh(path: &Path, data: DataSet, format: &str) -> Result<Mesh, MeshError> {
    let piece = one_piece(path, data)?;
    let nodes = piece_nodes(path, piece.points)?;
    let node_tags: Vec<u64> = (1..=nodes.len() as u64).collect();
    let n_cells = piece.cells.types.len();
    let regions = region_array(path, &piece.data.cell, n_cells)?;
    let mut cells = CellCollector::default();
    collect_cells(path, piece.cells, &nodes, regions.as_ref(), &mut cells)?;
    for (name, values) in point_tags(&piece.data.point, nodes.len()) {
        let set = values
            .iter()
            .enumerate()
            .filter(|(_, &v)| v != 0)
            .map(|(i, _)| i as u32);
        cells.node_set(name, set);
    }
    let mut mesh = Mesh {
        nodes,
        node_tags,
        source: path.display().to_string(),
        ..Mesh::default()
    };
    cells.finish(path, &mut mesh, format)?;
    mesh.validate()?;
    Ok(mesh)
}

/// The one inline unstructured grid piece of the data set.
fn one_piece(path: &Path, data: DataSet) -> Result<UnstructuredGridPiece, MeshError> {
    let pieces = match data {
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

/// A legacy cell list (`k v1 .. vk` per cell, `num_cells` cells) as XML connectivity and
/// end offsets. vtkio's own conversion sizes its output from `len - num_cells` and asserts
/// the counts, so a list that does not hold its cells (short, or with numbers left over)
/// would overflow or panic there: it is an error here.
fn legacy_cell_list(
    path: &Path,
    num_cells: u32,
    vertices: &[u32],
) -> Result<(Vec<u64>, Vec<u64>), MeshError> {
    let short = |c: u32| {
        perr(
            path,
            None,
            format!(
                "CELLS announces {num_cells} cells, its list of {} numbers ends in cell {c}",
                vertices.len()
            ),
        )
    };
    let mut connectivity = Vec::with_capacity(vertices.len());
    let mut offsets = Vec::with_capacity((num_cells as usize).min(vertices.len()));
    let mut at = 0usize;
    for c in 0..num_cells {
        let k = *vertices.get(at).ok_or_else(|| short(c))? as usize;
        let verts = vertices.get(at + 1..at + 1 + k).ok_or_else(|| short(c))?;
        connectivity.extend(verts.iter().map(|&v| u64::from(v)));
        offsets.push(connectivity.len() as u64);
        at += 1 + k;
    }
    if at != vertices.len() {
        return Err(perr(
            path,
            None,
            format!(
                "CELLS announces {num_cells} cells in {at} numbers, its list holds {}",
                vertices.len()
            ),
        ));
    }
    Ok((connectivity, offsets))
}

/// Every cell into the collector: hexahedra and wedges with their region tags, boundary
/// cells into the node set of their tag, the rest counted as unsupported.
fn collect_cells(
    path: &Path,
    cells: Cells,
    nodes: &[[f64; 3]],
    regions: Option<&(String, Vec<i64>)>,
    out: &mut CellCollector,
) -> Result<(), MeshError> {
    let types = cells.types;
    let (connectivity, mut offsets) = match cells.cell_verts {
        vtkio::model::VertexNumbers::Legacy {
            num_cells,
            vertices,
        } => legacy_cell_list(path, num_cells, &vertices)?,
        xml => xml.into_xml(),
    };
    // Legacy 5.1 OFFSETS start with the 0 the XML form leaves out.
    if offsets.len() == types.len() + 1 && offsets.first() == Some(&0) {
        offsets.remove(0);
    }
    if offsets.len() != types.len() {
        return Err(perr(
            path,
            None,
            format!("{} cells but {} CELL_TYPES", offsets.len(), types.len()),
        ));
    }
    let mut start = 0usize;
    let mut verts32 = Vec::with_capacity(8);
    for (ci, (&ty, &end)) in types.iter().zip(&offsets).enumerate() {
        let end = end as usize;
        let verts = connectivity.get(start..end).ok_or_else(|| {
            perr(
                path,
                None,
                format!("cell {ci}: connectivity offsets out of range"),
            )
        })?;
        start = end;
        let (kind, count, name) = vtk_type(ty as u8);
        if let Some(n) = count.filter(|&n| n != verts.len()) {
            return Err(perr(
                path,
                None,
                format!(
                    "cell {ci} is {name} but has {} points (expected {n})",
                    verts.len()
                ),
            ));
        }
        verts32.clear();
        for &v in verts {
            if v as usize >= nodes.len() {
                return Err(MeshError::NodeIndexOutOfRange {
                    path: path.to_path_buf(),
                    cell: ci,
                    index: u32::try_from(v).unwrap_or(u32::MAX),
                    nodes: nodes.len(),
                });
            }
            verts32.push(v as u32);
        }
        let tag = regions.map(|(_, v)| v[ci]).unwrap_or(0);
        match kind {
            CellKind::Unsupported => out.unsupported(name, 1),
            CellKind::Boundary { .. } => {
                let groups = match regions {
                    Some((array, _)) if tag != 0 => vec![format!("{array} {tag}")],
                    _ => Vec::new(),
                };
                out.boundary(&name, &verts32, &groups);
            }
            CellKind::Hexahedron | CellKind::Prism | CellKind::Tetrahedron => {
                // A hexahedron written as a degenerate prism (corner 3 on 2, 7 on 6) is one.
                let degenerate_prism = verts32.len() == 8
                    && crate::mesh::is_prism(&core::array::from_fn(|a| verts32[a]));
                for (a, &v) in verts32.iter().enumerate() {
                    if verts32[..a].contains(&v) && !degenerate_prism {
                        return Err(MeshError::RepeatedNode {
                            path: path.to_path_buf(),
                            item: format!("cell {ci}"),
                            node: v as u64 + 1,
                        });
                    }
                }
                let region = i32::try_from(tag).map_err(|_| {
                    perr(
                        path,
                        None,
                        format!("cell {ci}: region {tag} out of i32 range"),
                    )
                })?;
                out.volume(kind, &verts32, region, nodes);
            }
        }
    }
    Ok(())
}

/// Whether the buffer holds integers.
fn is_int(b: &IOBuffer) -> bool {
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
}

/// The one-component arrays of a data section, plain or inside FIELDs: (name, components,
/// values).
fn arrays(data: &[Attribute]) -> Vec<(&str, usize, &IOBuffer)> {
    let mut out = Vec::new();
    for a in data {
        match a {
            Attribute::DataArray(d) => {
                out.push((d.name.as_str(), d.elem.num_comp() as usize, &d.data))
            }
            Attribute::Field { data_array, .. } => {
                for f in data_array {
                    out.push((f.name.as_str(), f.elem as usize, &f.data));
                }
            }
        }
    }
    out
}

/// The region array (see [`REGION_ARRAY_NAMES`]) with its name, as i64, or `None`.
fn region_array(
    path: &Path,
    cell_data: &[Attribute],
    n_cells: usize,
) -> Result<Option<(String, Vec<i64>)>, MeshError> {
    let all = arrays(cell_data);
    let chosen = REGION_ARRAY_NAMES
        .iter()
        .find_map(|n| all.iter().find(|a| a.0 == *n))
        .or_else(|| {
            all.iter()
                .find(|a| a.1 == 1 && is_int(a.2) && a.2.len() == n_cells)
        });
    let Some(&(name, comps, data)) = chosen else {
        return Ok(None);
    };
    if comps != 1 {
        return Err(perr(
            path,
            None,
            format!("cell data {name:?} has {comps} components, a region tag has 1"),
        ));
    }
    let vals = data
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
    Ok(Some((name.to_string(), vals)))
}

/// One-component integer point arrays of one value per node: the tags that give node sets.
fn point_tags(point_data: &[Attribute], n_nodes: usize) -> Vec<(String, Vec<i64>)> {
    arrays(point_data)
        .into_iter()
        .filter(|a| a.1 == 1 && is_int(a.2) && a.2.len() == n_nodes)
        .filter_map(|(name, _, data)| Some((name.to_string(), data.cast_into::<i64>()?)))
        .collect()
}
