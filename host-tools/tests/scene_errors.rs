//! Bad input gets a clear error naming the file and the offending item.

use std::path::PathBuf;

mod common;

use host_tools::problem::Problem;
use host_tools::scene::Scene;

fn tmp_dir(name: &str) -> common::TempDir {
    common::temp_dir(&format!("scene-errors-{name}"))
}

fn resolve(dir: &std::path::Path, text: &str) -> anyhow::Result<Problem> {
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let scene = Scene::from_file(&path)?;
    Problem::from_scene(&scene, dir)
}

const BOX: &str = r#"
[mesh]
generate = { kind = "box", size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }
[material]
law = "neo-hookean"
youngs_modulus = 3.0e3
poisson_ratio = 0.45
density = 1000.0
"#;

fn err(dir: &std::path::Path, text: &str) -> String {
    format!(
        "{:#}",
        resolve(dir, text).expect_err("this scene must be refused")
    )
}

/// An unknown key names the file, the line and the key (a typo must not be ignored).
#[test]
fn unknown_key_is_named_with_file_and_line() {
    let d = tmp_dir("unknown");
    let e = err(
        &d,
        &format!("{BOX}[solver]\ndamping = 1.0\ndampnig = 2.0\n"),
    );
    assert!(
        e.contains("scene.toml") && e.contains("dampnig") && e.contains("line 11"),
        "{e}"
    );
}

/// A missing mesh file names the path it looked for.
#[test]
fn missing_mesh_file_is_named() {
    let d = tmp_dir("missing");
    let e = err(
        &d,
        &BOX.replace(
            r#"generate = { kind = "box", size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }"#,
            r#"file = "nowhere.msh""#,
        ),
    );
    assert!(e.contains("nowhere.msh"), "{e}");
}

/// A region without a material names the cell and its region.
#[test]
fn region_without_material_is_named() {
    let d = tmp_dir("region");
    let text = BOX.replace("[material]", "[[material]]\nregion = 7");
    let e = err(&d, &text);
    assert!(e.contains("region 7"), "{e}");
    // A material for region 1 (the box) but the scene names region "liver": refused by name.
    let e = err(
        &d,
        &BOX.replace("[material]", "[[material]]\nregion = \"liver\""),
    );
    assert!(e.contains("\"liver\""), "{e}");
}

/// A mesh with an inverted cell is refused naming the file and the cell.
#[test]
fn inverted_cell_is_named() {
    let d = tmp_dir("inverted");
    // One unit cube with its top and bottom faces swapped: negative Jacobian everywhere.
    let msh =
        "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 8 1 8\n3 1 0 8\n1\n2\n3\n4\n5\n6\n7\n8\n\
0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\n$EndNodes\n$Elements\n1 1 1 1\n3 1 5 1\n\
1 5 6 7 8 1 2 3 4\n$EndElements\n";
    std::fs::write(d.join("bad.msh"), msh).unwrap();
    let text = BOX.replace(
        r#"generate = { kind = "box", size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }"#,
        r#"file = "bad.msh""#,
    );
    let e = err(&d, &text);
    assert!(
        e.contains("bad.msh") && e.contains("cell 0") && e.contains("inverted"),
        "{e}"
    );
}

/// Physically invalid parameters are refused with the key named.
#[test]
fn invalid_parameters_are_named() {
    let d = tmp_dir("params");
    let e = err(
        &d,
        &BOX.replace("poisson_ratio = 0.45", "poisson_ratio = 0.5"),
    );
    assert!(e.contains("poisson_ratio"), "{e}");
    let e = err(&d, &BOX.replace("law = \"neo-hookean\"", "law = \"hooke\""));
    assert!(e.contains("hooke"), "{e}");
    let e = err(
        &d,
        &format!("{BOX}[[fixed]]\nbox = [[5.0, 5.0, 5.0], [6.0, 6.0, 6.0]]\n"),
    );
    assert!(
        e.contains("[[fixed]] 0") && e.contains("selects no node"),
        "{e}"
    );
}

