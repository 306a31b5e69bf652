//! Pruning the domain: the elements a scene's loads hardly move are removed and the nodes
//! where the kept part meets them are held.
//!
//! An element is kept when one of its nodes is *driven* (on a contact surface, loaded,
//! prescribed, or in a watched set), when one of its nodes moved at least a fraction of the
//! largest motion in the pilot run, or when it stored at least that fraction of the largest
//! element energy (a stiff part that hardly moves but carries load, such as a body pressed
//! by another, is not held rigid). Kept
//! pieces that hold no driven node (and feel no gravity) would stay at rest once cut off,
//! so they go too. The nodes a kept element shares with a removed one are held (fixed);
//! when such a node is driven, the elements around it are kept as well and the cut is
//! found again, so no load, tool, contact surface or prescribed motion is ever held or
//! loses an element it touches, and no face made by the cut can join a contact surface.
//!
//! The reduced scene says everything by node sets written with its mesh: `plan_fixed`
//! (the scene's fixed nodes that are kept, and the held ones), `plan_prescribed_K`,
//! `plan_load_K` and `plan_surface_K` (the nodes of the faces the surface had), beside the
//! mesh's own sets restricted to the kept nodes.

use std::collections::BTreeMap;

use anyhow::{bail, Result};

use crate::mesh::Mesh;
use crate::problem::{NodeKind, Problem};
use crate::scene::{FixedSpec, LoadSpec, MeshSpec, PrescribedSpec, RegionRef, Scene};

/// How each element of the full mesh fares (the PNG's colours).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CellKind {
    Pruned = 0,
    Kept = 1,
    /// Kept, with a node held at the cut.
    AtCut = 2,
    /// Kept because it touches a tool or contact surface, a load, a prescribed motion or a
    /// watched set.
    Driven = 3,
}

/// A pruned model of a problem.
#[derive(Clone, Debug)]
pub struct Reduced {
    pub scene: Scene,
    pub mesh: Mesh,
    pub node_sets: BTreeMap<String, Vec<u32>>,
    /// Full-mesh node → reduced node.
    pub node_map: Vec<Option<u32>>,
    /// Per full-mesh cell.
    pub cell_kind: Vec<CellKind>,
    /// The full mesh it was pruned from.
    pub full_mesh: Mesh,
    pub held_nodes: usize,
    /// Pruned below this fraction of the largest motion and element energy.
    pub fraction: Option<f64>,
    /// On a coarsened mesh ([`crate::mesh::coarsen`]), its scene's selections as given.
    pub coarsened: bool,
}

/// File name of the reduced mesh beside the reduced scene.
pub const MESH_FILE: &str = "mesh.msh";

/// Nodes of `p` that pruning must keep with every element around them.
pub fn driven_nodes(p: &Problem, watch: &[String]) -> Result<Vec<bool>> {
    let mut d = vec![false; p.mesh.nodes.len()];
    if let Some(c) = &p.contact {
        for &n in &c.node_globals {
            d[n as usize] = true;
        }
    }
    for l in &p.loads {
        d[l.node as usize] = true;
    }
    for (n, k) in p.node_kind.iter().enumerate() {
        if matches!(k, NodeKind::Prescribed(_)) {
            d[n] = true;
        }
    }
    for name in watch {
        let Some(set) = p.node_sets.get(name) else {
            bail!(
                "--watch {name:?}: the mesh has no node set of that name (it has {:?})",
                p.node_sets.keys().collect::<Vec<_>>()
            );
        };
        for &n in set {
            d[n as usize] = true;
        }
    }
    Ok(d)
}

/// Union-find root.
fn root(parent: &mut [u32], mut a: u32) -> u32 {
    while parent[a as usize] != a {
        parent[a as usize] = parent[parent[a as usize] as usize];
        a = parent[a as usize];
    }
    a
}

