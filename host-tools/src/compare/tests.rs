use super::*;

/// A shorter field, one flipped bit, and -0.0 against 0.0 are all differences; the
/// same field is not.
#[test]
fn bit_identical_checks_lengths_and_bits() {
    let a = vec![[1.0, -2.5e-4, 3.0], [0.0, 7.0, -1.0]];
    assert!(max_abs(&a) > 1.0, "not a field at rest");
    assert!(bit_identical(&a, &a.clone()).is_ok());
    let e = bit_identical(&a, &a[..1]).unwrap_err().to_string();
    assert!(e.contains("2 nodes against 1"), "{e}");
    let mut b = a.clone();
    b[1][2] = f64::from_bits((-1.0f64).to_bits() ^ 1);
    let e = bit_identical(&a, &b).unwrap_err().to_string();
    assert!(
        e.contains("1 of 6") && e.contains("node 1 component 2"),
        "{e}"
    );
    b = a.clone();
    b[1][0] = -0.0;
    assert!(bit_identical(&a, &b).is_err());
    assert_eq!(max_rel_diff(&a, &a[..1]), f64::INFINITY);
}

/// `f64::max` drops NaN (the defect these folds replace): one NaN anywhere, on either
/// side, makes the folds NaN, so `max_rel_diff(a, b) < tol` and `max_abs(a) > floor` fail.
#[test]
fn folds_propagate_nan_from_either_side() {
    assert_eq!(
        f64::NAN.max(1.0),
        1.0,
        "the std behaviour this module avoids"
    );
    assert!(nan_max(f64::NAN, 1.0).is_nan() && nan_max(1.0, f64::NAN).is_nan());
    assert_eq!(nan_max(-2.0, 3.0), 3.0);
    let a = vec![[1.0e-3, -2.0e-3, 5.0e-4]; 4];
    let mut b = a.clone();
    b[3][1] = f64::NAN;
    assert!(max_rel_diff(&a, &a) == 0.0 && max_abs(&a) == 2.0e-3);
    assert!(max_rel_diff(&a, &b).is_nan(), "NaN in the other field");
    assert!(max_rel_diff(&b, &a).is_nan(), "NaN in the reference");
    assert!(max_abs(&b).is_nan());
    let all_nan = vec![[f64::NAN; 3]; 4];
    assert!(
        !(max_rel_diff(&a, &all_nan) < 1.0),
        "a NaN field passes no tolerance"
    );
}

struct Files(std::path::PathBuf);

