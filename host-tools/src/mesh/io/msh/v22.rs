//! The sections of Gmsh MSH 2.2 that differ from 4.1: `$Nodes` (a count, then a tag and
//! three coordinates per node) and `$Elements` (per element its type, tags and nodes; in a
//! binary file, blocks of one type headed by type, count and number of tags). The first tag
//! of an element is its physical group, the second its elementary entity.

use super::super::cells::{gmsh_type, CellKind};
use super::super::*;
use super::contents::{read_element_nodes, MshContents};

/// `$Nodes` of MSH 2.2: coordinates in file order, their tags, and tag -> index.
pub(super) fn read_nodes(
    r: &mut Reader,
    path: &Path,
    m: &mut MshContents,
) -> Result<(), MeshError> {
    let (n, nline) = r.parse::<usize>("number of nodes")?;
    m.nodes.reserve(cap(n));
    m.node_tags.reserve(cap(n));
    start_binary(r, m.endian);
    for _ in 0..n {
        let tag = match r.bin {
            None => r.size("node tag")?,
            Some(_) => {
                u64::try_from(r.int("node tag")?).map_err(|_| r.err_item("negative node tag"))?
            }
        };
        if m.node_index.insert(tag, m.node_tags.len() as u32).is_some() {
            return Err(r.err_item(format!("node tag {tag} defined twice")));
        }
        let what = format!("coordinate of node {tag}");
        let p = [r.float(&what)?, r.float(&what)?, r.float(&what)?];
        if !p.iter().all(|x| x.is_finite()) {
            return Err(MeshError::NonFiniteCoordinate {
                path: path.to_path_buf(),
                node: tag,
                coords: p,
            });
        }
        m.node_tags.push(tag);
        m.nodes.push(p);
        if m.node_tags.len() > u32::MAX as usize {
            return Err(r.err(Some(nline), "more than 2^32 nodes"));
        }
    }
    r.expect_end("$EndNodes")
}

/// Binary data starts after the newline that ends the count line.
fn start_binary(r: &mut Reader, endian: Option<Endian>) {
    if endian.is_some() {
        r.skip_blank();
        if r.b.get(r.pos) == Some(&b'\n') {
            r.pos += 1;
            r.line += 1;
        }
    }
    r.bin = endian;
}

/// `$Elements` of MSH 2.2: as 4.1's, with the region and the node sets from each element's
/// own tags (first: physical group; 0 or no tag: none).
pub(super) fn read_elements(
    r: &mut Reader,
    path: &Path,
    m: &mut MshContents,
) -> Result<(), MeshError> {
    let (total, total_line) = r.parse::<usize>("number of elements")?;
    start_binary(r, m.endian);
    let binary = m.endian.is_some();
    let mut read = 0usize;
    let mut nodes = Vec::new();
    while read < total {
        // ASCII: one element per line. Binary: a block header (type, count, tags).
        let (etype, count, ntags) = if binary {
            let t = r.int("element type")?;
            let c = r.int("number of elements in block")?;
            let k = r.int("number of tags")?;
            match (usize::try_from(c), usize::try_from(k)) {
                (Ok(c), Ok(k)) if c > 0 && read + c <= total => (t, c, k),
                _ => {
                    return Err(r.err_item(format!(
                        "element block of {c} elements with {k} tags (at most {} remain)",
                        total - read
                    )))
                }
            }
        } else {
            (-1, 1, 0)
        };
        for _ in 0..count {
            let (etag, etype, ntags) = if binary {
                let tag = u64::try_from(r.int("element tag")?)
                    .map_err(|_| r.err_item("negative element tag"))?;
                (tag, etype, ntags)
            } else {
                let tag = r.size("element tag")?;
                let t = r.int("element type")?;
                (tag, t, r.num::<usize>("number of tags")?)
            };
            let (kind, nn, name) = gmsh_type(etype).ok_or_else(|| {
                r.err_item(format!("element {etag}: unknown Gmsh element type {etype}"))
            })?;
            let mut physical = 0;
            for k in 0..ntags {
                let t = r.int(&format!("tag {k} of element {etag}"))?;
                if k == 0 {
                    physical = t;
                }
            }
            nodes.clear();
            let distinct = matches!(
                kind,
                CellKind::Hexahedron | CellKind::Prism | CellKind::Tetrahedron
            );
            read_element_nodes(r, path, &m.node_index, etag, nn, distinct, true, &mut nodes)?;
            match kind {
                CellKind::Unsupported => m.cells.unsupported(name.to_string(), 1),
                CellKind::Boundary { dim } => {
                    let groups = if physical > 0 {
                        vec![m.group_name(dim, physical)]
                    } else {
                        Vec::new()
                    };
                    m.cells.boundary(name, &nodes, &groups);
                }
                CellKind::Hexahedron | CellKind::Prism | CellKind::Tetrahedron => {
                    m.cells.volume(kind, &nodes, physical.max(0), &m.nodes)
                }
            }
        }
        read += count;
    }
    if read != total {
        return Err(r.err(
            Some(total_line),
            format!("$Elements announces {total} elements, {read} were read"),
        ));
    }
    r.expect_end("$EndElements")
}
