//! The measured firmware cost table (`pe_firmware::profile::MEASURED_COST`, used by the
//! compile report's capacity figures and board-sim's timing model) against a fresh
//! measurement. `scripts/board-cost.sh` measures (QEMU with an exact instruction counter)
//! and then runs this test with `PE_BOARD_COST_CSV` set; CI runs that script. Ignored in a
//! plain `cargo test`, which has no measurement to compare with.

use pe_firmware::image::{Integration, Precision};
use pe_firmware::profile::measured_cost;

/// Relative difference beyond which the table is stale: the figures plan board counts, so
/// a few percent is noise, more changes the capacity the compiler reports.
const STALE: f64 = 0.03;

#[test]
#[ignore = "needs a measurement: run scripts/board-cost.sh"]
fn measured_cost_table_matches_the_firmware() {
    let path = std::env::var("PE_BOARD_COST_CSV")
        .expect("PE_BOARD_COST_CSV: the measurement of scripts/board-cost.sh");
    let text = std::fs::read_to_string(&path).expect("the measurement file");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("variant,scene,elements,boxes,cuboids,nodes,contact_nodes,kernel_general,element_step_general,kernel_box,element_step_box,kernel_cuboid,element_step_cuboid,step_per_element,per_node_update,contact_evaluation,check_evaluation,search_tests"),
        "{path}: header"
    );
    let mut rows = Vec::new();
    let mut parsed = Vec::new();
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 18, "{path}: {line}");
        let (precision, integration) = match f[0] {
            "f64-reduced" => (Precision::F64, Integration::Reduced),
            "f64-full" => (Precision::F64, Integration::Full),
            "f32-reduced" => (Precision::F32, Integration::Reduced),
            "f32-full" => (Precision::F32, Integration::Full),
            v => panic!("{path}: unknown variant {v}"),
        };
        let n: Vec<f64> = f[2..]
            .iter()
            .map(|v| v.parse().expect("a number"))
            .collect();
        // n: elements, boxes, cuboids, nodes, contact nodes, kernel/gen, step/gen,
        // kernel/box, step/box, kernel/cuboid, step/cuboid, step per element, update per
        // node, a step's contact evaluation, a check step's, the search's node-face tests.
        assert_eq!(n.len(), 16, "{path}: {line}");
        assert!(n[0] > 100.0 && n[3] > 100.0, "{path}: a real scene: {line}");
        parsed.push((precision, integration, f[1].to_string(), n));
        rows.push(format!("{}-{}", f[1], f[0]));
    }
    let mut stale = Vec::new();
    for (precision, integration, scene, n) in &parsed {
        let table = measured_cost(*precision, *integration);
        // The regular box: cuboids and plain nodes (no contact); the turned box:
        // parallelepipeds; the built-in anatomy: the general kernel (every cell
        // distorted), and a step's contact evaluation over its contact nodes (measured
        // between marks: the one board owns them all).
        if scene != "builtin" {
            // Without contact the evaluation returns at once: the marks measure nothing.
            assert!(n[13] < 50.0, "{path}: {scene} has no contact: {}", n[13]);
            assert!(n[14] < 50.0, "{path}: {scene} has no contact: {}", n[14]);
            assert_eq!(n[15], 0.0, "{path}: {scene} has no search");
        }
        let checks = match scene.as_str() {
            "regular" => {
                assert_eq!(n[2], n[0], "{path}: every cell of the box is a cuboid");
                assert_eq!(n[4], 0.0, "{path}: the box has no contact");
                vec![
                    (
                        "cuboid_kernel_per_element",
                        n[9],
                        table.cuboid_kernel_per_element,
                    ),
                    (
                        "cuboid_per_element_step",
                        n[10],
                        table.cuboid_per_element_step,
                    ),
                    ("per_node_update", n[12], table.per_node_update),
                ]
            }
            "turned" => {
                assert_eq!(
                    n[1], n[0],
                    "{path}: every cell of the turned box is a parallelepiped"
                );
                assert_eq!(n[4], 0.0, "{path}: the box has no contact");
                vec![
                    ("box_kernel_per_element", n[7], table.box_kernel_per_element),
                    ("box_per_element_step", n[8], table.box_per_element_step),
                ]
            }
            "builtin" => {
                assert_eq!(
                    n[1] + n[2],
                    0.0,
                    "{path}: the built-in has no parallelepipeds or cuboids"
                );
                assert!(n[4] > 10.0, "{path}: the built-in has contact nodes");
                let plain = parsed
                    .iter()
                    .find(|r| r.0 == *precision && r.2 == "regular")
                    .map(|r| r.3[12])
                    .expect("the regular box of the same precision");
                let contact = n[13] / n[4];
                // The check step's evaluation less the plain one, over the search's tests
                // (a check also keeps the groups: in the charge, a small share).
                assert!(
                    n[15] > 1000.0 && n[14] > n[13] + 10.0 * n[15],
                    "{path}: a search of {} tests: check {} against {}",
                    n[15],
                    n[14],
                    n[13]
                );
                let search = (n[14] - n[13]) / n[15];
                vec![
                    ("kernel_per_element", n[5], table.kernel_per_element),
                    ("per_element_step", n[6], table.per_element_step),
                    ("step_per_element", n[11], table.step_per_element),
                    ("per_contact_node", contact, table.per_contact_node),
                    ("per_node_update", plain, table.per_node_update),
                    ("per_search_test", search, table.per_search_test),
                ]
            }
            s => panic!("{path}: unknown scene {s}"),
        };
        for (what, measured, held) in checks {
            // Every figure is far from zero (a search test, the smallest, takes some ten).
            let floor = if what == "per_search_test" { 5.0 } else { 50.0 };
            assert!(
                measured > floor,
                "{path}: {what} of {precision:?} {integration:?} {scene} is {measured}"
            );
            if (held as f64 - measured).abs() > STALE * measured {
                stale.push(format!(
                    "{precision:?} {integration:?} {scene} {what}: table {held}, measured {measured:.0}"
                ));
            }
        }
    }
    rows.sort();
    assert_eq!(
        rows,
        [
            "builtin-f32-full",
            "builtin-f32-reduced",
            "builtin-f64-full",
            "builtin-f64-reduced",
            "regular-f32-reduced",
            "regular-f64-reduced",
            "turned-f32-reduced",
            "turned-f64-reduced"
        ],
        "{path}: every variant"
    );
    assert!(
        stale.is_empty(),
        "pe_firmware::profile::MEASURED_COST is stale (more than {}% off): update it:\n  {}",
        STALE * 100.0,
        stale.join("\n  ")
    );
}

