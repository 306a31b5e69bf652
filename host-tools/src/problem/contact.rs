//! A scene's contact resolved on its mesh: surfaces (boundary faces), the contact-node
//! table, tools and pairs, and the search parameters that follow from the time step. The
//! serial solver and the schedule compiler both start from [`ContactSetup`], so the tables
//! the boards get are the ones the reference run used.

use std::collections::{BTreeMap, BTreeSet};

use anyhow::{anyhow, bail, Result};
use pe_firmware::physics::contact::{
    Capsule, ContactFace, ContactNode, ContactPair, Tool, SURFACES_MAX,
};

use crate::mesh::Mesh;
use crate::scene::ContactSpec;

/// Boundary faces of the mesh with the cell each belongs to ([`Mesh::boundary_faces_with_cells`]),
/// oriented outward (counter-clockwise seen from outside) by the cell's centre, in cell order.
pub fn boundary_faces_with_cells(mesh: &Mesh) -> Vec<([u32; 4], u32)> {
    let mut out = Vec::new();
    for (q, ci) in mesh.boundary_faces_with_cells() {
        let c = &mesh.cells[ci as usize];
        let centre: [f64; 3] = core::array::from_fn(|i| {
            c.iter().map(|&n| mesh.nodes[n as usize][i]).sum::<f64>() / 8.0
        });
        let p = q.map(|n| mesh.nodes[n as usize]);
        let d1: [f64; 3] = core::array::from_fn(|i| p[2][i] - p[0][i]);
        let d2: [f64; 3] = core::array::from_fn(|i| p[3][i] - p[1][i]);
        let n = [
            d1[1] * d2[2] - d1[2] * d2[1],
            d1[2] * d2[0] - d1[0] * d2[2],
            d1[0] * d2[1] - d1[1] * d2[0],
        ];
        let fc: [f64; 3] = core::array::from_fn(|i| p.iter().map(|x| x[i]).sum::<f64>() / 4.0);
        let out_dot: f64 = (0..3).map(|i| n[i] * (fc[i] - centre[i])).sum();
        let q = if out_dot >= 0.0 {
            q
        } else {
            [q[0], q[3], q[2], q[1]]
        };
        out.push((q, ci));
    }
    out
}

/// One declared surface, resolved.
#[derive(Clone, Debug)]
pub struct Surface {
    pub name: String,
    /// Faces (mesh node indices, outward) and their cells.
    pub faces: Vec<([u32; 4], u32)>,
}

/// A scene's contact on its mesh, before the time step is known.
#[derive(Clone, Debug)]
pub struct ContactSetup {
    pub settings: ContactSpec,
    pub surfaces: Vec<Surface>,
    pub tool_names: Vec<String>,
    /// Each tool's trocar (the point it pivots about in a live session), if the scene names one.
    pub trocars: Vec<Option<[f64; 3]>>,
    /// Tools with `surface` an index into `surfaces` and `path` into the problem's paths.
    pub tools: Vec<Tool>,
    pub pairs: Vec<ContactPair>,
    /// Contact nodes: mesh indices (ascending) and surface masks.
    pub node_globals: Vec<u32>,
    pub node_surfaces: Vec<u8>,
    /// Faces in contact-node numbering.
    pub faces: Vec<ContactFace>,
    /// Longest face diagonal of the pair surfaces (m).
    pub face_diameter_max_m: f64,
}

/// The contact tables and search parameters for a time step `dt`.
#[derive(Clone, Debug)]
pub struct ContactRun {
    pub nodes: Vec<ContactNode>,
    pub faces: Vec<ContactFace>,
    pub pairs: Vec<ContactPair>,
    pub tools: Vec<Tool>,
    pub params: pe_firmware::image::ContactParams,
}

