//! One capacity table: a scene at a capacity limit of the emulated board
//! (`qemu-mps2-an500`, f64 reduced) passes all three deciders, and one over it fails all
//! three, naming the same table and figures: `pe compile`'s fit check, board-sim with
//! board-sized storage, and the firmware's own storage type (`pe-board`'s `BoardStorage`
//! for that profile: fixed-capacity vectors sized by `Capacities::for_board`) loading the
//! image with the firmware's loader. Elements are checked on the PE board in f64 full (140
//! at this writing: on the emulated board the node table binds first). The exchange tables
//! (4096 entries) are not reachable: a board's 1024 nodes bound its exchange lists first.

use board_sim::{load_check, StorageSizing};
use host_tools::compile::partition::Machine;
use host_tools::compile::{compile_images, fit_problems, plan};
use host_tools::problem::Problem;
use host_tools::scene::Scene;
use pe_firmware::image::ImageError;
use pe_firmware::physics::{HexFull, HexReduced};
use pe_firmware::profile::{BoardProfile, PE_BOARD, QEMU_MPS2_AN500};
use pe_firmware::runtime::{Capacities, Heapless, Runtime, RuntimeConfig, StorageBuf};

/// The firmware's storage type for a profile and variant (as `pe-board/src/config.rs`
/// builds it), and its verdict on an image: its loader on that storage, on a thread with
/// room for the fixed-capacity vectors (megabytes).
macro_rules! firmware {
    ($verdict:ident, $cap:ident, $profile:expr, $t:ty, $e:ty) => {
        const $cap: Capacities = Capacities::for_board::<$t, $e>(&$profile);
        fn $verdict(image: Vec<u8>) -> Result<(), ImageError> {
            type FirmwareStorage = StorageBuf<
                Heapless,
                $t,
                $e,
                { $cap.materials },
                { $cap.elements },
                { $cap.boxes },
                { $cap.cuboids },
                { $cap.nodes },
                { $cap.exchange },
                { $cap.path_points },
                { $cap.loads },
                { $cap.contact_nodes },
                { $cap.contact_faces },
                { $cap.contact_candidates },
                { $cap.contact_sends },
            >;
            std::thread::Builder::new()
                .stack_size(256 << 20)
                .spawn(move || {
                    let mut buf = Box::new(FirmwareStorage::empty());
                    let st = buf
                        .fill(&$cap)
                        .expect("the firmware's storage fills to its capacity");
                    Runtime::<$t, $e>::load(&image, [0; 3], st, RuntimeConfig::default())
                        .map(|_| ())
                })
                .expect("thread")
                .join()
                .expect("no panic")
        }
    };
}

firmware!(qemu_f64_reduced, CAP, QEMU_MPS2_AN500, f64, HexReduced<f64>);
firmware!(board_f64_full, CAP_FULL, PE_BOARD, f64, HexFull<f64>);
firmware!(board_f64_reduced, CAP_BOARD, PE_BOARD, f64, HexReduced<f64>);

/// A box of `cells` on one board, clamped at z = 0, with extra scene tables.
fn scene(cells: [usize; 3], extra: &str) -> Problem {
    let mesh = format!(
        "generate = {{ kind = \"box\", size = [0.03, 0.15, 0.15], cells = [{}, {}, {}] }}",
        cells[0], cells[1], cells[2]
    );
    scene_with(&mesh, MATERIAL, extra)
}

/// One soft material for the whole mesh.
const MATERIAL: &str =
    "[material]\nlaw = \"neo-hookean\"\nyoungs_modulus = 3.0e3\npoisson_ratio = 0.45\ndensity = 1000.0\n";

/// A scene of `mesh` (the `[mesh]` table's keys) with the `material` tables.
fn scene_with(mesh: &str, material: &str, extra: &str) -> Problem {
    let sc = scene_text(mesh, material, extra);
    Problem::from_scene(&sc, std::path::Path::new(".")).expect("scene resolves")
}

/// [`scene_with`]'s scene, unresolved.
fn scene_text(mesh: &str, material: &str, extra: &str) -> Scene {
    let text = format!(
        r#"
[mesh]
{mesh}

{material}

[[fixed]]
box = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1e-9]]

[solver]
steps = 2
{extra}
"#
    );
    Scene::from_toml(&text).expect("scene parses")
}

