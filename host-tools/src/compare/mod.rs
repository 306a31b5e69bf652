//! Fields and displacement files compared: `pe compare` (a board's semihosting report or a
//! nodes CSV against `pe solve`'s, bit for bit or within a tolerance) and the folds every
//! test that compares two fields goes through.
//!
//! Every fold here propagates NaN: `f64::max` drops a NaN operand (`NaN.max(1.0) == 1.0`),
//! so a fold through it reports a field of NaN as "no difference". [`nan_max`] is the one
//! maximum used instead. A file is matched node by node by its node tag when both files
//! carry tags (two nodes CSVs), by mesh node index otherwise (a board report has no tags;
//! a nodes CSV lists the mesh's nodes in index order), and the initial positions are
//! compared wherever both files carry them: a renumbered or shifted mesh is refused, not
//! compared.

use std::collections::HashMap;
use std::path::Path;

use anyhow::{bail, Context, Result};

pub use pe_firmware::physics::real::nan_max;

/// Largest `|component|` of a field: how far it is from rest (a comparison of two fields
/// at rest proves nothing); NaN when any component is NaN.
pub fn max_abs(a: &[[f64; 3]]) -> f64 {
    a.iter().flatten().fold(0.0, |m, v| nan_max(m, v.abs()))
}

/// Largest `|a − b|` over all components, relative to the largest `|a|`; infinite when the
/// two fields differ in length (a shorter output never passes for an equal one), NaN when
/// either holds a NaN (so `max_rel_diff(a, b) < tol` fails on it).
pub fn max_rel_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    if a.len() != b.len() {
        return f64::INFINITY;
    }
    let scale = max_abs(a);
    let d = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0, |m, (x, y)| nan_max(m, (x - y).abs()));
    if scale > 0.0 {
        d / scale
    } else {
        d
    }
}

/// `Ok` when `a` and `b` hold the same number of nodes and every component has the same
/// bits; otherwise an error naming both lengths, or the first differing node and component
/// and how many components differ (a shorter output never passes for an equal one).
pub fn bit_identical(a: &[[f64; 3]], b: &[[f64; 3]]) -> Result<()> {
    if a.len() != b.len() {
        bail!(
            "{} nodes against {}: the fields differ in length",
            a.len(),
            b.len()
        );
    }
    let differ = |(x, y): (&f64, &f64)| x.to_bits() != y.to_bits();
    let count = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .filter(|&p| differ(p))
        .count();
    if let Some(k) = a.iter().flatten().zip(b.iter().flatten()).position(differ) {
        bail!(
            "{count} of {} components differ, first node {} component {}: {:e} against {:e}",
            3 * a.len(),
            k / 3,
            k % 3,
            a[k / 3][k % 3],
            b[k / 3][k % 3]
        );
    }
    Ok(())
}

/// One node of a displacement file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeRow {
    /// The node's tag (a nodes CSV's `node` column); a board report has none.
    pub tag: Option<u64>,
    /// Initial position (m), where the file gives it (a nodes CSV).
    pub position_m: Option<[f64; 3]>,
    /// Displacement (m).
    pub u_m: [f64; 3],
    /// The line of the file it came from (1-based).
    pub line: usize,
}

impl NodeRow {
    /// How messages name the node: its tag, or its 0-based mesh index `index`.
    fn label(&self, index: usize) -> String {
        match self.tag {
            Some(t) => format!("node {t}"),
            None => format!("node index {index}"),
        }
    }
}

/// Final displacements by mesh node index, from a nodes CSV (`pe solve --output-nodes`,
/// header `node,x_m,y_m,z_m,ux_m,uy_m,uz_m` or the unit-less one of earlier versions, rows
/// in mesh node order) or a board report (semihosting lines `u,GLOBAL,UX,UY,UZ` with the
/// f64 bits in hex, between `pe-board: begin nodes` and `pe-board: end nodes`).
pub fn read_displacements(path: &Path) -> Result<Vec<Option<[f64; 3]>>> {
    Ok(read_rows(path)?
        .into_iter()
        .map(|r| r.map(|r| r.u_m))
        .collect())
}

/// [`read_displacements`] of a text already read; `name` (a path, or a board) names it in
/// errors.
pub fn parse_displacements(text: &str, name: &str) -> Result<Vec<Option<[f64; 3]>>> {
    Ok(parse_rows(text, name)?
        .into_iter()
        .map(|r| r.map(|r| r.u_m))
        .collect())
}

