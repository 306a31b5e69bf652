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
