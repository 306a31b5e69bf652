//! Painting the prepared primitives with plotters: quads with their outlines and group
//! boundaries, banded tool pieces, the title and the colour bar.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{colormap, ipt, rgb, Prepared, Prim, SurfaceImage, BACKGROUND, GROUP_LINE, TOOL_BANDS};

/// Round numbers for colour bar ticks over [0, top].
pub(super) fn ticks(top: f64) -> (Vec<f64>, f64) {
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

pub(super) fn tick_label(v: f64, step: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if !(1e-4..1e5).contains(&step) {
        return format!("{v:.1e}");
    }
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    format!("{v:.decimals$}")
}

type DrawResult<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// Paint the prepared primitives far to near, then the title and the colour bar.
pub(super) fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    img: &SurfaceImage<'_>,
    prep: &Prepared,
) -> DrawResult<DB> {
    root.fill(&BACKGROUND)?;
    for (_, prim) in &prep.prims {
        match prim {
            Prim::Quad {
                pts,
                fill,
                edge,
                group_edges,
            } => draw_quad(root, pts, *fill, *edge, group_edges)?,
            Prim::ToolPiece {
                a,
                b,
                r,
                cap_a,
                cap_b,
            } => draw_tool_piece(root, *a, *b, *r, *cap_a, *cap_b)?,
        }
    }
    draw_title_and_bar(root, img, prep)
}

/// A filled quad, its outline, and its edges on a group boundary.
fn draw_quad<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    pts: &[(i32, i32); 4],
    fill: RGBColor,
    edge: RGBColor,
    group_edges: &[bool; 4],
) -> DrawResult<DB> {
    root.draw(&Polygon::new(pts.to_vec(), fill.filled()))?;
    let mut ring = pts.to_vec();
    ring.push(pts[0]);
    root.draw(&PathElement::new(ring, edge))?;
    for (k, &is_group_edge) in group_edges.iter().enumerate() {
        if is_group_edge {
            root.draw(&PathElement::new(
                vec![pts[k], pts[(k + 1) % 4]],
                GROUP_LINE.stroke_width(2),
            ))?;
        }
    }
    Ok(())
}

/// A piece of a tool in grey bands, with half-disc caps where the capsule ends.
fn draw_tool_piece<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    a: (f64, f64),
    b: (f64, f64),
    r: f64,
    cap_a: bool,
    cap_b: bool,
) -> DrawResult<DB> {
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
        let ea = if cap_a { 0.0 } else { ext };
        let eb = if cap_b { 0.0 } else { ext };
        let a0 = (a.0 - ea * tx, a.1 - ea * ty);
        let b0 = (b.0 + eb * tx, b.1 + eb * ty);
        let corners = vec![
            ipt(a0.0 + nx, a0.1 + ny),
            ipt(b0.0 + nx, b0.1 + ny),
            ipt(b0.0 - nx, b0.1 - ny),
            ipt(a0.0 - nx, a0.1 - ny),
        ];
        root.draw(&Polygon::new(corners, colour.filled()))?;
        for (cap, c, sign) in [(cap_a, a, -1.0), (cap_b, b, 1.0)] {
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
    Ok(())
}

/// The title strip and the colour bar block (cleared of whatever a tool drew there).
fn draw_title_and_bar<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    img: &SurfaceImage<'_>,
    prep: &Prepared,
) -> DrawResult<DB> {
    let l = prep.layout;
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