/// The rows of a displacement file by mesh node index (see [`read_displacements`]).
pub fn read_rows(path: &Path) -> Result<Vec<Option<NodeRow>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse_rows(&text, &path.display().to_string())
}

/// [`read_rows`] of a text already read; `name` names it in errors.
pub fn parse_rows(text: &str, name: &str) -> Result<Vec<Option<NodeRow>>> {
    if text.starts_with("node,") {
        parse_csv_rows(text, name)
    } else {
        parse_board_rows(text, name)
    }
}

fn parse_csv_rows(text: &str, name: &str) -> Result<Vec<Option<NodeRow>>> {
    let header = text.lines().next().unwrap_or_default().trim();
    let legacy = "node,x,y,z,ux,uy,uz";
    if header != crate::output::NODES_CSV_HEADER.join(",") && header != legacy {
        bail!(
            "{}:1: header {header:?} is not a nodes CSV's ({:?}, or {legacy:?})",
            name,
            crate::output::NODES_CSV_HEADER.join(",")
        );
    }
    let mut out = Vec::new();
    let mut seen = HashMap::new();
    for (k, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != 7 {
            bail!("{}:{}: expected 7 fields, found {}", name, k + 1, f.len());
        }
        let v = |i: usize| -> Result<f64> {
            f[i].parse()
                .with_context(|| format!("{}:{}: bad number {:?}", name, k + 1, f[i]))
        };
        let tag: u64 = f[0]
            .parse()
            .with_context(|| format!("{}:{}: bad node tag {:?}", name, k + 1, f[0]))?;
        if let Some(first) = seen.insert(tag, k + 1) {
            bail!(
                "{}:{}: node {tag} again (first on line {first})",
                name,
                k + 1
            );
        }
        out.push(Some(NodeRow {
            tag: Some(tag),
            position_m: Some([v(1)?, v(2)?, v(3)?]),
            u_m: [v(4)?, v(5)?, v(6)?],
            line: k + 1,
        }));
    }
    Ok(out)
}

fn parse_board_rows(text: &str, name: &str) -> Result<Vec<Option<NodeRow>>> {
    let mut out: Vec<Option<NodeRow>> = Vec::new();
    let (mut begun, mut ended) = (false, false);
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.contains("pe-board: FAULT") {
            bail!("{}: the board reported a fault: {line}", name);
        }
        if line == "pe-board: begin nodes" {
            begun = true;
        } else if line == "pe-board: end nodes" {
            ended = true;
        } else if let Some(rest) = line.strip_prefix("u,") {
            let f: Vec<&str> = rest.split(',').collect();
            let bad = || format!("{}:{}: bad node line {line:?}", name, k + 1);
            if f.len() != 4 || !begun || ended {
                bail!(bad());
            }
            let n: usize = f[0].parse().with_context(bad)?;
            let mut u = [0.0; 3];
            for i in 0..3 {
                u[i] = f64::from_bits(u64::from_str_radix(f[i + 1], 16).with_context(bad)?);
            }
            if out.len() <= n {
                out.resize(n + 1, None);
            }
            let row = NodeRow {
                tag: None,
                position_m: None,
                u_m: u,
                line: k + 1,
            };
            if let Some(first) = out[n].replace(row) {
                bail!(
                    "{}:{}: node index {n} reported twice (first on line {})",
                    name,
                    k + 1,
                    first.line
                );
            }
        }
    }
    if !begun || !ended {
        bail!(
            "{}: no complete node report (missing 'pe-board: begin nodes'/'end nodes'): the run did not finish",
            name
        );
    }
    Ok(out)
}