/// Which cells pruning keeps at tolerance `tol_m`, and which nodes are held.
fn kept_cells(
    p: &Problem,
    pilot: &Pilot<'_>,
    driven: &[bool],
    fraction: Option<f64>,
) -> (Vec<bool>, Vec<bool>) {
    let mesh = &p.mesh;
    let nn = mesh.nodes.len();
    let mut node_cells: Vec<Vec<u32>> = vec![Vec::new(); nn];
    for (c, cell) in mesh.cells.iter().enumerate() {
        for &n in cell {
            let v = &mut node_cells[n as usize];
            if v.last() != Some(&(c as u32)) {
                v.push(c as u32);
            }
        }
    }
    let Some(f) = fraction else {
        return (vec![true; mesh.cells.len()], vec![false; nn]);
    };
    let tol_m = f * pilot.motion_m.iter().copied().fold(0.0, f64::max);
    let tol_j = f * pilot.energy_j.iter().copied().fold(0.0, f64::max);
    let gravity = p.gravity.iter().any(|g| *g != 0.0);
    let mut keep: Vec<bool> = mesh
        .cells
        .iter()
        .enumerate()
        .map(|(e, c)| {
            pilot.energy_j[e] >= tol_j
                || c.iter()
                    .any(|&n| driven[n as usize] || pilot.motion_m[n as usize] >= tol_m)
        })
        .collect();
    loop {
        // Kept pieces (cells joined through shared nodes) without a driven node go.
        if !gravity {
            let mut parent: Vec<u32> = (0..nn as u32).collect();
            for (c, cell) in mesh.cells.iter().enumerate() {
                if keep[c] {
                    for &n in &cell[1..] {
                        let (a, b) = (root(&mut parent, cell[0]), root(&mut parent, n));
                        parent[a as usize] = b;
                    }
                }
            }
            let mut live = vec![false; nn];
            for n in 0..nn {
                if driven[n] {
                    let r = root(&mut parent, n as u32);
                    live[r as usize] = true;
                }
            }
            for (c, cell) in mesh.cells.iter().enumerate() {
                if keep[c] && !live[root(&mut parent, cell[0]) as usize] {
                    keep[c] = false;
                }
            }
        }
        // Held: nodes of both a kept and a removed cell. A driven one keeps its cells.
        let mut grew = false;
        let mut held = vec![false; nn];
        for n in 0..nn {
            let cells = &node_cells[n];
            let kept = cells.iter().any(|&c| keep[c as usize]);
            let gone = cells.iter().any(|&c| !keep[c as usize]);
            if kept && gone {
                if driven[n] {
                    for &c in cells {
                        keep[c as usize] = true;
                    }
                    grew = true;
                } else {
                    held[n] = true;
                }
            }
        }
        if !grew {
            return (keep, held);
        }
    }
}

/// What the pilot run of the model being pruned measured.
#[derive(Clone, Copy)]
pub struct Pilot<'a> {
    /// Largest |u| of each node (m).
    pub motion_m: &'a [f64],
    /// Largest stored energy of each cell (J).
    pub energy_j: &'a [f64],
}

/// The model of `p` (resolved from `scene`) pruned at `fraction` of the pilot's largest
/// motion and largest element energy (`None`: nothing pruned, the scene only rewritten on
/// its mesh file).
pub fn prune(
    p: &Problem,
    scene: &Scene,
    pilot: Pilot<'_>,
    driven: &[bool],
    fraction: Option<f64>,
) -> Result<Reduced> {
    let mesh = &p.mesh;
    let (keep, held) = kept_cells(p, &pilot, driven, fraction);
    if !keep.iter().any(|&k| k) {
        bail!(
            "the scene has no tool, contact surface, load, prescribed motion or gravity: nothing moves it, nothing to plan"
        );
    }
    let (node_map, nodes) = kept_nodes(mesh, &keep);
    let (reduced_mesh, cell_kind) =
        kept_mesh(mesh, &keep, &held, driven, &node_map, nodes, fraction);
    let mut sets: BTreeMap<String, Vec<u32>> = BTreeMap::new();
    for (name, set) in &p.node_sets {
        let s = set_of(&node_map, &|n| set.binary_search(&(n as u32)).is_ok());
        if !s.is_empty() {
            sets.insert(name.clone(), s);
        }
    }
    let mut out = scene.clone();
    out.mesh = written_mesh();
    selections_as_sets(p, scene, &held, &node_map, &mut sets, &mut out)?;
    // A material whose region lost every cell would be refused.
    out.materials.retain(|m| match &m.region {
        None => true,
        Some(r) => {
            let tag = match r {
                RegionRef::Tag(t) => Some(*t),
                RegionRef::Name(name) => mesh
                    .region_names
                    .iter()
                    .find(|(_, v)| *v == name)
                    .map(|(t, _)| *t),
            };
            reduced_mesh.cell_regions.iter().any(|&c| Some(c) == tag)
        }
    });
    Ok(Reduced {
        scene: out,
        held_nodes: held.iter().filter(|&&h| h).count(),
        mesh: reduced_mesh,
        node_sets: sets,
        node_map,
        cell_kind,
        full_mesh: mesh.clone(),
        fraction,
        coarsened: false,
    })
}

