//! Tests across the search and the pair forces, on overlapping grids of quads.

extern crate std;
use super::face::{clearly_outside, QuadBounds};
use super::pairs::{evaluate_kept_pairs_bounded, evaluate_pairs, evaluate_pairs_bounded};
use super::search::{build_candidates, keep_applied_groups};
use super::*;
use std::{vec, vec::Vec};

/// Two overlapping grids of quads (surface 0 facing +z at z = 0, surface 1 facing -z at
/// z = -0.02, shifted half a cell, nodes jittered): every node of each is 0.02 deep in
/// the other. Nodes, faces and the pair (depth_max 0.05).
fn overlapping_grids() -> (Vec<ContactNode>, Vec<ContactFace>, [ContactPair; 1]) {
    let mut seed = 0x5851_f42d_4c95_7f2du64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let (side, h) = (6usize, 0.1);
    let mut nodes = Vec::new();
    let mut faces = Vec::new();
    for (surface, z, shift) in [(0u8, 0.0, 0.0), (1u8, -0.02, 0.5 * h)] {
        let base = nodes.len() as u32;
        for j in 0..side {
            for i in 0..side {
                nodes.push(ContactNode {
                    global: nodes.len() as u32,
                    reference: [
                        i as f64 * h + shift + 0.01 * rnd(),
                        j as f64 * h + shift + 0.01 * rnd(),
                        z + 0.002 * rnd(),
                    ],
                    penalty_n_per_m: 1e3,
                    surfaces: 1 << surface,
                });
            }
        }
        for j in 0..side - 1 {
            for i in 0..side - 1 {
                let k = |a: usize, b: usize| base + (b * side + a) as u32;
                let up = [k(i, j), k(i + 1, j), k(i + 1, j + 1), k(i, j + 1)];
                let down = [up[0], up[3], up[2], up[1]];
                faces.push(ContactFace {
                    nodes: if surface == 0 { up } else { down },
                    surface,
                });
            }
        }
    }
    let pairs = [ContactPair {
        a: 0,
        b: 1,
        depth_max_m: 0.05,
    }];
    (nodes, faces, pairs)
}

/// On [`overlapping_grids`], with a board's share of the nodes applied (a third, by
/// index), the groups [`keep_applied_groups`] keeps give the same forces and
/// statistics, bit for bit, as the whole list (which [`evaluate_pairs`] filters per
/// step), and so does [`evaluate_kept_pairs_bounded`] over them with bounds for only
/// the faces they name (as a board computes them); and the check means something:
/// forces are applied, groups are dropped and some are kept, some faces are not named.
#[test]
fn keeping_the_applied_groups_changes_no_force() {
    let (nodes, faces, pairs) = overlapping_grids();
    let m = ContactModel {
        nodes: &nodes,
        faces: &faces,
        pairs: &pairs,
        tools: &[],
    };
    let pos = |c: usize| nodes.get(c).map(|n| n.reference);
    let mut all = vec![Candidate::default(); 4096];
    let mut boxes = vec![QuadBounds::default(); faces.len()];
    let n = build_candidates(&m, pos, 0.03, &mut boxes, &mut all).expect("room for the candidates");
    all.truncate(n);
    let apply = |c: usize| c.is_multiple_of(3);
    let mut kept = all.clone();
    let k = keep_applied_groups(&m, &mut kept, apply).expect("valid indices");
    kept.truncate(k);
    assert!(0 < k && k < n, "kept {k} of {n} candidates");
    let run = |cands: &[Candidate]| {
        let mut force = vec![[0.0; 3]; nodes.len()];
        let mut stats = ContactStats::default();
        evaluate_pairs(&m, cands, pos, apply, 1.0, &mut force, &mut stats).expect("no error");
        (force, stats)
    };
    let ((f_all, s_all), (f_kept, s_kept)) = (run(&all), run(&kept));
    assert_eq!(f_all.len(), nodes.len());
    assert_eq!(f_kept.len(), nodes.len());
    let applied = f_all.iter().filter(|f| f.iter().any(|&v| v != 0.0)).count();
    assert!(applied > 10, "only {applied} nodes got a force");
    assert!(s_all.active > 10, "only {} contacts", s_all.active);
    for (a, b) in f_all.iter().zip(&f_kept) {
        assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
    }
    assert_eq!(s_all, s_kept);
    // The board's way: the kept groups without their test again, with bounds only for
    // the faces they name. The other faces' bounds hold a box far away that rejects
    // every slave: were one read, its face's contacts would be lost.
    let named: Vec<bool> = (0..faces.len())
        .map(|f| kept.iter().any(|c| c.face as usize == f))
        .collect();
    let unnamed = named.iter().filter(|&&u| !u).count();
    assert!(
        0 < unnamed && unnamed < faces.len(),
        "the kept groups name {} of {} faces",
        faces.len() - unnamed,
        faces.len()
    );
    let far = QuadBounds {
        lo: [1e9; 3],
        hi: [1e9; 3],
        edge_slack: 0.0,
    };
    let bounds: Vec<QuadBounds> = (0..faces.len())
        .map(|f| match named[f] {
            true => m.face_bounds(f, &pos).expect("valid face"),
            false => far,
        })
        .collect();
    let mut f_board = vec![[0.0; 3]; nodes.len()];
    let mut s_board = ContactStats::default();
    evaluate_kept_pairs_bounded(
        &m,
        &kept,
        pos,
        &bounds,
        apply,
        1.0,
        &mut f_board,
        &mut s_board,
    )
    .expect("no error");
    assert_eq!(f_board.len(), f_all.len());
    for (a, b) in f_all.iter().zip(&f_board) {
        assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
    }
    assert_eq!(s_all, s_board);
}