/// The three verdicts on a scene compiled for one emulated board: each `None` (fits) or
/// the table, the count and the capacity it names.
fn verdicts(
    p: &Problem,
    profile: BoardProfile,
    firmware: fn(Vec<u8>) -> Result<(), ImageError>,
) -> [Option<(String, u32, u32)>; 3] {
    let plan = plan(p, Machine::parse("1x1x1").unwrap()).unwrap();
    let images = compile_images(p, &plan).unwrap();
    assert_eq!(images.len(), 1);
    let fit = fit_problems(&images, &profile);
    let compiler = fit.first().map(|line| {
        // "board (0,0,0): N WHAT exceed the MAX the PROFILE firmware holds, ..."
        let rest = line.split(": ").nth(1).expect("a located line");
        let mut words = rest.split(" exceed the ");
        let (n_what, max) = (words.next().unwrap(), words.next().unwrap());
        let (n, what) = n_what.split_once(' ').unwrap();
        let max = max.split(' ').next().unwrap();
        (what.to_string(), n.parse().unwrap(), max.parse().unwrap())
    });
    let named = |e: ImageError| match e {
        ImageError::Capacity { what, count, max } => (what.to_string(), count, max),
        e => panic!("not a capacity error: {e}"),
    };
    let image = images[0].bytes.clone();
    let sim = load_check(&image, [0; 3], StorageSizing::Board(profile)).err();
    [compiler, sim.map(named), firmware(image).err().map(named)]
}

fn assert_limit(what: &str, cap: usize, at: &Problem, over: &Problem) {
    assert_limit_on(what, cap, at, over, QEMU_MPS2_AN500, qemu_f64_reduced);
}

fn assert_limit_on(
    what: &str,
    cap: usize,
    at: &Problem,
    over: &Problem,
    profile: BoardProfile,
    firmware: fn(Vec<u8>) -> Result<(), ImageError>,
) {
    let fits = verdicts(at, profile, firmware);
    assert_eq!(fits, [None, None, None], "{what} at the limit {cap}");
    let refused = verdicts(over, profile, firmware);
    let expected = Some((what.to_string(), cap as u32 + 1, cap as u32));
    assert_eq!(
        refused,
        [expected.clone(), expected.clone(), expected],
        "{what} over the limit"
    );
}

#[test]
fn the_capacity_table_is_the_same_for_compiler_board_sim_and_firmware() {
    // The table is not trivial: the profile's figures, and elements from the RAM.
    assert_eq!((CAP.nodes, CAP.loads, CAP.path_points), (1024, 256, 64));
    const { assert!(CAP.elements > 1000) };

    // Nodes: 4 x 16 x 16 = 1024 fit, 5 x 5 x 41 = 1025 do not.
    assert_eq!(scene([3, 15, 15], "").mesh.nodes.len(), 1024);
    assert_eq!(scene([4, 4, 40], "").mesh.nodes.len(), 1025);
    assert_limit(
        "nodes",
        CAP.nodes,
        &scene([3, 15, 15], ""),
        &scene([4, 4, 40], ""),
    );

    // Loads: the x = 0 plane holds 16 x 16 = 256 nodes; one more load on a corner.
    let plane =
        "[[load]]\nbox = [[-1.0, -1.0, -1.0], [1e-9, 1.0, 1.0]]\nforce = [0.0, 0.0, -0.01]\n";
    let corner = "[[load]]\nsphere = { center = [0.03, 0.15, 0.15], radius = 1e-6 }\nforce = [0.0, 0.0, -0.01]\n";
    let (at, over) = (
        scene([3, 15, 15], plane),
        scene([3, 15, 15], &format!("{plane}{corner}")),
    );
    assert_eq!((at.loads.len(), over.loads.len()), (256, 257));
    assert_limit("loads", CAP.loads, &at, &over);

    // Path points: a prescribed path of 64 points fits, of 65 does not.
    let path = |n: usize| {
        let pts: Vec<String> = (0..n)
            .map(|k| format!("[{}, 0.0, 0.0, {}]", k as f64 * 1e-3, -(k as f64) * 1e-6))
            .collect();
        format!(
            "[[prescribed]]\nbox = [[0.0299, -1.0, 0.001], [1.0, 1.0, 1.0]]\npath = [{}]\n",
            pts.join(", ")
        )
    };
    assert_limit(
        "path points",
        CAP.path_points,
        &scene([3, 15, 15], &path(64)),
        &scene([3, 15, 15], &path(65)),
    );
}

/// `[mesh] blocks` of 10 mm cubes side by side along x, with these cells.
fn blocks(cells: &[[usize; 3]]) -> String {
    let list: Vec<String> = cells
        .iter()
        .enumerate()
        .map(|(k, c)| {
            format!(
                "{{ name = \"b{k}\", origin = [{}, 0.0, 0.0], size = [0.01, 0.01, 0.01], cells = [{}, {}, {}] }}",
                0.02 * k as f64,
                c[0],
                c[1],
                c[2]
            )
        })
        .collect();
    format!("blocks = [{}]", list.join(", "))
}

