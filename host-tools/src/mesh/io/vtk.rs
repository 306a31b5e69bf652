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

use super::cells::{vtk_type, CellCollector, CellKind};
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

/// zlib inflates a byte into at most 1032 (RFC 1950/1951: a 258-byte match per 2 bits at
/// best); LZ4 into at most 255 + a little. Anything claiming more is not compressed data.
const INFLATE_RATIO_MAX: u64 = 1032;

/// The standard base64 alphabet's value of `c`, None for padding or anything else.
fn b64_value(c: u8) -> Option<u32> {
    Some(match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => return None,
    } as u32)
}

/// The first `n` bytes base64 `text` encodes (None if it holds fewer).
fn b64_prefix(text: &[u8], n: usize) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(n + 2);
    for quad in text.chunks(4) {
        if out.len() >= n {
            break;
        }
        let v: Vec<u32> = quad.iter().map_while(|&c| b64_value(c)).collect();
        if v.len() < 2 {
            return None;
        }
        let w = v.iter().fold(0u32, |a, &x| (a << 6) | x) << (6 * (4 - v.len()));
        out.extend_from_slice(&w.to_be_bytes()[1..v.len()]);
    }
    (out.len() >= n).then(|| {
        out.truncate(n);
        out
    })
}

/// A compressed VTU's binary arrays (inline, or appended base64) claim their
/// uncompressed size in a header that vtkio allocates before it inflates anything: a
/// damaged header (found by fuzzing: 2 GiB claimed by a 2.6 kB file) would make the tool
/// allocate it. Each header is read here first and a claim beyond what its compressed
/// bytes can inflate to is refused, naming the line of its DataArray.
fn check_compressed_sizes(path: &Path, bytes: &[u8]) -> Result<(), MeshError> {
    // The XML before any appended data is text (appended data may be raw bytes).
    let appended_at = find_bytes(bytes, b"<AppendedData");
    // Lossy: vtkio reads a file with stray non-UTF-8 bytes (in a comment, say) all the same
    // (libFuzzer found a 2 GiB claim behind one); they change no base64 text or newline.
    let text = String::from_utf8_lossy(&bytes[..appended_at.unwrap_or(bytes.len())]);
    let text: &str = &text;
    if !text.contains("compressor=") {
        return Ok(());
    }
    let width = if text.contains("header_type=\"UInt64\"") {
        8
    } else {
        4
    };
    let damaged = |line: usize, what: String| {
        perr(
            path,
            Some(line),
            format!("a compressed DataArray's header {what}: a damaged header"),
        )
    };
    // Inline arrays: the base64 text right after the tag.
    let mut at = 0;
    while let Some(k) = text[at..].find("format=\"binary\"") {
        let tag_end = match text[at + k..].find('>') {
            Some(e) => at + k + e + 1,
            None => break,
        };
        at = tag_end;
        let body = text[tag_end..].trim_start().as_bytes();
        let line = 1 + text[..tag_end].matches('\n').count();
        compressed_header_claim(body, width).map_err(|what| damaged(line, what))?;
    }
    // Appended arrays: at their `offset` after the `_` that opens the AppendedData.
    let Some(a) = appended_at else {
        return Ok(());
    };
    let Some(tag_len) = bytes[a..].iter().position(|&b| b == b'>') else {
        return Ok(());
    };
    if String::from_utf8_lossy(&bytes[a..a + tag_len]).contains("encoding=\"raw\"") {
        return Ok(()); // refused by `refuse_raw_appended`
    }
    let after_tag = &bytes[a + tag_len + 1..];
    let Some(underscore) = after_tag.iter().position(|&b| b == b'_') else {
        return Ok(());
    };
    let data = &after_tag[underscore + 1..];
    let mut at = 0;
    while let Some(k) = text[at..].find("format=\"appended\"") {
        let tag_start = text[..at + k].rfind('<').unwrap_or(0);
        let tag_end = text[at + k..].find('>').map_or(text.len(), |e| at + k + e);
        at = tag_end.max(at + k + 1);
        let line = 1 + text[..tag_start].matches('\n').count();
        let Some(offset) = attribute(&text[tag_start..tag_end], "offset") else {
            continue; // vtkio names the missing offset
        };
        let Some(body) = offset.parse::<usize>().ok().and_then(|o| data.get(o..)) else {
            return Err(damaged(
                line,
                format!(
                    "is at offset {offset}, beyond the {} bytes of appended data",
                    data.len()
                ),
            ));
        };
        compressed_header_claim(body, width).map_err(|what| damaged(line, what))?;
    }
    Ok(())
}

/// vtkio 0.7 reads no raw appended data (ParaView's default for `.vtu`): its own error
/// ("unknown variant `raw`") does not say what to do, this one does, naming the line.
fn refuse_raw_appended(path: &Path, bytes: &[u8]) -> Result<(), MeshError> {
    let Some(a) = find_bytes(bytes, b"<AppendedData") else {
        return Ok(());
    };
    let tag_len = bytes[a..]
        .iter()
        .position(|&b| b == b'>')
        .unwrap_or(bytes.len() - a);
    if !String::from_utf8_lossy(&bytes[a..a + tag_len]).contains("encoding=\"raw\"") {
        return Ok(());
    }
    let line = 1 + bytes[..a].iter().filter(|&&b| b == b'\n').count();
    Err(perr(
        path,
        Some(line),
        "appended data in raw encoding is not read (vtkio 0.7): save the file with its \
         appended data base64-encoded (ParaView: Encode Appended Data; VTK: \
         SetEncodeAppendedData(1)) or its data inline (meshio)"
            .to_string(),
    ))
}

