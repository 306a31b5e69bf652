//! Mesh import (Gmsh MSH 4.1, legacy VTK unstructured grids) and a structured box
//! generator, all producing the common [`Mesh`].
//!
//! The MSH reader is a hand-written parser for the MSH 4.1 sections volume meshes use
//! (`$MeshFormat`, `$PhysicalNames`, `$Entities`, `$Nodes`, `$Elements`; other sections are
//! skipped), ASCII or binary. It is used instead of the `mshio` crate because `mshio` 0.4
//! drops the per-block node tags when the global tag range is dense (so a permuted tag order
//! would be silently misread), does not read `$PhysicalNames`, and reports errors without
//! line numbers. (The tests still compare the two on a real file.)
//!
//! Legacy VTK files are read with `vtkio`, after a structural walk of the ASCII text that
//! locates faults by line (vtkio's own errors carry no position, and it silently drops a
//! cell data array cut short by truncation).
//!
//! Every error names the file and, where it has one, the line (or byte offset in binary
//! data) and the element or node tag.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use crate::mesh::Mesh;
pub use crate::mesh::MeshError;

/// Gmsh element type of the 8-node hexahedron.
const GMSH_HEX8: i32 = 5;
/// `VTK_HEXAHEDRON`.
const VTK_HEXAHEDRON: u8 = 12;

/// Load a hexahedral mesh, choosing the reader by extension (case-insensitive): `.msh`
/// (Gmsh MSH 4.1, see [`parse_msh`]) or `.vtk` (legacy VTK unstructured grid of
/// `VTK_HEXAHEDRON` cells, see [`parse_vtk`]). The result has passed [`Mesh::validate`].
pub fn load_mesh(path: &Path) -> Result<Mesh, MeshError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    if ext != "msh" && ext != "vtk" {
        return Err(MeshError::UnsupportedExtension {
            path: path.to_path_buf(),
            ext,
        });
    }
    let bytes = std::fs::read(path).map_err(|source| match source.kind() {
        std::io::ErrorKind::NotFound => MeshError::NotFound {
            path: path.to_path_buf(),
        },
        _ => MeshError::Io {
            path: path.to_path_buf(),
            source,
        },
    })?;
    if ext == "msh" {
        parse_msh(path, &bytes)
    } else {
        parse_vtk(path, &bytes)
    }
}

/// A structured box of `cells[0] x cells[1] x cells[2]` hexahedra spanning from the origin to
/// `size` (metres). Nodes are numbered x fastest, then y, then z; node tags are 1-based;
/// every cell is in region 1, named "box". With positive `size` every cell has a positive
/// Jacobian. A zero cell count in any direction gives an empty mesh. (Node indices are
/// `u32`: counts past 2^32 nodes are beyond this generator, and beyond memory anyway.)
pub fn generate_box(size: [f64; 3], cells: [usize; 3]) -> Mesh {
    let [nx, ny, nz] = cells;
    let (px, py) = (nx + 1, ny + 1);
    let node = |i: usize, j: usize, k: usize| (i + px * (j + py * k)) as u32;
    let mut mesh = Mesh {
        source: format!("generate_box(size = {size:?}, cells = {cells:?})"),
        ..Mesh::default()
    };
    if nx == 0 || ny == 0 || nz == 0 {
        return mesh;
    }
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                mesh.nodes.push([
                    size[0] * i as f64 / nx as f64,
                    size[1] * j as f64 / ny as f64,
                    size[2] * k as f64 / nz as f64,
                ]);
            }
        }
    }
    mesh.node_tags = (1..=mesh.nodes.len() as u64).collect();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                mesh.cells.push([
                    node(i, j, k),
                    node(i + 1, j, k),
                    node(i + 1, j + 1, k),
                    node(i, j + 1, k),
                    node(i, j, k + 1),
                    node(i + 1, j, k + 1),
                    node(i + 1, j + 1, k + 1),
                    node(i, j + 1, k + 1),
                ]);
            }
        }
    }
    mesh.cell_regions = vec![1; mesh.cells.len()];
    mesh.region_names.insert(1, "box".to_string());
    mesh
}