/// `scene_with`'s scene with every node sheared (x += 0.3 z): each cell an affine
/// parallelepiped that is not axis-aligned (the parallelepiped kernel's).
fn sheared(mesh: &str) -> Problem {
    let sc = scene_text(mesh, MATERIAL, "");
    let p = Problem::from_scene(&sc, std::path::Path::new(".")).expect("scene resolves");
    let mut mesh = p.mesh.clone();
    for x in &mut mesh.nodes {
        x[0] += 0.3 * x[2];
    }
    Problem::new(&sc, mesh, p.node_sets.clone()).expect("the sheared scene resolves")
}

#[test]
fn parallelepipeds_and_cuboids_at_their_limits_on_the_pe_board() {
    // The PE board's own tables (f64, reduced integration): 128 parallelepipeds and 256
    // cuboids, each bound before the nodes (512) or the general elements.
    const { assert!(CAP_BOARD.boxes == 128 && CAP_BOARD.cuboids == 256) };
    const { assert!(CAP_BOARD.nodes == 512 && CAP_BOARD.elements > 200) };
    let (at, over) = (blocks(&[[8, 8, 4]]), blocks(&[[8, 8, 4], [1, 1, 1]]));
    let (at_c, over_c) = (
        scene_with(&at, MATERIAL, ""),
        scene_with(&over, MATERIAL, ""),
    );
    assert_eq!((at_c.mesh.cells.len(), over_c.mesh.cells.len()), (256, 257));
    assert!(
        over_c.mesh.nodes.len() <= 512,
        "the node table must not bind first"
    );
    assert_limit_on("cuboids", 256, &at_c, &over_c, PE_BOARD, board_f64_reduced);

    let (at, over) = (blocks(&[[8, 4, 4]]), blocks(&[[8, 4, 4], [1, 1, 1]]));
    let (at_b, over_b) = (sheared(&at), sheared(&over));
    assert_eq!((at_b.mesh.cells.len(), over_b.mesh.cells.len()), (128, 129));
    assert_limit_on(
        "parallelepipeds",
        128,
        &at_b,
        &over_b,
        PE_BOARD,
        board_f64_reduced,
    );
}

#[test]
fn elements_and_materials_at_their_limits() {
    // Elements (PE board, f64 full): blocks of exactly the capacity (a q x q x 1 square
    // and a row of the rest), then one cell more in a block of its own.
    const { assert!(CAP_FULL.elements > 100 && CAP_FULL.elements < 400) };
    let n = CAP_FULL.elements;
    let q = (1..=n).rev().find(|q| q * q <= n).unwrap();
    let mut at_blocks = vec![[q, q, 1]];
    if n > q * q {
        at_blocks.push([n - q * q, 1, 1]);
    }
    let mut over_blocks = at_blocks.clone();
    over_blocks.push([1, 1, 1]);
    let full = "integration = \"full\"";
    let at = scene_with(&blocks(&at_blocks), MATERIAL, full);
    let over = scene_with(&blocks(&over_blocks), MATERIAL, full);
    assert_eq!((at.mesh.cells.len(), over.mesh.cells.len()), (n, n + 1));
    assert!(
        over.mesh.nodes.len() <= 1024,
        "the node table must not bind first"
    );
    assert_limit_on("elements", n, &at, &over, PE_BOARD, board_f64_full);

    // Materials: one block and one material (each of its own stiffness) per region.
    const { assert!(CAP.materials == 8) };
    let materials = |k: usize| {
        let cells = vec![[1, 1, 1]; k];
        let tables: Vec<String> = (0..k)
            .map(|m| {
                format!(
                    "[[material]]\nregion = \"b{m}\"\nlaw = \"neo-hookean\"\nyoungs_modulus = {}\npoisson_ratio = 0.45\ndensity = 1000.0\n",
                    3.0e3 + 100.0 * m as f64
                )
            })
            .collect();
        (blocks(&cells), tables.join("\n"))
    };
    let (mesh8, mat8) = materials(CAP.materials);
    let (mesh9, mat9) = materials(CAP.materials + 1);
    let at = scene_with(&mesh8, &mat8, "");
    let over = scene_with(&mesh9, &mat9, "");
    assert_eq!((at.laws.len(), over.laws.len()), (8, 9));
    assert_limit("materials", CAP.materials, &at, &over);
}
