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

use std::path::Path;

use anyhow::{anyhow, bail, Result};
use plotters::prelude::*;

mod paint;
mod project;
#[cfg(test)]
mod tests;

use paint::draw;
#[cfg(test)]
use paint::{tick_label, ticks};
use project::{prepare, Layout, Projector};

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
