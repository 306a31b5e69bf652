//! The compile report's real-time verdict: the busiest board's compute within half the
//! step and every link direction's exchange within the step.

use host_tools::compile::partition::Machine;
use host_tools::compile::{compile_images, plan, report, summary, CompileReport};
use host_tools::problem::Problem;
use pe_firmware::image::Precision;
use pe_firmware::profile::{measured_cost, BoardProfile, PE_BOARD};
use system_tests::repo_scene;

fn compiled(p: &Problem, machine: &str, profile: &BoardProfile) -> CompileReport {
    let plan = plan(p, Machine::parse(machine).expect("machine")).expect("plans");
    let images = compile_images(p, &plan).expect("images");
    report("test", p, &plan, &images, profile).expect("report")
}

/// A board fast enough that compute never decides the verdict (1000 x the PE board's
/// clock), so only the links can.
fn fast_clock(profile: &BoardProfile) -> BoardProfile {
    BoardProfile {
        clock_hz: profile.clock_hz * 1000,
        ..*profile
    }
}

/// The seed box on 4x4x4 with the PE board's links (3.125 MB/s each way): its busiest link
/// direction needs over twice the 100 us step. With compute out of the way, the summary
/// says "does NOT keep real time", names that link (board and face) with its time, and
/// never says "keeps real time"; report.json carries the same verdict. With links 1000
/// times faster it keeps real time (so the verdict is not stuck).
#[test]
fn a_scene_over_the_link_rate_names_the_link() {
    let p = repo_scene("seed-box.toml");
    let r = compiled(&p, "4x4x4", &fast_clock(&PE_BOARD));
    let v = &r.real_time;
    assert!(v.compute_fits, "{:?}", v.reasons);
    assert!(!v.keeps_real_time);
    assert!(v.links > 0 && v.links_over_count > 0 && !v.links_over.is_empty());
    let worst = &v.links_over[0];
    assert!(worst.time_per_step_s > r.dt_s && worst.bytes_per_step > 0);
    let text = summary(&r);
    assert!(text.contains("does NOT keep real time"), "{text}");
    assert!(!text.contains("keeps real time"), "{text}");
    let [x, y, z] = worst.board;
    let named = format!("link ({x},{y},{z}) {} needs", worst.face);
    assert!(text.contains(&named), "{named} missing in:\n{text}");
    // Only links are blamed: every reason names a link (or counts the links not listed).
    assert!(
        v.reasons
            .iter()
            .all(|l| l.starts_with("link") || l.contains("more links over dt")),
        "{:?}",
        v.reasons
    );
    let json = serde_json::to_value(&r).expect("json");
    assert_eq!(json["real_time"]["keeps_real_time"], false);
    assert_eq!(
        json["real_time"]["links_over_count"].as_u64(),
        Some(v.links_over_count as u64)
    );

    let fast = BoardProfile {
        link_bytes_per_s: PE_BOARD.link_bytes_per_s * 1000,
        link_latency_ns: 1,
        ..fast_clock(&PE_BOARD)
    };
    let r = compiled(&p, "4x4x4", &fast);
    assert!(r.real_time.keeps_real_time, "{:?}", r.real_time.reasons);
    let text = summary(&r);
    assert!(text.contains("verdict: keeps real time"), "{text}");
    assert!(!text.contains("does NOT"), "{text}");
}

