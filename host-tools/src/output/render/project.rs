//! The projection and the painter's order: the camera that fits the surface to the image,
//! the layout, and the depth-sorted primitives (shaded quads, tool pieces).

use std::collections::HashMap;

use super::{
    colormap, finite3, ipt, rgb, Prepared, Prim, SurfaceImage, View, GROUP_COLOURS, MAX_SIDE,
    MIN_SIDE,
};
use crate::geom::{cross, dot, sub};

/// Orthographic camera: world point -> (pixel x, pixel y) and depth (larger is nearer).
#[derive(Clone, Copy, Debug)]
pub(super) struct Projector {
    pub(super) dir: [f64; 3],
    pub(super) right: [f64; 3],
    pub(super) up: [f64; 3],
    pub(super) scale: f64,
    pub(super) u_c: f64,
    pub(super) v_c: f64,
    pub(super) cx: f64,
    pub(super) cy: f64,
}

impl Projector {
    fn basis(view: View) -> ([f64; 3], [f64; 3], [f64; 3]) {
        let (az, el) = (
            view.azimuth_deg.to_radians(),
            view.elevation_deg.to_radians(),
        );
        let dir = [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()];
        // Always a unit vector orthogonal to dir, also when looking straight down.
        let right = [-az.sin(), az.cos(), 0.0];
        let up = cross(dir, right);
        (dir, right, up)
    }

    pub(super) fn px(&self, p: [f64; 3]) -> (f64, f64) {
        let u = dot(p, self.right);
        let v = dot(p, self.up);
        (
            self.cx + (u - self.u_c) * self.scale,
            self.cy - (v - self.v_c) * self.scale,
        )
    }

    fn depth(&self, p: [f64; 3]) -> f64 {
        dot(p, self.dir)
    }
}

/// Where things go on the image, pixels.
#[derive(Clone, Copy, Debug)]
pub(super) struct Layout {
    pub(super) w: i32,
    pub(super) h: i32,
    pub(super) title_font: u32,
    pub(super) label_font: u32,
    /// The plot area is rows `plot_top..plot_bottom`, all columns.
    pub(super) plot_top: i32,
    pub(super) plot_bottom: i32,
    pub(super) bar_top: i32,
    pub(super) bar_h: i32,
    pub(super) bar_x0: i32,
    pub(super) bar_x1: i32,
}

impl Layout {
    fn new(w: u32, h: u32, has_title: bool) -> Layout {
        let (w, h) = (w as i32, h as i32);
        let s = w.min(h) as f64;
        let title_font = (s / 28.0).round().clamp(10.0, 36.0) as u32;
        let label_font = (s / 40.0).round().clamp(9.0, 24.0) as u32;
        let plot_top = if has_title {
            (title_font as f64 * 1.8).round() as i32
        } else {
            (0.02 * s).round() as i32
        };
        let pad = (0.02 * s).round().max(4.0) as i32;
        let bar_h = (s / 40.0).round().clamp(8.0, 24.0) as i32;
        let block = pad
            + bar_h
            + 4
            + (label_font as f64 * 1.3).round() as i32
            + (label_font as f64 * 1.5).round() as i32
            + pad;
        let plot_bottom = h - block;
        Layout {
            w,
            h,
            title_font,
            label_font,
            plot_top,
            plot_bottom,
            bar_top: plot_bottom + pad,
            bar_h,
            bar_x0: (0.2 * w as f64).round() as i32,
            bar_x1: (0.8 * w as f64).round() as i32,
        }
    }
}

/// Checks the input and builds the depth-sorted primitives; errors are plain messages.
pub(super) fn prepare(img: &SurfaceImage<'_>) -> std::result::Result<Prepared, String> {
    let drawn = check_input(img)?;
    let (proj, layout, vmax) = fit(img, &drawn)?;
    let mut prims: Vec<(f64, Prim)> = Vec::with_capacity(drawn.len() + 64);
    quad_prims(img, &drawn, &proj, vmax, &mut prims);
    tool_prims(img, &proj, &layout, &mut prims);
    prims.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(Prepared {
        layout,
        proj,
        prims,
        vmax,
    })
}