/// The first position of `needle` in `hay`.
fn find_bytes(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// The value of XML attribute `name="..."` in `tag`.
fn attribute<'t>(tag: &'t str, name: &str) -> Option<&'t str> {
    let key = format!(" {name}=\"");
    let from = tag.find(&key)? + key.len();
    let len = tag[from..].find('"')?;
    Some(&tag[from..from + len])
}

/// Checks the header of one compressed array, `body` being its base64 text (the header is
/// encoded on its own, the compressed blocks after it): the block count first, then the block size, the last block's size and each
/// block's compressed size, `width` bytes each, little-endian. The error says what the
/// header claims that its data cannot hold.
fn compressed_header_claim(body: &[u8], width: usize) -> Result<(), String> {
    let num = |b: &[u8]| -> u64 { b.iter().rev().fold(0u64, |a, &x| (a << 8) | u64::from(x)) };
    // The header's first `n` bytes.
    let header = |n: usize| b64_prefix(&body[..(4 * n.div_ceil(3)).min(body.len())], n);
    let Some(nb) = header(width).map(|h| num(&h)) else {
        return Ok(()); // too short for a block count: vtkio refuses it
    };
    // vtkio reads (and allocates) as many block sizes as the count claims.
    if nb == 0 || nb > body.len() as u64 {
        return Err(format!(
            "claims {nb} blocks in {} bytes of data",
            body.len()
        ));
    }
    let full = (3 + nb as usize) * width;
    let Some(h) = header(full) else {
        return Err(format!(
            "claims {nb} blocks, more sizes than its data holds"
        ));
    };
    let field = |i: usize| num(&h[i * width..(i + 1) * width]);
    let (block, last) = (field(1), field(2));
    let compressed: u64 = (3..3 + nb as usize).map(field).fold(0, u64::saturating_add);
    let claimed = block
        .saturating_mul(nb.saturating_sub(1))
        .saturating_add(last);
    if claimed
        > compressed
            .saturating_add(1)
            .saturating_mul(INFLATE_RATIO_MAX)
    {
        return Err(format!(
            "claims {claimed} bytes in {nb} blocks from {compressed} compressed bytes (compression inflates at most {INFLATE_RATIO_MAX}x)"
        ));
    }
    Ok(())
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

/// The mesh of a data set that must be one inline unstructured grid piece.
fn grid_mesh(path: &Path, data: DataSet, format: &str) -> Result<Mesh, MeshError> {
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

/// A parse error of `path` (at `line` when known).
fn perr(path: &Path, line: Option<usize>, msg: String) -> MeshError {
    MeshError::Parse {
        path: path.to_path_buf(),
        line,
        msg,
    }
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
            CellKind::Hexahedron | CellKind::Prism => {
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

/// Walk the sections of an ASCII legacy VTK file (POINTS, CELLS, CELL_TYPES,
/// CELL_DATA/POINT_DATA with SCALARS, VECTORS, NORMALS, FIELD), checking the counts and that
/// every value is a number. Stops without error at the first keyword it does not know.
fn walk_vtk(r: &mut Reader<'_>) -> Result<(), MeshError> {
    if !walk_vtk_header(r)? {
        return Ok(());
    }
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
                for i in 0..value_count(r, l, 3, n, "POINTS")? {
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
                for i in 0..value_count(r, l, attr_count, comps, "SCALARS")? {
                    let _: f64 = r.num(&format!("value {i} of SCALARS {name:?}"))?;
                }
            }
            "VECTORS" | "NORMALS" => {
                let (name, _) = r.token("array name")?;
                r.token("array type")?;
                for i in 0..value_count(r, l, 3, attr_count, kw)? {
                    let _: f64 = r.num(&format!("value {i} of {kw} {name:?}"))?;
                }
            }
            "FIELD" => {
                r.token("FIELD name")?;
                let arrays: usize = r.num("number of FIELD arrays")?;
                for _ in 0..arrays {
                    let (name, nl) = r.token("FIELD array name")?;
                    let comps: usize = r.num("FIELD array component count")?;
                    let tuples: usize = r.num("FIELD array tuple count")?;
                    r.token("FIELD array type")?;
                    for i in 0..value_count(r, nl, comps, tuples, "FIELD array")? {
                        let _: f64 = r.num(&format!("value {i} of FIELD array {name:?}"))?;
                    }
                }
            }
            // Anything else (METADATA, TENSORS, ...) is beyond this check: stop here.
            _ => return Ok(()),
        }
    }
}

/// `a * b` values of a section announced on line `l`; a product beyond `usize` (a count no
/// file can hold) is an error naming the line, not an overflow.
fn value_count(
    r: &Reader<'_>,
    l: usize,
    a: usize,
    b: usize,
    what: &str,
) -> Result<usize, MeshError> {
    a.checked_mul(b).ok_or_else(|| {
        r.err(
            Some(l),
            format!("{what} announces {a} x {b} values, more than any file holds"),
        )
    })
}

/// The four header lines: version, title, ASCII, `DATASET UNSTRUCTURED_GRID`; false for a
/// BINARY file (not walked).
fn walk_vtk_header(r: &mut Reader<'_>) -> Result<bool, MeshError> {
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
    if enc == "BINARY" {
        // Binary data is for vtkio alone.
        return Ok(false);
    }
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
    Ok(true)
}
