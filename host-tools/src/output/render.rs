//! PNG snapshots of a deformed organ surface, drawn with `plotters` (no system fonts:
//! DejaVu Sans is registered as "sans-serif", see [`crate::output::font`]).
//!
//! Orthographic projection along the view direction (world z is "up" on the image), the
//! surface fitted to the image with a margin, quads painted far to near by mean depth, each
//! filled with a viridis-like colour of its mean node value over `[0, max]` and shaded by
//! Lambert `|n·view|` (0.35 ambient + 0.65 diffuse). Boundaries between quad groups are drawn
//! as dark lines, quads large on screen get thin darker edges. Tool capsules are drawn grey,
//! cut into short pieces that take part in the depth sort so that the tissue hides them where
//! it is in front. A colour bar (values × `value_scale`) runs along the bottom, the title
//! along the top.

use std::collections::HashMap;
use std::path::Path;

use crate::geom::{cross, dot, sub};
use anyhow::{anyhow, bail, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// A view direction: the camera looks along -dir (from azimuth/elevation in degrees).
///
/// `dir = (cos el · cos az, cos el · sin az, sin el)`: azimuth is measured in the x-y plane
/// from +x towards +y, elevation from that plane towards +z. World +z points up on the
/// image, so `View { azimuth_deg: 0.0, elevation_deg: 0.0 }` looks at the +x side with +y
/// to the right.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
}

/// A rigid capsule tool to overlay (segment a-b, radius), metres.
#[derive(Clone, Copy, Debug)]
pub struct CapsuleOverlay {
    pub a: [f64; 3],
    pub b: [f64; 3],
    pub radius_m: f64,
}

/// Everything [`render_surface_png`] draws.
pub struct SurfaceImage<'a> {
    /// Deformed positions of ALL nodes (indexed by node id).
    pub positions: &'a [[f64; 3]],
    /// Surface quads (node ids), outward-oriented or not.
    pub quads: &'a [[u32; 4]],
    /// Per quad: a group (tissue/region) index. Boundaries between groups are drawn as dark
    /// lines; a quad whose value is not finite is filled with its group's base colour.
    pub quad_groups: &'a [u8],
    /// Per node scalar (e.g. displacement magnitude, m) for colour.
    pub node_values: &'a [f64],
    /// E.g. "displacement (mm)" for the colour bar.
    pub value_label: &'a str,
    /// Multiply values by this for the colour bar labels (e.g. 1e3 for mm).
    pub value_scale: f64,
    pub tools: &'a [CapsuleOverlay],
    pub title: &'a str,
    pub view: View,
    pub size_px: (u32, u32),
}

/// Smallest and largest accepted image side, pixels.
const MIN_SIDE: u32 = 128;
const MAX_SIDE: u32 = 8192;
const BACKGROUND: RGBColor = WHITE;
/// A tool is drawn as nested bands by distance from its axis (fraction of the radius):
/// dark rim, grey body, light highlight along the axis.
const TOOL_BANDS: [(f64, RGBColor); 3] = [
    (1.0, RGBColor(95, 97, 102)),
    (0.8, RGBColor(158, 160, 166)),
    (0.3, RGBColor(212, 214, 218)),
];
const GROUP_LINE: RGBColor = RGBColor(25, 25, 25);

/// Viridis at t = 0, 1/8, ..., 1.
const VIRIDIS: [[f64; 3]; 9] = [
    [68.0, 1.0, 84.0],
    [71.0, 44.0, 122.0],
    [59.0, 81.0, 139.0],
    [44.0, 113.0, 142.0],
    [33.0, 144.0, 141.0],
    [39.0, 173.0, 129.0],
    [92.0, 200.0, 99.0],
    [170.0, 220.0, 50.0],
    [253.0, 231.0, 37.0],
];

/// Base colours of quad groups (Tableau 10), used modulo their number.
const GROUP_COLOURS: [[f64; 3]; 10] = [
    [78.0, 121.0, 167.0],
    [242.0, 142.0, 43.0],
    [225.0, 87.0, 89.0],
    [118.0, 183.0, 178.0],
    [89.0, 161.0, 79.0],
    [237.0, 201.0, 72.0],
    [176.0, 122.0, 161.0],
    [255.0, 157.0, 167.0],
    [156.0, 117.0, 95.0],
    [186.0, 176.0, 172.0],
];