// ---------------------------------------------------------------------------------------
// Gmsh MSH 4.1 (ASCII and binary)
// ---------------------------------------------------------------------------------------

/// Byte order of the numbers in a binary MSH file.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Endian {
    Little,
    Big,
}

/// Cursor over the bytes of a mesh file that keeps track of line numbers. Reads
/// whitespace-separated text tokens, and, while `bin` is set (inside the binary sections of a
/// binary MSH file), fixed-size binary numbers.
struct Reader<'a> {
    path: &'a Path,
    b: &'a [u8],
    pos: usize,
    /// 1-based line number at `pos`.
    line: usize,
    /// Line of the last token read, for errors about that item.
    tok_line: usize,
    /// Byte order while reading binary numbers; `None` in text mode.
    bin: Option<Endian>,
}

impl<'a> Reader<'a> {
    fn new(path: &'a Path, b: &'a [u8]) -> Self {
        Reader {
            path,
            b,
            pos: 0,
            line: 1,
            tok_line: 1,
            bin: None,
        }
    }

    fn err(&self, line: Option<usize>, msg: impl Into<String>) -> MeshError {
        MeshError::Parse {
            path: self.path.to_path_buf(),
            line,
            msg: msg.into(),
        }
    }

    /// An error about the item just read: its line in text mode, the byte offset in binary.
    fn err_item(&self, msg: impl Into<String>) -> MeshError {
        match self.bin {
            None => self.err(Some(self.tok_line), msg),
            Some(_) => self.err(None, format!("{} (at byte {})", msg.into(), self.pos)),
        }
    }

    /// Line of the item just read (text mode only).
    fn item_line(&self) -> Option<usize> {
        self.bin.is_none().then_some(self.tok_line)
    }

    /// Line number to report for an unexpected end of file: the last line of the file.
    fn eof_line(&self) -> usize {
        if self.b.last() == Some(&b'\n') {
            self.line.saturating_sub(1).max(1)
        } else {
            self.line
        }
    }

    fn skip_ws(&mut self) {
        while let Some(&c) = self.b.get(self.pos) {
            if !c.is_ascii_whitespace() {
                break;
            }
            if c == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
    }

    /// Skip spaces and tabs (and `\r`), not newlines.
    fn skip_blank(&mut self) {
        while matches!(self.b.get(self.pos), Some(b' ' | b'\t' | b'\r')) {
            self.pos += 1;
        }
    }

    /// The rest of the current line (newline consumed, not returned).
    fn raw_line(&mut self) -> Option<&'a [u8]> {
        if self.pos >= self.b.len() {
            return None;
        }
        let rest = &self.b[self.pos..];
        let (line, used) = match rest.iter().position(|&c| c == b'\n') {
            Some(i) => {
                self.line += 1;
                (&rest[..i], i + 1)
            }
            None => (rest, rest.len()),
        };
        self.pos += used;
        Some(line.strip_suffix(b"\r").unwrap_or(line))
    }

    /// The next line that is not blank, trimmed, with its number.
    fn next_line(&mut self) -> Option<(usize, &'a str)> {
        self.skip_ws();
        let l = self.line;
        let raw = self.raw_line()?;
        Some((
            l,
            std::str::from_utf8(raw)
                .map(str::trim)
                .unwrap_or("<binary data>"),
        ))
    }

