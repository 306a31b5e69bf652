//! POLYDATA: points and cells as in VTK's polydata (OpenIGTLink
//! `Documents/Protocol/polydata.md`; `igtl_polydata_header` and `igtl_polydata_pack` in
//! `Source/igtlutil/igtl_polydata.{h,c}`; pyigtl `PolyDataMessage._pack_content`),
//! big-endian:
//!
//! | offset              | size | field                                          |
//! |---------------------|------|------------------------------------------------|
//! | 0                   | 4    | NPOINTS (u32)                                  |
//! | 4, 8                | 4, 4 | NVERTICES, SIZE_VERTICES (bytes)               |
//! | 12, 16              | 4, 4 | NLINES, SIZE_LINES                             |
//! | 20, 24              | 4, 4 | NPOLYGONS, SIZE_POLYGONS                       |
//! | 28, 32              | 4, 4 | NTRIANGLE_STRIPS, SIZE_TRIANGLE_STRIPS         |
//! | 36                  | 4    | NATTRIBUTES                                    |
//! | 40                  | 12 n | points: X Y Z f32 each (mm)                    |
//! | then, in this order | SIZE_* | vertices, lines, polygons, strips: each cell a u32 count `k` then `k` u32 point indices |
//! | then                |      | attributes (this codec writes none and skips them on reading) |
//!
//! This server sends the surface as POLYDATA: the surface nodes' current positions in
//! millimetres as points and every triangle as a 3-index polygon
//! (`SIZE_POLYGONS = 16 × triangles`), no attributes.
//!
//! # Panics
//! [`PolyData::new_checked`], [`PolyDataRepr::parse`] and [`PolyDataRepr::emit`] never
//! panic. The accessors of a [`PolyData`] made with [`PolyData::new_unchecked`] panic on a
//! buffer shorter than its counts announce.

use core::ops::Range;

use super::error::{Error, Result};

/// Bytes of the POLYDATA header (ten u32).
pub const POLYDATA_HEADER_LEN: usize = 40;
/// Bytes of one point.
pub const POINT_LEN: usize = 12;

/// The four cell arrays, in wire order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cells {
    Vertices = 0,
    Lines = 1,
    Polygons = 2,
    TriangleStrips = 3,
}

impl Cells {
    pub const ALL: [Cells; 4] = [
        Cells::Vertices,
        Cells::Lines,
        Cells::Polygons,
        Cells::TriangleStrips,
    ];

    fn name(self) -> &'static str {
        ["vertices", "lines", "polygons", "triangle strips"][self as usize]
    }
}

mod field {
    /// Offset of NPOINTS; a cell array's count and size follow at `4 + 8k` and `8 + 8k`.
    pub const NPOINTS: usize = 0;
    pub const NATTRIBUTES: usize = 36;
}

/// A zero-copy view of a POLYDATA content.
#[derive(Debug, Clone)]
pub struct PolyData<T: AsRef<[u8]>> {
    buffer: T,
}