/// The tetrahedra's measured cost (`pe_firmware::profile::MEASURED_TET_COST`) against a fresh
/// measurement of `pe-board-tet-bench` (`scripts/board-cost.sh` writes `PE_TET_COST_CSV`),
/// and the board's forces the host's, bit for bit: the digests of the plain and the T4ANP
/// loops' forces on the sample patch (`TetSample`), recomputed here. Before comparing,
/// the host's forces are checked to be far from trivial (largest component above 1 mN
/// where the patch's stresses of some hundred Pa on 1 cm² faces give tens of mN), to sum to
/// zero (internal forces: to 1e-9 of the largest in f64, 1e-4 in f32, a sum's rounding), and
/// the two forms to differ (ν = 0.49: the nodal pressure is not the element's).
#[test]
#[ignore = "needs a measurement: run scripts/board-cost.sh"]
fn measured_tet_cost_and_bits_match_the_firmware() {
    use pe_firmware::physics::{Real, TetPressure};
    use pe_firmware::profile::measured_tet_cost;
    use pe_firmware::profile::tet_cost::{digest, TetSample, SAMPLE_NODES, SAMPLE_TETS};

    fn host<T: Real>(sum_tolerance: f64) -> (u64, u64) {
        let sample = TetSample::<T>::new().expect("the sample patch");
        let mut out = [0u64; 2];
        let mut forces = Vec::new();
        for (k, form) in [TetPressure::Element, TetPressure::Nodal]
            .into_iter()
            .enumerate()
        {
            let mut f = [[T::ZERO; 3]; SAMPLE_NODES];
            sample.forces(form, &mut f).expect("the sample's forces");
            let largest = f.iter().flatten().fold(0.0f64, |m, v| {
                pe_firmware::physics::real::nan_max(m, v.to_f64().abs())
            });
            assert!(
                largest > 1e-3,
                "{form:?}: trivial forces, largest {largest} N"
            );
            for i in 0..3 {
                let sum: f64 = f.iter().map(|v| v[i].to_f64()).sum();
                assert!(
                    sum.abs() < sum_tolerance * largest,
                    "{form:?}: component {i} sums to {sum} N (largest {largest})"
                );
            }
            out[k] = digest(&f);
            forces.push(f.map(|v| v.map(T::to_f64)));
        }
        let apart = forces[0]
            .iter()
            .flatten()
            .zip(forces[1].iter().flatten())
            .fold(0.0f64, |m, (a, b)| {
                pe_firmware::physics::real::nan_max(m, (a - b).abs())
            });
        assert!(
            apart > 1e-4,
            "plain and T4ANP forces differ by only {apart} N"
        );
        (out[0], out[1])
    }

    let path = std::env::var("PE_TET_COST_CSV")
        .expect("PE_TET_COST_CSV: the measurement of scripts/board-cost.sh");
    let text = std::fs::read_to_string(&path).expect("the measurement file");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("precision,tets,nodes,kernel_plain,plain_step,nodal_step,digest_plain,digest_nodal"),
        "{path}: header"
    );
    let mut seen = Vec::new();
    let mut stale = Vec::new();
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 8, "{path}: {line}");
        let (precision, digests) = match f[0] {
            "f64" => (pe_firmware::image::Precision::F64, host::<f64>(1e-9)),
            "f32" => (pe_firmware::image::Precision::F32, host::<f32>(1e-4)),
            p => panic!("{path}: unknown precision {p}"),
        };
        assert_eq!(f[1], SAMPLE_TETS.to_string(), "{path}: {line}");
        assert_eq!(f[2], SAMPLE_NODES.to_string(), "{path}: {line}");
        assert!(
            [f[6], f[7]]
                .iter()
                .all(|d| u64::from_str_radix(d, 16).is_ok() && d.len() == 16),
            "{path}: digests {line}"
        );
        assert_eq!(
            [f[6].to_string(), f[7].to_string()],
            [digests.0, digests.1].map(|d| format!("{d:016x}")),
            "{path}: {} forces on the board differ from the host's (plain, T4ANP)",
            f[0]
        );
        let table = measured_tet_cost(precision);
        let n: Vec<f64> = f[3..6]
            .iter()
            .map(|v| v.parse().expect("a number"))
            .collect();
        for (what, measured, held) in [
            ("kernel_per_tet", n[0], table.kernel_per_tet),
            ("plain_per_tet_step", n[1], table.plain_per_tet_step),
            ("nodal_per_tet_step", n[2], table.nodal_per_tet_step),
        ] {
            assert!(measured > 50.0, "{path}: {what} of {} is {measured}", f[0]);
            if (held as f64 - measured).abs() > STALE * measured {
                stale.push(format!(
                    "{} {what}: table {held}, measured {measured:.0}",
                    f[0]
                ));
            }
        }
        seen.push(f[0].to_string());
    }
    seen.sort();
    assert_eq!(seen, ["f32", "f64"], "{path}: both precisions measured");
    assert!(
        stale.is_empty(),
        "MEASURED_TET_COST is stale (update pe-firmware/src/profile/tet_cost.rs):\n{}",
        stale.join("\n")
    );
}
