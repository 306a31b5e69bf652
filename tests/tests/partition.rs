//! The partitioner: its exchange count against an independent count from the element ->
//! board map alone, its load balance, and the seed's reference case.

use host_tools::compare::nan_max;
use host_tools::compile::partition::{slabs, Machine, BALANCE_MAX};
use host_tools::compile::{compile_images, plan, report};
use host_tools::problem::{NodeKind, Problem};
use pe_firmware::profile::PE_BOARD;
use system_tests::*;

/// Force vectors per step that the exchange rounds send, computed from the element ->
/// board map alone (not from the compiler's exchange lists).
///
/// A node is held by every board of the box spanned by the boards whose elements touch
/// it; say it spans `m_a + 1` boards along axis `a`. Its partial sums are reduced along x
/// on every x line of the box, `(m_y + 1)(m_z + 1)` lines, each ending on one board of the
/// line; then along y on the y lines through those boards, `m_z + 1` lines; then along z on
/// one line; then the total goes back the way it came. On a line of `m + 1` boards each of
/// the `m` links between neighbours carries the node once towards the line's root and once
/// back, `2m` vectors (for two boards on the node's last axis, the symmetric exchange: one
/// vector each way). So a node costs `2 m_x (m_y + 1)(m_z + 1) + 2 m_y (m_z + 1) + 2 m_z`
/// vectors per step: 2 for two boards, 6 for a 2x2 block, 14 for 2x2x2. A held node (fixed
/// or prescribed: its displacement is its path's whatever the force) costs none.
fn independent_vectors(problem: &Problem, machine: Machine, element_board: &[u32]) -> usize {
    let mesh = &problem.mesh;
    assert_eq!(problem.node_kind.len(), mesh.nodes.len());
    assert_eq!(element_board.len(), mesh.cells.len());
    let coords = |b: u32| -> [usize; 3] {
        let b = b as usize;
        let [dx, dy, _] = machine.dims();
        [b % dx, (b / dx) % dy, b / (dx * dy)]
    };
    let mut lo = vec![[usize::MAX; 3]; mesh.nodes.len()];
    let mut hi = vec![[0usize; 3]; mesh.nodes.len()];
    for (cell, &b) in mesh.cells.iter().zip(element_board) {
        let c = coords(b);
        for &n in cell {
            for a in 0..3 {
                lo[n as usize][a] = lo[n as usize][a].min(c[a]);
                hi[n as usize][a] = hi[n as usize][a].max(c[a]);
            }
        }
    }
    lo.iter()
        .zip(&hi)
        .zip(&problem.node_kind)
        .filter(|(_, k)| **k == NodeKind::Free)
        .map(|((l, h), _)| {
            let m = [h[0] - l[0], h[1] - l[1], h[2] - l[2]];
            2 * m[0] * (m[1] + 1) * (m[2] + 1) + 2 * m[1] * (m[2] + 1) + 2 * m[2]
        })
        .sum()
}

/// Max over mean elements per board, checking every board holds at least one.
fn balance(machine: Machine, element_board: &[u32]) -> f64 {
    let mut count = vec![0usize; machine.count()];
    for &b in element_board {
        count[b as usize] += 1;
    }
    assert!(count.iter().all(|&c| c > 0), "an empty board: {count:?}");
    let mean = element_board.len() as f64 / count.len() as f64;
    *count.iter().max().unwrap_or(&0) as f64 / mean
}

/// The compiler's count (the report's, from the exchange lists of every round) for
/// `problem` on `machine`, with the plan's element -> board map.
fn compiled(problem: &Problem, machine: Machine, name: &str) -> (usize, Vec<u32>, [usize; 3]) {
    let plan = plan(problem, machine).expect("plans");
    let images = compile_images(problem, &plan).expect("images");
    let rep = report(name, problem, &plan, &images, &PE_BOARD).expect("report");
    // The report counts what the rounds' send lists hold.
    let sends: usize = plan
        .boards
        .iter()
        .flat_map(|b| b.rounds.iter().flatten())
        .map(|r| r.send[0].len() + r.send[1].len())
        .sum();
    assert_eq!(rep.force_vectors_per_step, sends, "{name}");
    (rep.force_vectors_per_step, plan.element_board, rep.rounds)
}

