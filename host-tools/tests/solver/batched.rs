//! The batched element loop (`problem::batched`) against the scalar loop it replaces
//! (`Elements::internal_forces`, the firmware's kernels one element at a time): the same
//! bits, in f64 and f32, reduced (general, parallelepiped and cuboid kernels) and full
//! integration, on distorted cells, with element counts that are not a multiple of the
//! lane count, laws of several kinds side by side, one element alone, and an inverted
//! element (the same error, naming the same element, and the same forces up to it).
//!
//! Bit-identity is the property (the board computes the scalar loop's bits), so the
//! tolerance is zero; each comparison first checks that the forces are far from trivial.

use host_tools::compare::nan_max;
use host_tools::problem::batched::{Batched, Isa};
use host_tools::problem::elements::{Elements, Hexahedra, Tetrahedra};
use host_tools::problem::Problem;
use pe_firmware::physics::{
    LameParameters, MaterialLaw, PhysicsError, Real, ReferenceHex, Volumetric,
};

/// A seeded generator (SplitMix64), printed seeds are fixed here.
pub(crate) struct Rng(pub(crate) u64);
impl Rng {
    /// Uniform in [-1, 1).
    pub(crate) fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// Three laws of three kinds (a pack never mixes kinds).
fn laws() -> Vec<MaterialLaw<f64>> {
    vec![
        MaterialLaw::NeoHookean(LameParameters::from_young_poisson(3.0e3, 0.45)),
        MaterialLaw::MooneyRivlin {
            c10: 500.0,
            c01: 100.0,
            kappa: 2.0e4,
            volumetric: Volumetric::Log,
        },
        MaterialLaw::NeoHookeanDecoupled {
            mu: 1.0e3,
            kappa: 3.0e4,
        },
    ]
}

/// Material of cell `e`: runs of different lengths, so packs split where the kind changes.
fn material(e: usize) -> u16 {
    match e % 11 {
        0..=5 => 0,
        6 | 7 => 1,
        _ => 2,
    }
}

/// A row of `n` cells (1 cm), nodes shared; `jitter` moves every node by up to that
/// fraction of the cell (distorted cells), 0 leaves parallelepipeds.
fn row(n: usize, jitter: f64, rng: &mut Rng) -> (Vec<[f64; 3]>, Vec<[u32; 8]>) {
    let h = 0.01;
    let mut nodes = Vec::new();
    if n == 0 {
        return (nodes, Vec::new());
    }
    for i in 0..=n {
        for (y, z) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            nodes.push([
                (i as f64 + jitter * rng.next()) * h,
                (y + jitter * rng.next()) * h,
                (z + jitter * rng.next()) * h,
            ]);
        }
    }
    // Gmsh order: bottom face (z = 0) then top, counter-clockwise.
    let cells = (0..n as u32)
        .map(|i| {
            let (a, b) = (4 * i, 4 * (i + 1));
            [a, b, b + 1, a + 1, a + 3, b + 3, b + 2, a + 2]
        })
        .collect();
    (nodes, cells)
}

struct Case<T> {
    elements: Elements<T>,
    laws: Vec<MaterialLaw<T>>,
    u: Vec<[T; 3]>,
}