impl ContactSetup {
    /// Resolves surfaces (faces chosen by `face_filter(surface index, face nodes, cell)`),
    /// tools and pairs.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        mesh: &Mesh,
        settings: ContactSpec,
        surfaces: Vec<Surface>,
        tool_names: Vec<String>,
        tools: Vec<Tool>,
        pair_surfaces: Vec<([usize; 2], Option<f64>)>,
        cell_length: &dyn Fn(u32) -> f64,
    ) -> Result<ContactSetup> {
        if surfaces.len() > SURFACES_MAX {
            bail!(
                "{} [[surface]]s: at most {SURFACES_MAX} are supported",
                surfaces.len()
            );
        }
        let s = &settings;
        if !(s.penalty > 0.0 && s.penalty <= 1.0) {
            bail!(
                "[contact] penalty = {}: must lie in (0, 1] (a fraction of m/dt²; above that the contact springs break the explicit step's stability)",
                s.penalty
            );
        }
        if !(s.tolerance > 0.0) || !(s.speed_bound > 0.0) || !(s.gap > 0.0) {
            bail!("[contact] tolerance, speed_bound and gap must be positive");
        }
        let mut set: BTreeSet<u32> = BTreeSet::new();
        for sf in &surfaces {
            for (q, _) in &sf.faces {
                set.extend(q.iter().copied());
            }
        }
        // Tool surfaces contribute their nodes too (a surface may have no pair).
        let node_globals: Vec<u32> = set.into_iter().collect();
        let index: BTreeMap<u32, u32> = node_globals
            .iter()
            .enumerate()
            .map(|(i, &g)| (g, i as u32))
            .collect();
        let mut node_surfaces = vec![0u8; node_globals.len()];
        let mut faces = Vec::new();
        for (si, sf) in surfaces.iter().enumerate() {
            for (q, _) in &sf.faces {
                let nodes = q.map(|g| index[&g]);
                for &c in &nodes {
                    node_surfaces[c as usize] |= 1 << si;
                }
                faces.push(ContactFace {
                    nodes,
                    surface: si as u8,
                });
            }
        }
        let mut pairs = Vec::new();
        let mut diam: f64 = 0.0;
        for ([a, b], depth) in pair_surfaces {
            if a == b {
                bail!(
                    "[[contact_pair]] {:?} with itself: self-contact is not supported",
                    surfaces[a].name
                );
            }
            let thinnest = surfaces[a]
                .faces
                .iter()
                .chain(&surfaces[b].faces)
                .map(|(_, c)| cell_length(*c))
                .fold(f64::INFINITY, f64::min);
            let depth_max_m = depth.unwrap_or(thinnest / 3.0);
            if !(depth_max_m > 0.0) {
                bail!("[[contact_pair]] depth must be positive");
            }
            for (q, _) in surfaces[a].faces.iter().chain(&surfaces[b].faces) {
                for (i, j) in [(0, 2), (1, 3)] {
                    let (p, r) = (mesh.nodes[q[i] as usize], mesh.nodes[q[j] as usize]);
                    let d = (0..3).map(|k| (p[k] - r[k]).powi(2)).sum::<f64>().sqrt();
                    diam = diam.max(d);
                }
            }
            pairs.push(ContactPair {
                a: a as u8,
                b: b as u8,
                depth_max_m,
            });
        }
        Ok(ContactSetup {
            settings,
            surfaces,
            trocars: vec![None; tool_names.len()],
            tool_names,
            tools,
            pairs,
            node_globals,
            node_surfaces,
            faces,
            face_diameter_max_m: diam,
        })
    }

    /// Tables and search parameters for step `dt_s`, with inertial node masses `mass`.
    pub fn for_step(&self, mesh: &Mesh, inertial_mass: &[f64], dt_s: f64) -> ContactRun {
        let s = &self.settings;
        let nodes = self
            .node_globals
            .iter()
            .zip(&self.node_surfaces)
            .map(|(&g, &m)| ContactNode {
                global: g,
                reference: mesh.nodes[g as usize],
                penalty_n_per_m: s.penalty * inertial_mass[g as usize] / (dt_s * dt_s),
                surfaces: m,
            })
            .collect();
        let check =
            ((s.gap / (2.0 * s.speed_bound * dt_s)).floor() as u64).clamp(1, u32::MAX as u64);
        let travel = s.speed_bound * check as f64 * dt_s;
        let depth = self.pairs.iter().map(|p| p.depth_max_m).fold(0.0, f64::max);
        ContactRun {
            nodes,
            faces: self.faces.clone(),
            pairs: self.pairs.clone(),
            tools: self.tools.clone(),
            params: pe_firmware::image::ContactParams {
                check_interval_steps: check as u32,
                travel_max_m: travel,
                candidate_margin_m: 2.0 * travel + depth,
                box_margin_m: 2.0 * (self.face_diameter_max_m + depth) + 2.0 * travel,
                // A node deeper than a pair's depth_max would be lost as contact (taken to
                // be on the far side), so deeper than 0.9 of it is reported instead.
                tolerance_m: self
                    .pairs
                    .iter()
                    .map(|p| 0.9 * p.depth_max_m)
                    .fold(s.tolerance, f64::min),
                pair_surfaces: pe_firmware::physics::contact::pair_surface_mask(&self.pairs),
            },
        }
    }
}

