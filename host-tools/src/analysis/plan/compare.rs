//! How a candidate is measured against the reference: its displacement field read at the
//! reference's nodes ([`View`]), and the relative errors of the quantities of interest.

use super::Trace;
use crate::geom::norm;
use crate::mesh::Mesh;

/// How a candidate's field is read at the reference's nodes.
#[derive(Clone)]
pub(super) enum View {
    /// The reference's own mesh, every node simulated.
    Same,
    /// The reference's mesh pruned: reference node → model node (None: not simulated).
    Pruned(Vec<Option<u32>>),
    /// Another mesh (level), maybe pruned: that level's full mesh and its node → model node.
    Level {
        mesh: Mesh,
        node_map: Option<Vec<Option<u32>>>,
    },
}

impl View {
    /// The same view after pruning the model it reads with `map` (model node → pruned).
    pub(super) fn then_pruned(&self, map: &[Option<u32>]) -> View {
        let compose = |m: Option<&Vec<Option<u32>>>| -> Vec<Option<u32>> {
            match m {
                None => map.to_vec(),
                Some(m) => m.iter().map(|o| o.and_then(|k| map[k as usize])).collect(),
            }
        };
        match self {
            View::Same => View::Pruned(map.to_vec()),
            View::Pruned(m) => View::Pruned(compose(Some(m))),
            View::Level { mesh, node_map } => View::Level {
                mesh: mesh.clone(),
                node_map: Some(compose(node_map.as_ref())),
            },
        }
    }
}

/// The tool-force errors of a candidate at the rates the force's consumers sample it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct ForceErrors {
    /// Over the 1 ms means (the haptic loop's).
    pub haptic: f64,
    /// Over the 40 ms means (the graphics').
    pub graphics: f64,
}

impl ForceErrors {
    /// The worse of the two (NaN if either is: a NaN never passes a budget).
    pub fn worst(self) -> f64 {
        if self.haptic.is_nan() || self.graphics.is_nan() {
            f64::NAN
        } else {
            self.haptic.max(self.graphics)
        }
    }
}

/// `max_k |F_k − F_ref,k| / max_k |F_ref,k|` over the windows of each tool, the worst tool
/// (NaN propagates: `f64::max` would drop it).
fn force_error(reference: &[Vec<[f64; 3]>], cand: &[Vec<[f64; 3]>]) -> f64 {
    let nan_max = |a: f64, b: f64| {
        if a.is_nan() || b.is_nan() {
            f64::NAN
        } else {
            a.max(b)
        }
    };
    reference
        .iter()
        .zip(cand)
        .map(|(r, c)| {
            if r.len() != c.len() {
                return f64::NAN;
            }
            let scale = r.iter().map(|f| norm(*f)).fold(0.0, nan_max);
            let e = r
                .iter()
                .zip(c)
                .map(|(a, b)| norm(core::array::from_fn(|i| a[i] - b[i])))
                .fold(0.0, nan_max);
            e / scale.max(1e-300)
        })
        .fold(0.0, nan_max)
}

/// The errors of `cand` (read through `view`) against `reference` on `watched` nodes: the
/// tool force's (when the scene has tools), the displacement's, and the nodes compared.
pub(super) fn errors(
    reference: &Trace,
    ref_mesh: &Mesh,
    watched: &[usize],
    cand: &Trace,
    view: &View,
) -> (Option<ForceErrors>, f64, usize) {
    let force = (!reference.tool_force_haptic.is_empty()).then(|| ForceErrors {
        haptic: force_error(&reference.tool_force_haptic, &cand.tool_force_haptic),
        graphics: force_error(&reference.tool_force_graphics, &cand.tool_force_graphics),
    });
    let interp_mesh = match view {
        View::Level { mesh, .. } => Some(crate::analysis::tradeoff::Interpolator::new(mesh)),
        _ => None,
    };
    let (mut emax, mut umax, mut compared) = (0.0f64, 0.0f64, vec![false; watched.len()]);
    for (s, ur) in reference.u.iter().enumerate() {
        let uc = &cand.u[s];
        let expanded: Option<Vec<[f64; 3]>> = match view {
            View::Level {
                mesh,
                node_map: Some(m),
            } => Some(
                (0..mesh.nodes.len())
                    .map(|n| m[n].map(|k| uc[k as usize]).unwrap_or([0.0; 3]))
                    .collect(),
            ),
            _ => None,
        };
        for (w, &n) in watched.iter().enumerate() {
            let got = match view {
                View::Same => Some(uc[n]),
                View::Pruned(m) => Some(m[n].map(|k| uc[k as usize]).unwrap_or([0.0; 3])),
                View::Level { .. } => interp_mesh
                    .as_ref()
                    .and_then(|i| i.at(expanded.as_deref().unwrap_or(uc), ref_mesh.nodes[n])),
            };
            umax = umax.max(norm(ur[n]));
            if let Some(g) = got {
                compared[w] = true;
                emax = emax.max(norm(core::array::from_fn(|i| g[i] - ur[n][i])));
            }
        }
    }
    (
        force,
        emax / umax.max(1e-300),
        compared.iter().filter(|&&c| c).count(),
    )
}
