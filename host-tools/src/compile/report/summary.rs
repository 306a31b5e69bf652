//! The readable summary `pe compile` prints.

use super::step_model::step_model_needs;
use super::verdict::COMPUTE_MARGIN;
use super::{Balance, CompileReport};

/// The readable summary printed by `pe compile`.
pub fn summary(r: &CompileReport) -> String {
    let min = r.elements_per_board.iter().min().copied().unwrap_or(0);
    let max = r.elements_per_board.iter().max().copied().unwrap_or(0);
    let mut s = String::new();
    s += &format!(
        "{}: {} elements, {} nodes on {} boards ({}), {} {}\n",
        r.scene,
        r.elements,
        r.nodes,
        r.elements_per_board.len(),
        r.machine,
        r.precision,
        r.integration
    );
    s += &format!("  elements per board {min}..{max} (imbalance max/mean {:.3}); nodes per board {}..{}; {} replicas\n",
        r.load_imbalance, r.nodes_per_board.iter().min().copied().unwrap_or(0), r.nodes_per_board.iter().max().copied().unwrap_or(0), r.replicated_nodes);
    s += &format!(
        "  exchange rounds per step: x {}, y {}, z {} (of which after the z exchange, the broadcasts: x {}, y {})\n",
        r.rounds[0], r.rounds[1], r.rounds[2], r.late_rounds[0], r.late_rounds[1]
    );
    s += &format!(
        "  border nodes per face (max over boards): +x {} -x {} +y {} -y {} +z {} -z {}\n",
        r.border_nodes_per_face_max[0],
        r.border_nodes_per_face_max[1],
        r.border_nodes_per_face_max[2],
        r.border_nodes_per_face_max[3],
        r.border_nodes_per_face_max[4],
        r.border_nodes_per_face_max[5]
    );
    s += &format!(
        "  force vectors per step: {} in all, {} on the busiest link direction\n",
        r.force_vectors_per_step, r.force_vectors_per_link_max
    );
    s += "  (a force vector: one node's partial or summed force that one board sends to a neighbour over one link in one exchange round; every round and both directions counted. A node on k boards of one line costs 2(k - 1): its partial sums go to one board and the total comes back; a node on a 2x2 block of boards costs 6, on 2x2x2 14: reduced along x, then y, exchanged along z, broadcast back along y, then x)\n";
    s += &format!(
        "  partition: slabs refined by simulated annealing (seed {}) within {:.2} x the mean {} per board{}\n",
        crate::compile::partition::refine::ANNEAL_SEED,
        crate::compile::partition::BALANCE_MAX,
        match r.balance {
            Balance::Elements => "elements",
            Balance::Cost => "cost (kernel and contact instructions)",
        },
        match &r.balance_other {
            Some(o) => format!(
                "; chosen over balancing {}: worst time ratio {:.2} against {:.2}",
                o.balance.name(),
                r.real_time.worst_ratio,
                o.worst_ratio
            ),
            None => String::new(),
        }
    );
    s += &format!("  bytes per step: {} in all, {} on the busiest link; at dt = {:.3e} s ({:.0} steps/s): {:.3} GB/s in all, {:.1} MB/s on the busiest link ({:.0}% of its {:.3} MB/s)\n",
        r.bytes_per_step_total, r.bytes_per_step_per_link_max, r.dt_s, r.steps_per_s, r.bandwidth_total_bytes_per_s / 1e9,
        r.bandwidth_per_link_max_bytes_per_s / 1e6, 100.0 * r.link_utilisation_max, r.link_bandwidth_bytes_per_s as f64 / 1e6);
    s += &format!(
        "  largest image {} bytes, largest run-time state {} bytes ({} profile)\n",
        r.image_bytes_max, r.ram_bytes_max, r.profile
    );
    let parts: Vec<String> = pe_firmware::image::Feature::ALL
        .iter()
        .map(|f| {
            let n = r
                .boards
                .iter()
                .filter(|b| b.firmware_parts.contains(f))
                .count();
            format!("{} on {n} of {} boards", f.name(), r.boards.len())
        })
        .collect();
    s += &format!(
        "  firmware parts the images need (cargo features; `pe image` builds the firmware with those some board needs, and no other): {}\n",
        parts.join(", ")
    );
    let c = &r.capacity;
    s += &format!(
        "  element kernels: {} cuboids, {} parallelepipeds, {} general\n  board compute ({} profile, {:.0} MHz, measured {} instructions per element-step (general), {} (parallelepiped), {} (cuboid), {} per node update, {} more per contact node of the whole table on a board that owns one, one instruction per cycle assumed): busiest board {:.1} us per step against dt = {:.1} us ({}); {:.1} elements per board at this scene's rate, {:.1} at 10 kHz, so {} boards for this scene at 10 kHz\n",
        c.elements_per_kernel[2], c.elements_per_kernel[1], c.elements_per_kernel[0],
        r.profile, c.clock_hz as f64 / 1e6, c.instructions_per_element_step, c.instructions_per_box_element_step, c.instructions_per_cuboid_element_step, c.instructions_per_node_update, c.instructions_per_contact_node,
        c.step_compute_s_max * 1e6, r.dt_s * 1e6,
        if c.compute_keeps_real_time { "within dt" } else { "over dt" },
        c.elements_per_board_at_scene_rate, c.elements_per_board_at_10_khz, c.boards_needed_at_10_khz
    );
    if c.check_interval_steps > 0 {
        let [x, y, z] = c.check_step_board;
        s += &format!(
            "  check step (every {} steps): the candidate search, {} node-face tests at {} instructions each on every board that owns a contact node; busiest board ({x},{y},{z}) {:.1} us\n",
            c.check_interval_steps, c.search_tests, c.instructions_per_search_test, c.check_step_s_max * 1e6
        );
    }
    let g = &r.graphics;
    s += &format!(
        "  graphics: {} surface nodes every {} steps ({:.1} ms) spread over {} steps: {} packets, {} bytes per frame, {:.3} MB/s (the seed: 18 MB/s)\n",
        g.surface_nodes, g.interval_steps, g.interval_steps as f64 * r.dt_s * 1e3, g.spread_steps, g.packets_per_frame, g.bytes_per_frame, g.bytes_per_s / 1e6
    );
    if let Some(c) = &r.contact {
        s += &format!(
            "  contact: {} nodes, {} faces, {} pairs, {} tools on {} boards; bounding boxes every {} steps (travel {:.2} mm, box margin {:.2} mm); at rest {} channels, {} node vectors per step, {:.2} MB/s (the seed: ~300 vectors, 72 MB/s)\n",
            c.contact_nodes, c.contact_faces, c.pairs, c.tools, c.contact_boards, c.check_interval_steps, c.travel_max_m * 1e3, c.box_margin_m * 1e3,
            c.channels_at_rest, c.vectors_per_step_at_rest, c.bytes_per_s_at_rest / 1e6
        );
        if let Some(g) = &c.global_busiest_at_rest {
            let [x, y, z] = g.board;
            s += &format!(
                "  global ports ({:.1} MB/s into and out of each board): busiest at rest ({x},{y},{z}): {} bytes in, {} out per step, {:.1} us against dt = {:.1} us\n",
                r.global_bytes_per_s as f64 / 1e6, g.bytes_in_per_step, g.bytes_out_per_step, g.time_per_step_s * 1e6, r.dt_s * 1e6
            );
        }
    }
    s += &real_time_lines(r);
    s += "  seed's reference case: 2000 elements on 4x4x4 boards at dt = 100 us: 5600 force vectors per step, 1.35 GB/s in all\n";
    s += &format!(
        "  this scene at dt = 100 us: {} force vectors per step, {:.3} GB/s in all\n",
        r.force_vectors_per_step,
        r.bytes_per_step_total as f64 * 1e4 / 1e9
    );
    s
}

