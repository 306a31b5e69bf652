//! The sections of Gmsh MSH 4.1 that differ from 2.2: `$Entities` (the physical groups of
//! each entity), and `$Nodes` and `$Elements` in entity blocks.

use super::super::cells::{gmsh_type, CellKind};
use super::super::*;
use super::contents::{read_element_nodes, MshContents};

/// `$Entities`: the physical tags of each entity, by (dimension, entity tag).
pub(super) fn read_entities(
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
pub(super) fn read_nodes(
    r: &mut Reader,
    path: &Path,
    m: &mut MshContents,
) -> Result<(), MeshError> {
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
pub(super) fn read_elements(
    r: &mut Reader,
    path: &Path,
    m: &mut MshContents,
) -> Result<(), MeshError> {
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
            CellKind::Hexahedron | CellKind::Prism | CellKind::Tetrahedron => {
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
fn read_cell_nodes(
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