/// Outcome of a comparison.
#[derive(Clone, Debug)]
pub struct Comparison {
    pub nodes: usize,
    /// Components whose bits differ.
    pub differing: usize,
    /// Largest |a − b| (m) over all components; NaN when either file holds a NaN.
    pub max_abs_diff: f64,
    /// Largest |component| of the reference (m): how far the compared fields are from rest;
    /// NaN when the reference holds a NaN.
    pub max_abs_reference: f64,
    /// Components that are not finite, in either file, and the first of them
    /// (node, component, which file).
    pub non_finite: usize,
    pub first_non_finite: Option<(String, usize, &'static str)>,
    /// The first differences: (node, component, reference, other).
    pub first: Vec<(String, usize, f64, f64)>,
}

/// The pairs of rows that describe the same node: by tag where both files have tags, else
/// by mesh node index. Nodes missing from `other` or extra in it are errors, naming them.
fn pair_rows<'a>(
    a: &'a [Option<NodeRow>],
    b: &'a [Option<NodeRow>],
    (name_a, name_b): (&str, &str),
) -> Result<Vec<(usize, &'a NodeRow, &'a NodeRow)>> {
    let tagged = |rows: &[Option<NodeRow>]| rows.iter().flatten().all(|r| r.tag.is_some());
    let by_tag = tagged(a) && tagged(b);
    let key = |n: usize, r: &NodeRow| if by_tag { r.tag.unwrap_or(0) } else { n as u64 };
    let other: HashMap<u64, &NodeRow> = b
        .iter()
        .enumerate()
        .filter_map(|(n, r)| r.as_ref().map(|r| (key(n, r), r)))
        .collect();
    let mut pairs = Vec::new();
    let mut missing = Vec::new();
    for (n, ra) in a.iter().enumerate() {
        let Some(ra) = ra else { continue };
        match other.get(&key(n, ra)) {
            Some(rb) => pairs.push((n, ra, *rb)),
            None => missing.push(ra.label(n)),
        }
    }
    if !missing.is_empty() {
        bail!(
            "{name_b}: {} nodes of {name_a} missing (first: {})",
            missing.len(),
            missing[..missing.len().min(10)].join(", ")
        );
    }
    if pairs.len() < other.len() {
        let known: std::collections::HashSet<u64> =
            pairs.iter().map(|&(n, ra, _)| key(n, ra)).collect();
        let (n, extra) = b
            .iter()
            .enumerate()
            .find_map(|(n, r)| {
                r.as_ref()
                    .filter(|r| !known.contains(&key(n, r)))
                    .map(|r| (n, r))
            })
            .context("an extra node that cannot be found")?;
        bail!(
            "{name_b}:{}: {} is not in {name_a} ({} nodes extra)",
            extra.line,
            extra.label(n),
            other.len() - pairs.len()
        );
    }
    Ok(pairs)
}

/// Refuses pairs whose initial positions differ (where both files give them) by more than
/// 1e-9 of the mesh's extent: the files are of different meshes or numbered differently.
fn check_positions(
    pairs: &[(usize, &NodeRow, &NodeRow)],
    (name_a, name_b): (&str, &str),
) -> Result<()> {
    let extent = pairs
        .iter()
        .filter_map(|(_, ra, _)| ra.position_m)
        .flatten()
        .fold(0.0, |m, v| nan_max(m, v.abs()));
    let tol = 1e-9 * extent.max(1e-3);
    for &(n, ra, rb) in pairs {
        let (Some(pa), Some(pb)) = (ra.position_m, rb.position_m) else {
            continue;
        };
        if (0..3).any(|i| !((pa[i] - pb[i]).abs() <= tol)) {
            bail!(
                "{}: at {pa:?} m in {name_a} (line {}) but at {pb:?} m in {name_b} (line {}): the files are of different meshes, or number the nodes differently",
                ra.label(n),
                ra.line,
                rb.line
            );
        }
    }
    Ok(())
}

/// Compares every node of `reference` with `other`, bit for bit, matched by tag (two nodes
/// CSVs) or by mesh node index; nodes missing from `other` or extra in it, and nodes at
/// different initial positions, are errors.
pub fn compare(reference: &Path, other: &Path) -> Result<Comparison> {
    let a = read_rows(reference)?;
    let b = read_rows(other)?;
    let names = (reference.display().to_string(), other.display().to_string());
    let names = (names.0.as_str(), names.1.as_str());
    let pairs = pair_rows(&a, &b, names)?;
    check_positions(&pairs, names)?;
    let mut c = Comparison {
        nodes: pairs.len(),
        differing: 0,
        max_abs_diff: 0.0,
        max_abs_reference: 0.0,
        non_finite: 0,
        first_non_finite: None,
        first: Vec::new(),
    };
    for (n, ra, rb) in pairs {
        let (ua, ub) = (ra.u_m, rb.u_m);
        for i in 0..3 {
            for (v, which) in [(ua[i], "reference"), (ub[i], "other")] {
                if !v.is_finite() {
                    c.non_finite += 1;
                    c.first_non_finite.get_or_insert((ra.label(n), i, which));
                }
            }
            c.max_abs_reference = nan_max(c.max_abs_reference, ua[i].abs());
            if ua[i].to_bits() != ub[i].to_bits() {
                c.differing += 1;
                c.max_abs_diff = nan_max(c.max_abs_diff, (ua[i] - ub[i]).abs());
                if c.first.len() < 10 {
                    c.first.push((ra.label(n), i, ua[i], ub[i]));
                }
            }
        }
    }
    Ok(c)
}

#[cfg(test)]
mod tests;
