//! Mesh import (Gmsh MSH 4.1 and 2.2, legacy VTK up to 5.1, VTK XML `.vtu`), producing the
//! common [`Mesh`] (the generated box is [`crate::mesh::grid::generate_box`]). What becomes
//! of each kind of cell (hexahedra, prisms, boundary cells, others) is one rule for every
//! format, in `cells.rs`.
//!
//! The MSH reader is a hand-written parser for the MSH sections volume meshes use
//! (`$MeshFormat`, `$PhysicalNames`, `$Entities`, `$Nodes`, `$Elements`; other sections are
//! skipped), ASCII or binary. It is used instead of the `mshio` crate because `mshio` 0.4
//! drops the per-block node tags when the global tag range is dense (so a permuted tag order
//! would be silently misread), does not read `$PhysicalNames`, and reports errors without
//! line numbers. (The tests still compare the two on a real file.)
//!
//! VTK files are read with `vtkio` (legacy and XML); ASCII legacy files first get a structural walk of the ASCII text that
//! locates faults by line (vtkio's own errors carry no position, and it silently drops a
//! cell data array cut short by truncation).
//!
//! Every error names the file and, where it has one, the line (or byte offset in binary
//! data) and the element or node tag.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use crate::mesh::Mesh;
pub use crate::mesh::MeshError;

mod cells;
mod msh;
mod vtk;
mod write;

pub use msh::parse_msh;
pub use vtk::{parse_vtk, parse_vtu};
pub use write::to_msh22;

/// Load a hexahedral mesh, choosing the reader by extension (case-insensitive): `.msh`
/// (Gmsh MSH 4.1 or 2.2, see [`parse_msh`]), `.vtk` (legacy VTK unstructured grid up to
/// version 5.1, see [`parse_vtk`]) or `.vtu` (VTK XML unstructured grid, see
/// [`parse_vtu`]). The result has passed [`Mesh::validate`].
pub fn load_mesh(path: &Path) -> Result<Mesh, MeshError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    let parse = match ext.as_str() {
        "msh" => parse_msh,
        "vtk" => parse_vtk,
        "vtu" => parse_vtu,
        _ => {
            return Err(MeshError::UnsupportedExtension {
                path: path.to_path_buf(),
                ext,
            })
        }
    };
    let bytes = std::fs::read(path).map_err(|source| match source.kind() {
        std::io::ErrorKind::NotFound => MeshError::NotFound {
            path: path.to_path_buf(),
        },
        _ => MeshError::Io {
            path: path.to_path_buf(),
            source,
        },
    })?;
    parse(path, &bytes)
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

    /// A `size_t` used as a count of items that each take at least one byte of the file:
    /// more than the bytes left is an error, so that no count can size an allocation or
    /// overflow a product or sum (a count times a node count, a sum over blocks) later.
    fn count(&mut self, what: &str) -> Result<usize, MeshError> {
        let v = self.size(what)?;
        let left = self.b.len() - self.pos.min(self.b.len());
        match usize::try_from(v) {
            Ok(n) if n <= left => Ok(n),
            _ => Err(self.err_item(format!(
                "{what} {v} is more than the {left} bytes left in the file can hold"
            ))),
        }
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

/// Cap for `Vec::with_capacity` on counts read from a file, so a corrupt count cannot
/// request an absurd allocation before the data runs out.
fn cap(n: usize) -> usize {
    n.min(1 << 20)
}

// ---------------------------------------------------------------------------------------
// Legacy VTK (via vtkio)
// ---------------------------------------------------------------------------------------