/// The nodes of the kept cells: full-mesh node → reduced node, and the reduced nodes'
/// positions (in full-mesh order).
fn kept_nodes(mesh: &Mesh, keep: &[bool]) -> (Vec<Option<u32>>, Vec<[f64; 3]>) {
    let mut used = vec![false; mesh.nodes.len()];
    for (c, cell) in mesh.cells.iter().enumerate() {
        if keep[c] {
            for &n in cell {
                used[n as usize] = true;
            }
        }
    }
    let mut node_map = vec![None; mesh.nodes.len()];
    let mut nodes = Vec::new();
    for (n, &u) in used.iter().enumerate() {
        if u {
            node_map[n] = Some(nodes.len() as u32);
            nodes.push(mesh.nodes[n]);
        }
    }
    (node_map, nodes)
}

/// The mesh of the kept cells on `nodes` (pruned at `fraction`), and what became of each
/// full-mesh cell.
fn kept_mesh(
    mesh: &Mesh,
    keep: &[bool],
    held: &[bool],
    driven: &[bool],
    node_map: &[Option<u32>],
    nodes: Vec<[f64; 3]>,
    fraction: Option<f64>,
) -> (Mesh, Vec<CellKind>) {
    let map = |n: u32| node_map[n as usize].unwrap_or(u32::MAX);
    let mut cells = Vec::new();
    let mut cell_regions = Vec::new();
    let mut cell_kind = Vec::with_capacity(mesh.cells.len());
    for (c, cell) in mesh.cells.iter().enumerate() {
        if !keep[c] {
            cell_kind.push(CellKind::Pruned);
            continue;
        }
        cells.push(cell.map(map));
        cell_regions.push(mesh.cell_regions[c]);
        cell_kind.push(if cell.iter().any(|&n| driven[n as usize]) {
            CellKind::Driven
        } else if cell.iter().any(|&n| held[n as usize]) {
            CellKind::AtCut
        } else {
            CellKind::Kept
        });
    }
    let reduced_mesh = Mesh {
        node_tags: (1..=nodes.len() as u64).collect(),
        nodes,
        cells,
        cell_regions,
        region_names: mesh.region_names.clone(),
        source: match fraction {
            Some(f) => format!("{} pruned at {f:e} of its motion and energy", mesh.source),
            None => mesh.source.clone(),
        },
        node_sets: BTreeMap::new(),
        notes: Vec::new(),
    };
    (reduced_mesh, cell_kind)
}

/// The reduced nodes of the full-mesh nodes `n` for which `f(n)` holds, ascending.
fn set_of(node_map: &[Option<u32>], f: &dyn Fn(usize) -> bool) -> Vec<u32> {
    (0..node_map.len())
        .filter(|&n| f(n))
        .filter_map(|n| node_map[n])
        .collect()
}

