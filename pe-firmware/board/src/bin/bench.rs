//! On-board cost measurement (run under QEMU with the insncount plugin, see
//! `scripts/board-cost.sh`). Loads the schedule image like the firmware, runs all steps but
//! the last, then brackets with calls of `bench_mark` (the plugin prints the executed
//! instruction count at each call, numbered from 0):
//!
//! * marks 0→1: two back-to-back marks, the marker's own overhead;
//! * marks 2→3: `internal_forces` of `SAMPLES` elements spread over the mesh (the element
//!   kernel: strain, stress, forces, hourglass control), on the deformed state;
//! * marks 4→5: `accumulate_internal_forces` over the same elements (kernel plus gathering
//!   displacements and scattering forces: the per-element part of a step);
//! * marks 6→7: one whole step of the runtime (gather, kernel, scatter, external forces,
//!   update; no exchange on a 1x1x1 machine);
//! * marks 8→9 and 10→11: as 2→3 and 4→5, for the parallelepipeds;
//! * marks 12→13 and 14→15: the same for the axis-aligned cuboids (the cheapest kernel);
//! * marks 16→17: the contact evaluation of a step again, at the state after the measured
//!   step (`Runtime::evaluate_contact_again`: positions, travel check, tool and pair tests;
//!   not the check step's search), which the one board owns whole (nothing on a scene
//!   without contact);
//! * marks 18→19: a check step's contact evaluation at the same state
//!   (`Runtime::check_contact_again`: the candidate search and the groups kept, then the
//!   evaluation of 16→17), whose search makes `SEARCH_TESTS` node-face tests
//!   (`Runtime::contact_search_tests`).
//!
//! Marks 2→5 are on the general-kernel elements. Then prints
//! `bench,VARIANT,ELEMENTS,PARALLELEPIPEDS,CUBOIDS,NODES,CONTACT_NODES,SAMPLES,BOX_SAMPLES,CUBOID_SAMPLES,MAX_ABS_U_M,SEARCH_TESTS` via
//! semihosting and exits. Inputs pass
//! through `black_box` so nothing is folded at build time. No SysTick: nothing but the
//! measured code runs between marks.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use pe_board::config::{Element, Scalar, CAPACITIES, VARIANT};
use pe_board::region::{board_position, schedule_image};
use pe_board::{links, report, storage};
use pe_firmware::physics::{accumulate_internal_forces, HexElement, MaterialLaw, Real};
use pe_firmware::runtime::{Environment, Runtime, RuntimeConfig};

/// Elements sampled for the kernel measurement.
const SAMPLES: usize = 16;

#[inline(never)]
#[no_mangle]
pub extern "C" fn bench_mark(id: u32) {
    black_box(id);
}

/// A clock that only counts calls (no interrupts during the measurement; a 1x1x1 machine
/// never waits for a link).
struct CallClock(u64);

impl link_proto::Clock for CallClock {
    fn now_ns(&mut self) -> u64 {
        self.0 += 1;
        self.0
    }
}

impl Environment for CallClock {
    fn idle(&mut self) {}
}

fn fail(what: &str) -> ! {
    report::fault([0; 3], format_args!("bench: {what}"))
}

#[entry]
fn main() -> ! {
    // The firmware's floating-point mode (src/main.rs).
    pe_board::fpu::flush_subnormals();
    let board = board_position().unwrap_or_else(|| fail("identity"));
    let image = schedule_image().unwrap_or_else(|_| fail("no schedule image"));
    let store = storage::take().unwrap_or_else(|| fail("storage"));
    let mut rt = Runtime::<Scalar, Element>::load(image, board, store, RuntimeConfig::default())
        .unwrap_or_else(|e| report::fault(board, format_args!("bench: image refused: {e}")));
    let links = links::take([None; 6]).unwrap_or_else(|| fail("links"));
    let mut env = CallClock(0);
    let steps = rt.header.params.steps;
    while rt.step_index() + 1 < steps {
        if rt.step(links, &mut env).is_err() {
            fail("fault while warming up");
        }
    }

    // The laws, as the runtime loaded them.
    let (elements, loaded_laws) = rt.elements();
    let ne = elements.len();
    let nb = rt.boxes().len();
    let nq = rt.cuboids().len();
    let mut laws: Laws = heapless::Vec::new();
    if laws.extend_from_slice(loaded_laws).is_err() {
        fail("too many materials");
    }
    bench_mark(0);
    bench_mark(1);
    let measured = kernel_and_loop(elements, &laws, rt.displacements(), (2, 4));

    bench_mark(6);
    let r = rt.step(links, &mut env);
    bench_mark(7);
    if r.is_err() {
        fail("fault in the measured step");
    }
    // The plugin numbers marks in call order: these come last.
    let measured_boxes = kernel_and_loop(rt.boxes(), &laws, rt.displacements(), (8, 10));
    let measured_cuboids = kernel_and_loop(rt.cuboids(), &laws, rt.displacements(), (12, 14));
    bench_mark(16);
    let r = rt.evaluate_contact_again();
    bench_mark(17);
    if r.is_err() {
        fail("fault in the measured contact evaluation");
    }
    bench_mark(18);
    let r = rt.check_contact_again();
    bench_mark(19);
    if r.is_err() {
        fail("fault in the measured contact check");
    }

    // The largest displacement component, so a measurement on an undeformed state (where
    // the material law's functions take their cheapest paths) is seen and refused.
    let u_max = rt
        .displacements()
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.to_f64().abs()));
    pe_board::log_info!(
        "bench,{},{},{},{},{},{},{},{},{},{},{}",
        VARIANT,
        ne,
        nb,
        nq,
        rt.header.counts.nodes,
        rt.header.counts.contact_nodes,
        measured,
        measured_boxes,
        measured_cuboids,
        u_max,
        rt.contact_search_tests()
    );
    report::exit(true)
}