/// `general` distorted cells and `boxes` undistorted ones (reduced), or all of them full:
/// the first `boxes / 2` of these turned by 30° about x (parallelepipeds), the others
/// axis-aligned (cuboids).
fn case<T: Real>(general: usize, boxes: usize, full: bool, seed: u64) -> Case<T> {
    let mut rng = Rng(seed);
    let (mut nodes, mut cells) = row(general, 0.15, &mut rng);
    let turned = boxes / 2;
    let (s, c) = (0.5f64, 0.75f64.sqrt());
    for (n, y, turn) in [(turned, 0.05, true), (boxes - turned, 0.1, false)] {
        let (bn, bc) = row(n, 0.0, &mut rng);
        let off = nodes.len() as u32;
        nodes.extend(bn.iter().map(|x| match turn {
            true => [x[0], c * x[1] - s * x[2] + y, s * x[1] + c * x[2]],
            false => [x[0], x[1] + y, x[2]],
        }));
        cells.extend(bc.iter().map(|c| c.map(|n| n + off)));
    }
    let laws64 = laws();
    let refs: Vec<ReferenceHex> = cells
        .iter()
        .map(|c| ReferenceHex::new(&c.map(|n| nodes[n as usize])).expect("valid cell"))
        .collect();
    let elements = if full {
        Elements {
            hexes: Hexahedra::Full {
                records: refs
                    .iter()
                    .zip(&cells)
                    .enumerate()
                    .map(|(e, (r, c))| r.full(*c, material(e)))
                    .collect(),
                cells: (0..cells.len() as u32).collect(),
            },
            tets: Tetrahedra::default(),
        }
    } else {
        let k = |e: usize| laws64[material(e) as usize].hourglass_modulus();
        let g: Vec<_> = (0..general)
            .map(|e| refs[e].reduced(cells[e], material(e), k(e), 0.1))
            .collect();
        let b: Vec<_> = (general..general + turned)
            .map(|e| {
                assert!(refs[e].is_parallelepiped(), "cell {e} is a parallelepiped");
                assert!(!refs[e].is_cuboid(), "cell {e} is turned");
                refs[e].parallelepiped(cells[e], material(e), k(e), 0.1)
            })
            .collect();
        let q: Vec<_> = (general + turned..general + boxes)
            .map(|e| {
                assert!(refs[e].is_cuboid(), "cell {e} is a cuboid");
                refs[e].cuboid(cells[e], material(e), k(e), 0.1)
            })
            .collect();
        Elements {
            hexes: Hexahedra::Reduced {
                general: g,
                boxes: b,
                cuboids: q,
                cells: (0..(general + boxes) as u32).collect(),
            },
            tets: Tetrahedra::default(),
        }
    };
    let u = (0..nodes.len())
        .map(|_| core::array::from_fn(|_| T::from_f64(2e-3 * rng.next())))
        .collect();
    Case {
        elements,
        laws: laws64.iter().map(|l| l.cast::<T>()).collect(),
        u,
    }
}

/// Every instruction set this CPU runs (the portable lanes, AVX, AVX-512).
fn isas() -> Vec<Isa> {
    let v = Isa::available();
    assert_eq!(v.first(), Some(&Isa::Portable), "{v:?}");
    assert_eq!(v.last(), Some(&Isa::detect()), "{v:?}");
    v
}

/// Which lanes the bit-identity tests of this file run here and which they skip, and why:
/// printed (`scripts/test.sh` shows the line), so a machine that tests less says so. The
/// lanes a CPU lacks cannot run on it (`scripts/lanes-emulated.sh` runs this file again as
/// older CPUs under QEMU, which runs AVX and AVX2, not AVX-512); the AVX lanes run on every
/// x86-64 CPU with AVX, AVX-512 machines included, unless `PE_ISA` caps them.
#[test]
fn lanes_tested_and_skipped_are_named() {
    let run = isas();
    let cap = Isa::cap_from_env().expect("PE_ISA names an instruction set");
    // Narrowest first, as `PE_ISA` caps them.
    let all = [Isa::Portable, Isa::Avx, Isa::Avx512];
    let rank = |i: Isa| all.iter().position(|&a| a == i);
    let mut skipped = Vec::new();
    for isa in all {
        if run.contains(&isa) {
            continue;
        }
        skipped.push(match cap {
            Some(c) if rank(isa) > rank(c) => {
                format!("{} (capped by PE_ISA={})", isa.name(), c.name())
            }
            _ if !cfg!(target_arch = "x86_64") => format!("{} (x86-64 only)", isa.name()),
            _ => format!("{} (this CPU lacks it)", isa.name()),
        });
    }
    if !cfg!(target_arch = "aarch64") {
        skipped.push("neon (aarch64 only: the portable lanes' NEON clone)".into());
    }
    let mut names: Vec<&str> = run.iter().map(|i| i.name()).collect();
    if cfg!(target_arch = "aarch64") {
        names.push("neon (the portable lanes' NEON clone)");
    }
    println!(
        "lanes tested: {}; skipped: {}",
        names.join(", "),
        if skipped.is_empty() {
            "none".into()
        } else {
            skipped.join(", ")
        }
    );
    #[cfg(target_arch = "x86_64")]
    if cap.is_none() && std::arch::is_x86_feature_detected!("avx") {
        assert!(
            run.contains(&Isa::Avx),
            "an AVX CPU must test the AVX lanes: {names:?}"
        );
    }
}

