//! The Gmsh MSH 4.1 reader (ASCII and binary): the sections volume meshes use.

use super::*;

/// Gmsh element type of the 8-node hexahedron.
const GMSH_HEX8: i32 = 5;

/// Number of nodes of a Gmsh element type (the common ones; enough to skip any element
/// block a volume mesh has).
fn gmsh_nodes_per_element(t: u32) -> Option<usize> {
    Some(match t {
        1 => 2,
        2 => 3,
        3 => 4,
        4 => 4,
        5 => 8,
        6 => 6,
        7 => 5,
        8 => 3,
        9 => 6,
        10 => 9,
        11 => 10,
        12 => 27,
        13 => 18,
        14 => 14,
        15 => 1,
        16 => 8,
        17 => 20,
        18 => 15,
        19 => 13,
        20 => 9,
        21 => 10,
        22 => 12,
        23 => 15,
        24 => 15,
        25 => 21,
        26 => 4,
        27 => 5,
        28 => 6,
        29 => 20,
        30 => 35,
        31 => 56,
        92 => 64,
        93 => 125,
        _ => return None,
    })
}

/// What the sections read so far hold, assembled into a [`Mesh`] at the end.
#[derive(Default)]
struct MshContents {
    seen_format: bool,
    endian: Option<Endian>,
    region_names: BTreeMap<i32, String>,
    /// Volume entity tag -> physical group tag.
    volume_region: HashMap<i32, i32>,
    seen_entities: bool,
    nodes: Vec<[f64; 3]>,
    node_tags: Vec<u64>,
    node_index: HashMap<u64, u32>,
    seen_nodes: bool,
    cells: Vec<[u32; 8]>,
    cell_regions: Vec<i32>,
    seen_elements: bool,
    /// Element type -> count, for the "no hexahedra" message.
    other_types: BTreeMap<i32, usize>,
}

/// Parse the bytes of a Gmsh MSH 4.1 file, ASCII or binary. `path` is used for error
/// messages only. Takes the 8-node hexahedra (type 5); lower-dimensional elements are
/// ignored. A cell's region is the first physical tag of its volume entity (0 if it has
/// none), region names come from the dimension-3 `$PhysicalNames`. Nodes keep file order,
/// their tags in `node_tags`. Errors give the line (ASCII) or byte offset (binary).
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
        match header {
            "$MeshFormat" => {
                // A second (ASCII) $MeshFormat keeps the byte order already read.
                if let Some(e) = read_mesh_format(&mut r)? {
                    m.endian = Some(e);
                }
                m.seen_format = true;
            }
            "$PhysicalNames" => read_physical_names(&mut r, &mut m.region_names)?,
            "$Entities" => {
                m.seen_entities = true;
                r.bin = m.endian;
                read_entities(&mut r, &mut m.volume_region)?;
            }
            "$Nodes" => {
                if m.seen_nodes {
                    return Err(r.err(Some(line), "more than one $Nodes section"));
                }
                m.seen_nodes = true;
                r.bin = m.endian;
                read_nodes(&mut r, path, &mut m)?;
            }
            "$Elements" => {
                if m.seen_elements {
                    return Err(r.err(Some(line), "more than one $Elements section"));
                }
                if !m.seen_nodes {
                    return Err(r.err(Some(line), "$Elements before $Nodes"));
                }
                m.seen_elements = true;
                r.bin = m.endian;
                read_elements(&mut r, path, &mut m)?;
            }
            _ => skip_section(&mut r, line, header)?,
        }
    }
    finish(&r, path, m)
}

/// `$MeshFormat`: only version 4.1; returns the byte order of a binary file (None for
/// ASCII).
fn read_mesh_format(r: &mut Reader) -> Result<Option<Endian>, MeshError> {
    let (version, vline) = r.token("MSH format version")?;
    if version != "4.1" {
        return Err(r.err(
            Some(vline),
            format!(
                "MSH format version {version} is not supported, only 4.1 \
                 (gmsh: -format msh41)"
            ),
        ));
    }
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
    Ok(endian)
}