/// Viridis-like colour of `t` in [0, 1] (clamped; NaN gives the t = 0 end).
fn colormap(t: f64) -> [f64; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (VIRIDIS.len() - 1) as f64;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    [
        a[0] + f * (b[0] - a[0]),
        a[1] + f * (b[1] - a[1]),
        a[2] + f * (b[2] - a[2]),
    ]
}

fn rgb(c: [f64; 3], factor: f64) -> RGBColor {
    let ch = |x: f64| (x * factor).round().clamp(0.0, 255.0) as u8;
    RGBColor(ch(c[0]), ch(c[1]), ch(c[2]))
}

fn finite3(p: &[f64; 3]) -> bool {
    p.iter().all(|x| x.is_finite())
}

/// Pixel coordinates as plotters wants them; the clamp keeps any input from overflowing.
fn ipt(x: f64, y: f64) -> (i32, i32) {
    (
        x.round().clamp(-1e7, 1e7) as i32,
        y.round().clamp(-1e7, 1e7) as i32,
    )
}

/// Orthographic camera: world point -> (pixel x, pixel y) and depth (larger is nearer).
#[derive(Clone, Copy, Debug)]
struct Projector {
    dir: [f64; 3],
    right: [f64; 3],
    up: [f64; 3],
    scale: f64,
    u_c: f64,
    v_c: f64,
    cx: f64,
    cy: f64,
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

