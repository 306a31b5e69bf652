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
        Some("variant,scene,elements,boxes,nodes,kernel_general,element_step_general,kernel_box,element_step_box,step_per_element,per_node_update"),
        "{path}: header"
    );
    let mut stale = Vec::new();
    let mut rows = Vec::new();
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 11, "{path}: {line}");
        let (precision, integration) = match f[0] {
            "f64-reduced" => (Precision::F64, Integration::Reduced),
            "f64-full" => (Precision::F64, Integration::Full),
            "f32-reduced" => (Precision::F32, Integration::Reduced),
            "f32-full" => (Precision::F32, Integration::Full),
            v => panic!("{path}: unknown variant {v}"),
        };
        let n = |k: usize| -> f64 { f[k].parse().expect("a number") };
        let table = measured_cost(precision, integration);
        assert!(n(2) > 100.0 && n(4) > 100.0, "{path}: a real scene: {line}");
        // The built-in anatomy measures the general kernel and the node update (its cells
        // are all distorted); the regular box the parallelepiped kernel (all boxes).
        let checks = match f[1] {
            "builtin" => {
                assert_eq!(
                    n(3),
                    0.0,
                    "{path}: the built-in has no parallelepipeds: {line}"
                );
                vec![
                    ("kernel_per_element", n(5), table.kernel_per_element),
                    ("per_element_step", n(6), table.per_element_step),
                    ("step_per_element", n(9), table.step_per_element),
                    ("per_node_update", n(10), table.per_node_update),
                ]
            }
            "regular" => {
                assert_eq!(
                    n(3),
                    n(2),
                    "{path}: every cell of the box is a parallelepiped"
                );
                vec![
                    ("box_kernel_per_element", n(7), table.box_kernel_per_element),
                    ("box_per_element_step", n(8), table.box_per_element_step),
                ]
            }
            s => panic!("{path}: unknown scene {s}"),
        };
        for (what, measured, held) in checks {
            assert!(measured > 50.0, "{path}: {what} of {} is {measured}", f[0]);
            if (held as f64 - measured).abs() > STALE * measured {
                stale.push(format!(
                    "{} {} {what}: table {held}, measured {measured}",
                    f[0], f[1]
                ));
            }
        }
        rows.push(format!("{}-{}", f[1], f[0]));
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
            "regular-f64-reduced"
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
