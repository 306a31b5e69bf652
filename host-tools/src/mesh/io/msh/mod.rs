//! The Gmsh MSH reader, versions 4.1 and 2.2, ASCII and binary: the sections volume
//! meshes use. Hexahedra and prisms are the cells; points, curves and surfaces tagged
//! with a physical group give that group's node set (see [`CellCollector`]).

use super::*;

mod contents;
mod v22;
mod v41;

use contents::{MshContents, MshVersion};

/// Parse the bytes of a Gmsh MSH file, version 4.1 or 2.2, ASCII or binary. `path` is used
/// for error messages only. Hexahedra (type 5) and prisms (type 6, as degenerate
/// hexahedra) are the cells; a cell's region is the (first) physical tag of its volume
/// entity (4.1) or its first tag (2.2), 0 if it has none; region names come from the
/// dimension-3 `$PhysicalNames`. Points, lines, triangles and quadrangles in a physical
/// group give the group's node set, named by `$PhysicalNames` (or "surface N", "curve N",
/// "point N"). Other volume cells are refused, naming their type and count. Nodes keep file
/// order, their tags in `node_tags`. Errors give the line (ASCII) or byte offset (binary).
pub fn parse_msh(path: &Path, bytes: &[u8]) -> Result<Mesh, MeshError> {
    let mut r = Reader::new(path, bytes);
    let mut m = MshContents::default();

    while let Some((line, header)) = r.next_line() {
        if !header.starts_with('$') {
            return Err(r.err(
                Some(line),
                format!(
                    "expected a section header such as $Nodes, found {:?}",
                    truncate(header)
                ),
            ));
        }
        if !m.seen_format && header != "$MeshFormat" {
            return Err(r.err(
                Some(line),
                format!(
                    "expected $MeshFormat as the first section, found {:?}",
                    truncate(header)
                ),
            ));
        }
        let v2 = m.version == Some(MshVersion::V22);
        match header {
            "$MeshFormat" => {
                // A second (ASCII) $MeshFormat keeps the byte order already read.
                let (version, endian) = read_mesh_format(&mut r)?;
                if m.seen_format && m.version != Some(version) {
                    return Err(r.err(Some(line), "a second $MeshFormat with another version"));
                }
                if let Some(e) = endian {
                    m.endian = Some(e);
                }
                m.version = Some(version);
                m.seen_format = true;
            }
            "$PhysicalNames" => read_physical_names(&mut r, &mut m.physical_names)?,
            "$Entities" if !v2 => {
                m.seen_entities = true;
                r.bin = m.endian;
                v41::read_entities(&mut r, &mut m.entity_groups)?;
            }
            "$Nodes" => {
                if m.seen_nodes {
                    return Err(r.err(Some(line), "more than one $Nodes section"));
                }
                m.seen_nodes = true;
                if v2 {
                    v22::read_nodes(&mut r, path, &mut m)?;
                } else {
                    r.bin = m.endian;
                    v41::read_nodes(&mut r, path, &mut m)?;
                }
            }
            "$Elements" => {
                if m.seen_elements {
                    return Err(r.err(Some(line), "more than one $Elements section"));
                }
                if !m.seen_nodes {
                    return Err(r.err(Some(line), "$Elements before $Nodes"));
                }
                m.seen_elements = true;
                if v2 {
                    v22::read_elements(&mut r, path, &mut m)?;
                } else {
                    r.bin = m.endian;
                    v41::read_elements(&mut r, path, &mut m)?;
                }
            }
            _ => skip_section(&mut r, line, header)?,
        }
    }
    finish(&r, path, m)
}

