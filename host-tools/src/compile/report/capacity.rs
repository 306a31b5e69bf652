//! The boards' compute: the busiest board's step (and check step) from the firmware's
//! measured instruction counts, and the elements a board computes at a step rate.

use pe_firmware::profile::{BoardProfile, FirmwareCost};
use serde::{Deserialize, Serialize};

use crate::compile::plan::{BoardPlan, Plan};
use crate::problem::elements::kind_of;
use crate::problem::Problem;

/// What the scene asks of the busiest board's processor, from measured instruction counts.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Capacity {
    pub clock_hz: u64,
    /// Per element-step of the general kernel, of the parallelepiped kernel and of the
    /// cuboid kernel.
    pub instructions_per_element_step: u32,
    pub instructions_per_box_element_step: u32,
    pub instructions_per_cuboid_element_step: u32,
    /// Elements of the scene that take each kernel (general, parallelepiped, cuboid).
    pub elements_per_kernel: [usize; 3],
    pub instructions_per_node_update: u32,
    pub instructions_per_contact_node: u32,
    /// Instructions of one step on the busiest board (no exchange), and that board.
    pub step_instructions_max: f64,
    pub busiest_board: [usize; 3],
    /// That step's time at one instruction per cycle (s), against the scene's `dt_s`.
    pub step_compute_s_max: f64,
    pub compute_keeps_real_time: bool,
    /// A check step's candidate search: instructions per node-face test (measured), the
    /// tests of one search (the whole contact table with every position known: what each
    /// board that owns a contact node searches; 0 without pairs) and the steps between
    /// checks (0 without pairs).
    pub instructions_per_search_test: u32,
    pub search_tests: usize,
    pub check_interval_steps: u32,
    /// The busiest board at a check step: its step plus the search if it owns a contact
    /// node (s, one instruction per cycle), and that board (the steady figures without
    /// pairs).
    pub check_step_s_max: f64,
    pub check_step_board: [usize; 3],
    /// Elements one board computes per step at the scene's rate and at 10 kHz, with this
    /// scene's nodes per element on its busiest board.
    pub elements_per_board_at_scene_rate: f64,
    pub elements_per_board_at_10_khz: f64,
    /// Boards the scene needs at 10 kHz (compute only).
    pub boards_needed_at_10_khz: usize,
}

/// The busiest board's compute per step from the measured firmware cost, and the boards a
/// 10 kHz step would need.
/// `search`: the tests of a check step's candidate search and the steps between checks.
pub(super) fn capacity_report(
    problem: &Problem,
    plan: &Plan,
    profile: &BoardProfile,
    dt: f64,
    search: (usize, u32),
) -> Capacity {
    let cost =
        pe_firmware::profile::measured_cost(problem.solver.precision, problem.solver.integration);
    let per_kernel = |elements: &mut dyn Iterator<Item = usize>| {
        let mut n = [0usize; 3];
        for e in elements {
            // Tetrahedra never get here (`plan::refuse_tetrahedra`).
            if let Some(k) = kind_of(problem, e) {
                n[k.table()] += 1;
            }
        }
        n
    };
    let on_contact = contact_node_mask(problem);
    let table_nodes = on_contact.iter().filter(|&&c| c).count();
    let contact_nodes = |b: &BoardPlan| {
        let (_, owned) = board_contact_nodes(b, &on_contact);
        FirmwareCost::charged_contact_nodes(table_nodes, owned)
    };
    let (search_tests, check_interval_steps) = search;
    let search_instructions = search_tests as f64 * cost.per_search_test as f64;
    // Per board: a steady step, and a check step (the search if it owns a contact node).
    let steps: Vec<(f64, f64, [usize; 3])> = plan
        .boards
        .iter()
        .map(|b| {
            let kinds = per_kernel(&mut b.elements.iter().map(|&e| e as usize));
            let charged = contact_nodes(b);
            let step = cost.step_instructions(kinds, b.nodes.len(), charged);
            let searches = charged > 0 && search_tests > 0;
            let check = step + if searches { search_instructions } else { 0.0 };
            (step, check, b.coords)
        })
        .collect();
    let (busiest, busiest_board) = steps
        .iter()
        .map(|&(step, _, c)| (step, c))
        .fold((0.0f64, [0; 3]), |m, b| if b.0 > m.0 { b } else { m });
    let (check_busiest, check_board) = steps
        .iter()
        .map(|&(_, check, c)| (check, c))
        .fold((0.0f64, [0; 3]), |m, b| if b.0 > m.0 { b } else { m });
    let npe = plan
        .boards
        .iter()
        .max_by_key(|b| b.elements.len())
        .map(|b| b.nodes.len() as f64 / b.elements.len().max(1) as f64)
        .unwrap_or(2.0);
    let cpe = table_nodes as f64 / problem.mesh.cells.len().max(1) as f64;
    let n = problem.mesh.cells.len();
    let elements_per_kernel = per_kernel(&mut (0..n));
    let mix = elements_per_kernel.map(|k| k as f64 / n.max(1) as f64);
    let at_10k = cost.elements_per_board(profile, 1e4, npe, cpe, mix);
    Capacity {
        clock_hz: profile.clock_hz,
        instructions_per_element_step: cost.per_element_step,
        instructions_per_box_element_step: cost.box_per_element_step,
        instructions_per_cuboid_element_step: cost.cuboid_per_element_step,
        elements_per_kernel,
        instructions_per_node_update: cost.per_node_update,
        instructions_per_contact_node: cost.per_contact_node,
        step_instructions_max: busiest,
        busiest_board,
        step_compute_s_max: busiest / profile.clock_hz as f64,
        compute_keeps_real_time: busiest / profile.clock_hz as f64 <= dt,
        instructions_per_search_test: cost.per_search_test,
        search_tests,
        check_interval_steps,
        check_step_s_max: check_busiest / profile.clock_hz as f64,
        check_step_board: check_board,
        elements_per_board_at_scene_rate: cost.elements_per_board(profile, 1.0 / dt, npe, cpe, mix),
        elements_per_board_at_10_khz: at_10k,
        boards_needed_at_10_khz: (n as f64 / at_10k).ceil() as usize,
    }
}

/// Whether each mesh node lies on a contact surface.
pub(super) fn contact_node_mask(problem: &Problem) -> Vec<bool> {
    let mut on_contact = vec![false; problem.mesh.nodes.len()];
    if let Some(c) = &problem.contact {
        for &n in &c.node_globals {
            on_contact[n as usize] = true;
        }
    }
    on_contact
}

/// The contact nodes board `b` holds, and how many of them it owns.
pub(super) fn board_contact_nodes(b: &BoardPlan, on_contact: &[bool]) -> (usize, usize) {
    let contact = |n: &u32| on_contact.get(*n as usize).copied().unwrap_or(false);
    let held = b.nodes.iter().filter(|n| contact(n)).count();
    let owned = (b.nodes.iter().zip(&b.owner))
        .filter(|(n, o)| **o && contact(n))
        .count();
    (held, owned)
}
