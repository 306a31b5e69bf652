//! The `pe` command line as a user meets it: every subcommand's help shows an example, and
//! `pe solve`'s outputs (console summary, nodes CSV, ParaView frames) follow the stated
//! conventions: the frames' points are the reference positions with the motion in
//! `displacement_m` (the nodes CSV's displacement, not twice it), units in the names, the
//! tool force printed when the scene has tools and the prescribed reaction only when it has
//! prescribed nodes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use host_tools::output::vtk;

const PE: &str = env!("CARGO_BIN_EXE_pe");

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pe-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs `pe ARGS`; its stdout, or a panic with its stderr.
fn pe(args: &[&str]) -> String {
    let out = Command::new(PE).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "pe {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The subcommand names a clap help text lists under `Commands:` (without `help`).
fn subcommands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_string)
        .collect()
}

/// `pe --help` and every subcommand's `--help` show at least one example invocation, and
/// each example names the command it documents.
#[test]
fn every_help_has_an_example() {
    let top = pe(&["--help"]);
    assert!(top.contains("Example"), "{top}");
    let subs = subcommands(&top);
    // The thirteen subcommands of pe (a list that came back empty would prove nothing).
    assert_eq!(subs.len(), 13, "{subs:?}");
    for sub in &subs {
        let help = pe(&[sub, "--help"]);
        assert!(
            help.contains("Example"),
            "pe {sub} --help has no example:\n{help}"
        );
        assert!(
            help.contains(&format!("pe {sub} ")),
            "pe {sub}'s example does not run pe {sub}:\n{help}"
        );
    }
}

/// A frame read back: the points and the point arrays by name (flattened), and the text.
struct Frame {
    points: Vec<f64>,
    arrays: BTreeMap<String, Vec<f64>>,
    text: String,
}

fn read_frame(path: &Path) -> Frame {
    use vtkio::model::{Attribute, DataSet, Piece};
    let vtk = vtkio::Vtk::import(path).unwrap();
    let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
        panic!("{}: not an unstructured grid", path.display())
    };
    let Some(Piece::Inline(p)) = pieces.into_iter().next() else {
        panic!("{}: no inline piece", path.display())
    };
    let arrays = p
        .data
        .point
        .iter()
        .filter_map(|a| match a {
            Attribute::DataArray(d) => {
                Some((d.name.clone(), d.data.clone().cast_into::<f64>().unwrap()))
            }
            _ => None,
        })
        .collect();
    Frame {
        points: p.points.cast_into::<f64>().unwrap(),
        arrays,
        text: std::fs::read_to_string(path).unwrap(),
    }
}

/// The nodes CSV: its header (with units) and the rows' numbers (x_m .. uz_m).
fn read_nodes_csv(path: &Path) -> Vec<[f64; 6]> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some(host_tools::output::NODES_CSV_HEADER.join(",").as_str())
    );
    assert_eq!(
        host_tools::output::NODES_CSV_HEADER.join(","),
        "node,x_m,y_m,z_m,ux_m,uy_m,uz_m"
    );
    lines
        .map(|l| {
            let f: Vec<f64> = l.split(',').skip(1).map(|v| v.parse().unwrap()).collect();
            assert_eq!(f.len(), 6, "{l}");
            core::array::from_fn(|i| f[i])
        })
        .collect()
}

