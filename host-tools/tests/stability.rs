//! The stability suite at the extremes (issue "speed/accuracy trade and stability").
//!
//! Each case lives in `host_tools::stability`, where its expected outcome, its measured
//! figures and every bound with its reason are written down; `pe stability` prints the same
//! cases as a report. A test here runs one case and asserts that every check held.
//! The 1e7-step run is `#[ignore]` (about 90 s): `cargo test --release -p host-tools --test
//! stability -- --ignored` or `pe stability --long`.

use host_tools::stability;

/// ν = 0.49: stable, step follows the bulk wave speed, no locking, energy conserved.
#[test]
fn poisson_0_49() {
    stability::poisson(0.49).unwrap().assert_passed();
}

/// ν = 0.499.
#[test]
fn poisson_0_499() {
    stability::poisson(0.499).unwrap().assert_passed();
}

/// ν = 0.4999 (λ/μ ≈ 5000).
#[test]
fn poisson_0_4999() {
    stability::poisson(0.4999).unwrap().assert_passed();
}

/// 50% uniaxial compression: the fixed step faults, the re-checked one adapts and matches
/// the closed form.
#[test]
fn compression_to_half_height() {
    stability::compression_50().unwrap().assert_passed();
}

/// 180° rigid rotation stays stress free and returns to zero stored energy.
#[test]
fn large_rigid_rotation() {
    stability::rigid_rotation().unwrap().assert_passed();
}

/// 0.5, 0.9, 0.99 of critical: stable with bounded energy.
#[test]
fn dt_below_critical_is_stable() {
    for f in [0.5, 0.9, 0.99] {
        stability::dt_fraction(f).unwrap().assert_passed();
    }
}

/// 1.01, 1.1 of critical: refused; forced, caught within a few hundred steps.
#[test]
fn dt_above_critical_is_refused_or_caught() {
    for f in [1.01, 1.1] {
        stability::dt_fraction(f).unwrap().assert_passed();
    }
}

/// 1e6 undamped steps in f64 and f32: bounded energy, f64 without drift, f32 drift bounded.
#[test]
fn million_steps_bounded_energy_f32_and_f64() {
    stability::long_run(1_000_000).unwrap().assert_passed();
}

/// 1e7 undamped steps (slow: run on request).
#[test]
#[ignore]
fn ten_million_steps_bounded_energy_f32_and_f64() {
    stability::long_run(10_000_000).unwrap().assert_passed();
}

/// 100 load cycles: periodic, no drift, back to rest.
#[test]
fn hundred_load_cycles_without_drift() {
    stability::load_cycles(100).unwrap().assert_passed();
}

/// Stiffness ratio 1000 side by side.
#[test]
fn soft_and_stiff_regions() {
    stability::soft_stiff().unwrap().assert_passed();
}

/// Aspect ratio 10.
#[test]
fn distorted_aspect_ratio_10() {
    stability::distorted_aspect().unwrap().assert_passed();
}

/// Strong skew.
#[test]
fn distorted_strong_skew() {
    stability::distorted_skew().unwrap().assert_passed();
}

/// The stable step under large deformation, re-estimated during the run.
#[test]
fn sagging_cantilever_critical_step_recheck() {
    stability::sagging_cantilever().unwrap().assert_passed();
}

/// Speed, NaN and J ≤ 0 guards each name the step and the node or element.
#[test]
fn runtime_guards_name_the_fault() {
    stability::guards().unwrap().assert_passed();
}