/// The scene's selections rewritten as node sets of the reduced mesh (into `sets`):
/// `plan_fixed` (the fixed nodes kept and the held ones), `plan_prescribed_K`,
/// `plan_load_K` and `plan_surface_K`, and `out`'s selections pointed at them.
fn selections_as_sets(
    p: &Problem,
    scene: &Scene,
    held: &[bool],
    node_map: &[Option<u32>],
    sets: &mut BTreeMap<String, Vec<u32>>,
    out: &mut Scene,
) -> Result<()> {
    let fixed = set_of(node_map, &|n| held[n] || p.node_kind[n] == NodeKind::Fixed);
    out.fixed = if fixed.is_empty() {
        vec![]
    } else {
        sets.insert("plan_fixed".into(), fixed);
        vec![set_spec("plan_fixed")]
    };
    out.prescribed = scene
        .prescribed
        .iter()
        .enumerate()
        .map(|(k, ps)| {
            let name = format!("plan_prescribed_{k}");
            sets.insert(
                name.clone(),
                set_of(node_map, &|n| {
                    p.node_kind[n] == NodeKind::Prescribed(k as u32)
                }),
            );
            PrescribedSpec {
                box_: None,
                sphere: None,
                set: Some(name),
                path: ps.path.clone(),
                shape: ps.shape,
            }
        })
        .collect();
    let mut loads = Vec::new();
    for (k, l) in scene.load.iter().enumerate() {
        let chosen = p.select_nodes(l.selector(), &format!("[[load]] {k}"))?;
        let name = format!("plan_load_{k}");
        sets.insert(
            name.clone(),
            set_of(node_map, &|n| chosen.binary_search(&(n as u32)).is_ok()),
        );
        loads.push(LoadSpec {
            box_: None,
            sphere: None,
            set: Some(name),
            force: l.force,
            ramp: l.ramp.clone(),
            shape: l.shape,
        });
    }
    out.load = loads;
    if let Some(c) = &p.contact {
        for (k, (spec, s)) in out.surface.iter_mut().zip(&c.surfaces).enumerate() {
            let mut on = vec![false; node_map.len()];
            for (q, _) in &s.faces {
                for &n in q {
                    on[n as usize] = true;
                }
            }
            let name = format!("plan_surface_{k}");
            sets.insert(name.clone(), set_of(node_map, &|n| on[n]));
            spec.box_ = None;
            spec.sphere = None;
            spec.set = Some(name);
        }
    }
    Ok(())
}

fn set_spec(name: &str) -> FixedSpec {
    FixedSpec {
        box_: None,
        sphere: None,
        set: Some(name.into()),
    }
}

/// The mesh spec of a written model: [`MESH_FILE`] beside its scene, in metres.
fn written_mesh() -> MeshSpec {
    MeshSpec {
        file: Some(MESH_FILE.into()),
        unit: None,
        generate: None,
        builtin: None,
        level: None,
        blocks: vec![],
    }
}

impl Reduced {
    /// `scene` on a coarsened mesh of its own, nothing pruned: every cell kept, the mesh's
    /// node sets the ones its selections by name read.
    pub fn coarsened(scene: &Scene, mesh: Mesh) -> Reduced {
        let mut out = scene.clone();
        out.mesh = written_mesh();
        Reduced {
            scene: out,
            node_sets: mesh.node_sets.clone(),
            node_map: (0..mesh.nodes.len() as u32).map(Some).collect(),
            cell_kind: vec![CellKind::Kept; mesh.cells.len()],
            full_mesh: mesh.clone(),
            mesh,
            held_nodes: 0,
            fraction: None,
            coarsened: true,
        }
    }

    /// The reduced problem, resolved from the in-memory mesh as the written files give it.
    pub fn problem(&self) -> Result<Problem> {
        let mut mesh = self.mesh.clone();
        mesh.node_sets = self.node_sets.clone();
        Problem::new(&self.scene, mesh, self.node_sets.clone())
    }

    /// Writes `dir/scene.toml` and `dir/mesh.msh`.
    pub fn write(&self, dir: &std::path::Path, header: &str) -> Result<()> {
        use anyhow::Context;
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let m = dir.join(MESH_FILE);
        crate::output::file::write_atomic(
            &m,
            crate::mesh::io::to_msh22(&self.mesh, &self.node_sets),
        )?;
        let s = dir.join("scene.toml");
        crate::output::file::write_atomic(&s, format!("{header}{}", self.scene.to_toml()?))?;
        Ok(())
    }
}
