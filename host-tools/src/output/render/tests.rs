//! Tests of the surface renderer: projection, depth order, input checks, colour bar.

use super::*;
use std::path::PathBuf;

/// Unit cube corners in VTK hexahedron order and its 6 faces.
fn cube() -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
    crate::mesh::cube_surface(1.0)
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