/// `pe solve` of a scene with prescribed nodes and no tools (tests/scenes/node_kinds.toml:
/// the upper block's top pushed down 0.3 mm over 0.1 s, the lower block's base fixed):
/// - the summary prints the prescribed reaction (non-zero: the push) and no tool line;
/// - every frame's points are the reference positions, which are the nodes CSV's x_m..z_m
///   (bit for bit: both are written shortest-round-trip or with 17 digits);
/// - the last frame's `displacement_m` is the nodes CSV's ux_m..uz_m bit for bit (the
///   motion is written once; it is far from zero: the push moves the top 0.3 mm);
/// - `velocity_m_per_s` of the prescribed nodes is the path's slope, [0, 0, -3 mm/s],
///   while the push lasts (relative 1e-9: `(u_n − u_{n−1})/dt` of a linear path in f64 is
///   exact to round-off of ~1e-13) and zero once it holds (t > 0.1 s), and the fixed
///   nodes' velocity is zero in every frame; the rest frame is zero everywhere.
#[test]
fn solve_frames_are_reference_points_with_displacement_and_velocity() {
    let d = temp_dir("solve");
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/scenes/node_kinds.toml");
    let (frames, nodes) = (d.join("frames"), d.join("nodes.csv"));
    let stdout = pe(&[
        "solve",
        scene.to_str().unwrap(),
        "--quiet",
        "--vtk",
        frames.to_str().unwrap(),
        "--output-nodes",
        nodes.to_str().unwrap(),
    ]);
    assert!(
        stdout.contains("prescribed reaction (25 prescribed nodes"),
        "{stdout}"
    );
    assert!(
        !stdout.contains("tool "),
        "no tools in this scene: {stdout}"
    );

    let rows = read_nodes_csv(&nodes);
    assert_eq!(rows.len(), 250);
    let reference: Vec<f64> = rows.iter().flat_map(|r| r[..3].to_vec()).collect();
    let u_final: Vec<f64> = rows.iter().flat_map(|r| r[3..].to_vec()).collect();
    let u_max = u_final.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(u_max > 2e-4, "the push moved the top: max |u| = {u_max}");

    let pvd = std::fs::read_to_string(frames.join("series.pvd")).unwrap();
    let times: Vec<f64> = pvd
        .lines()
        .filter_map(|l| l.split("timestep=\"").nth(1))
        .map(|r| r.split('"').next().unwrap().parse().unwrap())
        .collect();
    assert!(
        times.len() >= 4,
        "rest, pushing and holding frames: {times:?}"
    );
    assert!(times.iter().any(|&t| t > 0.0 && t < 0.1) && times.iter().any(|&t| t > 0.1));
    let prescribed: Vec<usize> = (0..rows.len()).filter(|&n| rows[n][2] >= 0.01009).collect();
    let fixed: Vec<usize> = (0..rows.len()).filter(|&n| rows[n][2] <= 1e-9).collect();
    assert_eq!((prescribed.len(), fixed.len()), (25, 25));
    for (f, &t) in times.iter().enumerate() {
        let fr = read_frame(&frames.join(format!("frame_{f:05}.vtu")));
        assert_eq!(fr.points, reference, "frame {f}: points are the reference");
        let names: Vec<&str> = fr.arrays.keys().map(String::as_str).collect();
        assert_eq!(names, [vtk::DISPLACEMENT, vtk::VELOCITY], "frame {f}");
        let (u, v) = (&fr.arrays[vtk::DISPLACEMENT], &fr.arrays[vtk::VELOCITY]);
        assert_eq!((u.len(), v.len()), (750, 750));
        let regions = vtk::region_names(&fr.text).unwrap();
        let regions: Vec<&str> = regions.values().map(String::as_str).collect();
        assert_eq!(regions, ["lower", "upper"], "frame {f}");
        if f == 0 {
            assert!(u.iter().chain(v).all(|&x| x == 0.0), "the rest frame");
            continue;
        }
        let slope = if t < 0.1 { -0.0003 / 0.1 } else { 0.0 };
        for &n in &prescribed {
            let vn = &v[3 * n..3 * n + 3];
            assert!(
                vn[0].abs() <= 1e-12 && vn[1].abs() <= 1e-12,
                "node {n}: {vn:?}"
            );
            assert!(
                (vn[2] - slope).abs() <= 1e-9 * 0.003,
                "frame {f} (t = {t}) node {n}: vz = {} against {slope}",
                vn[2]
            );
        }
        for &n in &fixed {
            assert_eq!(&v[3 * n..3 * n + 3], [0.0; 3], "fixed node {n}");
        }
    }
    let last = read_frame(&frames.join(format!("frame_{:05}.vtu", times.len() - 1)));
    assert_eq!(last.arrays[vtk::DISPLACEMENT], u_final);
    let _ = std::fs::remove_dir_all(&d);
}

/// `pe solve --builtin` (a scene with a tool, the probe, and no prescribed nodes) prints
/// the probe's force at the end and its peak, non-zero after it touches the tube (about
/// 800 steps in), and no prescribed reaction (there is none to print).
#[test]
fn solve_summary_prints_tool_forces() {
    let stdout = pe(&[
        "solve",
        "--builtin",
        "--level",
        "coarse",
        "--steps",
        "1500",
        "--quiet",
    ]);
    assert!(!stdout.contains("prescribed reaction"), "{stdout}");
    let line = stdout
        .lines()
        .find(|l| l.contains("tool \"probe\": force of the tissue at the end"))
        .unwrap_or_else(|| panic!("no probe force line: {stdout}"));
    let peak: f64 = line
        .split("peak |F| = ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no peak in {line}"));
    assert!(peak > 1e-5, "the probe touched the tube: {line}");
}