/// Run settings that cannot mean anything are refused before the run, naming the key:
/// a negative duration, zero steps, a gravity that is not a number.
#[test]
fn absurd_run_settings_are_refused() {
    let d = tmp_dir("absurd");
    assert!(resolve(&d, BOX).is_ok(), "the base scene resolves");
    let e = err(&d, &format!("{BOX}[solver]\nduration = -1.0\n"));
    assert!(e.contains("duration") && e.contains("-1"), "{e}");
    let e = err(&d, &format!("{BOX}[solver]\nsteps = 0\n"));
    assert!(e.contains("steps") && e.contains("at least 1"), "{e}");
    let e = err(
        &d,
        &format!("{BOX}[gravity]\nacceleration = [0.0, nan, -9.81]\n"),
    );
    assert!(e.contains("[gravity]") && e.contains("NaN"), "{e}");
    // A box far too large is refused with its memory estimate, not by an allocation abort.
    let e = err(
        &d,
        &BOX.replace("cells = [4, 1, 1]", "cells = [100000, 100000, 100000]"),
    );
    assert!(
        e.contains("[mesh] generate") && e.contains("1.000e15 hexahedra") && e.contains("bytes"),
        "{e}"
    );
}

/// A real organ mesh from ../shared/meshes runs through `Problem` (every cell valid, masses
/// positive, total mass = density × volume within round-off 1e-12 relative).
#[test]
fn real_liver_mesh_resolves_with_consistent_mass() {
    let dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes"));
    let shared = dir.join("../../shared/meshes/sofaenv_liver_hex2k.msh");
    assert!(
        shared.exists(),
        "../shared/meshes is missing beside the checkout ({})",
        shared.display()
    );
    let scene = Scene::from_file(&dir.join("liver.toml")).unwrap();
    let p = Problem::from_scene(&scene, &dir).unwrap();
    let volume: f64 = p.reference.iter().map(|r| r.volume()).sum();
    let mass: f64 = p.mass.iter().sum();
    assert!(p.mass.iter().all(|m| *m > 0.0));
    assert!(
        (mass - 1060.0 * volume).abs() < 1e-12 * mass,
        "{mass} vs {}",
        1060.0 * volume
    );
}

/// A number that is not finite anywhere in a scene (a load, a material parameter, a path
/// point, a setting) is refused while reading it, naming the file, the table, the key with
/// its index and the value: none of them would show until a node went non-finite.
#[test]
fn non_finite_numbers_are_refused_naming_the_key() {
    let d = tmp_dir("non-finite");
    let cases = [
        (
            format!(
                "{BOX}[[load]]\nbox = [[0.099, -1.0, -1.0], [1.0, 1.0, 1.0]]\nforce = [0.0, nan, 0.0]\n"
            ),
            "[[load]] 0 force[1] = NaN",
        ),
        (
            BOX.replace("youngs_modulus = 3.0e3", "youngs_modulus = inf"),
            "[material] youngs_modulus = inf",
        ),
        (
            format!(
                "{BOX}[[prescribed]]\nbox = [[0.099, -1.0, -1.0], [1.0, 1.0, 1.0]]\n\
                 path = [[0.0, 0.0, 0.0, 0.0], [0.01, 0.0, 0.0, -inf]]\n"
            ),
            "[[prescribed]] 0 path[1][3] = -inf",
        ),
        (
            format!("{BOX}[solver]\ndamping = nan\n"),
            "[solver] damping = NaN",
        ),
        (
            BOX.replace("size = [0.1,", "size = [nan,"),
            "[mesh] generate.size[0] = NaN",
        ),
    ];
    for (text, named) in cases {
        let e = err(&d, &text);
        assert!(
            e.contains("scene.toml") && e.contains(named) && e.contains("not a finite number"),
            "expected {named:?} in: {e}"
        );
    }
}
