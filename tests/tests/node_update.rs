//! The board's node update and external forces: free, fixed, prescribed, loaded (one load
//! ramped along a smooth POLY345 step, gravity along a linear ramp) and contact nodes in
//! one scene give the serial
//! solver's bits on one board (displacements,
//! kinetic energy, reactions), and the external-force lists of the images hold exactly the
//! owned nodes that have an external force, once, at the stage the exchange rounds give
//! them, with their own loads and contact node.

use std::collections::BTreeMap;

use board_sim::{run, SimOptions};
use host_tools::compile::partition::Machine;
use host_tools::compile::{compile_images, decode_image, plan, DecodedImage};
use host_tools::problem::{NodeKind, Problem};
use host_tools::solver;
use pe_firmware::image::STAGES;
use system_tests::*;

/// `node_kinds.toml` on one board is the serial run bit for bit, including the kinetic
/// energy (each node's term is the serial solver's, summed in mesh order) and the
/// reactions; on 2x2x2 (loads, contact and held nodes on several boards, replicas) it
/// agrees to round-off, the reactions too (held nodes are not exchanged: each board adds
/// its part of a held node's force, and the boards' sums add up; relative 1e-9 of each
/// reaction's magnitude, which is far from zero, against round-off near 1e-14).
#[test]
fn mixed_node_kinds_equal_serial_bit_for_bit() {
    let (p, src) = file_problem("node_kinds.toml");
    let kinds = |k: fn(&NodeKind) -> bool| p.node_kind.iter().filter(|n| k(n)).count();
    let loaded: std::collections::BTreeSet<u32> = p.loads.iter().map(|l| l.node).collect();
    assert!(kinds(|k| matches!(k, NodeKind::Fixed)) > 0);
    assert!(kinds(|k| matches!(k, NodeKind::Prescribed(_))) > 0);
    assert!(!loaded.is_empty() && loaded.len() < p.mesh.nodes.len() / 4);
    assert!(p.loads.len() > loaded.len(), "a node with two loads");
    let smooth = |l: &host_tools::problem::Load| {
        l.ramp
            .as_ref()
            .is_some_and(|r| r.segment == pe_firmware::image::Segment::Poly345)
    };
    assert!(p.loads.iter().any(smooth), "a load ramped along POLY345");
    let g = p.gravity_ramp.as_ref().expect("gravity ramped");
    assert!(
        g.at(0.0)[0] == 0.25 && g.at(0.02)[0] > 0.5 && g.at(1.0)[0] == 1.0,
        "gravity's ramp moves during the run (700 steps of about 0.14 ms)"
    );
    let serial = solver::run(&p, "serial", &mut ()).unwrap();
    let r = &serial.report;
    let c = r.contact.as_ref().unwrap();
    println!(
        "serial: KE {:e} J, prescribed reaction {:?} N, contacts {}, depth {:e} m",
        r.kinetic_energy_final,
        r.prescribed_reaction_n,
        c.active_contacts_final,
        c.max_penetration_m
    );
    assert!(c.active_contacts_final > 0, "the blocks touch");
    assert!(r.kinetic_energy_final > 0.0 && r.prescribed_reaction_n[2] != 0.0);
    for m in ["1x1x1", "2x2x2"] {
        let dir = compile(&p, &src, m, &format!("node-kinds-{m}"));
        let out = run(&dir, &SimOptions::default(), &mut |_, _| {}).unwrap();
        let d = max_rel_diff(&serial.displacements, &out.displacements);
        println!("{m}: max relative difference {d:e}");
        if m == "1x1x1" {
            assert_bit_identical(&serial.displacements, &out.displacements, m);
            assert_eq!(
                out.kinetic_energy.to_bits(),
                r.kinetic_energy_final.to_bits()
            );
            assert_eq!(
                out.reaction_prescribed.map(f64::to_bits),
                r.prescribed_reaction_n.map(f64::to_bits)
            );
            assert_eq!(
                out.reaction_fixed.map(f64::to_bits),
                r.fixed_reaction_n.map(f64::to_bits)
            );
        }
        assert!(d < 1e-10, "{m}: {d:e}");
        for (name, a, b) in [
            (
                "prescribed",
                out.reaction_prescribed,
                r.prescribed_reaction_n,
            ),
            ("fixed", out.reaction_fixed, r.fixed_reaction_n),
        ] {
            let size = b.iter().map(|v| v * v).sum::<f64>().sqrt();
            assert!(
                size > 1e-6,
                "{m}: the {name} reaction {b:?} N is not trivial"
            );
            for i in 0..3 {
                assert!(
                    (a[i] - b[i]).abs() <= 1e-9 * size,
                    "{m}: {name} reaction {a:?} against the serial {b:?}"
                );
            }
        }
        let ke = (out.kinetic_energy - r.kinetic_energy_final).abs();
        assert!(ke <= 1e-9 * r.kinetic_energy_final, "{m}: KE {ke:e}");
    }
}