/// Both loops from zero forces; returns (scalar, batched) results and forces.
#[allow(clippy::type_complexity)]
fn both<T: Real>(
    c: &Case<T>,
    isa: Isa,
) -> (
    (Result<(), PhysicsError>, Vec<[T; 3]>),
    (Result<(), PhysicsError>, Vec<[T; 3]>),
) {
    let n = c.u.len();
    let mut fs = vec![[T::ZERO; 3]; n];
    let rs = c.elements.internal_forces(&c.laws, &c.u, &mut fs);
    let b = Batched::build(&c.elements, &c.laws, isa).expect("packs");
    let mut fb = vec![[T::ZERO; 3]; n];
    let rb = b.internal_forces(&c.elements, &c.laws, &c.u, &mut fb);
    ((rs, fs), (rb, fb))
}

fn assert_same_bits<T: Real>(a: &[[T; 3]], b: &[[T; 3]], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let max = a
        .iter()
        .flatten()
        .fold(0.0, |m, v| nan_max(m, v.to_f64().abs()));
    let nonzero = a.iter().flatten().filter(|v| v.to_f64() != 0.0).count();
    // Displacements of 2e-3 m on 1 cm cells of kPa materials: forces of order 1e-2 N.
    assert!(max > 1e-5, "{what}: forces are trivial (max {max:e})");
    assert!(
        nonzero == 3 * a.len(),
        "{what}: {nonzero} of {} components non-zero",
        3 * a.len()
    );
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        for i in 0..3 {
            assert_eq!(
                x[i].to_f64().to_bits(),
                y[i].to_f64().to_bits(),
                "{what}: node {k} component {i}: scalar {:e}, batched {:e}",
                x[i].to_f64(),
                y[i].to_f64()
            );
        }
    }
}

fn same_bits_for<T: Real>() {
    // Counts that are multiples of neither 4 nor 8, one element, and only boxes.
    for (general, boxes) in [(13, 11), (1, 0), (0, 1), (0, 21), (29, 0)] {
        for full in [false, true] {
            let c = case::<T>(general, boxes, full, 7 + general as u64);
            for isa in isas() {
                let ((rs, fs), (rb, fb)) = both(&c, isa);
                let what = format!(
                    "{} {} general {general} boxes {boxes} {isa:?}",
                    T::NAME,
                    if full { "full" } else { "reduced" }
                );
                assert_eq!(rs, Ok(()), "{what}: scalar");
                assert_eq!(rb, Ok(()), "{what}: batched");
                assert_same_bits(&fs, &fb, &what);
            }
        }
    }
}

#[test]
fn batched_loop_gives_the_scalar_loops_bits_f64() {
    same_bits_for::<f64>();
}

#[test]
fn batched_loop_gives_the_scalar_loops_bits_f32() {
    same_bits_for::<f32>();
}

/// 13 general cells and 11 boxes (or 24 full) with cell 6 folded (general, lane 2 of the
/// second pack of 4, the first of 8): its top face (nodes of x-station 7, z = 1) pushed
/// through its bottom.
fn folded_case<T: Real>(full: bool) -> Case<T> {
    let mut c = case::<T>(13, 11, full, 3);
    let cell6 = match &c.elements.hexes {
        Hexahedra::Reduced { general, .. } => general[6].connectivity.nodes,
        Hexahedra::Full { records: v, .. } => v[6].connectivity.nodes,
    };
    for &n in &cell6[4..] {
        c.u[n as usize][2] = T::from_f64(-0.03);
    }
    c
}