/// `$MeshFormat`: version 4.1 or 2.2, and the byte order of a binary file (None for ASCII).
fn read_mesh_format(r: &mut Reader) -> Result<(MshVersion, Option<Endian>), MeshError> {
    let (version, vline) = r.token("MSH format version")?;
    let version = match version {
        "4.1" => MshVersion::V41,
        "2.2" | "2.1" | "2" | "2.0" => MshVersion::V22,
        _ => {
            return Err(r.err(
                Some(vline),
                format!(
                    "MSH format version {version} is not supported, only 4.1 and 2.2 \
                     (gmsh: -format msh41 or msh22)"
                ),
            ))
        }
    };
    let (file_type, fline) = r.parse::<u32>("MSH file type (0 ASCII, 1 binary)")?;
    let (data_size, dline) = r.parse::<u32>("MSH data size")?;
    let endian = match file_type {
        0 => None,
        1 => {
            if data_size != 8 {
                return Err(r.err(
                    Some(dline),
                    format!("binary MSH with {data_size}-byte size_t is not supported (only 8)"),
                ));
            }
            r.skip_blank();
            if r.b.get(r.pos) == Some(&b'\n') {
                r.pos += 1;
                r.line += 1;
            }
            r.bin = Some(Endian::Little);
            let one = r.take::<4>("binary endianness marker")?;
            if i32::from_le_bytes(one) == 1 {
                Some(Endian::Little)
            } else if i32::from_be_bytes(one) == 1 {
                Some(Endian::Big)
            } else {
                return Err(r.err_item(format!(
                    "binary endianness marker is {one:?}, expected the int 1"
                )));
            }
        }
        other => {
            return Err(r.err(
                Some(fline),
                format!("MSH file type must be 0 (ASCII) or 1 (binary), found {other}"),
            ))
        }
    };
    r.expect_end("$EndMeshFormat")?;
    Ok((version, endian))
}

/// `$PhysicalNames` (text even in binary files): every group's name by (dimension, tag).
fn read_physical_names(
    r: &mut Reader,
    names: &mut BTreeMap<(i32, i32), String>,
) -> Result<(), MeshError> {
    let n: usize = r.num("number of physical names")?;
    for _ in 0..n {
        let dim: i32 = r.num("physical name dimension")?;
        let tag: i32 = r.num("physical tag")?;
        let (name, nline) = r.rest_of_line("physical name")?;
        let name = name
            .strip_prefix('"')
            .and_then(|s| s.strip_suffix('"'))
            .ok_or_else(|| r.err(Some(nline), format!("physical name {name:?} is not quoted")))?;
        names.insert((dim, tag), name.to_string());
    }
    r.expect_end("$EndPhysicalNames")
}

/// Skip an unknown section up to its end marker.
fn skip_section(r: &mut Reader, line: usize, header: &str) -> Result<(), MeshError> {
    let name = &header[1..];
    let end = format!("$End{name}");
    loop {
        match r.next_line() {
            Some((_, l)) if l == end => return Ok(()),
            Some(_) => {}
            None => {
                return Err(r.err(
                    Some(line),
                    format!("section {header} is never closed by {end}"),
                ))
            }
        }
    }
}

/// The checks once every section is read, then the validated mesh.
fn finish(r: &Reader, path: &Path, m: MshContents) -> Result<Mesh, MeshError> {
    if !m.seen_format {
        return Err(r.err(None, "empty file: no $MeshFormat header"));
    }
    if !m.seen_nodes {
        return Err(r.err(None, "no $Nodes section"));
    }
    if !m.seen_elements {
        return Err(MeshError::NoHexahedra {
            path: path.to_path_buf(),
            detail: "the file has no $Elements section".to_string(),
        });
    }
    let mut mesh = Mesh {
        nodes: m.nodes,
        node_tags: m.node_tags,
        region_names: m
            .physical_names
            .iter()
            .filter(|((dim, _), _)| *dim == 3)
            .map(|((_, tag), name)| (*tag, name.clone()))
            .collect(),
        source: path.display().to_string(),
        ..Mesh::default()
    };
    m.cells.finish(path, &mut mesh, "MSH")?;
    mesh.validate()?;
    Ok(mesh)
}
