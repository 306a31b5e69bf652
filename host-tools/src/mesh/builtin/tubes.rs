//! The fallopian tubes of the built-in anatomy: O-grid rings grown from a P × P patch of the
//! outer body surface along ±y, flared at the root.

use super::body::{tan_quarter, Grid};
use super::HexBuild;
use crate::geom::{add, dot, scale, sub, unit, V3};

/// Where the tubes end (|y|), their outer and lumen radius and the length of the flared root.
const TUBE_END_Y: f64 = 140.0;
pub(super) const TUBE_R_OUT: f64 = 1.75;
const TUBE_R_IN: f64 = 0.875;
const TUBE_FLARE: f64 = 14.0;

/// The straight part of a tube: where it starts, its axis and the two directions across it.
struct TubeFrame {
    origin: V3,
    axis: V3,
    ea: V3,
    eb: V3,
    length: f64,
}

impl TubeFrame {
    /// `x` without its component along the axis.
    fn flatten(&self, x: V3) -> V3 {
        sub(x, scale(self.axis, dot(x, self.axis)))
    }
}

/// Add the tube along `sign`·y whose root is the patch at ring index `i0` of the outer
/// surface (cells of `region`). Returns the probe site on it: the top (+z) point of the
/// outer surface at the node layer nearest the middle, and the push direction (−z).
pub(super) fn add_tube(b: &mut HexBuild, g: &Grid, sign: f64, region: i32, i0: usize) -> (V3, V3) {
    let p = g.p;
    let pp = p.patch;
    let r0 = p.n_cap - pp / 2;
    let root = |a: usize, c: usize| g.wall_id(g.side(i0 + a, r0 + c), p.n_wall);
    let f = tube_frame(&b.nodes, &root, pp, sign);
    let dist = |k: usize| -> f64 {
        if k <= p.n_flare {
            TUBE_FLARE * k as f64 / p.n_flare as f64
        } else {
            TUBE_FLARE
                + (f.length - TUBE_FLARE) * (k - p.n_flare) as f64 / (p.n_tube - p.n_flare) as f64
        }
    };
    let ids = tube_nodes(&mut b.nodes, &f, &root, pp, p.n_tube, &dist);
    tube_cells(b, &ids, pp, region);

    let k_mid = (1..=p.n_tube)
        .min_by(|&x, &y| {
            (dist(x) - 0.5 * f.length)
                .abs()
                .total_cmp(&(dist(y) - 0.5 * f.length).abs())
        })
        .unwrap_or(p.n_tube);
    let centre = add(f.origin, scale(f.axis, dist(k_mid)));
    // +z, made exactly perpendicular to the axis.
    let up = unit(f.flatten([0.0, 0.0, 1.0]));
    (add(centre, scale(up, TUBE_R_OUT)), scale(up, -1.0))
}

/// The frame of a tube from its root patch (`root(a, b)`: node id of patch node (a, b)).
fn tube_frame(nodes: &[V3], root: &dyn Fn(usize, usize) -> u32, pp: usize, sign: f64) -> TubeFrame {
    let half = pp / 2;
    let pos = |id: u32| nodes[id as usize];
    let axis = [0.0, sign, 0.0];
    let origin = scale(
        [half, half + 1]
            .iter()
            .flat_map(|&a| [half, half + 1].map(|b| pos(root(a, b))))
            .fold([0.0; 3], add),
        0.25,
    );
    let length = TUBE_END_Y - sign * origin[1];
    let mut f = TubeFrame {
        origin,
        axis,
        ea: [0.0; 3],
        eb: [0.0; 3],
        length,
    };
    let mut ea = [0.0; 3];
    let mut eb = [0.0; 3];
    for k in 0..=pp {
        ea = add(ea, sub(pos(root(pp, k)), pos(root(0, k))));
        eb = add(eb, sub(pos(root(k, pp)), pos(root(k, 0))));
    }
    f.ea = unit(f.flatten(ea));
    f.eb = unit(f.flatten(sub(eb, scale(f.ea, dot(eb, f.ea)))));
    f
}

/// The node ids of the tube, `ids[k][a][b]` for layer k (0: the root patch) and patch node
/// (a, b); adds the nodes of layers 1.. to `nodes`. Layer k lies at `dist(k)` along the
/// axis, blended from the root patch to the annulus over the flare.
fn tube_nodes(
    nodes: &mut Vec<V3>,
    f: &TubeFrame,
    root: &dyn Fn(usize, usize) -> u32,
    pp: usize,
    n_tube: usize,
    dist: &dyn Fn(usize) -> f64,
) -> Vec<Vec<Vec<u32>>> {
    let half = pp / 2;
    let tan = tan_quarter;
    let mut ids = vec![vec![vec![0u32; pp + 1]; pp + 1]; n_tube + 1];
    for (a, col) in ids[0].iter_mut().enumerate() {
        for (b, id) in col.iter_mut().enumerate() {
            *id = root(a, b);
        }
    }
    for (k, layer) in ids.iter_mut().enumerate().skip(1) {
        let d = dist(k);
        let beta = (1.0 - d / TUBE_FLARE).max(0.0).powi(2);
        for (a, col) in layer.iter_mut().enumerate() {
            for (b, id) in col.iter_mut().enumerate() {
                let x = a as f64 - pp as f64 / 2.0;
                let y = b as f64 - pp as f64 / 2.0;
                let rho = x.abs().max(y.abs());
                let rad = TUBE_R_IN + (rho - 0.5) / half as f64 * (TUBE_R_OUT - TUBE_R_IN);
                let phi = tan(y / rho).atan2(tan(x / rho));
                let circle = add(
                    f.origin,
                    add(scale(f.ea, rad * phi.cos()), scale(f.eb, rad * phi.sin())),
                );
                let rootp = nodes[root(a, b) as usize];
                let q = add(
                    scale(f.axis, d),
                    add(scale(rootp, beta), scale(circle, 1.0 - beta)),
                );
                *id = nodes.len() as u32;
                nodes.push(q);
            }
        }
    }
    ids
}

/// The cells between consecutive layers of `ids`, the centre quad left out as the lumen.
fn tube_cells(b: &mut HexBuild, ids: &[Vec<Vec<u32>>], pp: usize, region: i32) {
    let half = pp / 2;
    for k in 0..ids.len() - 1 {
        for qa in 0..pp {
            for qb in 0..pp {
                if qa == half && qb == half {
                    continue; // the lumen
                }
                let (l0, l1) = (&ids[k], &ids[k + 1]);
                b.cells.push([
                    l0[qa][qb],
                    l0[qa + 1][qb],
                    l0[qa + 1][qb + 1],
                    l0[qa][qb + 1],
                    l1[qa][qb],
                    l1[qa + 1][qb],
                    l1[qa + 1][qb + 1],
                    l1[qa][qb + 1],
                ]);
                b.regions.push(region);
            }
        }
    }
}
