//! Criterion benchmark of the element kernel: one element's internal force (reduced with
//! hourglass control, and full 2x2x2) in f64 and f32, at a generic deformed state.
//! `cargo bench -p host-tools --bench element_step`

use criterion::{criterion_group, criterion_main, Criterion};
use pe_firmware::physics::{HexElement, LameParameters, MaterialLaw, Real, ReferenceHex};

fn kernel<T: Real>(c: &mut Criterion) {
    let x: [[f64; 3]; 8] = [
        [0.0, 0.0, 0.0],
        [1.1, 0.1, -0.1],
        [1.3, 0.9, 0.05],
        [-0.1, 1.2, 0.0],
        [0.1, -0.1, 0.9],
        [1.0, 0.0, 1.2],
        [1.2, 1.1, 1.0],
        [0.05, 0.95, 1.1],
    ];
    let r = ReferenceHex::new(&x).expect("valid cell");
    let law = MaterialLaw::NeoHookean(LameParameters::from_young_poisson(3e3, 0.45));
    let modulus = law.hourglass_modulus();
    let law_t = law.cast::<T>();
    let u: [[T; 3]; 8] = core::array::from_fn(|a| {
        core::array::from_fn(|i| T::from_f64(0.01 * ((a * 3 + i) as f64).sin()))
    });
    let reduced = r.reduced::<T>([0; 8], 0, modulus, 0.1);
    let full = r.full::<T>([0; 8], 0);
    c.bench_function(&format!("reduced {}", T::NAME), |b| {
        b.iter(|| reduced.internal_forces(&law_t, std::hint::black_box(&u)))
    });
    c.bench_function(&format!("full {}", T::NAME), |b| {
        b.iter(|| full.internal_forces(&law_t, std::hint::black_box(&u)))
    });
}

fn benches(c: &mut Criterion) {
    kernel::<f64>(c);
    kernel::<f32>(c);
}

criterion_group!(element_step, benches);
criterion_main!(element_step);
