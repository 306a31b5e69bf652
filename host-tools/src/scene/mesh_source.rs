//! Turns a scene's `[mesh]` into a mesh plus the named node sets it provides (a file, a
//! generated box, blocks, or the built-in anatomy with its node sets).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Result};

use crate::mesh::builtin::{self, Level};
use crate::mesh::Mesh;
use crate::scene::builtin::PROBE_TIP_RADIUS_M;
use crate::scene::*;

/// The scene's mesh in metres and its named node sets (the file's physical groups or point
/// tags, or the built-in anatomy's sets). `[mesh] unit` converts the coordinates; a mesh
/// whose size looks mis-scaled for soft tissue gets a warning in its notes.
pub fn load(spec: &MeshSpec, scene_dir: &Path) -> Result<(Mesh, BTreeMap<String, Vec<u32>>)> {
    let metres_per_unit = match spec.unit.as_deref() {
        None | Some("m") => 1.0,
        Some("cm") => 1e-2,
        Some("mm") => 1e-3,
        Some(other) => {
            bail!("[mesh] unit = {other:?}: the units known are \"m\", \"cm\" and \"mm\"")
        }
    };
    if spec.builtin.is_some() && metres_per_unit != 1.0 {
        bail!("[mesh] unit: the built-in anatomy is in metres already; remove `unit`");
    }
    let (mut mesh, sets) = load_in_file_units(spec, scene_dir)?;
    if metres_per_unit != 1.0 {
        for p in &mut mesh.nodes {
            *p = p.map(|x| x * metres_per_unit);
        }
        mesh.notes.push(format!(
            "coordinates converted from {} to metres (x {metres_per_unit})",
            spec.unit.as_deref().unwrap_or("m")
        ));
    }
    if let Some(w) = size_warning(&mesh) {
        mesh.notes.push(w);
    }
    Ok((mesh, sets))
}

/// Soft-tissue scenes are between a few millimetres and a metre or two across; outside
/// [`PLAUSIBLE_SIZE_M`], a warning that names the likely unit mistake.
fn size_warning(mesh: &Mesh) -> Option<String> {
    if mesh.nodes.is_empty() {
        return None;
    }
    let (lo, hi) = mesh.bounding_box();
    let size = (0..3).map(|i| hi[i] - lo[i]).fold(0.0, f64::max);
    let (min, max) = PLAUSIBLE_SIZE_M;
    if size > max {
        Some(format!(
            "warning: the mesh is {size:.4} m across, large for soft tissue: if its coordinates are millimetres, set [mesh] unit = \"mm\""
        ))
    } else if size < min {
        Some(format!(
            "warning: the mesh is {size:.3e} m across, small for soft tissue: check [mesh] unit (coordinates must end up in metres)"
        ))
    } else {
        None
    }
}

/// Sizes (m) of a plausible soft-tissue scene, smallest and largest extent: outside them
/// the mesh is probably in another unit.
pub const PLAUSIBLE_SIZE_M: (f64, f64) = (2e-3, 2.0);

fn load_in_file_units(
    spec: &MeshSpec,
    scene_dir: &Path,
) -> Result<(Mesh, BTreeMap<String, Vec<u32>>)> {
    let given = [
        spec.file.is_some(),
        spec.generate.is_some(),
        spec.builtin.is_some(),
        !spec.blocks.is_empty(),
    ];
    if given.iter().filter(|g| **g).count() != 1 {
        bail!("[mesh] needs exactly one of `file`, `generate`, `builtin`, `blocks`");
    }
    if !spec.blocks.is_empty() {
        let mut mesh = Mesh {
            source: "[[mesh.blocks]]".into(),
            ..Mesh::default()
        };
        for (k, b) in spec.blocks.iter().enumerate() {
            if b.cells.contains(&0) || b.size.iter().any(|&s| !(s > 0.0)) {
                bail!(
                    "[[mesh.blocks]] {k} ({:?}): size and cells must be positive",
                    b.name
                );
            }
            check_box_size(&format!("[[mesh.blocks]] {k} ({:?})", b.name), b.cells)?;
            let part = crate::mesh::grid::generate_box(b.size, b.cells);
            let base = mesh.nodes.len() as u32;
            let region = k as i32 + 1;
            mesh.nodes.extend(
                part.nodes
                    .iter()
                    .map(|p| core::array::from_fn(|i| p[i] + b.origin[i])),
            );
            mesh.cells
                .extend(part.cells.iter().map(|c| c.map(|n| n + base)));
            mesh.cell_regions
                .extend(std::iter::repeat_n(region, part.cells.len()));
            mesh.region_names.insert(region, b.name.clone());
        }
        mesh.node_tags = (1..=mesh.nodes.len() as u64).collect();
        return Ok((mesh, BTreeMap::new()));
    }
    if let Some(f) = &spec.file {
        let path = scene_dir.join(f);
        let mut mesh = crate::mesh::io::load_mesh(&path)?;
        let sets = std::mem::take(&mut mesh.node_sets);
        return Ok((mesh, sets));
    }
    if let Some(g) = &spec.generate {
        if g.kind != "box" {
            bail!(
                "[mesh] generate.kind = \"{}\": only \"box\" is known",
                g.kind
            );
        }
        if g.cells.contains(&0) || g.size.iter().any(|&s| !(s > 0.0)) {
            bail!("[mesh] generate: size and cells must be positive");
        }
        check_box_size("[mesh] generate", g.cells)?;
        return Ok((
            crate::mesh::grid::generate_box(g.size, g.cells),
            BTreeMap::new(),
        ));
    }
    let name = spec.builtin.as_deref().unwrap_or_default();
    if name != "uterus" && name != "uterus_ovary" {
        bail!("[mesh] builtin = \"{name}\": the built-in meshes are \"uterus\" (uterus and both tubes) and \"uterus_ovary\" (plus the right ovary under the right tube)");
    }
    let level: Level = spec
        .level
        .as_deref()
        .unwrap_or("medium")
        .parse()
        .map_err(|e| anyhow!("[mesh] level: {e}"))?;
    let mut a = builtin::generate(level);
    let mut sets = BTreeMap::new();
    if name == "uterus_ovary" {
        let site = crate::mesh::ovary::add_right_ovary(&mut a, level);
        sets.insert("right_ovary_base".to_string(), site.fixed_nodes);
    }
    sets.insert("cervix".to_string(), a.cervix_nodes.clone());
    sets.insert("probe".to_string(), probe_nodes(&a));
    for (region, name) in [
        (builtin::REGION_LEFT_OVIDUCT, "left_tube_end"),
        (builtin::REGION_RIGHT_OVIDUCT, "right_tube_end"),
    ] {
        sets.insert(name.to_string(), tube_end_nodes(&a.mesh, region));
    }
    Ok((a.mesh, sets))
}