/// Checks sizes, counts, angles, the value scale, the tools and the node indices; returns
/// the quads to draw (those whose nodes all have finite positions, at least one).
fn check_input(img: &SurfaceImage<'_>) -> std::result::Result<Vec<usize>, String> {
    let (w, h) = img.size_px;
    if !(MIN_SIDE..=MAX_SIDE).contains(&w) || !(MIN_SIDE..=MAX_SIDE).contains(&h) {
        return Err(format!(
            "image size {w}x{h} px is outside {MIN_SIDE}..={MAX_SIDE} px per side"
        ));
    }
    if img.positions.is_empty() {
        return Err("no node positions".into());
    }
    if img.quads.is_empty() {
        return Err("no surface quads".into());
    }
    if img.quad_groups.len() != img.quads.len() {
        return Err(format!(
            "quad_groups has {} entries, expected {} (one per quad)",
            img.quad_groups.len(),
            img.quads.len()
        ));
    }
    if img.node_values.len() != img.positions.len() {
        return Err(format!(
            "node_values has {} entries, expected {} (one per node position)",
            img.node_values.len(),
            img.positions.len()
        ));
    }
    if !img.view.azimuth_deg.is_finite() || !img.view.elevation_deg.is_finite() {
        return Err(format!("view angles {:?} are not finite", img.view));
    }
    if !(img.value_scale.is_finite() && img.value_scale > 0.0) {
        return Err(format!(
            "value_scale {} is not a positive finite number",
            img.value_scale
        ));
    }
    for (i, t) in img.tools.iter().enumerate() {
        if !(finite3(&t.a) && finite3(&t.b) && t.radius_m.is_finite() && t.radius_m >= 0.0) {
            return Err(format!(
                "tool {i} has a non-finite end point or a negative/non-finite radius: {t:?}"
            ));
        }
    }
    let n = img.positions.len();
    for (qi, q) in img.quads.iter().enumerate() {
        if let Some(&bad) = q.iter().find(|&&v| v as usize >= n) {
            return Err(format!(
                "quad {qi} refers to node {bad}, but there are {n} node positions"
            ));
        }
    }
    // Indices are in range from here on.
    let node = |v: u32| img.positions[v as usize];
    let drawn: Vec<usize> = (0..img.quads.len())
        .filter(|&qi| img.quads[qi].iter().all(|&v| finite3(&node(v))))
        .collect();
    if drawn.is_empty() {
        return Err("every quad has a node with a non-finite position".into());
    }
    Ok(drawn)
}