/// The built-in scene and a shared mesh (the liver) on 4x4x4, and the built-in scene on two
/// other machines: the compiler's count equals the independent one exactly (tolerance 0:
/// both count whole vectors of the same scheme), every board holds elements and the
/// balance is within the partitioner's bound, 1.05 (the stated goal). The counts compared
/// are far from zero (over 300 vectors: hundreds of nodes are exchanged), and the refined partition sends fewer
/// vectors than the slab partition it starts from (counted the same independent way).
#[test]
fn exchange_count_matches_an_independent_count() {
    shared_meshes_dir();
    let cases = [
        (
            "builtin medium 4x4x4",
            builtin_problem("medium", 10),
            "4x4x4",
        ),
        ("liver 4x4x4", repo_scene("liver.toml"), "4x4x4"),
        (
            "builtin medium 4x2x2",
            builtin_problem("medium", 10),
            "4x2x2",
        ),
        (
            "builtin coarse 2x3x2",
            builtin_problem("coarse", 10),
            "2x3x2",
        ),
    ];
    for (name, p, m) in cases {
        let machine = Machine::parse(m).expect("machine");
        let (count, element_board, rounds) = compiled(&p, machine, name);
        let independent = independent_vectors(&p, machine, &element_board);
        assert!(count > 300, "{name}: {count} vectors is too few to compare");
        assert_eq!(count, independent, "{name}");
        let b = balance(machine, &element_board);
        assert!(b <= BALANCE_MAX, "{name}: imbalance {b}");
        let start = slabs(&p.mesh, machine).expect("slabs");
        let before = independent_vectors(&p, machine, &start);
        println!("{name}: {before} -> {count} vectors, balance {b:.3}, rounds {rounds:?}");
        assert!(count < before, "{name}: {count} vs the slabs' {before}");
    }
}

/// The seed's reference case (2000 elements, 20x10x10 box, 4x4x4 boards): the seed counts
/// 5600 force vectors per step (issue 15's bound). With the balance bound 1.05 (at most 32
/// elements per board) and the clamped face's nodes not exchanged, the partitioner gets
/// 4702, the busiest link direction 25 (measured; 24 with every line's default root, which
/// the roots chosen for the step's chain of rounds trade for a step over a fifth shorter; with a
/// symmetric exchange along every line of a node's box, the scheme before the
/// reduce-and-broadcast rounds, 5654 and 27). The bounds here, 4720 vectors and 25 on a
/// link, are the measured figures plus 0.4% and exact, so that a change of the annealing's
/// parameters that loses ground is caught. No
/// relays: rounds 0 and 1 along each axis (x's round 1 empty: nothing is summed before x)
/// and the broadcast after the z exchange along x and y.
#[test]
fn seed_box_on_4x4x4() {
    let p = repo_scene("seed-box.toml");
    assert_eq!(p.mesh.cells.len(), 2000);
    let machine = Machine::parse("4x4x4").expect("machine");
    let (count, element_board, rounds) = compiled(&p, machine, "seed-box");
    assert_eq!(count, independent_vectors(&p, machine, &element_board));
    let b = balance(machine, &element_board);
    let link_max = compiled_link_max(&p, machine);
    println!(
        "seed box: {count} vectors, busiest link {link_max}, balance {b:.3}, rounds {rounds:?}"
    );
    assert!(b <= BALANCE_MAX, "imbalance {b}");
    assert!(count > 4000 && count <= 4720, "{count} vectors");
    assert!(link_max > 10 && link_max <= 25, "busiest link {link_max}");
    assert_eq!(rounds, [3, 3, 2]);
}

/// The busiest link direction's vectors per step, from the plan's send lists (each round
/// sends one frame per face; a link direction is a board's face).
fn compiled_link_max(problem: &Problem, machine: Machine) -> usize {
    let plan = plan(problem, machine).expect("plans");
    assert_eq!(plan.boards.len(), machine.count());
    plan.boards
        .iter()
        .flat_map(|b| {
            (0..6).map(move |face| {
                b.rounds[face / 2]
                    .iter()
                    .map(|r| r.send[face % 2].len())
                    .sum::<usize>()
            })
        })
        .max()
        .unwrap_or(0)
}

/// A held node (fixed or prescribed) is in no exchange list and is on exactly the boards
/// whose elements touch it (not on the rest of their box): on the seed box, whose clamped
/// face at x = 0 is cut by the boards of the x = 0 slab, over 20 held nodes are shared by
/// two boards or more (so the property is not met by having none), and every free node
/// shared by boards is still exchanged (a board with an element at a free node it shares
/// sends it).
#[test]
fn held_nodes_are_not_exchanged() {
    let p = repo_scene("seed-box.toml");
    let machine = Machine::parse("4x4x4").expect("machine");
    let plan = plan(&p, machine).expect("plans");
    assert_eq!(plan.element_board.len(), p.mesh.cells.len());
    let mut touching: Vec<Vec<usize>> = vec![Vec::new(); p.mesh.nodes.len()];
    for (cell, &b) in p.mesh.cells.iter().zip(&plan.element_board) {
        for &n in cell {
            touching[n as usize].push(b as usize);
        }
    }
    for t in &mut touching {
        t.sort_unstable();
        t.dedup();
    }
    let mut holding: Vec<Vec<usize>> = vec![Vec::new(); p.mesh.nodes.len()];
    let mut sent = vec![false; p.mesh.nodes.len()];
    for (b, bp) in plan.boards.iter().enumerate() {
        for &n in &bp.nodes {
            holding[n as usize].push(b);
        }
        for r in bp.rounds.iter().flatten() {
            for &n in r.send.iter().flatten() {
                sent[n as usize] = true;
            }
            for &(n, _) in r.recv.iter().flatten() {
                sent[n as usize] = true;
            }
        }
    }
    let mut shared_held = 0;
    for n in 0..p.mesh.nodes.len() {
        if p.node_kind[n] == NodeKind::Free {
            assert_eq!(sent[n], touching[n].len() > 1, "free node {n}");
        } else {
            assert!(!sent[n], "held node {n} is exchanged");
            assert_eq!(holding[n], touching[n], "held node {n}");
            shared_held += usize::from(touching[n].len() > 1);
        }
    }
    println!("{shared_held} held nodes shared by boards");
    assert!(
        shared_held > 20,
        "{shared_held} held nodes shared by boards"
    );
}