fn be_u32(b: &[u8], at: usize) -> u32 {
    u32::from_be_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

impl<T: AsRef<[u8]>> PolyData<T> {
    pub const fn new_unchecked(buffer: T) -> PolyData<T> {
        PolyData { buffer }
    }

    /// A view whose points and cell arrays fit the buffer (and fill it when there are no
    /// attributes).
    pub fn new_checked(buffer: T) -> Result<PolyData<T>> {
        let have = buffer.as_ref().len();
        if have < POLYDATA_HEADER_LEN {
            return Err(Error::Truncated {
                what: "POLYDATA header",
                need: POLYDATA_HEADER_LEN,
                have,
            });
        }
        let v = PolyData { buffer };
        let need = v.cells_end();
        if need > have as u64 || (v.attributes() == 0 && need != have as u64) {
            return Err(Error::BadLength {
                what: "POLYDATA content",
                len: have,
                expected: "40 + 12·NPOINTS + the four SIZE_* (+ attributes)",
            });
        }
        Ok(v)
    }

    pub fn points(&self) -> u32 {
        be_u32(self.buffer.as_ref(), field::NPOINTS)
    }

    /// Number of cells of `kind`.
    pub fn count(&self, kind: Cells) -> u32 {
        be_u32(self.buffer.as_ref(), 4 + 8 * kind as usize)
    }

    /// Bytes of the cell array `kind`.
    pub fn size(&self, kind: Cells) -> u32 {
        be_u32(self.buffer.as_ref(), 8 + 8 * kind as usize)
    }

    pub fn attributes(&self) -> u32 {
        be_u32(self.buffer.as_ref(), field::NATTRIBUTES)
    }

    /// Where the cell arrays end, as the counts say (u64: never overflows).
    fn cells_end(&self) -> u64 {
        let points = POLYDATA_HEADER_LEN as u64 + POINT_LEN as u64 * u64::from(self.points());
        points
            + Cells::ALL
                .iter()
                .map(|&k| u64::from(self.size(k)))
                .sum::<u64>()
    }

    fn cells_range(&self, kind: Cells) -> Range<usize> {
        let mut at = POLYDATA_HEADER_LEN + POINT_LEN * self.points() as usize;
        for k in &Cells::ALL[..kind as usize] {
            at += self.size(*k) as usize;
        }
        at..at + self.size(kind) as usize
    }

    /// Point `i` (mm).
    pub fn point(&self, i: usize) -> [f32; 3] {
        let b = self.buffer.as_ref();
        let at = POLYDATA_HEADER_LEN + POINT_LEN * i;
        core::array::from_fn(|k| f32::from_bits(be_u32(b, at + 4 * k)))
    }

    /// The raw cell array `kind` (count-prefixed index lists).
    pub fn cells(&self, kind: Cells) -> &[u8] {
        &self.buffer.as_ref()[self.cells_range(kind)]
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> PolyData<T> {
    fn set_u32(&mut self, at: usize, v: u32) {
        self.buffer.as_mut()[at..at + 4].copy_from_slice(&v.to_be_bytes());
    }

    /// Writes the header: the point count, each cell array's count and size, no attributes.
    pub fn set_header(&mut self, points: u32, cells: [(u32, u32); 4]) {
        self.set_u32(field::NPOINTS, points);
        for (k, (count, size)) in cells.into_iter().enumerate() {
            self.set_u32(4 + 8 * k, count);
            self.set_u32(8 + 8 * k, size);
        }
        self.set_u32(field::NATTRIBUTES, 0);
    }

    pub fn set_point(&mut self, i: usize, xyz: [f32; 3]) {
        let at = POLYDATA_HEADER_LEN + POINT_LEN * i;
        for (k, v) in xyz.into_iter().enumerate() {
            self.set_u32(at + 4 * k, v.to_bits());
        }
    }

    /// The cell array `kind` to write (after [`PolyData::set_header`]).
    pub fn cells_mut(&mut self, kind: Cells) -> &mut [u8] {
        let r = self.cells_range(kind);
        &mut self.buffer.as_mut()[r]
    }
}

/// A polydata's points and cells (attributes are not kept).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PolyDataRepr {
    /// Points (mm).
    pub points: Vec<[f32; 3]>,
    /// Cells by [`Cells`] kind, each a list of point indices.
    pub cells: [Vec<Vec<u32>>; 4],
}

impl PolyDataRepr {
    /// Reads points and the four cell arrays: each array must hold exactly its count of
    /// cells in exactly its size, every index below NPOINTS.
    pub fn parse<T: AsRef<[u8]>>(v: &PolyData<T>) -> Result<PolyDataRepr> {
        let n = v.points() as usize;
        let points = (0..n).map(|i| v.point(i)).collect();
        let mut cells: [Vec<Vec<u32>>; 4] = Default::default();
        for kind in Cells::ALL {
            cells[kind as usize] = parse_cells(kind, v.cells(kind), v.count(kind), n)?;
        }
        Ok(PolyDataRepr { points, cells })
    }

    pub fn parse_bytes(content: &[u8]) -> Result<PolyDataRepr> {
        Self::parse(&PolyData::new_checked(content)?)
    }

    /// Bytes of cell array `kind`.
    fn cells_len(&self, kind: Cells) -> usize {
        self.cells[kind as usize]
            .iter()
            .map(|c| 4 * (1 + c.len()))
            .sum()
    }

    pub fn buffer_len(&self) -> usize {
        POLYDATA_HEADER_LEN
            + POINT_LEN * self.points.len()
            + Cells::ALL.iter().map(|&k| self.cells_len(k)).sum::<usize>()
    }

    /// Writes the content into `buf` (exactly [`PolyDataRepr::buffer_len`] bytes); refuses
    /// counts past u32 and indices past the points.
    pub fn emit(&self, buf: &mut [u8]) -> Result<()> {
        let need = self.buffer_len();
        if buf.len() != need {
            return Err(Error::BufferTooSmall {
                need,
                have: buf.len(),
            });
        }
        let big = |what: &'static str, n: usize| Error::TooLong {
            field: what,
            text: format!("{n}"),
            max: u32::MAX as usize,
        };
        let points = u32::try_from(self.points.len())
            .map_err(|_| big("POLYDATA points", self.points.len()))?;
        let mut header = [(0u32, 0u32); 4];
        for kind in Cells::ALL {
            let list = &self.cells[kind as usize];
            if let Some(&index) = list
                .iter()
                .flatten()
                .find(|&&i| i as usize >= self.points.len())
            {
                return Err(Error::BadIndex {
                    what: kind.name(),
                    index,
                    count: self.points.len(),
                });
            }
            let size = self.cells_len(kind);
            header[kind as usize] = (
                u32::try_from(list.len()).map_err(|_| big(kind.name(), list.len()))?,
                u32::try_from(size).map_err(|_| big(kind.name(), size))?,
            );
        }
        let mut v = PolyData::new_unchecked(buf);
        v.set_header(points, header);
        for (i, p) in self.points.iter().enumerate() {
            v.set_point(i, *p);
        }
        for kind in Cells::ALL {
            let out = v.cells_mut(kind);
            let mut at = 0;
            for cell in &self.cells[kind as usize] {
                for x in std::iter::once(cell.len() as u32).chain(cell.iter().copied()) {
                    out[at..at + 4].copy_from_slice(&x.to_be_bytes());
                    at += 4;
                }
            }
        }
        Ok(())
    }
}

/// Bytes of `n` triangles as a polygon cell array (`3, a, b, c` each).
pub const fn triangles_len(n: usize) -> usize {
    16 * n
}

/// `triangles` as a polygon cell array ([`triangles_len`] bytes), to copy into
/// [`PolyData::cells_mut`] frame after frame.
pub fn triangle_cells(triangles: &[[u32; 3]]) -> Vec<u8> {
    let mut out = Vec::with_capacity(triangles_len(triangles.len()));
    for t in triangles {
        for x in [3, t[0], t[1], t[2]] {
            out.extend_from_slice(&x.to_be_bytes());
        }
    }
    out
}

/// The cells of one count-prefixed array.
fn parse_cells(kind: Cells, bytes: &[u8], count: u32, points: usize) -> Result<Vec<Vec<u32>>> {
    let bad = |why: String| {
        Err(Error::BadCells {
            kind: kind.name(),
            why,
        })
    };
    if !bytes.len().is_multiple_of(4) {
        return bad("not whole u32".into());
    }
    let words: Vec<u32> = bytes
        .chunks_exact(4)
        .map(|w| u32::from_be_bytes([w[0], w[1], w[2], w[3]]))
        .collect();
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < words.len() {
        let k = words[at] as usize;
        let Some(cell) = words.get(at + 1..at + 1 + k) else {
            return bad(format!(
                "cell {} of {k} indices runs past the array",
                out.len()
            ));
        };
        if let Some(&index) = cell.iter().find(|&&i| i as usize >= points) {
            return Err(Error::BadIndex {
                what: kind.name(),
                index,
                count: points,
            });
        }
        out.push(cell.to_vec());
        at += 1 + k;
    }
    if out.len() != count as usize {
        return bad(format!("{} cells, the header says {count}", out.len()));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_triangles() -> PolyDataRepr {
        PolyDataRepr {
            points: vec![
                [0.0, 0.0, 0.0],
                [10.0, 0.0, 0.0],
                [0.0, 10.0, 0.0],
                [10.0, 10.0, 1.5],
            ],
            cells: [
                vec![],
                vec![vec![0, 3]],
                vec![vec![0, 1, 2], vec![1, 3, 2]],
                vec![],
            ],
        }
    }

    #[test]
    fn polydata_round_trips_in_the_spec_layout() {
        let p = two_triangles();
        let mut b = vec![0xAA; p.buffer_len()];
        assert_eq!(b.len(), 40 + 48 + 12 + 32);
        p.emit(&mut b).unwrap();
        let words: Vec<u32> = b[..40]
            .chunks_exact(4)
            .map(|w| u32::from_be_bytes([w[0], w[1], w[2], w[3]]))
            .collect();
        // NPOINTS, (NVERTICES, SIZE), (NLINES, SIZE), (NPOLYGONS, SIZE), (NSTRIPS, SIZE), NATTR.
        assert_eq!(words, [4, 0, 0, 1, 12, 2, 32, 0, 0, 0]);
        assert_eq!(
            &b[76..88],
            &[10.0f32, 10.0, 1.5].map(f32::to_be_bytes).concat()[..]
        );
        // Lines then polygons: (2, 0, 3), (3, 0, 1, 2), (3, 1, 3, 2).
        let cells: Vec<u32> = b[88..]
            .chunks_exact(4)
            .map(|w| u32::from_be_bytes([w[0], w[1], w[2], w[3]]))
            .collect();
        assert_eq!(cells, [2, 0, 3, 3, 0, 1, 2, 3, 1, 3, 2]);
        assert_eq!(PolyDataRepr::parse_bytes(&b).unwrap(), p);
    }

    #[test]
    fn attributes_after_the_cells_are_skipped() {
        let p = two_triangles();
        let mut b = vec![0; p.buffer_len()];
        p.emit(&mut b).unwrap();
        b[36..40].copy_from_slice(&1u32.to_be_bytes());
        b.extend_from_slice(&[
            0, 0, 0, 0, 0, 4, b'a', 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
        ]);
        assert_eq!(PolyDataRepr::parse_bytes(&b).unwrap(), p);
    }

    #[test]
    fn counts_sizes_and_indices_that_disagree_are_refused() {
        let p = two_triangles();
        let mut b = vec![0; p.buffer_len()];
        p.emit(&mut b).unwrap();
        // A short buffer for the announced points.
        assert!(matches!(
            PolyDataRepr::parse_bytes(&b[..100]),
            Err(Error::BadLength { .. })
        ));
        // NPOLYGONS says 3.
        let mut c = b.clone();
        c[20..24].copy_from_slice(&3u32.to_be_bytes());
        let e = PolyDataRepr::parse_bytes(&c).unwrap_err();
        assert!(
            e.to_string()
                .contains("polygons: 2 cells, the header says 3"),
            "{e}"
        );
        // An index past the points.
        let mut d = b.clone();
        d[b.len() - 4..].copy_from_slice(&4u32.to_be_bytes());
        assert!(matches!(
            PolyDataRepr::parse_bytes(&d),
            Err(Error::BadIndex { index: 4, .. })
        ));
        // A cell running past its array.
        let mut e = b.clone();
        e[100..104].copy_from_slice(&9u32.to_be_bytes());
        assert!(PolyDataRepr::parse_bytes(&e)
            .unwrap_err()
            .to_string()
            .contains("runs past"));
        // Emitting an index past the points.
        let mut q = p.clone();
        q.cells[2][0][1] = 7;
        let mut out = vec![0; q.buffer_len()];
        assert!(matches!(
            q.emit(&mut out),
            Err(Error::BadIndex { index: 7, .. })
        ));
        // Huge counts do not overflow the size check.
        let mut h = b;
        h[0..4].copy_from_slice(&u32::MAX.to_be_bytes());
        assert!(matches!(
            PolyDataRepr::parse_bytes(&h),
            Err(Error::BadLength { .. })
        ));
    }
}