/// [`evaluate_pairs_bounded`] gives [`evaluate_pairs`]'s forces and statistics, bit for
/// bit, on [`overlapping_grids`] with a wide search margin (so that many candidates lie
/// outside their face's bounds): with every position known and with every seventh
/// unknown (a partner's node not received: those faces' bounds are
/// [`QuadBounds::UNKNOWN`]), with bounds for every face and for only the first half
/// (the rest take the full test). The check means something: forces are applied, and
/// the bounds decide at least a third of the candidates.
#[test]
fn the_face_bounds_change_no_force() {
    let (nodes, faces, pairs) = overlapping_grids();
    let m = ContactModel {
        nodes: &nodes,
        faces: &faces,
        pairs: &pairs,
        tools: &[],
    };
    for unknown_every in [0usize, 7] {
        let pos = |c: usize| {
            let known = unknown_every == 0 || !c.is_multiple_of(unknown_every);
            nodes.get(c).filter(|_| known).map(|n| n.reference)
        };
        let mut cands = vec![Candidate::default(); 8192];
        let mut boxes = vec![QuadBounds::default(); faces.len()];
        let n = build_candidates(&m, pos, 0.15, &mut boxes, &mut cands)
            .expect("room for the candidates");
        cands.truncate(n);
        let bounds: Vec<QuadBounds> = (0..faces.len())
            .map(|f| m.face_bounds(f, &pos).expect("valid face"))
            .collect();
        assert_eq!(bounds.len(), faces.len());
        // `face_bounds` folds the corners' bounds into their reading: the bounds of the
        // four corners read first, bit for bit, and unknown where a corner is.
        let mut known = 0;
        for (f, b) in bounds.iter().enumerate() {
            let mut q = [[0.0; 3]; 4];
            if m.face_points(f, &pos, &mut q).expect("valid face") {
                let r = QuadBounds::new(&q);
                let bits = |b: &QuadBounds| {
                    (
                        b.lo.map(f64::to_bits),
                        b.hi.map(f64::to_bits),
                        b.edge_slack.to_bits(),
                    )
                };
                assert_eq!(bits(b), bits(&r), "face {f}");
                assert!(r.edge_slack > 0.0, "face {f} has an extent");
                known += 1;
            } else {
                assert!(b.edge_slack.is_nan(), "face {f} has an unknown corner");
            }
        }
        // Every face when all nodes are known; with every seventh node unknown about
        // half of them have a corner unknown.
        let least = if unknown_every == 0 {
            faces.len()
        } else {
            faces.len() / 3
        };
        assert!(known >= least, "{known} of {} faces known", faces.len());
        let depth_max = pairs[0].depth_max_m;
        let decided = cands
            .iter()
            .filter(|c| {
                pos(c.slave as usize)
                    .is_some_and(|x| clearly_outside(x, &bounds[c.face as usize], depth_max))
            })
            .count();
        assert!(
            3 * decided >= n,
            "the bounds decide {decided} of {n} candidates"
        );
        let run = |bounds: Option<&[QuadBounds]>| {
            let mut force = vec![[0.0; 3]; nodes.len()];
            let mut stats = ContactStats::default();
            let all = |_| true;
            match bounds {
                None => evaluate_pairs(&m, &cands, pos, all, 1.0, &mut force, &mut stats),
                Some(b) => {
                    evaluate_pairs_bounded(&m, &cands, pos, b, all, 1.0, &mut force, &mut stats)
                }
            }
            .expect("no error");
            (force, stats)
        };
        let (f_ref, s_ref) = run(None);
        assert_eq!(f_ref.len(), nodes.len());
        let applied = f_ref.iter().filter(|f| f.iter().any(|&v| v != 0.0)).count();
        assert!(applied > 10, "only {applied} nodes got a force");
        for b in [&bounds[..], &bounds[..bounds.len() / 2]] {
            let (f, st) = run(Some(b));
            assert_eq!(f.len(), f_ref.len());
            for (a, b) in f_ref.iter().zip(&f) {
                assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
            }
            assert_eq!(s_ref, st);
        }
    }
}