/// The stage of each local node, from the decoded exchange rounds alone: the first axis
/// whose lists (sends or receives, any round, either face) hold it, else 3 (before the
/// update).
fn stages_from_rounds(d: &DecodedImage) -> Vec<usize> {
    let mut stage = vec![3usize; d.nodes.len()];
    for a in (0..3).rev() {
        for round in &d.rounds[a] {
            for f in 0..2 {
                let nodes = round.send[f]
                    .iter()
                    .copied()
                    .chain(round.recv[f].iter().map(|e| e.node));
                for l in nodes {
                    stage[l as usize] = a;
                }
            }
        }
    }
    stage
}

/// Checks one problem's images against what the problem says: every owned node with
/// non-zero gravity, a load or a contact node has exactly one external record on its
/// owner, none else has; the record's stage is the one its exchange rounds give, its
/// gravity is the node's, its loads are the node's in the scene's order, its contact node
/// is the node's. Returns the (records, owned nodes) over the machine.
fn check_external_lists(p: &Problem, machine: &str) -> (usize, usize) {
    let plan = plan(p, Machine::parse(machine).unwrap()).unwrap();
    let images = compile_images(p, &plan).unwrap();
    let mut loads_of: BTreeMap<u32, Vec<[f64; 3]>> = BTreeMap::new();
    for l in &p.loads {
        loads_of.entry(l.node).or_default().push(l.force);
    }
    let mut records_of = vec![0usize; p.mesh.nodes.len()];
    let (mut records, mut owned) = (0, 0);
    for im in &images {
        let d = decode_image(&im.bytes, Some(im.header.board)).unwrap();
        let contact_of: BTreeMap<u32, u32> = d
            .contact_nodes
            .iter()
            .enumerate()
            .map(|(c, (n, _))| (n.global, c as u32))
            .collect();
        let stages = stages_from_rounds(&d);
        let mut seen = vec![false; d.nodes.len()];
        assert_eq!(d.loads.len(), d.header.counts.loads as usize);
        for (stage, list) in d.external.iter().enumerate() {
            assert!(stage < STAGES);
            for x in list {
                let k = x.node as usize;
                let n = &d.nodes[k];
                assert!(n.owner, "a record for replica {}", n.global);
                assert!(!seen[k], "node {} twice on one board", n.global);
                seen[k] = true;
                records_of[n.global as usize] += 1;
                records += 1;
                assert_eq!(stages[k], stage, "node {}", n.global);
                let mass = p.mass[n.global as usize];
                assert_eq!(x.gravity, p.gravity.map(|g| g * mass));
                let first = x.first_load as usize;
                let mine: Vec<[f64; 3]> = d.loads[first..first + x.loads as usize]
                    .iter()
                    .map(|l| {
                        assert_eq!(l.node, x.node);
                        l.force
                    })
                    .collect();
                let want = loads_of.get(&n.global).cloned().unwrap_or_default();
                assert_eq!(mine, want, "loads of node {}", n.global);
                assert_eq!(x.contact, contact_of.get(&n.global).copied());
            }
        }
        for (k, n) in d.nodes.iter().enumerate() {
            owned += n.owner as usize;
            let forced = p
                .gravity
                .iter()
                .any(|&g| g * p.mass[n.global as usize] != 0.0)
                || loads_of.contains_key(&n.global)
                || contact_of.contains_key(&n.global);
            assert_eq!(
                seen[k],
                n.owner && forced,
                "node {} (owner {})",
                n.global,
                n.owner
            );
        }
    }
    assert!(records_of.iter().all(|&r| r <= 1));
    (records, owned)
}

/// The external-force lists, read back from the images: under gravity they cover every
/// owned node exactly once (every node has a force); without it (the built-in scene) only
/// the contact and loaded nodes, and nothing else is touched.
#[test]
fn external_lists_hold_each_forced_owned_node_once_at_its_stage() {
    let (p, _) = file_problem("node_kinds.toml");
    for m in ["1x1x1", "2x2x2", "4x2x1"] {
        let (records, owned) = check_external_lists(&p, m);
        assert_eq!(owned, p.mesh.nodes.len(), "{m}: one owner per node");
        assert_eq!(records, owned, "{m}: under gravity every owned node");
    }
    let p = builtin_problem("coarse", 10);
    let (records, owned) = check_external_lists(&p, "2x2x2");
    let contact = p.contact.as_ref().map_or(0, |c| c.node_globals.len());
    println!("built-in: {records} records, {owned} nodes, {contact} contact nodes");
    assert!(records >= contact && records > 0 && records < owned / 2);
}