impl Files {
    fn new(tag: &str) -> Self {
        let d = std::env::temp_dir().join(format!("pe-compare-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        Files(d)
    }
    fn put(&self, name: &str, text: &str) -> std::path::PathBuf {
        let p = self.0.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }
}

impl Drop for Files {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

const HEAD: &str = "node,x_m,y_m,z_m,ux_m,uy_m,uz_m\n";

#[test]
fn board_reports_compare_bitwise() {
    let d = Files::new("bits");
    let csv = d.put(
        "ref.csv",
        &format!("{HEAD}1,0,0,0,1.5e-3,0,-2.0e-4\n2,1,0,0,0,0,0\n"),
    );
    // A nodes CSV of an earlier version (no units in the header) reads the same; a
    // header that is neither is refused rather than read by position.
    let legacy = d.put(
        "legacy.csv",
        "node,x,y,z,ux,uy,uz\n1,0,0,0,1.5e-3,0,-2.0e-4\n2,1,0,0,0,0,0\n",
    );
    let (a, b) = (
        read_displacements(&csv).unwrap(),
        read_displacements(&legacy).unwrap(),
    );
    assert_eq!(a.len(), 2);
    assert_eq!(a[0], Some([1.5e-3, 0.0, -2.0e-4]), "non-zero row read");
    assert_eq!(a, b);
    let other = d.put(
        "other.csv",
        "node,ux_m,uy_m,uz_m,x_m,y_m,z_m\n1,0,0,0,0,0,0\n",
    );
    let e = read_displacements(&other).unwrap_err().to_string();
    assert!(e.contains("other.csv:1: header"), "{e}");
    let bits = |v: f64| format!("{:016x}", v.to_bits());
    let log = |uz: f64| {
        format!(
            "pe-board: begin nodes\nu,1,{},{},{}\nu,0,{},{},{}\npe-board: end nodes\n",
            bits(0.0),
            bits(0.0),
            bits(0.0),
            bits(1.5e-3),
            bits(0.0),
            bits(uz)
        )
    };
    let same = d.put("same.txt", &log(-2.0e-4));
    let c = compare(&csv, &same).unwrap();
    assert_eq!((c.nodes, c.differing, c.non_finite), (2, 0, 0));
    let off = d.put("off.txt", &log(f64::from_bits((-2.0e-4f64).to_bits() + 1)));
    let c = compare(&csv, &off).unwrap();
    assert_eq!(c.differing, 1);
    assert_eq!(c.first[0].0, "node 1", "named by the reference's tag");
    let cut = d.put("cut.txt", "pe-board: begin nodes\n");
    assert!(compare(&csv, &cut).is_err());
    let fault = d.put(
        "fault.txt",
        "pe-board: FAULT board (0,0,0) step 3: element 1 inverted\n",
    );
    assert!(compare(&csv, &fault)
        .unwrap_err()
        .to_string()
        .contains("inverted"));
}

/// The review's cases: NaN against finite values in either order is counted and makes the
/// largest difference NaN (it printed "max |diff| 0" before); rows in another order match
/// by tag; rows shifted by 5 m, a missing node and an extra one are refused, naming them.
#[test]
fn nan_renumbered_and_shifted_files_are_told_apart() {
    let d = Files::new("rows");
    let rows = |r: &[(u64, f64, f64)]| {
        let mut s = HEAD.to_string();
        for &(tag, x, uz) in r {
            s += &format!("{tag},{x:.17e},0,0,1.0e-3,0,{uz:.17e}\n");
        }
        s
    };
    let reference = d.put(
        "ref.csv",
        &rows(&[(10, 0.0, -2e-4), (20, 1.0, 3e-4), (30, 2.0, 0.0)]),
    );
    let nan = d.put("nan.csv", "node,x_m,y_m,z_m,ux_m,uy_m,uz_m\n10,0,0,0,NaN,NaN,NaN\n20,1,0,0,NaN,NaN,NaN\n30,2,0,0,NaN,NaN,NaN\n");
    for (x, y) in [(&reference, &nan), (&nan, &reference)] {
        let c = compare(x, y).unwrap();
        assert_eq!(c.non_finite, 9, "every component of one file is NaN");
        assert!(c.max_abs_diff.is_nan(), "{:e}", c.max_abs_diff);
        assert_eq!(
            c.first_non_finite.as_ref().map(|f| f.0.as_str()),
            Some("node 10")
        );
    }
    let shuffled = d.put(
        "shuffled.csv",
        &rows(&[(30, 2.0, 0.0), (10, 0.0, -2e-4), (20, 1.0, 3e-4)]),
    );
    let c = compare(&reference, &shuffled).unwrap();
    assert_eq!((c.nodes, c.differing), (3, 0), "matched by tag, not by row");
    let renumbered = d.put(
        "renum.csv",
        &rows(&[(10, 1.0, -2e-4), (20, 0.0, 3e-4), (30, 2.0, 0.0)]),
    );
    let e = compare(&reference, &renumbered).unwrap_err().to_string();
    assert!(
        e.contains("node 10") && e.contains("different meshes"),
        "{e}"
    );
    let shifted = d.put(
        "shifted.csv",
        &rows(&[(10, 5.0, -2e-4), (20, 6.0, 3e-4), (30, 7.0, 0.0)]),
    );
    let e = compare(&reference, &shifted).unwrap_err().to_string();
    assert!(
        e.contains("node 10") && e.contains("different meshes"),
        "{e}"
    );
    let short = d.put("short.csv", &rows(&[(10, 0.0, -2e-4), (30, 2.0, 0.0)]));
    let e = compare(&reference, &short).unwrap_err().to_string();
    assert!(e.contains("1 nodes of") && e.contains("node 20"), "{e}");
    let long = d.put(
        "long.csv",
        &rows(&[
            (10, 0.0, -2e-4),
            (20, 1.0, 3e-4),
            (30, 2.0, 0.0),
            (40, 3.0, 0.0),
        ]),
    );
    let e = compare(&reference, &long).unwrap_err().to_string();
    assert!(e.contains("long.csv:5: node 40 is not in"), "{e}");
    let twice = d.put("twice.csv", &rows(&[(10, 0.0, -2e-4), (10, 1.0, 3e-4)]));
    let e = compare(&reference, &twice).unwrap_err().to_string();
    assert!(
        e.contains("twice.csv:3: node 10 again (first on line 2)"),
        "{e}"
    );
}