/// `$PhysicalNames` (text even in binary files): the names of the dimension-3 groups.
fn read_physical_names(
    r: &mut Reader,
    region_names: &mut BTreeMap<i32, String>,
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
        if dim == 3 {
            region_names.insert(tag, name.to_string());
        }
    }
    r.expect_end("$EndPhysicalNames")
}

/// `$Entities`: the first physical tag of each volume entity.
fn read_entities(r: &mut Reader, volume_region: &mut HashMap<i32, i32>) -> Result<(), MeshError> {
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
            let mut first = None;
            for _ in 0..nphys {
                let p = r.int("physical tag")?;
                first.get_or_insert(p);
            }
            if dim > 0 {
                let nb = r.count("number of bounding entities")?;
                for _ in 0..nb {
                    r.int("bounding entity tag")?;
                }
            }
            if dim == 3 {
                volume_region.insert(tag, first.unwrap_or(0));
            }
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

/// `$Elements`: the hexahedra with their regions; other element types are skipped and
/// counted.
fn read_elements(r: &mut Reader, path: &Path, m: &mut MshContents) -> Result<(), MeshError> {
    let (nblocks, total, total_line) = block_header(r, "element")?;
    let mut read = 0usize;
    for _ in 0..nblocks {
        let dim = r.int("element block entity dimension")?;
        let entity = r.int("element block entity tag")?;
        let etype = r.int("element type")?;
        let nn = u32::try_from(etype)
            .ok()
            .and_then(gmsh_nodes_per_element)
            .ok_or_else(|| r.err_item(format!("unknown Gmsh element type {etype}")))?;
        let n = r.count("number of elements in block")?;
        read += n;
        if etype != GMSH_HEX8 {
            *m.other_types.entry(etype).or_insert(0) += n;
            for _ in 0..n * (nn + 1) {
                r.size("element data")?;
            }
            continue;
        }
        // Without $Entities there is no physical group information: region 0.
        // With it, a block on an unlisted volume is an inconsistent file (meshio 5
        // writes such files) and guessing would mislabel tissue.
        let region = match m.volume_region.get(&entity) {
            _ if dim != 3 || !m.seen_entities => 0,
            Some(&p) => p,
            None => {
                return Err(r.err_item(format!(
                    "hexahedron block on volume entity {entity}, which $Entities \
                     does not list (so its physical group is unknown)"
                )))
            }
        };
        m.cells.reserve(cap(n));
        for _ in 0..n {
            let cell = read_hexahedron(r, path, &m.node_index)?;
            m.cells.push(cell);
            m.cell_regions.push(region);
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

/// One hexahedron of an element block: its tag and eight distinct known node tags.
fn read_hexahedron(
    r: &mut Reader,
    path: &Path,
    node_index: &HashMap<u64, u32>,
) -> Result<[u32; 8], MeshError> {
    let etag = r.size("element tag")?;
    let mut cell = [0u32; 8];
    let what = format!("node tag of element {etag}");
    for a in 0..8 {
        let ntag = r.size(&what)?;
        let idx = *node_index.get(&ntag).ok_or(MeshError::UnknownNode {
            path: path.to_path_buf(),
            line: r.item_line(),
            element: etag,
            node: ntag,
        })?;
        if cell[..a].contains(&idx) {
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
        cell[a] = idx;
    }
    Ok(cell)
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
    if m.cells.is_empty() {
        let detail = if !m.seen_elements {
            "the file has no $Elements section".to_string()
        } else if m.other_types.is_empty() {
            "the $Elements section is empty".to_string()
        } else {
            let types: Vec<String> = m
                .other_types
                .iter()
                .map(|(t, n)| format!("{n} of Gmsh type {t}"))
                .collect();
            format!("elements are {} (hexahedron is type 5)", types.join(", "))
        };
        return Err(MeshError::NoHexahedra {
            path: path.to_path_buf(),
            detail,
        });
    }

    let mesh = Mesh {
        nodes: m.nodes,
        node_tags: m.node_tags,
        cells: m.cells,
        cell_regions: m.cell_regions,
        region_names: m.region_names,
        source: path.display().to_string(),
    };
    mesh.validate()?;
    Ok(mesh)
}
