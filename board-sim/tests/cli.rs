//! board-sim's command line as a user meets it: every subcommand's help shows an example,
//! and `board-sim builtin`'s outputs agree with each other (the frames the report counts
//! are the frames in series.pvd) and follow the ParaView and CSV conventions.

use std::path::{Path, PathBuf};
use std::process::Command;

use host_tools::output::vtk;

const SIM: &str = env!("CARGO_BIN_EXE_board-sim");

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("board-sim-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs `board-sim ARGS`; its stdout, or a panic with its stderr.
fn sim(args: &[&str]) -> String {
    let out = Command::new(SIM).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "board-sim {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// `board-sim --help` and every subcommand's `--help` show an example that runs it.
#[test]
fn every_help_has_an_example() {
    let top = sim(&["--help"]);
    assert!(top.contains("Example"), "{top}");
    let subs: Vec<String> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_string)
        .collect();
    // run, live, bench, campaign, qemu, builtin (an empty list would prove nothing).
    assert_eq!(
        subs,
        ["run", "live", "bench", "campaign", "qemu", "builtin"]
    );
    for sub in &subs {
        let help = sim(&[sub, "--help"]);
        assert!(help.contains("Example"), "board-sim {sub} --help:\n{help}");
        assert!(help.contains(&format!("board-sim {sub} ")), "{help}");
    }
}

/// `board-sim builtin --level coarse --steps 580`: graphics frames start every 286 steps
/// and their chunks are spread over 20 steps, so the frames of steps 0 and 286 complete
/// and the one started at step 572 cannot (it would end at step 591). The report's
/// `graphics_frames` and `paraview_frames`, the summary and series.pvd all count the two
/// complete frames (the incomplete one is reported apart), and the surface_*.vtu files are
/// those two. Each frame's points are the reference positions of the surface nodes (the
/// nodes CSV's x_m..z_m, bit for bit), the regions carry their names, and the tool force
/// CSV's header has units, one row per step and tool.
#[test]
fn builtin_frame_counts_agree_and_frames_follow_the_conventions() {
    let d = temp_dir("builtin");
    let stdout = sim(&[
        "builtin",
        "--level",
        "coarse",
        "--boards",
        "2x2x2",
        "--steps",
        "580",
        "--quiet",
        "--out",
        d.to_str().unwrap(),
    ]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("report.json")).unwrap()).unwrap();
    let g = &report["global_network"];
    let pvd = std::fs::read_to_string(d.join("frames/series.pvd")).unwrap();
    let listed = pvd.matches("<DataSet ").count();
    let mut files: Vec<String> = std::fs::read_dir(d.join("frames"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".vtu"))
        .collect();
    files.sort();
    assert_eq!(files, ["surface_00000.vtu", "surface_00001.vtu"]);
    assert_eq!(listed, 2, "{pvd}");
    assert_eq!(report["paraview_frames"].as_u64(), Some(2), "{report}");
    assert_eq!(g["graphics_frames"].as_u64(), Some(2), "{g}");
    assert_eq!(g["graphics_frames_incomplete"].as_u64(), Some(1), "{g}");
    assert!(
        stdout.contains(
            "graphics: 2 complete frames (the surface series' frames) and 1 started too close to the end"
        ),
        "{stdout}"
    );
    // Only the probe's tool force is printed (the builtin scene prescribes no nodes).
    assert!(!stdout.contains("prescribed reaction"), "{stdout}");

    // Reference positions, from the nodes CSV (header with units).
    let nodes = std::fs::read_to_string(d.join("nodes.csv")).unwrap();
    let mut lines = nodes.lines();
    assert_eq!(lines.next(), Some("node,x_m,y_m,z_m,ux_m,uy_m,uz_m"));
    let xyz: Vec<[f64; 3]> = lines
        .map(|l| {
            let f: Vec<f64> = l.split(',').skip(1).map(|v| v.parse().unwrap()).collect();
            [f[0], f[1], f[2]]
        })
        .collect();
    let scene = host_tools::scene::builtin::builtin_scene("coarse").unwrap();
    let pr = host_tools::problem::Problem::from_scene(&scene, Path::new(".")).unwrap();
    assert_eq!(xyz.len(), pr.mesh.nodes.len());
    let mask = pr.surface_node_mask();
    let surface: Vec<f64> = (0..mask.len())
        .filter(|&n| mask[n])
        .flat_map(|n| xyz[n])
        .collect();
    assert!(surface.len() > 300, "{} surface coordinates", surface.len());
    let used: std::collections::BTreeSet<i32> = pr
        .surface_face_cells
        .iter()
        .map(|&c| pr.mesh.cell_regions[c as usize])
        .collect();
    let names: std::collections::BTreeMap<i32, String> = used
        .iter()
        .map(|r| (*r, pr.mesh.region_names.get(r).cloned().unwrap_or_default()))
        .collect();
    assert!(
        names.len() >= 3 && names.values().all(|n| !n.is_empty()),
        "{names:?}"
    );
    for f in &files {
        use vtkio::model::{DataSet, Piece};
        let path = d.join("frames").join(f);
        let vtk = vtkio::Vtk::import(&path).unwrap();
        let DataSet::UnstructuredGrid { pieces, .. } = vtk.data else {
            panic!("{f}: not an unstructured grid")
        };
        let Some(Piece::Inline(p)) = pieces.into_iter().next() else {
            panic!("{f}: no inline piece")
        };
        assert_eq!(p.points.cast_into::<f64>().unwrap(), surface, "{f}");
        let arrays: Vec<&str> = p.data.point.iter().map(|a| a.name()).collect();
        assert_eq!(arrays, [vtk::DISPLACEMENT], "{f}");
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(vtk::region_names(&text).as_ref(), Some(&names), "{f}");
    }

    let forces = std::fs::read_to_string(d.join("tool_force.csv")).unwrap();
    let mut lines = forces.lines();
    assert_eq!(lines.next(), Some("step,time_s,tool,fx_n,fy_n,fz_n"));
    assert_eq!(lines.count(), 580, "one row per step for the one tool");
    let _ = std::fs::remove_dir_all(&d);
}

/// Link-model and run options are checked as they are parsed, naming the option
/// (`--link-bandwidth 0` printed NaN/inf step times with exit 0; `--steps 0` was reported as
/// lost packets; `--steps` with `--duration` let one win silently). The directory need not
/// exist: nothing is read before the options are checked.
#[test]
fn run_options_are_checked_before_work() {
    for (args, needle) in [
        (
            &["run", "nowhere", "--link-bandwidth", "0"][..],
            "--link-bandwidth",
        ),
        (
            &["run", "nowhere", "--link-bandwidth=-1e6"],
            "--link-bandwidth",
        ),
        (
            &["run", "nowhere", "--link-latency-s", "NaN"],
            "--link-latency-s",
        ),
        (&["run", "nowhere", "--steps", "0"], "--steps"),
        (&["run", "nowhere", "--duration", "0"], "--duration"),
        (&["run", "nowhere", "--workers", "0"], "--workers"),
        (
            &["run", "nowhere", "--steps", "5", "--duration", "0.1"],
            "cannot be used with",
        ),
        (&["campaign", "nowhere", "--runs", "0"], "--runs"),
    ] {
        let out = Command::new(SIM)
            .args(args)
            .env("RUST_BACKTRACE", "1")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "board-sim {args:?} was accepted");
        assert!(
            err.contains(needle),
            "board-sim {args:?}: {needle:?} not in {err}"
        );
        assert!(!err.contains("acktrace"), "board-sim {args:?}: {err}");
    }
}