/// An inverted element in the middle of a pack: the batched loop reports what the scalar
/// loop reports (element, Jacobian), with the same forces added before it.
fn inverted_for<T: Real>() {
    for full in [false, true] {
        let c = folded_case::<T>(full);
        for isa in isas() {
            let ((rs, fs), (rb, fb)) = both(&c, isa);
            let what = format!("{} full {full} {isa:?}", T::NAME);
            let e = rs.expect_err("the scalar loop finds the folded cell");
            match e {
                PhysicsError::InvertedElement { element, .. } => {
                    assert!(element <= 6, "{what}: scalar names element {element}")
                }
                e => panic!("{what}: unexpected {e}"),
            }
            assert_eq!(rb, Err(e), "{what}: the same error");
            assert_eq!(fs.len(), fb.len());
            for (x, y) in fs.iter().flatten().zip(fb.iter().flatten()) {
                assert_eq!(x.to_f64().to_bits(), y.to_f64().to_bits(), "{what}");
            }
            let added = fs.iter().flatten().filter(|v| v.to_f64() != 0.0).count();
            assert!(
                added > 0,
                "{what}: the elements before it added their forces"
            );
        }
    }
}

#[test]
fn an_inverted_element_is_named_as_the_scalar_loop_names_it() {
    inverted_for::<f64>();
    inverted_for::<f32>();
}

/// A node index outside the displacements (the last node dropped: the last cell of the box
/// row, in the last pack, points past the end): the batched loop reports what the scalar
/// loop reports, with the same forces added before it, and reads nothing out of bounds.
fn bad_index_for<T: Real>() {
    for full in [false, true] {
        let mut c = case::<T>(13, 11, full, 5);
        c.u.pop();
        for isa in isas() {
            let ((rs, fs), (rb, fb)) = both(&c, isa);
            let what = format!("{} full {full} {isa:?}", T::NAME);
            let e = rs.expect_err("the scalar loop finds the bad index");
            assert_eq!(e, PhysicsError::BadIndex { element: 23 }, "{what}");
            assert_eq!(rb, Err(e), "{what}: the same error");
            assert_eq!(fs.len(), fb.len(), "{what}: lengths");
            let added = fs.iter().flatten().filter(|v| v.to_f64() != 0.0).count();
            assert!(added > 0, "{what}: the elements before it added forces");
            for (x, y) in fs.iter().flatten().zip(fb.iter().flatten()) {
                assert_eq!(x.to_f64().to_bits(), y.to_f64().to_bits(), "{what}");
            }
        }
    }
}

#[test]
fn a_node_outside_the_mesh_is_named_as_the_scalar_loop_names_it() {
    bad_index_for::<f64>();
    bad_index_for::<f32>();
}