/// `pe compile ... | head`: a standard output closed before pe writes its report ends pe
/// quietly by SIGPIPE, as any Unix tool, and not with a panic and a backtrace on stderr.
#[cfg(unix)]
#[test]
fn a_closed_stdout_ends_pe_quietly() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::Stdio;
    let d = temp_dir("sigpipe");
    let mut child = Command::new(PE)
        .args([
            "compile",
            "--builtin",
            "--level",
            "coarse",
            "--boards",
            "2x2x2",
            "-o",
        ])
        .arg(&d)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("pe runs");
    // The reader goes away before pe has written anything.
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("pe ends");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "pe panicked:\n{stderr}");
    assert_eq!(
        out.status.signal(),
        Some(libc::SIGPIPE),
        "pe ends by SIGPIPE, not {:?}:\n{stderr}",
        out.status
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// `PE_ISA` caps the element loop's registers (how an AVX-512 machine measures what an AVX2
/// laptop runs): with `PE_ISA=avx` the report's kernel is never an AVX-512 one, and with
/// `portable` it is the portable lanes; a value naming no instruction set is refused before
/// work, naming the variable and the known values.
#[test]
fn pe_isa_caps_the_lanes() {
    let dir = temp_dir("isa");
    let kernel = |isa: &str| {
        let report = dir.join(format!("{isa}.json"));
        let out = Command::new(PE)
            .env("PE_ISA", isa)
            .args([
                "solve",
                "--builtin",
                "--level",
                "coarse",
                "--steps",
                "20",
                "--quiet",
            ])
            .arg("--report")
            .arg(&report)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
        r["kernel"].as_str().unwrap().to_string()
    };
    let avx = kernel("avx");
    assert!(!avx.is_empty() && !avx.contains("avx512"), "{avx}");
    let portable = kernel("portable");
    assert!(portable.ends_with("portable"), "{portable}");
    let out = Command::new(PE)
        .env("PE_ISA", "sse9")
        .args(["solve", "--builtin", "--level", "coarse", "--steps", "20"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("PE_ISA") && err.contains("avx512"), "{err}");
}

/// `pe bench` names the CPU and its lanes, times the box and the built-in medium scene
/// (the general kernel and contact), and its figures are consistent: a positive ns per
/// element-step in every row, the medium scene's 2192 elements, a positive contact cost
/// per step (the probe's tests run every step, touching or not), and no more steps in
/// contact than steps timed.
#[test]
fn bench_times_the_box_and_the_builtin_scene_with_its_contact() {
    let out = pe(&[
        "bench",
        "--elements",
        "16",
        "--seconds",
        "0.05",
        "--runs",
        "1",
        "--integration",
        "reduced",
        "--precision",
        "f64",
        "--threads",
        "1",
    ]);
    assert!(out.starts_with("CPU: "), "{out}");
    assert!(out.contains("element loops: "), "{out}");
    let rows: Vec<Vec<&str>> = out
        .lines()
        .filter(|l| l.starts_with("reduced  f64"))
        .map(|l| l.split_whitespace().collect())
        .collect();
    assert_eq!(rows.len(), 2, "the box and the built-in scene: {out}");
    for r in &rows {
        let ns: f64 = r[4].parse().unwrap();
        assert!(ns > 0.0 && ns.is_finite(), "{r:?}");
    }
    let (bx, anatomy) = (&rows[0], &rows[1]);
    assert_eq!(bx[2], "16", "{bx:?}");
    assert_eq!(anatomy[2], "2192", "{anatomy:?}");
    // integr. prec. elements threads ns (min .. max) steps contact touching "steps"
    let steps: u64 = anatomy[8].parse().unwrap();
    let contact_us: f64 = anatomy[9].parse().unwrap();
    let touching: u64 = anatomy[10].parse().unwrap();
    assert!(steps >= 16 && contact_us > 0.0, "{anatomy:?}");
    assert!(touching <= steps, "{anatomy:?}");
}