/// The partition is the same on every run (the annealing's seed is fixed).
#[test]
fn partition_is_deterministic() {
    let p = builtin_problem("coarse", 10);
    let machine = Machine::parse("2x2x2").expect("machine");
    let a = host_tools::compile::partition::partition(&p.mesh, machine).expect("partition");
    let b = host_tools::compile::partition::partition(&p.mesh, machine).expect("partition");
    assert_eq!(a.len(), p.mesh.cells.len());
    assert!(a.iter().any(|&x| x != a[0]), "more than one board used");
    assert_eq!(a, b);
}

/// Balancing cost: each element weighs its kernel's measured instructions (parallelepiped
/// or general, `measured_cost` for the scene's precision) plus, for each of its corners on
/// a contact surface, the contact cost over the elements around that corner; computed here
/// from the mesh, the cells' geometry and the contact node list. On the built-in medium scene (both
/// kernels and contact, so the weights differ by over 1.4x) on 4x4x4 and the built-in coarse
/// scene on 2x3x2, the cost partition keeps every board within `BALANCE_MAX` of the mean
/// cost (the element partition does not: the contact nodes crowd a few boards), every
/// board non-empty, and its exchange count is the independent one.
#[test]
fn balancing_cost_keeps_every_boards_cost_within_the_bound() {
    use host_tools::compile::{plan_balanced, Balance};
    use pe_firmware::profile::measured_cost;
    for (name, p, m) in [
        (
            "builtin medium 4x4x4",
            builtin_problem("medium", 10),
            "4x4x4",
        ),
        (
            "builtin coarse 2x3x2",
            builtin_problem("coarse", 10),
            "2x3x2",
        ),
    ] {
        let machine = Machine::parse(m).expect("machine");
        let cost = measured_cost(p.solver.precision, p.solver.integration);
        let mut valence = vec![0usize; p.mesh.nodes.len()];
        for c in &p.mesh.cells {
            for &n in c {
                valence[n as usize] += 1;
            }
        }
        let contact = &p.contact.as_ref().expect("contact").node_globals;
        let w: Vec<f64> = p
            .mesh
            .cells
            .iter()
            .enumerate()
            .map(|(e, c)| {
                let r = p.reference[e].hex().expect("a hexahedral mesh");
                let k = if !r.is_parallelepiped() {
                    cost.per_element_step
                } else if r.is_cuboid() {
                    cost.cuboid_per_element_step
                } else {
                    cost.box_per_element_step
                } as f64;
                k + c
                    .iter()
                    .filter(|n| contact.contains(n))
                    .map(|&n| cost.per_contact_node as f64 / valence[n as usize] as f64)
                    .sum::<f64>()
            })
            .collect();
        let (lo, hi) = w
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
        assert!(hi > 1.4 * lo, "{name}: weights {lo}..{hi} differ");
        let load = |board: &[u32]| {
            assert_eq!(board.len(), w.len());
            let mut l = vec![0.0; machine.count()];
            for (&b, &x) in board.iter().zip(&w) {
                l[b as usize] += x;
            }
            let mean = l.iter().sum::<f64>() / l.len() as f64;
            l.iter().copied().fold(0.0, nan_max) / mean
        };
        let by_cost = plan_balanced(&p, machine, Balance::Cost).expect("plans");
        let by_elements = plan_balanced(&p, machine, Balance::Elements).expect("plans");
        assert_eq!(by_cost.balance, Balance::Cost);
        balance(machine, &by_cost.element_board); // every board non-empty
        let (c, e) = (
            load(&by_cost.element_board),
            load(&by_elements.element_board),
        );
        println!("{name}: cost imbalance {c:.3} balancing cost, {e:.3} balancing elements");
        // Rounding the weights to whole instructions moves the bound by under 1e-3.
        assert!(c <= BALANCE_MAX + 1e-3, "{name}: cost imbalance {c}");
        assert!(
            e > c,
            "{name}: balancing cost balances cost better ({c} vs {e})"
        );
        let images = compile_images(&p, &by_cost).expect("images");
        let rep = report(name, &p, &by_cost, &images, &PE_BOARD).expect("report");
        assert_eq!(
            rep.force_vectors_per_step,
            independent_vectors(&p, machine, &by_cost.element_board),
            "{name}"
        );
    }
}