/// One board's batches (board-sim: `problem::batched::board`) from zero forces, batch by
/// batch in step order, by the firmware's scalar loop and by the packs; `cuts` are the
/// batch ends (fractions of each list), so batches of 0, 1 and uneven counts occur.
#[allow(clippy::type_complexity)]
fn board_both<T: Real>(
    c: &Case<T>,
    isa: Isa,
    cuts: [f64; 4],
) -> (
    (Result<(), PhysicsError>, Vec<[T; 3]>),
    (Result<(), PhysicsError>, Vec<[T; 3]>),
) {
    use host_tools::problem::batched::board::{BoardBatches, BoardElements};
    use pe_firmware::physics::{HexBox, HexCuboid, HexElement};
    use pe_firmware::runtime::{batch_range, BatchForces, BatchSlices, ScalarBatches};
    fn run<T: Real, E: HexElement<T>>(
        k: &impl BatchForces<T, E>,
        board: &BoardElements<'_, T, E>,
        c: &Case<T>,
    ) -> (Result<(), PhysicsError>, Vec<[T; 3]>) {
        let mut f = vec![[T::ZERO; 3]; c.u.len()];
        for b in 0..4 {
            let (g, x, q) = (
                batch_range(board.general_ends, b),
                batch_range(board.box_ends, b),
                batch_range(board.cuboid_ends, b),
            );
            let slices = BatchSlices {
                index: b,
                first_general: g.start as u32,
                general: &board.general[g],
                first_box: (board.general.len() + x.start) as u32,
                boxes: &board.boxes[x],
                first_cuboid: (board.general.len() + board.boxes.len() + q.start) as u32,
                cuboids: &board.cuboids[q],
            };
            let r = k.batch_forces(slices, board.laws, &c.u, &mut f);
            if r.is_err() {
                return (r, f);
            }
        }
        (Ok(()), f)
    }
    fn both_of<T: Real + 'static, E: HexElement<T> + Copy + 'static>(
        general: &[E],
        boxes: &[HexBox<T>],
        cuboids: &[HexCuboid<T>],
        c: &Case<T>,
        isa: Isa,
        cuts: [f64; 4],
    ) -> (
        (Result<(), PhysicsError>, Vec<[T; 3]>),
        (Result<(), PhysicsError>, Vec<[T; 3]>),
    ) {
        let ends = |n: usize| cuts.map(|x| (x * n as f64).round() as u32);
        let board = BoardElements {
            general,
            boxes,
            cuboids,
            laws: &c.laws,
            general_ends: ends(general.len()),
            box_ends: ends(boxes.len()),
            cuboid_ends: ends(cuboids.len()),
        };
        let packed = BoardBatches::build(&board, isa).expect("packs");
        assert!(
            !packed.describe().contains("scalar"),
            "{}: packed for lanes",
            packed.describe()
        );
        (run(&ScalarBatches, &board, c), run(&packed, &board, c))
    }
    match &c.elements.hexes {
        Hexahedra::Reduced {
            general,
            boxes,
            cuboids,
            ..
        } => both_of(general, boxes, cuboids, c, isa, cuts),
        Hexahedra::Full { records: v, .. } => both_of::<T, _>(v, &[], &[], c, isa, cuts),
    }
}

/// board-sim's boards run their batches on the lanes with the bits of the firmware's scalar
/// loop: f64 and f32, reduced (general, parallelepiped and cuboid kernels, laws of three kinds) and
/// full, batches cut unevenly (an empty one, odd counts), from forces far from trivial.
#[test]
fn a_boards_batches_on_lanes_give_the_scalar_loops_bits() {
    fn for_type<T: Real + 'static>() {
        for cuts in [[0.25, 0.5, 0.75, 1.0], [0.0, 0.3, 0.35, 1.0]] {
            for full in [false, true] {
                let c = case::<T>(29, 23, full, 11);
                for isa in isas() {
                    let ((rs, fs), (rb, fb)) = board_both(&c, isa, cuts);
                    let what = format!("board {} full {full} {isa:?} cuts {cuts:?}", T::NAME);
                    assert_eq!(rs, Ok(()), "{what}: scalar");
                    assert_eq!(rb, Ok(()), "{what}: lanes");
                    assert_same_bits(&fs, &fb, &what);
                }
            }
        }
    }
    for_type::<f64>();
    for_type::<f32>();
}

