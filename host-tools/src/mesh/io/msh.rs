//! The Gmsh MSH reader, versions 4.1 and 2.2, ASCII and binary: the sections volume
//! meshes use. Hexahedra and prisms are the cells; points, curves and surfaces tagged
//! with a physical group give that group's node set (see [`CellCollector`]).

use super::cells::{gmsh_type, CellCollector, CellKind};
use super::*;

/// The MSH versions read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum MshVersion {
    V41,
    V22,
}

/// What the sections read so far hold, assembled into a [`Mesh`] at the end.
#[derive(Default)]
pub(super) struct MshContents {
    seen_format: bool,
    pub version: Option<MshVersion>,
    pub endian: Option<Endian>,
    /// (dimension, physical tag) -> name.
    pub physical_names: BTreeMap<(i32, i32), String>,
    /// (dimension, entity tag) -> the entity's physical tags.
    entity_groups: HashMap<(i32, i32), Vec<i32>>,
    seen_entities: bool,
    pub nodes: Vec<[f64; 3]>,
    pub node_tags: Vec<u64>,
    pub node_index: HashMap<u64, u32>,
    pub seen_nodes: bool,
    pub cells: CellCollector,
    seen_elements: bool,
}

impl MshContents {
    /// The node set name of physical group `tag` of dimension `dim` (0-2): its
    /// `$PhysicalNames` name, else "point N", "curve N" or "surface N".
    pub fn group_name(&self, dim: i32, tag: i32) -> String {
        match self.physical_names.get(&(dim, tag)) {
            Some(n) => n.clone(),
            None => {
                let kind = ["point", "curve", "surface", "volume"];
                format!("{} {tag}", kind.get(dim as usize).unwrap_or(&"group"))
            }
        }
    }
}

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
                read_entities(&mut r, &mut m.entity_groups)?;
            }
            "$Nodes" => {
                if m.seen_nodes {
                    return Err(r.err(Some(line), "more than one $Nodes section"));
                }
                m.seen_nodes = true;
                if v2 {
                    super::msh2::read_nodes(&mut r, path, &mut m)?;
                } else {
                    r.bin = m.endian;
                    read_nodes(&mut r, path, &mut m)?;
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
                    super::msh2::read_elements(&mut r, path, &mut m)?;
                } else {
                    r.bin = m.endian;
                    read_elements(&mut r, path, &mut m)?;
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

/// `$Entities`: the physical tags of each entity, by (dimension, entity tag).
fn read_entities(
    r: &mut Reader,
    groups: &mut HashMap<(i32, i32), Vec<i32>>,
) -> Result<(), MeshError> {
    let np = r.count("number of point entities")?;
    let nc = r.count("number of curve entities")?;
    let ns = r.count("number of surface entities")?;
    let nv = r.count("number of volume entities")?;
    for (dim, count) in [(0, np), (1, nc), (2, ns), (3, nv)] {
        for _ in 0..count {
            let tag = r.int("entity tag")?;
            let coords = if dim == 0 { 3 } else { 6 };
            for _ in 0..coords {
                r.float("entity bounding box coordinate")?;
            }
            let nphys = r.count("number of physical tags")?;
            let mut tags = Vec::with_capacity(cap(nphys));
            for _ in 0..nphys {
                tags.push(r.int("physical tag")?);
            }
            if dim > 0 {
                let nb = r.count("number of bounding entities")?;
                for _ in 0..nb {
                    r.int("bounding entity tag")?;
                }
            }
            groups.insert((dim, tag), tags);
        }
    }
    r.expect_end("$EndEntities")
}

/// `$Nodes`: coordinates in file order, their tags, and tag -> index.
fn read_nodes(r: &mut Reader, path: &Path, m: &mut MshContents) -> Result<(), MeshError> {
    let (nblocks, total, total_line) = block_header(r, "node")?;
    m.nodes.reserve(cap(total));
    m.node_tags.reserve(cap(total));
    for _ in 0..nblocks {
        let dim = r.int("node block entity dimension")?;
        r.int("node block entity tag")?;
        let parametric = r.int("node block parametric flag")?;
        if !(0..=1).contains(&parametric) || !(0..=3).contains(&dim) {
            return Err(r.err_item(format!(
                "node block with dimension {dim} and parametric flag {parametric} \
                 (expected 0..3 and 0 or 1)"
            )));
        }
        let n = r.count("number of nodes in block")?;
        let first = m.node_tags.len();
        for _ in 0..n {
            let tag = r.size("node tag")?;
            if m.node_index.insert(tag, m.node_tags.len() as u32).is_some() {
                return Err(r.err_item(format!("node tag {tag} defined twice")));
            }
            m.node_tags.push(tag);
        }
        let extra = if parametric == 1 { dim } else { 0 };
        for i in 0..n {
            let tag = m.node_tags[first + i];
            let what = format!("coordinate of node {tag}");
            let p = [r.float(&what)?, r.float(&what)?, r.float(&what)?];
            for _ in 0..extra {
                r.float(&format!("parametric coordinate of node {tag}"))?;
            }
            if !p.iter().all(|x| x.is_finite()) {
                return Err(MeshError::NonFiniteCoordinate {
                    path: path.to_path_buf(),
                    node: tag,
                    coords: p,
                });
            }
            m.nodes.push(p);
        }
        if m.node_tags.len() > u32::MAX as usize {
            return Err(r.err_item("more than 2^32 nodes"));
        }
    }
    check_total(r, "Nodes", total, m.nodes.len(), total_line)
}

/// `$Elements`: hexahedra and prisms with their regions, boundary cells into the node sets
/// of their entity's physical groups, other volume cells counted (and refused at the end).
fn read_elements(r: &mut Reader, path: &Path, m: &mut MshContents) -> Result<(), MeshError> {
    let (nblocks, total, total_line) = block_header(r, "element")?;
    let mut read = 0usize;
    let mut nodes = Vec::new();
    for _ in 0..nblocks {
        let dim = r.int("element block entity dimension")?;
        let entity = r.int("element block entity tag")?;
        let etype = r.int("element type")?;
        let (kind, nn, name) = gmsh_type(etype)
            .ok_or_else(|| r.err_item(format!("unknown Gmsh element type {etype}")))?;
        let n = r.count("number of elements in block")?;
        read += n;
        match kind {
            CellKind::Unsupported => {
                m.cells.unsupported(name.to_string(), n);
                for _ in 0..n * (nn + 1) {
                    r.size("element data")?;
                }
            }
            CellKind::Boundary { .. } => {
                let groups: Vec<String> = m
                    .entity_groups
                    .get(&(dim, entity))
                    .map(|tags| tags.iter().map(|&t| m.group_name(dim, t)).collect())
                    .unwrap_or_default();
                for _ in 0..n {
                    nodes.clear();
                    read_cell_nodes(r, path, &m.node_index, nn, false, &mut nodes)?;
                    m.cells.boundary(name, &nodes, &groups);
                }
            }
            CellKind::Hexahedron | CellKind::Prism => {
                // Without $Entities there is no physical group information: region 0.
                // With it, a block on an unlisted volume is an inconsistent file (meshio 5
                // writes such files) and guessing would mislabel tissue.
                let region = match m.entity_groups.get(&(3, entity)) {
                    _ if dim != 3 || !m.seen_entities => 0,
                    Some(tags) => tags.first().copied().unwrap_or(0),
                    None => {
                        return Err(r.err_item(format!(
                            "{name} block on volume entity {entity}, which $Entities \
                             does not list (so its physical group is unknown)"
                        )))
                    }
                };
                for _ in 0..n {
                    nodes.clear();
                    read_cell_nodes(r, path, &m.node_index, nn, true, &mut nodes)?;
                    m.cells.volume(kind, &nodes, region, &m.nodes);
                }
            }
        }
    }
    check_total(r, "Elements", total, read, total_line)
}

/// The header of `$Nodes` / `$Elements` (`what`: "node" / "element"): the number of blocks,
/// the total count (and its line), the tag range (skipped).
fn block_header(r: &mut Reader, what: &str) -> Result<(usize, usize, Option<usize>), MeshError> {
    let nblocks = r.count(&format!("number of {what} blocks"))?;
    let total = r.count(&format!("number of {what}s"))?;
    let total_line = r.item_line();
    r.size(&format!("minimum {what} tag"))?;
    r.size(&format!("maximum {what} tag"))?;
    Ok((nblocks, total, total_line))
}

/// The end of section `$NAME` (`Nodes` / `Elements`), after checking that its blocks held
/// the `total` its header announced.
fn check_total(
    r: &mut Reader,
    name: &str,
    total: usize,
    held: usize,
    total_line: Option<usize>,
) -> Result<(), MeshError> {
    if held != total {
        let what = name.to_lowercase();
        let msg = format!("${name} header announces {total} {what}, blocks hold {held}");
        return Err(r.err(total_line, msg));
    }
    r.expect_end(&format!("$End{name}"))
}

/// One element of a block: its tag and `n` known node tags (appended to `out` as
/// indices), distinct if `distinct`.
pub(super) fn read_cell_nodes(
    r: &mut Reader,
    path: &Path,
    node_index: &HashMap<u64, u32>,
    n: usize,
    distinct: bool,
    out: &mut Vec<u32>,
) -> Result<u64, MeshError> {
    let etag = r.size("element tag")?;
    read_element_nodes(r, path, node_index, etag, n, distinct, false, out)?;
    Ok(etag)
}

/// The `n` node tags of element `etag` (appended to `out` as indices), distinct if
/// `distinct`; binary tags are 4-byte `int`s if `int_tags` (MSH 2.2), else `size_t`.
#[allow(clippy::too_many_arguments)]
pub(super) fn read_element_nodes(
    r: &mut Reader,
    path: &Path,
    node_index: &HashMap<u64, u32>,
    etag: u64,
    n: usize,
    distinct: bool,
    int_tags: bool,
    out: &mut Vec<u32>,
) -> Result<(), MeshError> {
    let what = format!("node tag of element {etag}");
    let start = out.len();
    for _ in 0..n {
        let ntag = match (int_tags, r.bin) {
            (true, Some(_)) => {
                u64::try_from(r.int(&what)?).map_err(|_| r.err_item(format!("negative {what}")))?
            }
            _ => r.size(&what)?,
        };
        let idx = *node_index.get(&ntag).ok_or(MeshError::UnknownNode {
            path: path.to_path_buf(),
            line: r.item_line(),
            element: etag,
            node: ntag,
        })?;
        if distinct && out[start..].contains(&idx) {
            let at = match r.item_line() {
                Some(l) => format!("element {etag} (line {l})"),
                None => format!("element {etag}"),
            };
            return Err(MeshError::RepeatedNode {
                path: path.to_path_buf(),
                item: at,
                node: ntag,
            });
        }
        out.push(idx);
    }
    Ok(())
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