/// [`search_tests`] counts what the search's doc says it tests: the grids have 6x6 nodes
/// and 5x5 faces per surface, so each direction tests 36 slaves against the master's 25
/// faces (1800 in all, not 3600: the slave's own surface's faces are not tested);
/// without the faces of surface 1 the direction whose master it is tests nothing, and
/// the other 36 slaves against the 25 faces left.
#[test]
fn the_search_tests_are_counted_as_the_search_runs() {
    let (nodes, faces, pairs) = overlapping_grids();
    assert_eq!((nodes.len(), faces.len()), (72, 50));
    let m = ContactModel {
        nodes: &nodes,
        faces: &faces,
        pairs: &pairs,
        tools: &[],
    };
    assert_eq!(search_tests(&m), 2 * 36 * 25);
    let only_0: Vec<ContactFace> = faces.iter().filter(|f| f.surface == 0).copied().collect();
    let m = ContactModel {
        faces: &only_0,
        ..m
    };
    assert_eq!(search_tests(&m), 36 * 25);
}

/// [`build_candidates`] searches over boxes written per part of the faces and sorts;
/// the list must be the one of the search as its doc states it, node by node (written
/// out here, the slave-major loop over the faces' corners): the same candidates in the
/// same order, on [`overlapping_grids`] at three margins, with every node's position
/// known and with every seventh unknown (a partner's node not received), with boxes for
/// every face, for 7 or 1 at a time, or none lent. Non-trivial: candidates are found,
/// and fewer than all node-face pairs. With too little room it reports the same number
/// needed.
#[test]
fn the_face_major_search_gives_the_slave_major_list() {
    let (nodes, faces, pairs) = overlapping_grids();
    let m = ContactModel {
        nodes: &nodes,
        faces: &faces,
        pairs: &pairs,
        tools: &[],
    };
    let slave_major = |pos: &dyn Fn(usize) -> Option<V3>, margin: f64| {
        let mut out = Vec::new();
        for direction in 0..2 * pairs.len() {
            let (slave, master, _) = m.roles(direction).expect("a direction");
            for (s, node) in nodes.iter().enumerate() {
                let Some(x) = pos(s) else { continue };
                if node.surfaces & (1 << slave) == 0 {
                    continue;
                }
                for (f, face) in faces.iter().enumerate() {
                    if face.surface != master || face.nodes.contains(&(s as u32)) {
                        continue;
                    }
                    let q: Option<Vec<V3>> = face.nodes.iter().map(|&c| pos(c as usize)).collect();
                    let Some(q) = q else { continue };
                    let inside = (0..3).all(|i| {
                        let lo = q.iter().map(|p| p[i]).fold(f64::INFINITY, f64::min);
                        let hi = q.iter().map(|p| p[i]).fold(f64::NEG_INFINITY, f64::max);
                        x[i] >= lo - margin && x[i] <= hi + margin
                    });
                    if inside {
                        out.push(Candidate {
                            direction: direction as u16,
                            slave: s as u32,
                            face: f as u32,
                        });
                    }
                }
            }
        }
        out
    };
    let known = |c: usize| nodes.get(c).map(|n| n.reference);
    let some_unknown = |c: usize| {
        if c % 7 == 3 {
            None
        } else {
            nodes.get(c).map(|n| n.reference)
        }
    };
    let all_pairs = nodes.len() * faces.len();
    for margin in [0.025, 0.05, 0.12] {
        for (name, pos) in [
            ("known", &known as &dyn Fn(usize) -> Option<V3>),
            ("some unknown", &some_unknown),
        ] {
            let want = slave_major(pos, margin);
            assert!(
                20 < want.len() && want.len() < all_pairs / 2,
                "{name}, margin {margin}: {} candidates",
                want.len()
            );
            assert!(faces.len() > 7, "the parts of 7 faces split the faces");
            for lent in [faces.len(), 7, 1, 0] {
                let mut boxes = vec![QuadBounds::default(); lent];
                let mut got = vec![Candidate::default(); all_pairs];
                let n = build_candidates(&m, pos, margin, &mut boxes, &mut got).expect("room");
                got.truncate(n);
                assert_eq!(
                    got.len(),
                    want.len(),
                    "{name}, margin {margin}, {lent} boxes"
                );
                assert_eq!(got, want, "{name}, margin {margin}, {lent} boxes");
                let mut small = vec![Candidate::default(); want.len() - 1];
                assert_eq!(
                    build_candidates(&m, pos, margin, &mut boxes, &mut small),
                    Err(want.len()),
                    "{name}, margin {margin}, {lent} boxes"
                );
            }
        }
    }
}