type Laws = heapless::Vec<MaterialLaw<Scalar>, { CAPACITIES.materials }>;

/// Measures up to `SAMPLES` of `elements` spread over the list: their kernels between marks
/// `marks.0` and `marks.0 + 1`, then the element loop over them (renumbered onto their own
/// node arrays) between `marks.1` and `marks.1 + 1`. Returns how many were measured (the
/// marks are passed even for none, so the numbering stays fixed).
fn kernel_and_loop<E: HexElement<Scalar> + Copy + Connected>(
    elements: &[E],
    laws: &Laws,
    u: &[[Scalar; 3]],
    marks: (u32, u32),
) -> usize {
    // Stack-frugal: the elements are large (1.6 KB for f64 full) and the statics fill RAM.
    let mut list: heapless::Vec<E, SAMPLES> = heapless::Vec::new();
    let mut ues: heapless::Vec<[[Scalar; 3]; 8], SAMPLES> = heapless::Vec::new();
    let ne = elements.len();
    for (k, e) in elements.iter().enumerate() {
        if k % (ne / SAMPLES).max(1) == 0 && !list.is_full() {
            let ue = e
                .nodes()
                .map(|n| u.get(n as usize).copied().unwrap_or([Scalar::ZERO; 3]));
            let _ = ues.push(ue);
            let _ = list.push(*e);
        }
    }
    bench_mark(marks.0);
    for (e, ue) in list.iter().zip(&ues) {
        let law = laws
            .get(e.material())
            .unwrap_or_else(|| fail("material index"));
        let f = black_box(e).internal_forces(black_box(law), black_box(ue));
        black_box(&f);
    }
    bench_mark(marks.0 + 1);
    let mut ul = [[Scalar::ZERO; 3]; 8 * SAMPLES];
    let mut fl = [[Scalar::ZERO; 3]; 8 * SAMPLES];
    for (j, (e, ue)) in list.iter_mut().zip(&ues).enumerate() {
        e.renumber(core::array::from_fn(|a| (8 * j + a) as u32));
        ul[8 * j..8 * j + 8].copy_from_slice(ue);
    }
    bench_mark(marks.1);
    let r = accumulate_internal_forces(
        black_box(&list[..]),
        0,
        black_box(laws),
        black_box(&ul),
        black_box(&mut fl),
    );
    bench_mark(marks.1 + 1);
    black_box(&fl);
    if r.is_err() {
        fail("fault in the element loop");
    }
    list.len()
}

/// Elements whose nodes the bench can renumber.
trait Connected {
    fn renumber(&mut self, nodes: [u32; 8]);
}

impl Connected for Element {
    fn renumber(&mut self, nodes: [u32; 8]) {
        self.connectivity.nodes = nodes;
    }
}

impl Connected for pe_firmware::physics::HexBox<Scalar> {
    fn renumber(&mut self, nodes: [u32; 8]) {
        self.connectivity.nodes = nodes;
    }
}

impl Connected for pe_firmware::physics::HexCuboid<Scalar> {
    fn renumber(&mut self, nodes: [u32; 8]) {
        self.connectivity.nodes = nodes;
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    report::fault([0; 3], format_args!("bench panic: {info}"))
}
