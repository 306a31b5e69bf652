//! The structural walk of an ASCII legacy VTK file: its sections' counts and numbers
//! checked with line numbers, before vtkio (whose errors carry no position) reads it.

use super::*;

/// Walk the sections of an ASCII legacy VTK file (POINTS, CELLS, CELL_TYPES,
/// CELL_DATA/POINT_DATA with SCALARS, VECTORS, NORMALS, FIELD), checking the counts and that
/// every value is a number. Stops without error at the first keyword it does not know.
pub(super) fn walk_vtk(r: &mut Reader<'_>) -> Result<(), MeshError> {
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