/// The camera that fits the drawn quads into the plot area with a margin, the layout, and
/// the upper end of the colour scale.
fn fit(
    img: &SurfaceImage<'_>,
    drawn: &[usize],
) -> std::result::Result<(Projector, Layout, f64), String> {
    let (w, h) = img.size_px;
    let node = |v: u32| img.positions[v as usize];
    let (dir, right, up) = Projector::basis(img.view);
    let (mut u0, mut u1, mut v0, mut v1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let mut vmax = 0.0f64;
    for &qi in drawn {
        for &v in &img.quads[qi] {
            let p = node(v);
            let (u, w) = (dot(p, right), dot(p, up));
            u0 = u0.min(u);
            u1 = u1.max(u);
            v0 = v0.min(w);
            v1 = v1.max(w);
            let val = img.node_values[v as usize];
            if val.is_finite() {
                vmax = vmax.max(val);
            }
        }
    }
    let top = vmax * img.value_scale;
    if !(vmax > 0.0 && top > 0.0 && top.is_finite()) {
        // Nothing to scale by (e.g. the undeformed frame): the bar runs from 0 to 1.
        vmax = 1.0 / img.value_scale;
    }
    let layout = Layout::new(w, h, !img.title.is_empty());
    let area_w = layout.w as f64;
    let area_h = (layout.plot_bottom - layout.plot_top) as f64;
    if area_h < 16.0 {
        return Err(format!("image size {w}x{h} px leaves no room for the plot"));
    }
    let margin = 0.06 * area_w.min(area_h) + 4.0;
    let (du, dv) = (u1 - u0, v1 - v0);
    let mut scale = f64::INFINITY;
    if du > 0.0 {
        scale = scale.min((area_w - 2.0 * margin) / du);
    }
    if dv > 0.0 {
        scale = scale.min((area_h - 2.0 * margin) / dv);
    }
    if !scale.is_finite() || !(scale > 0.0) {
        // A surface that projects to a point (or spans beyond f64): any scale will do.
        scale = 1.0;
    }
    let proj = Projector {
        dir,
        right,
        up,
        scale,
        u_c: 0.5 * (u0 + u1),
        v_c: 0.5 * (v0 + v1),
        cx: 0.5 * area_w,
        cy: layout.plot_top as f64 + 0.5 * area_h,
    };
    Ok((proj, layout, vmax))
}

/// For each edge (smaller node id first) whether it separates quads of two groups.
fn group_boundaries(img: &SurfaceImage<'_>, drawn: &[usize]) -> HashMap<(u32, u32), (u8, bool)> {
    let mut edge_groups: HashMap<(u32, u32), (u8, bool)> = HashMap::new();
    for &qi in drawn {
        let q = img.quads[qi];
        let g = img.quad_groups[qi];
        for k in 0..4 {
            let (a, b) = (q[k], q[(k + 1) % 4]);
            let key = (a.min(b), a.max(b));
            edge_groups
                .entry(key)
                .and_modify(|e| e.1 |= e.0 != g)
                .or_insert((g, false));
        }
    }
    edge_groups
}

/// One shaded, coloured quad primitive per drawn quad.
fn quad_prims(
    img: &SurfaceImage<'_>,
    drawn: &[usize],
    proj: &Projector,
    vmax: f64,
    prims: &mut Vec<(f64, Prim)>,
) {
    let node = |v: u32| img.positions[v as usize];
    let edge_groups = group_boundaries(img, drawn);
    for &qi in drawn {
        let q = img.quads[qi];
        let p = [node(q[0]), node(q[1]), node(q[2]), node(q[3])];
        let nrm = cross(sub(p[2], p[0]), sub(p[3], p[1]));
        let len = dot(nrm, nrm).sqrt();
        let lambert = if len > 0.0 && len.is_finite() {
            (dot(nrm, proj.dir) / len).abs().min(1.0)
        } else {
            0.0
        };
        let shade = 0.35 + 0.65 * lambert;
        let mean = q.iter().map(|&v| img.node_values[v as usize]).sum::<f64>() / 4.0;
        let base = if mean.is_finite() {
            colormap(mean / vmax)
        } else {
            GROUP_COLOURS[img.quad_groups[qi] as usize % GROUP_COLOURS.len()]
        };
        let fill = rgb(base, shade);
        let pts2: Vec<(f64, f64)> = p.iter().map(|&x| proj.px(x)).collect();
        let perimeter: f64 = (0..4)
            .map(|k| {
                let (a, b) = (pts2[k], pts2[(k + 1) % 4]);
                ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt()
            })
            .sum();
        let edge = if perimeter / 4.0 >= 12.0 {
            rgb(base, shade * 0.6)
        } else {
            fill
        };
        let mut group_edges = [false; 4];
        for (k, ge) in group_edges.iter_mut().enumerate() {
            let (a, b) = (q[k], q[(k + 1) % 4]);
            *ge = edge_groups.get(&(a.min(b), a.max(b))).is_some_and(|e| e.1);
        }
        let depth = p.iter().map(|&x| proj.depth(x)).sum::<f64>() / 4.0;
        let ip = |k: usize| ipt(pts2[k].0, pts2[k].1);
        prims.push((
            depth,
            Prim::Quad {
                pts: [ip(0), ip(1), ip(2), ip(3)],
                fill,
                edge,
                group_edges,
            },
        ));
    }
}

/// Tools: clipped to (a neighbourhood of) the image, then cut into pieces short enough to
/// sort sensibly among the quads and to keep the rasterizer's work bounded.
fn tool_prims(
    img: &SurfaceImage<'_>,
    proj: &Projector,
    layout: &Layout,
    prims: &mut Vec<(f64, Prim)>,
) {
    let max_side = layout.w.max(layout.h) as f64;
    for t in img.tools {
        let r = (t.radius_m * proj.scale).min(2.0 * max_side);
        let (pa, pb) = (proj.px(t.a), proj.px(t.b));
        let Some((t0, t1)) = clip_segment(
            pa,
            pb,
            (-r - 2.0, -r - 2.0),
            (layout.w as f64 + r + 2.0, layout.h as f64 + r + 2.0),
        ) else {
            continue;
        };
        let at = |s: f64| {
            [
                t.a[0] + s * (t.b[0] - t.a[0]),
                t.a[1] + s * (t.b[1] - t.a[1]),
                t.a[2] + s * (t.b[2] - t.a[2]),
            ]
        };
        let (ca, cb) = (proj.px(at(t0)), proj.px(at(t1)));
        let len = ((cb.0 - ca.0).powi(2) + (cb.1 - ca.1).powi(2)).sqrt();
        let pieces = (len / r.max(4.0))
            .max(len / (0.25 * max_side))
            .ceil()
            .clamp(1.0, 512.0) as usize;
        for k in 0..pieces {
            let s0 = t0 + (t1 - t0) * k as f64 / pieces as f64;
            let s1 = t0 + (t1 - t0) * (k + 1) as f64 / pieces as f64;
            let depth = proj.depth(at(0.5 * (s0 + s1)));
            prims.push((
                depth,
                Prim::ToolPiece {
                    a: proj.px(at(s0)),
                    b: proj.px(at(s1)),
                    r,
                    cap_a: k == 0,
                    cap_b: k + 1 == pieces,
                },
            ));
        }
    }
}

/// The parameter range of segment a-b inside the rectangle lo-hi (Liang-Barsky), if any.
fn clip_segment(
    a: (f64, f64),
    b: (f64, f64),
    lo: (f64, f64),
    hi: (f64, f64),
) -> Option<(f64, f64)> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, a.0 - lo.0),
        (dx, hi.0 - a.0),
        (-dy, a.1 - lo.1),
        (dy, hi.1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then_some((t0, t1))
}