/// The links against the step and the verdict, for the summary.
fn real_time_lines(r: &CompileReport) -> String {
    let v = &r.real_time;
    let mut s = String::new();
    match &v.link_busiest {
        Some(l) => {
            let [x, y, z] = l.board;
            s += &format!(
                "  links ({:.3} MB/s each way, {:.1} us per frame): busiest ({x},{y},{z}) {}: {} bytes in {} frames per step, {:.1} us against dt = {:.1} us; {} of {} link directions over dt\n",
                r.link_bandwidth_bytes_per_s as f64 / 1e6,
                r.link_frame_latency_s * 1e6,
                l.face,
                l.bytes_per_step,
                l.frames_per_step,
                l.time_per_step_s * 1e6,
                v.dt_s * 1e6,
                v.links_over_count,
                v.links
            );
        }
        None => s += "  links: nothing exchanged\n",
    }
    let m = &r.step_model.timing;
    let [x, y, z] = m.slowest_board;
    s += &format!(
        "  step model (every board runs the firmware's step program; a round waits for its frames): a step ends at {:.1} us on board ({x},{y},{z}) ({:.1} us computing){} against dt = {:.1} us; {}\n",
        m.step_s * 1e6,
        m.compute_s * 1e6,
        match m.check_step_s {
            Some(c) => {
                let [x, y, z] = m.check_slowest_board;
                format!(", a check step at {:.1} us on board ({x},{y},{z})", c * 1e6)
            }
            None => String::new(),
        },
        m.dt_s * 1e6,
        step_model_needs(&r.step_model)
    );
    if v.keeps_real_time {
        s += &format!(
            "  verdict: keeps real time (busiest board's compute {:.1} us{} within dt / {COMPUTE_MARGIN} = {:.1} us, every link within dt{}, the modelled step within dt)\n",
            v.compute_s_max * 1e6,
            if v.check_interval_steps > 0 {
                format!(", {:.1} us at a check step", v.check_step_s_max * 1e6)
            } else {
                String::new()
            },
            v.compute_budget_s * 1e6,
            if v.global_busiest.is_some() { ", every global port's contact traffic at rest within dt" } else { "" }
        );
    } else {
        s += "  verdict: does NOT keep real time:\n";
        for why in &v.reasons {
            s += &format!("    {why}\n");
        }
    }
    s
}