/// An inverted element in a board's batch: the lanes report what the board's scalar loop
/// reports (the element numbered as the board numbers it, its Jacobian), with the same
/// forces added before it.
#[test]
fn an_inverted_element_in_a_boards_batch_is_named_as_the_board_names_it() {
    fn for_type<T: Real + 'static>() {
        for full in [false, true] {
            let c = folded_case::<T>(full);
            for isa in isas() {
                // Cell 6 in the second batch (elements 3 to 8 of 13).
                let ((rs, fs), (rb, fb)) = board_both(&c, isa, [0.25, 0.7, 0.8, 1.0]);
                let what = format!("board {} full {full} {isa:?}", T::NAME);
                match rs {
                    Err(PhysicsError::InvertedElement { element, .. }) => {
                        assert!((3..=6).contains(&element), "{what}: names {element}")
                    }
                    ref e => panic!("{what}: unexpected {e:?}"),
                }
                assert_eq!(rb, rs, "{what}: the same error");
                assert_eq!(fs.len(), fb.len());
                let added = fs.iter().flatten().filter(|v| v.to_f64() != 0.0).count();
                assert!(added > 0, "{what}: the batches before it added forces");
                for (x, y) in fs.iter().flatten().zip(fb.iter().flatten()) {
                    assert_eq!(x.to_f64().to_bits(), y.to_f64().to_bits(), "{what}");
                }
            }
        }
    }
    for_type::<f64>();
    for_type::<f32>();
}

/// The parallel plan (`pe solve --threads N`) checks who owns a node only on the packs
/// that touch a node of an earlier block; the rest add their forces straight in. Counted
/// independently from the mesh: the bench box's cells are all cuboids, packed in mesh
/// order `N` at a time, and block `b` starts at the first pack `p` with
/// `p N parts >= b cells` (the plan's equal split); a pack is checked when one of its
/// cells' nodes belongs to a cell of an earlier block. A cut at a layer boundary checks
/// one layer of `nx ny` cells, so 4 blocks of the 20 000-cell box check about 14%.
#[test]
fn the_parallel_plan_checks_owners_only_where_blocks_meet() {
    use pe_firmware::image::{Integration, Precision};
    for cells in [2000, 20000] {
        let scene =
            host_tools::analysis::bench::bench_scene(cells, Integration::Reduced, Precision::F64)
                .expect("scene");
        let p = Problem::from_scene(&scene, std::path::Path::new(".")).expect("problem");
        let elements = Elements::<f64>::build(&p);
        let laws: Vec<MaterialLaw<f64>> = p.laws.iter().map(|l| l.cast::<f64>()).collect();
        for isa in isas() {
            let b = Batched::build(&elements, &laws, isa).expect("packs");
            let lanes = if b.describe().starts_with("f64x4") {
                4
            } else if b.describe().starts_with("f64x8") {
                8
            } else {
                0
            };
            assert!(
                lanes == 4 || lanes == 8,
                "f64 packs 4 or 8 lanes: {}",
                b.describe()
            );
            let count = p.mesh.cells.len();
            let packs = count.div_ceil(lanes);
            for parts in [1, 2, 4, 6] {
                let plan = b
                    .element_loop()
                    .plan(parts, p.mesh.nodes.len())
                    .expect("plan");
                assert_eq!(plan.blocks(), parts, "{count} cells: blocks");
                let block_of = |pack: usize| {
                    (0..parts)
                        .rev()
                        .find(|&b| pack * lanes * parts >= b * count)
                        .unwrap_or(0)
                };
                let mut first = vec![usize::MAX; p.mesh.nodes.len()];
                for (c, nodes) in p.mesh.cells.iter().enumerate() {
                    for &n in nodes {
                        first[n as usize] = first[n as usize].min(block_of(c / lanes));
                    }
                }
                let checked = (0..packs)
                    .filter(|&k| {
                        let cells = &p.mesh.cells[k * lanes..((k + 1) * lanes).min(count)];
                        cells
                            .iter()
                            .flatten()
                            .any(|&n| first[n as usize] < block_of(k))
                    })
                    .count();
                let what = format!("{count} cells, {parts} blocks, {}", b.describe());
                assert_eq!(plan.checked_packs(), (checked, packs), "{what}");
                assert_eq!(checked == 0, parts == 1, "{what}: {checked} checked");
                if count > 20000 && parts <= 4 {
                    // (parts - 1) cuts, each one layer of 44 x 22 cells: 14% at 4 blocks.
                    assert!(checked * 100 <= 15 * packs, "{what}: {checked} of {packs}");
                }
            }
        }
    }
}