    /// The next whitespace-separated text token, with its line number.
    fn token(&mut self, what: &str) -> Result<(&'a str, usize), MeshError> {
        self.skip_ws();
        let l = self.line;
        self.tok_line = l;
        match self.b.get(self.pos) {
            None => {
                return Err(self.err(
                    Some(self.eof_line()),
                    format!("unexpected end of file while reading {what} (file truncated?)"),
                ))
            }
            Some(b'$') => {
                let marker = self.b[self.pos..]
                    .split(|c| c.is_ascii_whitespace())
                    .next()
                    .unwrap_or_default();
                return Err(self.err(
                    Some(l),
                    format!(
                        "expected {what}, found section marker {:?} (section too short)",
                        String::from_utf8_lossy(marker)
                    ),
                ));
            }
            Some(_) => {}
        }
        let start = self.pos;
        while self
            .b
            .get(self.pos)
            .is_some_and(|c| !c.is_ascii_whitespace())
        {
            self.pos += 1;
        }
        let tok = std::str::from_utf8(&self.b[start..self.pos])
            .map_err(|_| self.err(Some(l), format!("expected {what}, found non-text bytes")))?;
        Ok((tok, l))
    }

    /// The next text token parsed as `T`.
    fn parse<T: std::str::FromStr>(&mut self, what: &str) -> Result<(T, usize), MeshError> {
        let (tok, line) = self.token(what)?;
        match tok.parse() {
            Ok(v) => Ok((v, line)),
            Err(_) => Err(self.err(Some(line), format!("expected {what}, found {tok:?}"))),
        }
    }

    fn num<T: std::str::FromStr>(&mut self, what: &str) -> Result<T, MeshError> {
        self.parse(what).map(|(v, _)| v)
    }

    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], MeshError> {
        match self.b.get(self.pos..self.pos + N) {
            Some(s) => {
                self.pos += N;
                let mut out = [0u8; N];
                out.copy_from_slice(s);
                Ok(out)
            }
            None => Err(self.err_item(format!(
                "unexpected end of file while reading {what} (file truncated?)"
            ))),
        }
    }

    /// A `size_t` (8 bytes in binary mode).
    fn size(&mut self, what: &str) -> Result<u64, MeshError> {
        match self.bin {
            None => self.num(what),
            Some(Endian::Little) => Ok(u64::from_le_bytes(self.take(what)?)),
            Some(Endian::Big) => Ok(u64::from_be_bytes(self.take(what)?)),
        }
    }

    /// A `size_t` used as a count.
    fn count(&mut self, what: &str) -> Result<usize, MeshError> {
        let v = self.size(what)?;
        usize::try_from(v).map_err(|_| self.err_item(format!("{what} {v} is too large")))
    }

    /// An `int` (4 bytes in binary mode).
    fn int(&mut self, what: &str) -> Result<i32, MeshError> {
        match self.bin {
            None => self.num(what),
            Some(Endian::Little) => Ok(i32::from_le_bytes(self.take(what)?)),
            Some(Endian::Big) => Ok(i32::from_be_bytes(self.take(what)?)),
        }
    }

    /// A `double` (8 bytes in binary mode).
    fn float(&mut self, what: &str) -> Result<f64, MeshError> {
        match self.bin {
            None => self.num(what),
            Some(Endian::Little) => Ok(f64::from_le_bytes(self.take(what)?)),
            Some(Endian::Big) => Ok(f64::from_be_bytes(self.take(what)?)),
        }
    }

    /// What is left of the current line, trimmed; an error if it is empty.
    fn rest_of_line(&mut self, what: &str) -> Result<(&'a str, usize), MeshError> {
        self.skip_blank();
        let l = self.line;
        let raw = self.raw_line().unwrap_or_default();
        match std::str::from_utf8(raw).map(str::trim) {
            Ok(s) if !s.is_empty() => Ok((s, l)),
            _ => Err(self.err(Some(l), format!("expected {what} on this line"))),
        }
    }

    /// Require the section end marker `end` after the section body (leaves binary mode).
    fn expect_end(&mut self, end: &str) -> Result<(), MeshError> {
        let binary = self.bin.take().is_some();
        let at = |r: &Self, line: usize, msg: String| {
            if binary {
                r.err(
                    None,
                    format!("{msg} (at byte {}; binary section size wrong?)", r.pos),
                )
            } else {
                r.err(Some(line), msg)
            }
        };
        let mid_line = self.pos > 0 && self.b[self.pos - 1] != b'\n';
        self.skip_blank();
        if !binary && mid_line && self.b.get(self.pos).is_some_and(|&c| c != b'\n') {
            let (extra, l) = self.token("")?;
            return Err(self.err(
                Some(l),
                format!("unexpected extra value {extra:?} where {end} was expected"),
            ));
        }
        match self.next_line() {
            Some((_, l)) if l == end => Ok(()),
            Some((line, l)) => Err(at(
                self,
                line,
                format!("expected {end}, found {:?}", truncate(l)),
            )),
            None => Err(at(
                self,
                self.eof_line(),
                format!("unexpected end of file, {end} missing (file truncated?)"),
            )),
        }
    }
}