/// Nodes of the last cross-section of a tube (the one farthest from the body along y).
fn tube_end_nodes(mesh: &Mesh, region: i32) -> Vec<u32> {
    let mut nodes: Vec<u32> = mesh
        .cells
        .iter()
        .zip(&mesh.cell_regions)
        .filter(|(_, r)| **r == region)
        .flat_map(|(c, _)| c.iter().copied())
        .collect();
    nodes.sort_unstable();
    nodes.dedup();
    let far = nodes
        .iter()
        .map(|&n| mesh.nodes[n as usize][1].abs())
        .fold(0.0, f64::max);
    nodes.retain(|&n| mesh.nodes[n as usize][1].abs() > far - 1e-4);
    nodes
}

/// The tube's nodes under the probe tip: every node of the tube's cross-section within the
/// tip radius of the tube axis point below the contact point (until contact exists, the
/// probe is a prescribed displacement of these nodes, so the whole section moves with it).
fn probe_nodes(a: &builtin::Anatomy) -> Vec<u32> {
    let p = &a.probe;
    let c: [f64; 3] =
        core::array::from_fn(|i| p.contact_point[i] + p.tube_radius_m * p.push_direction[i]);
    let mut r = PROBE_TIP_RADIUS_M;
    loop {
        let v: Vec<u32> = (0..a.mesh.nodes.len() as u32)
            .filter(|&n| {
                let p = a.mesh.nodes[n as usize];
                (0..3).map(|i| (p[i] - c[i]).powi(2)).sum::<f64>() <= r * r
            })
            .collect();
        if !v.is_empty() {
            return v;
        }
        r *= 1.5;
    }
}

/// Most cells a problem may have where the machine's memory is unknown (about 130 GB at
/// [`BYTES_PER_CELL`]).
pub const MAX_GENERATED_CELLS: f64 = 2e7;
/// Memory a problem takes per hexahedron (bytes) in its dearest configuration, full
/// integration in f64: measured peak resident memory of `pe solve` on 80 000 cells, 6.1 kB
/// (reduced integration: 3.1 kB). Re-measured by `host-tools/tests/bad_input.rs`
/// (`the_memory_estimate_bounds_a_runs_peak`), which fails when cells grow dearer.
pub const BYTES_PER_CELL: f64 = 6.5e3;

/// Refuses a generated box too large for this machine's memory, with the memory it would
/// take, before any allocation.
fn check_box_size(what: &str, cells: [usize; 3]) -> Result<()> {
    let n = cells.iter().map(|&c| c as f64).product::<f64>();
    check_memory(what, n)
}

/// Refuses a problem of `cells` hexahedra (named by `what`) whose estimated memory
/// ([`BYTES_PER_CELL`] each) exceeds what this machine has available, or
/// [`MAX_GENERATED_CELLS`]' worth where that is unknown.
pub fn check_memory(what: &str, cells: f64) -> Result<()> {
    let need = cells * BYTES_PER_CELL;
    let (limit, source) = match available_memory_bytes() {
        Some(b) => (b, "available on this machine (MemAvailable)"),
        None => (
            MAX_GENERATED_CELLS * BYTES_PER_CELL,
            "the limit where memory is unknown",
        ),
    };
    if !(need <= limit) {
        bail!(
            "{what}: {cells:.3e} hexahedra take about {:.1} GB of memory ({BYTES_PER_CELL:.0} bytes each), above the {:.1} GB {source}",
            need / 1e9,
            limit / 1e9
        );
    }
    Ok(())
}

/// This machine's available memory in bytes (`MemAvailable` in `/proc/meminfo`), where the
/// system says.
pub fn available_memory_bytes() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}
