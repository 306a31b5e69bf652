//! The tetrahedra's cost on the board (run under QEMU with the insncount plugin, see
//! `scripts/board-cost.sh`). The boards do not load tetrahedra yet; this measures their
//! kernels, the shared code, on [`TetSample`] (a deformed Kuhn patch), bracketed with calls
//! of `bench_mark` (the plugin prints the executed instruction count at each call,
//! numbered from 0):
//!
//! * marks 0→1: two back-to-back marks, the marker's own overhead;
//! * marks 2→3: `Tet4::internal_forces` of every tetrahedron, displacements gathered
//!   beforehand (the plain kernel alone);
//! * marks 4→5: the plain loop ([`TetPressure::Element`]: gather, kernel, scatter);
//! * marks 6→7: the T4ANP loop ([`TetPressure::Nodal`]: the nodal passes, then each
//!   element's isochoric stress with the mean nodal pressure, gather and scatter).
//!
//! Then prints `tet-bench,PRECISION,TETS,NODES,DIGEST_PLAIN,DIGEST_NODAL` (the digests of
//! the two loops' forces: [`digest`]) via semihosting and exits. Inputs pass through
//! `black_box` so nothing is folded at build time.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use pe_board::config::Scalar;
use pe_board::report;
use pe_firmware::physics::element::Scratch;
use pe_firmware::physics::{Real, TetPressure};
use pe_firmware::profile::tet_cost::{digest, TetSample, SAMPLE_NODES, SAMPLE_TETS};

#[inline(never)]
#[no_mangle]
pub extern "C" fn bench_mark(id: u32) {
    black_box(id);
}

fn fail(what: &str) -> ! {
    report::fault([0; 3], format_args!("tet bench: {what}"))
}

#[entry]
fn main() -> ! {
    // The firmware's floating-point mode (src/main.rs).
    pe_board::fpu::flush_subnormals();
    let sample = TetSample::<Scalar>::new().unwrap_or_else(|_| fail("sample"));
    let law = &sample.laws[0];
    let mut ues = [[[Scalar::ZERO; 3]; 4]; SAMPLE_TETS];
    for (ue, t) in ues.iter_mut().zip(&sample.tets) {
        *ue = t.nodes.map(|n| sample.u[n as usize]);
    }
    let mut ratio = [Scalar::ZERO; SAMPLE_NODES];
    let mut pressure = [Scalar::ZERO; SAMPLE_NODES];
    let mut plain = [[Scalar::ZERO; 3]; SAMPLE_NODES];
    let mut nodal = [[Scalar::ZERO; 3]; SAMPLE_NODES];

    bench_mark(0);
    bench_mark(1);
    bench_mark(2);
    for (t, ue) in sample.tets.iter().zip(&ues) {
        let f = black_box(t).internal_forces(black_box(law), black_box(ue));
        if black_box(f).is_err() {
            fail("an inverted tetrahedron");
        }
    }
    bench_mark(3);
    let mut run = |form, f: &mut [[Scalar; 3]; SAMPLE_NODES]| {
        let scratch = Scratch {
            ratio: &mut ratio,
            pressure: &mut pressure,
        };
        black_box(sample.tet_loop(form)).accumulate(scratch, black_box(&sample.u), f)
    };
    bench_mark(4);
    let r = run(TetPressure::Element, &mut plain);
    bench_mark(5);
    if r.is_err() {
        fail("plain loop");
    }
    bench_mark(6);
    let r = run(TetPressure::Nodal, &mut nodal);
    bench_mark(7);
    if r.is_err() {
        fail("nodal loop");
    }
    pe_board::log_info!(
        "tet-bench,{},{},{},{:016x},{:016x}",
        if core::mem::size_of::<Scalar>() == 4 {
            "f32"
        } else {
            "f64"
        },
        SAMPLE_TETS,
        SAMPLE_NODES,
        digest(&plain),
        digest(&nodal)
    );
    report::exit(true)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    report::fault([0; 3], format_args!("tet bench panic: {info}"))
}