fn truncate(s: &str) -> String {
    if s.len() > 60 {
        let mut end = 60;
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        format!("{}...", &s[..end])
    } else {
        s.to_string()
    }
}

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

/// Cap for `Vec::with_capacity` on counts read from a file, so a corrupt count cannot
/// request an absurd allocation before the data runs out.
fn cap(n: usize) -> usize {
    n.min(1 << 20)
}

/// Parse the bytes of a Gmsh MSH 4.1 file, ASCII or binary. `path` is used for error
/// messages only. Takes the 8-node hexahedra (type 5); lower-dimensional elements are
/// ignored. A cell's region is the first physical tag of its volume entity (0 if it has
/// none), region names come from the dimension-3 `$PhysicalNames`. Nodes keep file order,
/// their tags in `node_tags`. Errors give the line (ASCII) or byte offset (binary).
pub fn parse_msh(path: &Path, bytes: &[u8]) -> Result<Mesh, MeshError> {
    let mut r = Reader::new(path, bytes);

    let mut seen_format = false;
    let mut endian: Option<Endian> = None;
    let mut region_names = BTreeMap::new();
    // Volume entity tag -> physical group tag.
    let mut volume_region: HashMap<i32, i32> = HashMap::new();
    let mut seen_entities = false;
    let mut nodes: Vec<[f64; 3]> = Vec::new();
    let mut node_tags: Vec<u64> = Vec::new();
    let mut node_index: HashMap<u64, u32> = HashMap::new();
    let mut seen_nodes = false;
    let mut cells: Vec<[u32; 8]> = Vec::new();
    let mut cell_regions: Vec<i32> = Vec::new();
    let mut seen_elements = false;
    // Element type -> count, for the "no hexahedra" message.
    let mut other_types: BTreeMap<i32, usize> = BTreeMap::new();

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
        if !seen_format && header != "$MeshFormat" {
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
                match file_type {
                    0 => {}
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
                        endian = if i32::from_le_bytes(one) == 1 {
                            Some(Endian::Little)
                        } else if i32::from_be_bytes(one) == 1 {
                            Some(Endian::Big)
                        } else {
                            return Err(r.err_item(format!(
                                "binary endianness marker is {one:?}, expected the int 1"
                            )));
                        };
                    }
                    other => {
                        return Err(r.err(
                            Some(fline),
                            format!("MSH file type must be 0 (ASCII) or 1 (binary), found {other}"),
                        ))
                    }
                }
                r.expect_end("$EndMeshFormat")?;
                seen_format = true;
            }
            "$PhysicalNames" => {
                // Text even in binary files.
                let n: usize = r.num("number of physical names")?;
                for _ in 0..n {
                    let dim: i32 = r.num("physical name dimension")?;
                    let tag: i32 = r.num("physical tag")?;
                    let (name, nline) = r.rest_of_line("physical name")?;
                    let name = name
                        .strip_prefix('"')
                        .and_then(|s| s.strip_suffix('"'))
                        .ok_or_else(|| {
                            r.err(Some(nline), format!("physical name {name:?} is not quoted"))
                        })?;
                    if dim == 3 {
                        region_names.insert(tag, name.to_string());
                    }
                }
                r.expect_end("$EndPhysicalNames")?;
            }
            "$Entities" => {
                seen_entities = true;
                r.bin = endian;
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
                r.expect_end("$EndEntities")?;
            }
            "$Nodes" => {
                if seen_nodes {
                    return Err(r.err(Some(line), "more than one $Nodes section"));
                }
                seen_nodes = true;
                r.bin = endian;
                let nblocks = r.count("number of node blocks")?;
                let total = r.count("number of nodes")?;
                let total_line = r.item_line();
                r.size("minimum node tag")?;
                r.size("maximum node tag")?;
                nodes.reserve(cap(total));
                node_tags.reserve(cap(total));
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
                    let first = node_tags.len();
                    for _ in 0..n {
                        let tag = r.size("node tag")?;
                        if node_index.insert(tag, node_tags.len() as u32).is_some() {
                            return Err(r.err_item(format!("node tag {tag} defined twice")));
                        }
                        node_tags.push(tag);
                    }
                    let extra = if parametric == 1 { dim } else { 0 };
                    for i in 0..n {
                        let tag = node_tags[first + i];
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
                        nodes.push(p);
                    }
                    if node_tags.len() > u32::MAX as usize {
                        return Err(r.err_item("more than 2^32 nodes"));
                    }
                }
                if nodes.len() != total {
                    let msg = format!(
                        "$Nodes header announces {total} nodes, blocks hold {}",
                        nodes.len()
                    );
                    return Err(r.err(total_line, msg));
                }
                r.expect_end("$EndNodes")?;
            }
            "$Elements" => {
                if seen_elements {
                    return Err(r.err(Some(line), "more than one $Elements section"));
                }
                if !seen_nodes {
                    return Err(r.err(Some(line), "$Elements before $Nodes"));
                }
                seen_elements = true;
                r.bin = endian;
                let nblocks = r.count("number of element blocks")?;
                let total = r.count("number of elements")?;
                let total_line = r.item_line();
                r.size("minimum element tag")?;
                r.size("maximum element tag")?;
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
                        *other_types.entry(etype).or_insert(0) += n;
                        for _ in 0..n * (nn + 1) {
                            r.size("element data")?;
                        }
                        continue;
                    }
                    // Without $Entities there is no physical group information: region 0.
                    // With it, a block on an unlisted volume is an inconsistent file (meshio 5
                    // writes such files) and guessing would mislabel tissue.
                    let region = match volume_region.get(&entity) {
                        _ if dim != 3 || !seen_entities => 0,
                        Some(&p) => p,
                        None => {
                            return Err(r.err_item(format!(
                                "hexahedron block on volume entity {entity}, which $Entities \
                                 does not list (so its physical group is unknown)"
                            )))
                        }
                    };
                    cells.reserve(cap(n));
                    for _ in 0..n {
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
                        cells.push(cell);
                        cell_regions.push(region);
                    }
                }
                if read != total {
                    let msg =
                        format!("$Elements header announces {total} elements, blocks hold {read}");
                    return Err(r.err(total_line, msg));
                }
                r.expect_end("$EndElements")?;
            }
            _ => {
                // Skip an unknown section up to its end marker.
                let name = &header[1..];
                let end = format!("$End{name}");
                loop {
                    match r.next_line() {
                        Some((_, l)) if l == end => break,
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
        }
    }

    if !seen_format {
        return Err(r.err(None, "empty file: no $MeshFormat header"));
    }
    if !seen_nodes {
        return Err(r.err(None, "no $Nodes section"));
    }
    if cells.is_empty() {
        let detail = if !seen_elements {
            "the file has no $Elements section".to_string()
        } else if other_types.is_empty() {
            "the $Elements section is empty".to_string()
        } else {
            let types: Vec<String> = other_types
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
        nodes,
        node_tags,
        cells,
        cell_regions,
        region_names,
        source: path.display().to_string(),
    };
    mesh.validate()?;
    Ok(mesh)
}

// ---------------------------------------------------------------------------------------
// Legacy VTK (via vtkio)
// ---------------------------------------------------------------------------------------

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
    use vtkio::model::{Attribute, CellType, DataSet, IOBuffer, Piece};

    let perr = |line: Option<usize>, msg: String| MeshError::Parse {
        path: path.to_path_buf(),
        line,
        msg,
    };
    // vtkio reports neither where nor what went wrong, and silently drops a cell data array
    // cut short by a truncated file, so walk the ASCII structure first: it finds those faults
    // with a line number.
    if std::str::from_utf8(bytes).is_ok() {
        walk_vtk(&mut Reader::new(path, bytes))?;
    }
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
                None,
                "dataset is not an UNSTRUCTURED_GRID".to_string(),
            ))
        }
    };
    if pieces.len() != 1 {
        return Err(perr(
            None,
            format!(
                "expected one unstructured grid piece, found {}",
                pieces.len()
            ),
        ));
    }
    let piece = match pieces.into_iter().next() {
        Some(Piece::Inline(p)) => *p,
        _ => {
            return Err(perr(
                None,
                "unstructured grid data is not inline".to_string(),
            ))
        }
    };

    let coords: Vec<f64> = match piece.points {
        IOBuffer::F64(v) => v,
        IOBuffer::F32(v) => v.into_iter().map(f64::from).collect(),
        other => other
            .cast_into::<f64>()
            .ok_or_else(|| perr(None, "POINTS have an unsupported number type".to_string()))?,
    };
    if !coords.chunks_exact(3).remainder().is_empty() {
        return Err(perr(
            None,
            format!("POINTS hold {} numbers, not a multiple of 3", coords.len()),
        ));
    }
    let nodes: Vec<[f64; 3]> = coords.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let node_tags: Vec<u64> = (1..=nodes.len() as u64).collect();
    for (i, p) in nodes.iter().enumerate() {
        if !p.iter().all(|x| x.is_finite()) {
            return Err(MeshError::NonFiniteCoordinate {
                path: path.to_path_buf(),
                node: node_tags[i],
                coords: *p,
            });
        }
    }

    let types = piece.cells.types;
    let (connectivity, offsets) = piece.cells.cell_verts.into_xml();
    if offsets.len() != types.len() {
        return Err(perr(
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
                None,
                format!("cell {ci}: connectivity offsets out of range"),
            )
        })?;
        if verts.len() != 8 {
            return Err(perr(
                None,
                format!(
                    "cell {ci} is VTK_HEXAHEDRON ({VTK_HEXAHEDRON}) but has {} points",
                    verts.len()
                ),
            ));
        }
        let mut cell = [0u32; 8];
        for (a, &v) in verts.iter().enumerate() {
            if v as usize >= nodes.len() {
                return Err(MeshError::NodeIndexOutOfRange {
                    path: path.to_path_buf(),
                    cell: ci,
                    index: u32::try_from(v).unwrap_or(u32::MAX),
                    nodes: nodes.len(),
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

    // Region tags from an integer cell data array.
    let arrays: Vec<_> = piece
        .data
        .cell
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
                .find(|a| is_int(&a.data) && a.data.len() == cells.len())
        });
    let cell_regions = match chosen {
        None => vec![0; cells.len()],
        Some(a) => {
            let name = a.name.clone();
            let vals = a
                .data
                .clone()
                .cast_into::<i64>()
                .ok_or_else(|| perr(None, format!("cell data {name:?} is not numeric")))?;
            if vals.len() != cells.len() {
                return Err(MeshError::LengthMismatch {
                    path: path.to_path_buf(),
                    what: format!("cell data {name:?}"),
                    expected: cells.len(),
                    got: vals.len(),
                });
            }
            vals.into_iter()
                .map(|v| {
                    i32::try_from(v).map_err(|_| perr(None, format!("region {v} out of i32 range")))
                })
                .collect::<Result<Vec<i32>, _>>()?
        }
    };

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

/// Walk the sections of an ASCII legacy VTK file (POINTS, CELLS, CELL_TYPES,
/// CELL_DATA/POINT_DATA with SCALARS, VECTORS, NORMALS, FIELD), checking the counts and that
/// every value is a number. Stops without error at the first keyword it does not know.
fn walk_vtk(r: &mut Reader<'_>) -> Result<(), MeshError> {
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