/// The verdict against one computed here from the plan's send lists and the measured cost
/// (not from the report's link table): per board and face, bytes = sum over rounds of 3
/// components x the precision's width x the vectors sent, plus one frame header and CRC
/// per round that sends; time = bytes / rate + frames x frame latency. Compute = the most
/// instructions of any board (elements x per element-step + nodes x per node update) over
/// the clock. Keeps real time iff compute <= dt / 2 and no link direction needs more than
/// dt. Cases of both outcomes (the liver at its 1.4 ms step keeps it; the seed box at
/// 100 us and the built-in scene on a slow-link profile do not). Times compare to a
/// relative 1e-12 (the same sums in another order), counts exactly.
#[test]
fn verdict_matches_an_independent_computation() {
    let slow_links = BoardProfile {
        link_bytes_per_s: 200_000,
        ..fast_clock(&PE_BOARD)
    };
    let cases = [
        ("liver", repo_scene("liver.toml"), "4x4x4", PE_BOARD, true),
        (
            "seed box",
            repo_scene("seed-box.toml"),
            "4x4x4",
            PE_BOARD,
            false,
        ),
        (
            "builtin coarse, slow links",
            system_tests::builtin_problem("coarse", 10),
            "2x2x2",
            slow_links,
            false,
        ),
    ];
    for (name, p, machine, profile, expected) in cases {
        let plan = plan(&p, Machine::parse(machine).expect("machine")).expect("plans");
        let images = compile_images(&p, &plan).expect("images");
        let r = report(name, &p, &plan, &images, &profile).expect("report");
        let dt = p.time_step.dt_s;
        let w = if p.solver.precision == Precision::F32 {
            4
        } else {
            8
        };
        let overhead = link_proto::FRAME_HEADER_LEN + link_proto::CRC_LEN;
        let mut times = Vec::new();
        for b in &plan.boards {
            for f in 0..6 {
                let sent: Vec<usize> = b.rounds[f / 2]
                    .iter()
                    .map(|r| r.send[f % 2].len())
                    .filter(|&n| n > 0)
                    .collect();
                if sent.is_empty() {
                    continue;
                }
                let bytes: usize = sent.iter().map(|n| 3 * w * n + overhead).sum();
                times.push(
                    bytes as f64 / profile.link_bytes_per_s as f64
                        + sent.len() as f64 * profile.link_latency_ns as f64 * 1e-9,
                );
            }
        }
        assert!(!times.is_empty(), "{name}: links send");
        let over = times.iter().filter(|&&t| t > dt).count();
        let busiest = times.iter().copied().fold(0.0, f64::max);
        let cost = measured_cost(p.solver.precision, p.solver.integration);
        let compute = plan
            .boards
            .iter()
            .map(|b| {
                // Each element at its kernel's cost (parallelepipeds are cheaper).
                let elements: f64 = b
                    .elements
                    .iter()
                    .map(|&e| {
                        if host_tools::problem::elements::is_box(&p, e as usize) {
                            cost.box_per_element_step as f64
                        } else {
                            cost.per_element_step as f64
                        }
                    })
                    .sum();
                let contact = p.contact.as_ref().map_or(0, |c| {
                    b.nodes
                        .iter()
                        .filter(|n| c.node_globals.contains(n))
                        .count()
                });
                (elements
                    + b.nodes.len() as f64 * cost.per_node_update as f64
                    + contact as f64 * cost.per_contact_node as f64)
                    / profile.clock_hz as f64
            })
            .fold(0.0, f64::max);
        assert!(compute > 0.0 && busiest > 0.0);
        let keeps = compute <= dt / 2.0 && over == 0;
        let v = &r.real_time;
        println!(
            "{name}: compute {compute:e} s, busiest link {busiest:e} s, {over} of {} over, dt {dt:e}: {keeps}",
            times.len()
        );
        assert_eq!(
            keeps, expected,
            "{name}: the case is what it is meant to be"
        );
        assert_eq!(v.keeps_real_time, keeps, "{name}: {:?}", v.reasons);
        assert_eq!(v.links, times.len(), "{name}");
        assert_eq!(v.links_over_count, over, "{name}");
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
        let got = v.link_busiest.as_ref().expect("a busiest link");
        assert!(close(got.time_per_step_s, busiest), "{name}");
        assert!(close(v.compute_s_max, compute), "{name}");
        assert_eq!(v.compute_fits, compute <= dt / 2.0, "{name}");
        assert_eq!(v.reasons.is_empty(), keeps, "{name}");
    }
}
