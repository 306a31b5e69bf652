//! Step 2b of the search: each contact surface cut down to the faces that came near a tool
//! or the surface it pairs with in the held model's run (contact costs per surface node
//! every step).

use anyhow::Result;

use super::search::{Held, Model, Search};
use super::{prune, Trace, TRIM_FACE_DIAMETERS};
use crate::geom::{norm, sub};
use crate::problem::contact::ContactSetup;
use crate::problem::Problem;

/// The first of [`TRIM_FACE_DIAMETERS`] whose trimmed model passes, held.
pub(super) fn try_trims(s: &mut Search<'_>, held: &mut Held, watch: &[String]) -> Result<()> {
    if held.problem.contact.is_some() {
        for k in TRIM_FACE_DIAMETERS {
            if let Some(h) = try_trim(s, held, watch, k)? {
                *held = h;
                break;
            }
        }
    }
    Ok(())
}

/// The held model with each contact surface cut down to its faces with a node that came
/// within `k` longest face diagonals of a tool of the surface or of a node of the surface
/// it pairs with, at a sample of the held model's run (a face is kept whole: the other
/// side's nodes meet it anywhere on it); measured. None when it changes nothing or would
/// leave a surface without a face.
fn try_trim(s: &mut Search<'_>, held: &Held, watch: &[String], k: f64) -> Result<Option<Held>> {
    let p = &held.problem;
    let Some(c) = &p.contact else {
        return Ok(None);
    };
    let (mut r, view) = match (&held.model, held.unpruned_scene()) {
        (Model::Pruned(r), None) => ((**r).clone(), held.view.clone()),
        (_, Some(scene)) => {
            let d = prune::driven_nodes(p, watch)?;
            let pilot = prune::Pilot {
                motion_m: &held.trace.motion_m,
                energy_j: &held.trace.energy_j,
            };
            let r = prune::prune(p, &scene, pilot, &d, None)?;
            let v = held.view.then_pruned(&r.node_map);
            (r, v)
        }
        // (A full model is its scene: not reached.)
        (Model::Full { .. }, None) => return Ok(None),
    };
    let margin = k * c.face_diameter_max_m;
    let near = nearest_approach(p, c, &held.trace);
    let mut dropped = 0usize;
    for (si, surf) in c.surfaces.iter().enumerate() {
        let kept: Vec<u32> = {
            let mut v: Vec<u32> = surf
                .faces
                .iter()
                .filter(|(q, _)| q.iter().any(|&n| near[n as usize] <= margin))
                .flat_map(|(q, _)| q.iter().copied())
                .collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        if kept.is_empty() {
            return Ok(None);
        }
        dropped += surface_nodes(c, si).len() - kept.len();
        r.node_sets.insert(format!("plan_surface_{si}"), kept);
    }
    if dropped == 0 {
        return Ok(None);
    }
    let q = r.problem()?;
    let kept_nodes = q.contact.as_ref().map_or(0, |c| c.node_globals.len());
    let choice = format!(
        "contact surfaces cut to what came within {k} face diagonals ({:.2} mm) of a tool or the paired surface: {kept_nodes} contact nodes of {}",
        1e3 * margin,
        c.node_globals.len()
    );
    Ok(s.try_model(&choice, &q, &view)?.map(|t| Held {
        model: Model::Pruned(Box::new(r)),
        problem: q,
        trace: t,
        view,
    }))
}

/// The nodes of contact surface `si`, ascending, each once.
fn surface_nodes(c: &ContactSetup, si: usize) -> Vec<usize> {
    let mut v: Vec<usize> = c.surfaces[si]
        .faces
        .iter()
        .flat_map(|(q, _)| q.iter().map(|&n| n as usize))
        .collect();
    v.sort_unstable();
    v.dedup();
    v
}

/// Per mesh node, the closest it came (m) to a tool of its surface (the distance to the
/// capsule, negative inside) or to a node of the surface its surface pairs with, over the
/// samples of `trace`; infinite for a node on no contact surface.
fn nearest_approach(p: &Problem, c: &ContactSetup, trace: &Trace) -> Vec<f64> {
    let at = |n: usize, smp: usize| -> [f64; 3] {
        core::array::from_fn(|i| p.mesh.nodes[n][i] + trace.u[smp][n][i])
    };
    let mut near = vec![f64::INFINITY; p.mesh.nodes.len()];
    for (si, _) in c.surfaces.iter().enumerate() {
        let mine = surface_nodes(c, si);
        for smp in 0..trace.u.len() {
            let t = trace.times_s[smp];
            for tool in c.tools.iter().filter(|t| t.surface as usize == si) {
                let capsule = tool.capsule.translated(p.paths[tool.path as usize].at(t));
                for &n in &mine {
                    let x = at(n, smp);
                    let d = norm(sub(x, capsule.closest_axis_point(x))) - capsule.radius_m;
                    near[n] = near[n].min(d);
                }
            }
            for pair in &c.pairs {
                let other = match (pair.a as usize, pair.b as usize) {
                    (a, b) if a == si => b,
                    (a, b) if b == si => a,
                    _ => continue,
                };
                let theirs: Vec<[f64; 3]> = surface_nodes(c, other)
                    .iter()
                    .map(|&n| at(n, smp))
                    .collect();
                for &n in &mine {
                    let x = at(n, smp);
                    for y in &theirs {
                        near[n] = near[n].min(norm(sub(x, *y)));
                    }
                }
            }
        }
    }
    near
}