    fn px(&self, p: [f64; 3]) -> (f64, f64) {
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
struct Layout {
    w: i32,
    h: i32,
    title_font: u32,
    label_font: u32,
    /// The plot area is rows `plot_top..plot_bottom`, all columns.
    plot_top: i32,
    plot_bottom: i32,
    bar_top: i32,
    bar_h: i32,
    bar_x0: i32,
    bar_x1: i32,
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

/// One thing to paint, in depth order.
#[derive(Clone, Debug)]
enum Prim {
    Quad {
        pts: [(i32, i32); 4],
        fill: RGBColor,
        /// Thin darker outline (quads large on screen) or an outline in the fill colour
        /// (closes the rasterizer's cracks between neighbours).
        edge: RGBColor,
        /// Edges 0-1, 1-2, 2-3, 3-0 that separate two groups.
        group_edges: [bool; 4],
    },
    /// A piece of a tool's projected segment, with a round cap where the capsule ends.
    ToolPiece {
        a: (f64, f64),
        b: (f64, f64),
        r: f64,
        cap_a: bool,
        cap_b: bool,
    },
}

struct Prepared {
    layout: Layout,
    /// The camera; the tests use it to find world points on the image.
    #[cfg_attr(not(test), allow(dead_code))]
    proj: Projector,
    /// (depth, primitive), sorted far to near.
    prims: Vec<(f64, Prim)>,
    /// Upper end of the colour scale, in value units (> 0).
    vmax: f64,
}

/// Checks the input and builds the depth-sorted primitives; errors are plain messages.
fn prepare(img: &SurfaceImage<'_>) -> std::result::Result<Prepared, String> {
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

    let (dir, right, up) = Projector::basis(img.view);
    let (mut u0, mut u1, mut v0, mut v1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let mut vmax = 0.0f64;
    for &qi in &drawn {
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

    // Edges between quads of different groups.
    let mut edge_groups: HashMap<(u32, u32), (u8, bool)> = HashMap::new();
    for &qi in &drawn {
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

    let mut prims: Vec<(f64, Prim)> = Vec::with_capacity(drawn.len() + 64);
    for &qi in &drawn {
        let q = img.quads[qi];
        let p = [node(q[0]), node(q[1]), node(q[2]), node(q[3])];
        let nrm = cross(sub(p[2], p[0]), sub(p[3], p[1]));
        let len = dot(nrm, nrm).sqrt();
        let lambert = if len > 0.0 && len.is_finite() {
            (dot(nrm, dir) / len).abs().min(1.0)
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

    // Tools: clipped to (a neighbourhood of) the image, then cut into pieces short enough
    // to sort sensibly among the quads and to keep the rasterizer's work bounded.
    let max_side = layout.w.max(layout.h) as f64;
    for t in img.tools {
        let r = (t.radius_m * scale).min(2.0 * max_side);
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
    prims.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(Prepared {
        layout,
        proj,
        prims,
        vmax,
    })
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

/// Round numbers for colour bar ticks over [0, top].
fn ticks(top: f64) -> (Vec<f64>, f64) {
    let raw = top / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let norm = raw / mag;
    let step = mag
        * if norm < 1.5 {
            1.0
        } else if norm < 3.5 {
            2.0
        } else if norm < 7.5 {
            5.0
        } else {
            10.0
        };
    let mut v = Vec::new();
    let mut k = 0u32;
    while (k as f64) * step <= top * (1.0 + 1e-9) && k <= 20 {
        v.push(k as f64 * step);
        k += 1;
    }
    (v, step)
}

fn tick_label(v: f64, step: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if !(1e-4..1e5).contains(&step) {
        return format!("{v:.1e}");
    }
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    format!("{v:.decimals$}")
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    img: &SurfaceImage<'_>,
    prep: &Prepared,
) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let l = prep.layout;
    root.fill(&BACKGROUND)?;
    for (_, prim) in &prep.prims {
        match prim {
            Prim::Quad {
                pts,
                fill,
                edge,
                group_edges,
            } => {
                root.draw(&Polygon::new(pts.to_vec(), fill.filled()))?;
                let mut ring = pts.to_vec();
                ring.push(pts[0]);
                root.draw(&PathElement::new(ring, *edge))?;
                for (k, &is_group_edge) in group_edges.iter().enumerate() {
                    if is_group_edge {
                        root.draw(&PathElement::new(
                            vec![pts[k], pts[(k + 1) % 4]],
                            GROUP_LINE.stroke_width(2),
                        ))?;
                    }
                }
            }
            Prim::ToolPiece {
                a,
                b,
                r,
                cap_a,
                cap_b,
            } => {
                let (dx, dy) = (b.0 - a.0, b.1 - a.1);
                let len = (dx * dx + dy * dy).sqrt();
                // Band k covers the points within its radius of the piece's axis, so the
                // innermost band drawn over a pixel is set by the distance to the axis and
                // the bands of neighbouring pieces join without seams. Caps are half discs
                // on the outer side so that they do not spill over the neighbouring piece.
                for (band, (frac, colour)) in TOOL_BANDS.into_iter().enumerate() {
                    let rb = (r * frac).max(1.0);
                    if len <= 0.5 {
                        let ri = rb.round() as u32;
                        root.draw(&Circle::new(ipt(a.0, a.1), ri, colour.filled()))?;
                        continue;
                    }
                    let (tx, ty) = (dx / len, dy / len);
                    let (nx, ny) = (-ty * rb, tx * rb);
                    // Longer where the piece joins the next one: no cracks between pieces,
                    // and each inner band reaches further than the band around it so that
                    // it covers the pixels the outer band's (rounded) end put over the
                    // neighbour's inner band.
                    let ext = 1.0 + 1.5 * band as f64;
                    let ea = if *cap_a { 0.0 } else { ext };
                    let eb = if *cap_b { 0.0 } else { ext };
                    let a0 = (a.0 - ea * tx, a.1 - ea * ty);
                    let b0 = (b.0 + eb * tx, b.1 + eb * ty);
                    let corners = vec![
                        ipt(a0.0 + nx, a0.1 + ny),
                        ipt(b0.0 + nx, b0.1 + ny),
                        ipt(b0.0 - nx, b0.1 - ny),
                        ipt(a0.0 - nx, a0.1 - ny),
                    ];
                    root.draw(&Polygon::new(corners, colour.filled()))?;
                    for (cap, c, sign) in [(*cap_a, a, -1.0), (*cap_b, b, 1.0)] {
                        if cap {
                            let half_disc: Vec<(i32, i32)> = (0..=24)
                                .map(|k| {
                                    let th = std::f64::consts::PI * (k as f64 / 24.0 - 0.5);
                                    let (along, across) = (sign * th.cos(), th.sin());
                                    ipt(
                                        c.0 + rb * (along * tx - across * ty),
                                        c.1 + rb * (along * ty + across * tx),
                                    )
                                })
                                .collect();
                            root.draw(&Polygon::new(half_disc, colour.filled()))?;
                        }
                    }
                }
            }
        }
    }
    // Title strip and colour bar block: clear whatever a tool drew there.
    root.draw(&Rectangle::new(
        [(0, 0), (l.w, l.plot_top)],
        BACKGROUND.filled(),
    ))?;
    root.draw(&Rectangle::new(
        [(0, l.plot_bottom), (l.w, l.h)],
        BACKGROUND.filled(),
    ))?;
    if !img.title.is_empty() {
        let style = ("sans-serif", l.title_font)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Top));
        root.draw(&Text::new(
            img.title,
            (l.w / 2, (l.title_font as f64 * 0.4).round() as i32),
            style,
        ))?;
    }
    // Colour bar.
    let (x0, x1) = (l.bar_x0, l.bar_x1.max(l.bar_x0 + 1));
    let (y0, y1) = (l.bar_top, l.bar_top + l.bar_h);
    for x in x0..x1 {
        let t = (x - x0) as f64 / (x1 - x0 - 1).max(1) as f64;
        root.draw(&Rectangle::new(
            [(x, y0), (x + 1, y1)],
            rgb(colormap(t), 1.0).filled(),
        ))?;
    }
    root.draw(&Rectangle::new([(x0, y0), (x1, y1)], BLACK))?;
    let top = prep.vmax * img.value_scale;
    let (tick_values, step) = ticks(top);
    let tick_style = ("sans-serif", l.label_font)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Top));
    for v in tick_values {
        let x = x0 + ((v / top) * (x1 - x0) as f64).round() as i32;
        root.draw(&PathElement::new(vec![(x, y1), (x, y1 + 4)], BLACK))?;
        root.draw(&Text::new(
            tick_label(v, step),
            (x, y1 + 5),
            tick_style.clone(),
        ))?;
    }
    if !img.value_label.is_empty() {
        root.draw(&Text::new(
            img.value_label,
            (l.w / 2, y1 + 5 + (l.label_font as f64 * 1.3).round() as i32),
            tick_style,
        ))?;
    }
    Ok(())
}

/// Render `img` to the PNG file `path` (its extension must be `.png`; the directory must
/// exist). Quads with a non-finite node position are left out; an empty or inconsistent
/// input, a node index out of range or an unwritable path is an error naming the file.
pub fn render_surface_png(path: &Path, img: &SurfaceImage<'_>) -> Result<()> {
    let is_png = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !is_png {
        bail!(
            "rendering {}: the file name must end in .png",
            path.display()
        );
    }
    let prep = prepare(img).map_err(|m| anyhow!("rendering {}: {m}", path.display()))?;
    crate::output::font::register_font();
    let err = |e: &dyn std::fmt::Display| anyhow!("rendering {}: {e}", path.display());
    let root = BitMapBackend::new(path, img.size_px).into_drawing_area();
    draw(&root, img, &prep).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::HEX_FACES;
    use std::path::PathBuf;

    /// Unit cube corners in VTK hexahedron order and its 6 faces.
    fn cube() -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
        let nodes = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
        let quads = HEX_FACES
            .iter()
            .map(|f| [f[0] as u32, f[1] as u32, f[2] as u32, f[3] as u32])
            .collect();
        (nodes, quads)
    }

    fn temp_dir(tag: &str) -> PathBuf {
        static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let k = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let d = std::env::temp_dir().join(format!("pe-render-{tag}-{}-{k}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn image<'a>(
        nodes: &'a [[f64; 3]],
        quads: &'a [[u32; 4]],
        groups: &'a [u8],
        values: &'a [f64],
        tools: &'a [CapsuleOverlay],
        view: View,
    ) -> SurfaceImage<'a> {
        SurfaceImage {
            positions: nodes,
            quads,
            quad_groups: groups,
            node_values: values,
            value_label: "displacement (mm)",
            value_scale: 1e3,
            tools,
            title: "cube",
            view,
            size_px: (320, 240),
        }
    }

    /// The RGB pixels `render_surface_png` would write, drawn into memory.
    fn render_rgb(img: &SurfaceImage<'_>) -> (Vec<u8>, Prepared) {
        let prep = prepare(img).unwrap();
        crate::output::font::register_font();
        let (w, h) = img.size_px;
        let mut buf = vec![0u8; 3 * (w * h) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            draw(&root, img, &prep).unwrap();
            root.present().unwrap();
        }
        (buf, prep)
    }

    fn pixel(buf: &[u8], w: u32, (x, y): (i32, i32)) -> [u8; 3] {
        let i = 3 * (y as usize * w as usize + x as usize);
        [buf[i], buf[i + 1], buf[i + 2]]
    }

    const ISO: View = View {
        azimuth_deg: 30.0,
        elevation_deg: 25.0,
    };
    const FROM_PLUS_X: View = View {
        azimuth_deg: 0.0,
        elevation_deg: 0.0,
    };

    #[test]
    fn cube_png_has_requested_size_and_covers_centre() {
        let (nodes, quads) = cube();
        let groups = [0, 0, 0, 1, 1, 1];
        let values: Vec<f64> = nodes.iter().map(|p| 1e-3 * p[2]).collect();
        let tools = [CapsuleOverlay {
            a: [1.2, 0.5, 1.2],
            b: [2.0, 0.5, 2.5],
            radius_m: 0.1,
        }];
        let img = image(&nodes, &quads, &groups, &values, &tools, ISO);
        let dir = temp_dir("cube");
        let path = dir.join("cube.png");
        render_surface_png(&path, &img).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.len() > 24, "PNG too short: {} bytes", bytes.len());
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
        assert_eq!(&bytes[12..16], b"IHDR", "first chunk must be IHDR");
        let w = u32::from_be_bytes([bytes[16], bytes[17], bytes[18], bytes[19]]);
        let h = u32::from_be_bytes([bytes[20], bytes[21], bytes[22], bytes[23]]);
        assert_eq!((w, h), img.size_px, "IHDR width/height");

        let (buf, _) = render_rgb(&img);
        let c = pixel(&buf, w, (w as i32 / 2, h as i32 / 2));
        assert_ne!(
            c,
            [255, 255, 255],
            "the cube is fitted around the plot area's centre, which lies within a few \
             pixels of the image centre, so the centre pixel must be painted, not background"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Looking at the +x face with values = x: the near face (value 1, full Lambert) must
    /// win over the far face (value 0) whatever order the quads come in.
    #[test]
    fn painter_order_shows_the_near_face_and_tools_in_depth_order() {
        let (nodes, quads) = cube();
        let groups = [0; 6];
        let values: Vec<f64> = nodes.iter().map(|p| p[0]).collect();
        for reversed in [false, true] {
            let mut q = quads.clone();
            if reversed {
                q.reverse();
            }
            let img = image(&nodes, &q, &groups, &values, &[], FROM_PLUS_X);
            let (buf, prep) = render_rgb(&img);
            let (x, y) = prep.proj.px([1.0, 0.5, 0.5]);
            let c = pixel(&buf, img.size_px.0, ipt(x, y));
            let top = rgb(colormap(1.0), 1.0);
            assert_eq!(
                c,
                [top.0, top.1, top.2],
                "centre of the near (+x) face must show the top colour of the map"
            );
        }
        // A tool in front of the +x face is drawn over it; one behind the cube is hidden.
        let front = [CapsuleOverlay {
            a: [1.5, 0.5, 0.5],
            b: [2.5, 0.5, 0.5],
            radius_m: 0.2,
        }];
        let behind = [CapsuleOverlay {
            a: [-1.5, 0.5, 0.5],
            b: [-0.5, 0.5, 0.5],
            radius_m: 0.2,
        }];
        for (tools, want_tool) in [(&front, true), (&behind, false)] {
            let img = image(&nodes, &quads, &groups, &values, tools, FROM_PLUS_X);
            let (buf, prep) = render_rgb(&img);
            let (x, y) = prep.proj.px([1.0, 0.5, 0.5]);
            let c = pixel(&buf, img.size_px.0, ipt(x, y));
            // Seen end-on, the tool's centre shows its innermost (highlight) band.
            let light = TOOL_BANDS[2].1;
            assert_eq!(
                c == [light.0, light.1, light.2],
                want_tool,
                "tool in front must cover the face centre, tool behind must not (pixel {c:?})"
            );
        }
    }

    #[test]
    fn bad_input_is_an_error_naming_the_file() {
        let (nodes, quads) = cube();
        let values = vec![0.0; nodes.len()];
        let dir = temp_dir("bad");
        let path = dir.join("bad.png");
        let name = path.display().to_string();

        let groups = [0u8; 5];
        let img = image(&nodes, &quads, &groups, &values, &[], ISO);
        let e = render_surface_png(&path, &img).unwrap_err().to_string();
        assert!(e.contains(&name) && e.contains("quad_groups"), "{e}");

        let groups = [0u8; 6];
        let short = &values[..7];
        let img = image(&nodes, &quads, &groups, short, &[], ISO);
        let e = render_surface_png(&path, &img).unwrap_err().to_string();
        assert!(e.contains(&name) && e.contains("node_values"), "{e}");

        let mut q = quads.clone();
        q[2][1] = 8;
        let img = image(&nodes, &q, &groups, &values, &[], ISO);
        let e = render_surface_png(&path, &img).unwrap_err().to_string();
        assert!(
            e.contains(&name) && e.contains("quad 2 refers to node 8"),
            "{e}"
        );

        let img = image(&nodes, &[], &[], &values, &[], ISO);
        let e = render_surface_png(&path, &img).unwrap_err().to_string();
        assert!(e.contains(&name) && e.contains("no surface quads"), "{e}");

        let img = image(&nodes, &quads, &groups, &values, &[], ISO);
        let missing = dir.join("no-such-dir").join("x.png");
        let e = render_surface_png(&missing, &img).unwrap_err().to_string();
        assert!(e.contains(&missing.display().to_string()), "{e}");
        let e = render_surface_png(&dir.join("x.jpg"), &img)
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.jpg") && e.contains(".png"), "{e}");
        assert!(!path.exists(), "no file is written for bad input");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// NaN positions drop their quads, NaN values and huge far-away tools do not panic.
    #[test]
    fn non_finite_data_is_skipped_not_fatal() {
        let (mut nodes, quads) = cube();
        nodes[6] = [f64::NAN, 0.0, 0.0];
        let mut values: Vec<f64> = nodes.iter().map(|p| p[2]).collect();
        values[0] = f64::NAN;
        let groups = [0, 1, 2, 3, 4, 5];
        let tools = [CapsuleOverlay {
            a: [-1e9, 0.5, 0.5],
            b: [1e9, 0.5, 0.5],
            radius_m: 0.05,
        }];
        let img = image(&nodes, &quads, &groups, &values, &tools, ISO);
        let prep = prepare(&img).unwrap();
        let n_quads = prep
            .prims
            .iter()
            .filter(|p| matches!(p.1, Prim::Quad { .. }))
            .count();
        assert_eq!(n_quads, 3, "the three faces touching node 6 are left out");
        let dir = temp_dir("nan");
        render_surface_png(&dir.join("nan.png"), &img).unwrap();
        let _ = std::fs::remove_dir_all(&dir);

        let all_nan = vec![[f64::NAN; 3]; 8];
        let img = image(&all_nan, &quads, &groups, &values, &[], ISO);
        assert!(prepare(&img).is_err());
    }

    #[test]
    fn ticks_are_round_and_cover_the_range() {
        let (t, step) = ticks(9.0);
        assert_eq!(step, 2.0);
        assert_eq!(t, [0.0, 2.0, 4.0, 6.0, 8.0]);
        let (t, step) = ticks(1.0);
        assert_eq!(step, 0.2);
        assert_eq!(t.len(), 6);
        assert_eq!(tick_label(0.4, 0.2), "0.4");
        assert_eq!(tick_label(2e-6, 1e-6), "2.0e-6");
        assert_eq!(rgb(colormap(0.0), 1.0), RGBColor(68, 1, 84));
        assert_eq!(rgb(colormap(f64::NAN), 1.0), RGBColor(68, 1, 84));
        assert_eq!(rgb(colormap(2.0), 1.0), RGBColor(253, 231, 37));
    }
}
