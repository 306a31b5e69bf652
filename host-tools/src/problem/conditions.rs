//! How a scene acts on its mesh's nodes: the node selectors, `[[fixed]]` and
//! `[[prescribed]]` (how each node moves), `[[load]]` and `[gravity]` (the forces and their
//! ramps in time).

use std::collections::BTreeMap;

use anyhow::{anyhow, bail, Result};
use pe_firmware::image::Segment;

use super::curves::Curves;
use super::{Load, NodeKind, Path1, Problem};
use crate::mesh::Mesh;
use crate::scene::{Scene, Selector};

/// Selects mesh nodes by box, sphere or named node set.
pub(super) struct NodeSelector<'a> {
    pub(super) mesh: &'a Mesh,
    pub(super) node_sets: &'a BTreeMap<String, Vec<u32>>,
}

impl NodeSelector<'_> {
    /// The nodes in the box, the sphere or the set of `s` (at least one).
    pub(super) fn select(&self, s: Selector<'_>, what: &str) -> Result<Vec<u32>> {
        let (mesh, node_sets) = (self.mesh, self.node_sets);
        let n_nodes = mesh.nodes.len();
        let mut out = Vec::new();
        if s.box_.is_none() && s.sphere.is_none() && s.set.is_none() {
            bail!("{what}: give `box`, `sphere` or `set`");
        }
        let mut in_set = vec![false; n_nodes];
        if let Some(name) = s.set {
            let set = node_sets.get(name).ok_or_else(|| {
                anyhow!(
                    "{what}: the mesh provides no node set \"{name}\" (it has {:?})",
                    node_sets.keys().collect::<Vec<_>>()
                )
            })?;
            for &n in set {
                in_set[n as usize] = true;
            }
        }
        for (n, p) in mesh.nodes.iter().enumerate() {
            let in_box = s
                .box_
                .is_some_and(|b| (0..3).all(|i| b[0][i] <= p[i] && p[i] <= b[1][i]));
            let in_sphere = s.sphere.is_some_and(|sp| {
                (0..3).map(|i| (p[i] - sp.center[i]).powi(2)).sum::<f64>() <= sp.radius * sp.radius
            });
            if in_box || in_sphere || in_set[n] {
                out.push(n as u32);
            }
        }
        if out.is_empty() {
            bail!("{what} selects no node of mesh {}", mesh.source);
        }
        Ok(out)
    }

    /// A contact surface's node mask (None when it selects no nodes by position or set:
    /// the whole region).
    pub(super) fn surface(&self, sp: &crate::scene::SurfaceSpec) -> Result<Option<Vec<bool>>> {
        let sel = sp.selector();
        if sel.box_.is_none() && sel.sphere.is_none() && sel.set.is_none() {
            return Ok(None);
        }
        let mut m = vec![false; self.mesh.nodes.len()];
        for n in self.select(sel, &format!("[[surface]] {:?}", sp.name))? {
            m[n as usize] = true;
        }
        Ok(Some(m))
    }
}

/// `[[fixed]]` and `[[prescribed]]`: how every node moves, and the prescribed paths.
pub(super) fn constraints(
    scene: &Scene,
    sel: &NodeSelector,
) -> Result<(Vec<NodeKind>, Vec<Path1<3>>)> {
    let mut node_kind = vec![NodeKind::Free; sel.mesh.nodes.len()];
    for (k, f) in scene.fixed.iter().enumerate() {
        for n in sel.select(f.selector(), &format!("[[fixed]] {k}"))? {
            node_kind[n as usize] = NodeKind::Fixed;
        }
    }
    let mut paths = Vec::new();
    for (k, p) in scene.prescribed.iter().enumerate() {
        let what = format!("[[prescribed]] {k}");
        if p.path.is_empty() || p.path.windows(2).any(|w| !(w[1][0] > w[0][0])) {
            bail!("{what}: `path` needs points [t, ux, uy, uz] with increasing t");
        }
        for n in sel.select(p.selector(), &what)? {
            if node_kind[n as usize] == NodeKind::Fixed {
                bail!(
                    "{what}: node {} is also fixed",
                    sel.mesh.node_tags[n as usize]
                );
            }
            node_kind[n as usize] = NodeKind::Prescribed(paths.len() as u32);
        }
        paths.push(Path1 {
            points: p.path.iter().map(|q| (q[0], [q[1], q[2], q[3]])).collect(),
            segment: p.shape.unwrap_or_default(),
        });
    }
    Ok((node_kind, paths))
}

/// `[[load]]`: each load's force shared equally by its nodes.
pub(super) fn nodal_loads(scene: &Scene, sel: &NodeSelector) -> Result<Vec<Load>> {
    let mut loads = Vec::new();
    for (k, l) in scene.load.iter().enumerate() {
        let what = format!("[[load]] {k}");
        let nodes = sel.select(l.selector(), &what)?;
        let share = 1.0 / nodes.len() as f64;
        let ramp = ramp_of(l.ramp.as_deref(), l.shape, &what)?;
        for n in nodes {
            loads.push(Load {
                node: n,
                force: l.force.map(|f| f * share),
                ramp: ramp.clone(),
            });
        }
    }
    Ok(loads)
}

/// A `ramp = [[t, factor], ...]` with its `shape` (`what` names the table in errors).
fn ramp_of(
    ramp: Option<&[[f64; 2]]>,
    shape: Option<Segment>,
    what: &str,
) -> Result<Option<Path1<1>>> {
    let Some(r) = ramp else {
        if shape.is_some() {
            bail!("{what}: `shape` without a `ramp` (give ramp = [[t, factor], ...])");
        }
        return Ok(None);
    };
    if r.is_empty() || r.windows(2).any(|w| !(w[1][0] > w[0][0])) {
        bail!("{what}: `ramp` needs points [t, factor] with increasing t");
    }
    Ok(Some(Path1 {
        points: r.iter().map(|q| (q[0], [q[1]])).collect(),
        segment: shape.unwrap_or_default(),
    }))
}

/// `[gravity] ramp`, checked as a load's.
pub(super) fn gravity_ramp_of(scene: &Scene) -> Result<Option<Path1<1>>> {
    match &scene.gravity {
        Some(g) => ramp_of(g.ramp.as_deref(), g.shape, "[gravity]"),
        None => Ok(None),
    }
}

/// The gravity vector, refused unless finite.
pub(super) fn gravity_of(scene: &Scene) -> Result<[f64; 3]> {
    let g = scene
        .gravity
        .as_ref()
        .map(|g| g.acceleration)
        .unwrap_or([0.0; 3]);
    if !g.iter().all(|v| v.is_finite()) {
        bail!("[gravity] acceleration must be finite (m/s²), got {g:?}");
    }
    Ok(g)
}

impl Problem {
    /// The distinct ramps of the loads and gravity, one [`Curves`] for the solver and the
    /// compiler: user `k < loads.len()` is load `k`, user [`Self::gravity_ramp_user`] is
    /// gravity.
    pub fn ramp_curves(&self) -> Curves<1> {
        let loads = self.loads.iter().map(|l| l.ramp.as_ref());
        Curves::of(loads.chain([self.gravity_ramp.as_ref()]))
    }

    /// Gravity's user in [`Self::ramp_curves`].
    pub fn gravity_ramp_user(&self) -> usize {
        self.loads.len()
    }
}