/// Resolves the scene's `[[surface]]`, `[[tool]]` and `[[contact_pair]]` (None if it has
/// none) on the mesh's boundary faces (`faces`, outward, with their `cells`, from
/// [`boundary_faces_with_cells`]). `select(surface spec)`: the selected mesh nodes (None: no restriction);
/// `region(spec)`: the region tag; `add_path`: registers a tool path, returns its index.
#[allow(clippy::too_many_arguments)]
pub fn resolve(
    scene: &crate::scene::Scene,
    mesh: &Mesh,
    faces: &[[u32; 4]],
    cells: &[u32],
    select: &dyn Fn(&crate::scene::SurfaceSpec) -> Result<Option<Vec<bool>>>,
    region: &dyn Fn(&crate::scene::RegionRef) -> Option<i32>,
    add_path: &mut dyn FnMut(Vec<(f64, [f64; 3])>) -> u32,
    cell_length: &dyn Fn(u32) -> f64,
) -> Result<Option<ContactSetup>> {
    if scene.surface.is_empty() && scene.tool.is_empty() && scene.contact_pair.is_empty() {
        if scene.contact.is_some() {
            bail!("[contact] is given but there is no [[tool]] or [[contact_pair]]");
        }
        return Ok(None);
    }
    let mut surfaces = Vec::new();
    for (k, s) in scene.surface.iter().enumerate() {
        let what = format!("[[surface]] {k} ({:?})", s.name);
        if scene.surface[..k].iter().any(|o| o.name == s.name) {
            bail!("{what}: the name is used twice");
        }
        let tag = match &s.region {
            Some(r) => Some(region(r).ok_or_else(|| {
                anyhow!(
                    "{what}: mesh {} has no region {r} (regions: {:?})",
                    mesh.source,
                    mesh.region_names
                )
            })?),
            None => None,
        };
        let sel = select(s)?;
        let chosen: Vec<([u32; 4], u32)> = faces
            .iter()
            .zip(cells)
            .filter(|(q, c)| {
                tag.is_none_or(|t| mesh.cell_regions[**c as usize] == t)
                    && sel
                        .as_ref()
                        .is_none_or(|m| q.iter().all(|&n| m[n as usize]))
            })
            .map(|(q, c)| (*q, *c))
            .collect();
        if chosen.is_empty() {
            bail!(
                "{what}: no boundary face of mesh {} lies in it",
                mesh.source
            );
        }
        surfaces.push(Surface {
            name: s.name.clone(),
            faces: chosen,
        });
    }
    let find = |name: &str, what: &str| {
        surfaces.iter().position(|s| s.name == name).ok_or_else(|| {
            anyhow!(
                "{what}: no [[surface]] named {name:?} (surfaces: {:?})",
                surfaces.iter().map(|s| &s.name).collect::<Vec<_>>()
            )
        })
    };
    let mut tools = Vec::new();
    let mut names = Vec::new();
    let mut trocars = Vec::new();
    for (k, t) in scene.tool.iter().enumerate() {
        let what = format!("[[tool]] {k} ({:?})", t.name);
        if t.shape != "capsule" {
            bail!("{what}: shape = {:?}: expected \"capsule\"", t.shape);
        }
        if !(t.radius > 0.0) {
            bail!("{what}: radius must be positive, got {}", t.radius);
        }
        if t.path.is_empty() || t.path.windows(2).any(|w| !(w[1][0] > w[0][0])) {
            bail!("{what}: `path` needs points [t, dx, dy, dz] with increasing t");
        }
        let surface = find(&t.surface, &what)?;
        let path = add_path(t.path.iter().map(|q| (q[0], [q[1], q[2], q[3]])).collect());
        tools.push(Tool {
            capsule: Capsule {
                a: t.a,
                b: t.b,
                radius_m: t.radius,
            },
            path: u16::try_from(path).map_err(|_| anyhow!("{what}: too many paths"))?,
            surface: surface as u8,
        });
        names.push(t.name.clone());
        if let Some(p) = t.trocar.filter(|p| p.iter().any(|v| !v.is_finite())) {
            bail!("{what}: trocar {p:?} must be finite (m)");
        }
        trocars.push(t.trocar);
    }
    let mut pairs = Vec::new();
    for (k, p) in scene.contact_pair.iter().enumerate() {
        let what = format!("[[contact_pair]] {k}");
        pairs.push((
            [find(&p.surfaces[0], &what)?, find(&p.surfaces[1], &what)?],
            p.depth,
        ));
    }
    ContactSetup::new(
        mesh,
        scene.contact.clone().unwrap_or_default(),
        surfaces,
        names,
        tools,
        pairs,
        cell_length,
    )
    .map(|setup| Some(ContactSetup { trocars, ..setup }))
}
