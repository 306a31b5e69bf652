//! What an MSH file's sections hold as they are read (both versions' readers fill it), and
//! the node tags of one element.

use super::super::cells::CellCollector;
use super::super::*;

/// The MSH versions read.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum MshVersion {
    V41,
    V22,
}

/// What the sections read so far hold, assembled into a [`Mesh`] at the end.
#[derive(Default)]
pub(crate) struct MshContents {
    pub seen_format: bool,
    pub version: Option<MshVersion>,
    pub endian: Option<Endian>,
    /// (dimension, physical tag) -> name.
    pub physical_names: BTreeMap<(i32, i32), String>,
    /// (dimension, entity tag) -> the entity's physical tags.
    pub entity_groups: HashMap<(i32, i32), Vec<i32>>,
    pub seen_entities: bool,
    pub nodes: Vec<[f64; 3]>,
    pub node_tags: Vec<u64>,
    pub node_index: HashMap<u64, u32>,
    pub seen_nodes: bool,
    pub cells: CellCollector,
    pub seen_elements: bool,
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

/// The `n` node tags of element `etag` (appended to `out` as indices), distinct if
/// `distinct`; binary tags are 4-byte `int`s if `int_tags` (MSH 2.2), else `size_t`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn read_element_nodes(
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
