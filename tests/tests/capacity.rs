//! One capacity table: a scene at a capacity limit of the emulated board
//! (`qemu-mps2-an500`, f64 reduced) passes all three deciders, and one over it fails all
//! three, naming the same table and figures: `pe compile`'s fit check, board-sim with
//! board-sized storage, and the firmware's own storage type (`pe-board`'s `BoardStorage`
//! for that profile: fixed-capacity vectors sized by `Capacities::for_board`) loading the
//! image with the firmware's loader.

use board_sim::{load_check, StorageSizing};
use host_tools::compile::partition::Machine;
use host_tools::compile::{compile_images, fit_problems, plan};
use host_tools::problem::Problem;
use host_tools::scene::Scene;
use pe_firmware::image::ImageError;
use pe_firmware::physics::HexReduced;
use pe_firmware::profile::QEMU_MPS2_AN500;
use pe_firmware::runtime::{Capacities, Heapless, Runtime, RuntimeConfig, StorageBuf};

const CAP: Capacities = Capacities::for_board::<f64, HexReduced<f64>>(&QEMU_MPS2_AN500);

/// The firmware's storage for the emulation profile, f64 reduced (as `pe-board/src/config.rs`
/// builds it with features `qemu`).
type FirmwareStorage = StorageBuf<
    Heapless,
    f64,
    HexReduced<f64>,
    { CAP.materials },
    { CAP.elements },
    { CAP.nodes },
    { CAP.exchange },
    { CAP.path_points },
    { CAP.loads },
    { CAP.contact_nodes },
    { CAP.contact_faces },
    { CAP.contact_candidates },
    { CAP.contact_sends },
>;

/// The firmware's verdict: its loader on its storage (on a thread with room for the
/// fixed-capacity storage, 4 MiB of vectors).
fn firmware_verdict(image: Vec<u8>) -> Result<(), ImageError> {
    std::thread::Builder::new()
        .stack_size(256 << 20)
        .spawn(move || {
            let mut buf = Box::new(FirmwareStorage::empty());
            let st = buf
                .fill(&CAP)
                .expect("the firmware's storage fills to its capacity");
            Runtime::<f64, HexReduced<f64>>::load(&image, [0; 3], st, RuntimeConfig::default())
                .map(|_| ())
        })
        .expect("thread")
        .join()
        .expect("no panic")
}

/// A box of `cells` on one board, clamped at z = 0, with extra scene tables.
fn scene(cells: [usize; 3], extra: &str) -> Problem {
    let text = format!(
        r#"
[mesh]
generate = {{ kind = "box", size = [0.03, 0.15, 0.15], cells = [{}, {}, {}] }}

[material]
law = "neo-hookean"
youngs_modulus = 3.0e3
poisson_ratio = 0.45
density = 1000.0

[[fixed]]
box = [[-1.0, -1.0, -1.0], [1.0, 1.0, 1e-9]]

[solver]
steps = 2
{extra}
"#,
        cells[0], cells[1], cells[2]
    );
    let sc = Scene::from_toml(&text).expect("scene parses");
    Problem::from_scene(&sc, std::path::Path::new(".")).expect("scene resolves")
}

/// The three verdicts on a scene compiled for one emulated board: each `None` (fits) or
/// the table, the count and the capacity it names.
fn verdicts(p: &Problem) -> [Option<(String, u32, u32)>; 3] {
    let plan = plan(p, Machine::parse("1x1x1").unwrap()).unwrap();
    let images = compile_images(p, &plan).unwrap();
    assert_eq!(images.len(), 1);
    let fit = fit_problems(&images, &QEMU_MPS2_AN500);
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
    let sim = load_check(&image, [0; 3], StorageSizing::Board(QEMU_MPS2_AN500)).err();
    let firmware = firmware_verdict(image).err();
    [compiler, sim.map(named), firmware.map(named)]
}

fn assert_limit(what: &str, cap: usize, at: &Problem, over: &Problem) {
    let fits = verdicts(at);
    assert_eq!(fits, [None, None, None], "{what} at the limit {cap}");
    let refused = verdicts(over);
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