/// A node under the ridge of two faces tilted alike is at equal depths in exact
/// arithmetic: the lower face index wins whichever way round-off tips the depths
/// (a shift of 1e-13 m across the ridge changes the depths by 2e-14 m), so the serial run and the boards agree.
#[test]
fn equal_depths_are_a_tie_won_by_the_lower_face() {
    // A roof: faces 0 (x ≤ 0) and 1 (x ≥ 0) rising to a ridge along y at z = 0.1.
    let nodes: [V3; 6] = [
        [-1.0, 0.0, 0.0],
        [0.0, 0.0, 0.1],
        [0.0, 1.0, 0.1],
        [-1.0, 1.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
    ];
    let table: [ContactNode; 7] = core::array::from_fn(|i| ContactNode {
        global: i as u32,
        reference: if i < 6 { nodes[i] } else { [0.0; 3] },
        penalty_n_per_m: 1.0,
        surfaces: if i < 6 { 1 } else { 2 },
    });
    let faces = [
        ContactFace {
            nodes: [0, 1, 2, 3],
            surface: 0,
        },
        ContactFace {
            nodes: [1, 4, 5, 2],
            surface: 0,
        },
    ];
    let pairs = [ContactPair {
        a: 1,
        b: 0,
        depth_max_m: 0.5,
    }];
    let m = ContactModel {
        nodes: &table,
        faces: &faces,
        pairs: &pairs,
        tools: &[],
    };
    let candidates = [
        Candidate {
            direction: 0,
            slave: 6,
            face: 0,
        },
        Candidate {
            direction: 0,
            slave: 6,
            face: 1,
        },
    ];
    for shift in [-1e-13, 0.0, 1e-13] {
        let slave = [shift, 0.5, 0.05];
        let pos = |c: usize| Some(if c < 6 { nodes[c] } else { slave });
        let mut force = [[0.0; 3]; 7];
        let mut stats = ContactStats::default();
        evaluate_pairs(&m, &candidates, pos, |_| true, 1.0, &mut force, &mut stats)
            .expect("evaluates");
        // Face 0's outward normal leans to −x: the slave is pushed that way.
        assert!(force[6][0] < 0.0, "shift {shift:e}: {:?}", force[6]);
        assert_eq!(force[4], [0.0; 3], "face 1's own node takes nothing");
    }
}
