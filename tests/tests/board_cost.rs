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
        Some("variant,elements,nodes,kernel_per_element,per_element_step,step_per_element,per_node_update"),
        "{path}: header"
    );
    let mut stale = Vec::new();
    let mut variants = 0;
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 7, "{path}: {line}");
        let (precision, integration) = match f[0] {
            "f64-reduced" => (Precision::F64, Integration::Reduced),
            "f64-full" => (Precision::F64, Integration::Full),
            "f32-reduced" => (Precision::F32, Integration::Reduced),
            "f32-full" => (Precision::F32, Integration::Full),
            v => panic!("{path}: unknown variant {v}"),
        };
        let n = |k: usize| -> f64 { f[k].parse().expect("a number") };
        let table = measured_cost(precision, integration);
        assert!(n(1) > 100.0 && n(2) > 100.0, "{path}: a real scene: {line}");
        for (what, measured, held) in [
            ("kernel_per_element", n(3), table.kernel_per_element),
            ("per_element_step", n(4), table.per_element_step),
            ("step_per_element", n(5), table.step_per_element),
            ("per_node_update", n(6), table.per_node_update),
        ] {
            assert!(measured > 50.0, "{path}: {what} of {} is {measured}", f[0]);
            if (held as f64 - measured).abs() > STALE * measured {
                stale.push(format!(
                    "{} {what}: table {held}, measured {measured}",
                    f[0]
                ));
            }
        }
        variants += 1;
    }
    assert_eq!(variants, 4, "{path}: every precision and integration");
    assert!(
        stale.is_empty(),
        "pe_firmware::profile::MEASURED_COST is stale (more than {}% off): update it:\n  {}",
        STALE * 100.0,
        stale.join("\n  ")
    );
}
