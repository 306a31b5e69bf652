//! Physics tests against closed forms, independent computations and exact solutions.
#![allow(clippy::needless_range_loop)]

use pe_firmware::physics::element::hex::{natural_gradients, NODE_XI};
use pe_firmware::physics::material::cauchy_stress;
use pe_firmware::physics::real::nan_max;
use pe_firmware::physics::tensor::{self, Mat3};
use pe_firmware::physics::{HexElement, LameParameters, MaterialLaw, ReferenceHex, Volumetric};

const E: f64 = 3000.0;
const NU: f64 = 0.45;

fn lame() -> LameParameters<f64> {
    LameParameters::from_young_poisson(E, NU)
}

/// The four laws of the shared reference (E = 3000 Pa, ν = 0.45; c10 = 0.3 μ, c01 = 0.2 μ).
fn laws() -> Vec<(&'static str, MaterialLaw<f64>)> {
    let l = lame();
    let kappa = l.bulk_modulus();
    vec![
        ("nh", MaterialLaw::NeoHookean(l)),
        ("dnh", MaterialLaw::NeoHookeanDecoupled { mu: l.mu, kappa }),
        (
            "mr-q",
            MaterialLaw::MooneyRivlin {
                c10: 0.3 * l.mu,
                c01: 0.2 * l.mu,
                kappa,
                volumetric: Volumetric::Quadratic,
            },
        ),
        (
            "mr-l",
            MaterialLaw::MooneyRivlin {
                c10: 0.3 * l.mu,
                c01: 0.2 * l.mu,
                kappa,
                volumetric: Volumetric::Log,
            },
        ),
    ]
}

/// Independent closed form of the Cauchy stress in terms of `b = F Fᵀ` (spatial form, not
/// the code's material form): nh `σ = μ/J (b − I) + λ ln J / J I`; decoupled laws
/// `σ = 2/J dev((c10 + c01 Ī1) b̄ − c01 b̄²) + p I`.
fn cauchy_closed_form(law: &str, f: &Mat3<f64>) -> Mat3<f64> {
    let l = lame();
    let (mu, lam) = (l.mu, l.lambda);
    let kappa = l.bulk_modulus();
    let j = tensor::det(f);
    let b = tensor::mul(f, &tensor::transpose(f));
    let id = tensor::identity::<f64>();
    let mut s = [[0.0; 3]; 3];
    if law == "nh" {
        for i in 0..3 {
            for k in 0..3 {
                s[i][k] = mu / j * (b[i][k] - id[i][k]) + lam * j.ln() / j * id[i][k];
            }
        }
        return s;
    }
    let (c10, c01) = if law == "dnh" {
        (mu / 2.0, 0.0)
    } else {
        (0.3 * mu, 0.2 * mu)
    };
    let bb: Mat3<f64> =
        core::array::from_fn(|i| core::array::from_fn(|k| j.powf(-2.0 / 3.0) * b[i][k]));
    let i1 = tensor::trace(&bb);
    let bb2 = tensor::mul(&bb, &bb);
    let mut a: Mat3<f64> = core::array::from_fn(|i| {
        core::array::from_fn(|k| (c10 + c01 * i1) * bb[i][k] - c01 * bb2[i][k])
    });
    let tr = tensor::trace(&a) / 3.0;
    for i in 0..3 {
        a[i][i] -= tr;
    }
    let p = if law == "mr-l" {
        kappa * j.ln() / j
    } else {
        kappa * (j - 1.0)
    };
    for i in 0..3 {
        for k in 0..3 {
            s[i][k] = 2.0 / j * a[i][k] + p * id[i][k];
        }
    }
    s
}

fn code_cauchy(law: &MaterialLaw<f64>, f: &Mat3<f64>) -> Mat3<f64> {
    let s = law.second_piola_kirchhoff(f).expect("positive J");
    cauchy_stress(f, &s)
}

fn diag(a: f64, b: f64, c: f64) -> Mat3<f64> {
    [[a, 0.0, 0.0], [0.0, b, 0.0], [0.0, 0.0, c]]
}

fn shear(g: f64) -> Mat3<f64> {
    [[1.0, g, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
}

fn max_abs_diff(a: &Mat3<f64>, b: &Mat3<f64>) -> f64 {
    let mut m: f64 = 0.0;
    for i in 0..3 {
        for k in 0..3 {
            m = nan_max(m, (a[i][k] - b[i][k]).abs());
        }
    }
    m
}

/// Bisection for the lateral stretch t with σ22(diag(l, t, t)) = 0 (closed form).
fn lateral_stretch(law: &str, l: f64) -> f64 {
    let (mut lo, mut hi) = (0.2, 1.2);
    let g = |t: f64| cauchy_closed_form(law, &diag(l, t, t))[1][1];
    assert!(g(lo) * g(hi) < 0.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if g(lo) * g(mid) <= 0.0 {
            hi = mid
        } else {
            lo = mid
        }
    }
    0.5 * (lo + hi)
}

/// Values printed by ../shared/reference/closed_forms.py (numpy/scipy, independent of us):
/// (law, shear g, σ12, σ11) and (law, stretch l, t, σ11). Printed to 1e-6 Pa.
const REF_SHEAR: &[(&str, f64, f64, f64)] = &[
    ("nh", 0.5, 517.241379, 258.620690),
    ("nh", 1.0, 1034.482759, 1034.482759),
    ("dnh", 1.0, 1034.482759, 689.655172),
    ("mr-q", 0.5, 517.241379, 137.931034),
    ("mr-l", 1.0, 1034.482759, 551.724138),
];
const REF_UNIAXIAL: &[(&str, f64, f64, f64)] = &[
    ("nh", 1.1, 0.957844464, 299.858875),
    ("nh", 2.0, 0.725935006, 3408.826229),
    ("dnh", 1.5, 0.836396930, 1480.192068),
    ("mr-q", 2.0, 0.736195163, 2518.999048),
    ("mr-l", 1.5, 0.835171423, 1296.855024),
];

/// Simple shear γ = 0.1, 0.5, 1.0: the code's Cauchy stress (from its material-form S)
/// equals the spatial closed form. Tolerance 1e-9 relative to μ: both are exact formulas in
/// f64 whose only difference is round-off (~1e-13 relative).
#[test]
fn simple_shear_matches_closed_form_for_every_law() {
    let mu = lame().mu;
    for (name, law) in laws() {
        for g in [0.1, 0.5, 1.0] {
            let f = shear(g);
            let d = max_abs_diff(&code_cauchy(&law, &f), &cauchy_closed_form(name, &f));
            assert!(d < 1e-9 * mu, "{name} shear {g}: |Δσ| = {d:e} Pa");
        }
    }
    // Cross-check the test's formula itself against the shared numpy reference (printed to 1e-6).
    for &(name, g, s12, s11) in REF_SHEAR {
        let s = cauchy_closed_form(name, &shear(g));
        assert!(
            (s[0][1] - s12).abs() < 2e-6 && (s[0][0] - s11).abs() < 2e-6,
            "{name} {g}"
        );
    }
}

/// Uniaxial stretch 1.1, 1.5, 2.0 with the lateral stretch solved for zero lateral stress:
/// the code's σ11 matches the closed form and its lateral stress vanishes (1e-9 μ).
#[test]
fn uniaxial_stretch_matches_closed_form_for_every_law() {
    let mu = lame().mu;
    for (name, law) in laws() {
        for l in [1.1, 1.5, 2.0] {
            let t = lateral_stretch(name, l);
            let f = diag(l, t, t);
            let s = code_cauchy(&law, &f);
            let c = cauchy_closed_form(name, &f);
            assert!(max_abs_diff(&s, &c) < 1e-9 * mu, "{name} l={l}");
            assert!(s[1][1].abs() < 1e-9 * mu && s[2][2].abs() < 1e-9 * mu);
        }
    }
    for &(name, l, t_ref, s11) in REF_UNIAXIAL {
        let t = lateral_stretch(name, l);
        let s = cauchy_closed_form(name, &diag(l, t, t));
        assert!((t - t_ref).abs() < 2e-9, "{name} {l}: t {t} vs {t_ref}");
        assert!(
            (s[0][0] - s11).abs() < 2e-6,
            "{name} {l}: {} vs {s11}",
            s[0][0]
        );
    }
}

/// Strain energy is the potential of the stress: S = 2 ∂W/∂C checked by central differences
/// of W along random-ish directions (P : dF = dW). Tolerance 1e-6 relative: the O(h²)
/// truncation of the difference with h = 1e-6.
#[test]
fn stress_is_derivative_of_energy() {
    let f0 = [[1.2, 0.1, -0.05], [0.03, 0.9, 0.2], [0.0, -0.1, 1.05]];
    let df = [[0.3, -0.2, 0.1], [0.05, 0.4, -0.3], [0.2, 0.1, -0.25]];
    for (name, law) in laws() {
        let s = law.second_piola_kirchhoff(&f0).unwrap();
        let p = tensor::mul(&f0, &s);
        let h = 1e-6;
        let fp: Mat3<f64> =
            core::array::from_fn(|i| core::array::from_fn(|k| f0[i][k] + h * df[i][k]));
        let fm: Mat3<f64> =
            core::array::from_fn(|i| core::array::from_fn(|k| f0[i][k] - h * df[i][k]));
        let dw = (law.strain_energy_density(&fp).unwrap()
            - law.strain_energy_density(&fm).unwrap())
            / (2.0 * h);
        let pdf = tensor::ddot(&p, &df);
        assert!(
            (dw - pdf).abs() < 1e-6 * pdf.abs().max(1.0),
            "{name}: {dw} vs {pdf}"
        );
    }
}

fn unit_cube() -> [[f64; 3]; 8] {
    NODE_XI.map(|p| p.map(|v| 0.5 * (v + 1.0)))
}

/// A homogeneous deformation of one element: the reduced element's nodal forces are the
/// tractions P·N on its faces, lumped to the corners: the total force on the face X = 1
/// equals P·e1 · area. Closed form via the code's own P is not independent, so we compare
/// with the closed-form Cauchy stress mapped back: P = J σ F⁻ᵀ. Tolerance 1e-9 μ.
#[test]
fn element_forces_equal_face_tractions_under_homogeneous_stretch() {
    let x = unit_cube();
    let r = ReferenceHex::new(&x).unwrap();
    let mu = lame().mu;
    for (name, law) in laws() {
        let l = 1.5;
        let t = lateral_stretch(name, l);
        let f = diag(l, t, t);
        let u: [[f64; 3]; 8] = core::array::from_fn(|a| {
            let p = tensor::mul(
                &f,
                &[
                    [x[a][0], 0.0, 0.0],
                    [x[a][1], 0.0, 0.0],
                    [x[a][2], 0.0, 0.0],
                ],
            );
            [p[0][0] - x[a][0], p[1][0] - x[a][1], p[2][0] - x[a][2]]
        });
        let sigma = cauchy_closed_form(name, &f);
        let j = tensor::det(&f);
        let p11 = j * sigma[0][0] / l; // P = J σ F⁻ᵀ, diagonal F
        for el in [
            Box::new(r.reduced::<f64>([0, 1, 2, 3, 4, 5, 6, 7], 0, 1e4, 0.1))
                as Box<dyn HexElement<f64>>,
            Box::new(r.full::<f64>([0, 1, 2, 3, 4, 5, 6, 7], 0)),
        ] {
            let fe = el.internal_forces(&law, &u).unwrap();
            let face_x1: f64 = (0..8).filter(|&a| x[a][0] > 0.5).map(|a| fe[a][0]).sum();
            assert!(
                (face_x1 - p11).abs() < 1e-9 * mu,
                "{name}: {face_x1} vs {p11}"
            );
            // Zero lateral traction: y-forces on the face Y = 1 vanish.
            let face_y1: f64 = (0..8).filter(|&a| x[a][1] > 0.5).map(|a| fe[a][1]).sum();
            assert!(face_y1.abs() < 1e-9 * mu);
        }
    }
}

fn rotation_z(theta: f64) -> Mat3<f64> {
    let (s, c) = theta.sin_cos();
    [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
}

fn apply(f: &Mat3<f64>, x: &[[f64; 3]; 8]) -> [[f64; 3]; 8] {
    core::array::from_fn(|a| {
        let y: [f64; 3] = core::array::from_fn(|i| (0..3).map(|k| f[i][k] * x[a][k]).sum());
        [y[0] - x[a][0], y[1] - x[a][1], y[2] - x[a][2]]
    })
}

/// Objectivity: a rigid rotation by 90° (about a skew axis, on a distorted element) gives
/// zero stress and zero nodal force, hourglass included. Tolerance 1e-10 · M·V·|B|: the
/// round-off of cancelling O(1) terms in F·S with M·V·|B| the force scale.
#[test]
fn rigid_rotation_by_90_degrees_gives_zero_force() {
    let x = [
        [0.0, 0.0, 0.0],
        [1.1, 0.1, -0.1],
        [1.3, 0.9, 0.05],
        [-0.1, 1.2, 0.0],
        [0.1, -0.1, 0.9],
        [1.0, 0.0, 1.2],
        [1.2, 1.1, 1.0],
        [0.05, 0.95, 1.1],
    ];
    let r = ReferenceHex::new(&x).unwrap();
    // 90° about z, then 90° about x: a rotation that moves every axis.
    let rx = [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]];
    let rot = tensor::mul(&rx, &rotation_z(core::f64::consts::FRAC_PI_2));
    let u = apply(&rot, &x);
    for (name, law) in laws() {
        let m = law.dilatational_modulus();
        let scale = m * r.volume * r.gradient_norm_sq().sqrt();
        let s = law.second_piola_kirchhoff(&rot).unwrap();
        assert!(
            s.iter().flatten().all(|v| v.abs() < 1e-10 * m),
            "{name}: S = {s:?}"
        );
        for el in [
            Box::new(r.reduced::<f64>([0; 8], 0, m, 0.1)) as Box<dyn HexElement<f64>>,
            Box::new(r.full::<f64>([0; 8], 0)),
        ] {
            let fe = el.internal_forces(&law, &u).unwrap();
            let fmax = fe.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(
                fmax < 1e-10 * scale,
                "{name}: max |f| = {fmax:e}, scale {scale:e}"
            );
        }
    }
}

/// Uniform gradients are exact integrals: Σ_a B_a ⊗ X_a = I for any cell (a linear field is
/// reproduced exactly) and Σ_a B_a = 0; the volume equals an independent tetrahedral split.
#[test]
fn mean_gradients_reproduce_linear_fields_on_distorted_cells() {
    let x = [
        [0.249, 0.342, 0.192],
        [0.826, 0.288, 0.288],
        [0.850, 0.649, 0.263],
        [0.273, 0.750, 0.230],
        [0.320, 0.186, 0.643],
        [0.677, 0.305, 0.683],
        [0.788, 0.693, 0.644],
        [0.165, 0.745, 0.702],
    ];
    let r = ReferenceHex::new(&x).unwrap();
    for i in 0..3 {
        for j in 0..3 {
            let s: f64 = (0..8).map(|a| r.mean_gradients[a][i] * x[a][j]).sum();
            assert!((s - if i == j { 1.0 } else { 0.0 }).abs() < 1e-13);
        }
        let s: f64 = (0..8).map(|a| r.mean_gradients[a][i]).sum();
        assert!(s.abs() < 1e-13);
    }
    // Trilinear volume = exact Gauss volume: compare with the divergence-theorem volume of
    // the bilinear surface, computed here by fine midpoint quadrature of det J (independent
    // of the 2-point rule; converges as h²).
    let n = 40;
    let mut v = 0.0;
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let xi = [i, j, k].map(|m| -1.0 + (2.0 * m as f64 + 1.0) / n as f64);
                let dn = natural_gradients(xi);
                let mut jm = [[0.0; 3]; 3];
                for a in 0..8 {
                    for p in 0..3 {
                        for q in 0..3 {
                            jm[p][q] += x[a][p] * dn[a][q];
                        }
                    }
                }
                v += tensor::det(&jm) * (2.0 / n as f64).powi(3);
            }
        }
    }
    assert!(
        (v - r.volume).abs() < 1e-4 * r.volume,
        "{v} vs {}",
        r.volume
    );
}

/// An inverted cell (two nodes swapped) and a degenerate one (a collapsed face) are refused.
#[test]
fn inverted_and_degenerate_cells_are_refused() {
    let mut x = unit_cube();
    x.swap(0, 4);
    assert!(ReferenceHex::new(&x).is_err());
    let mut y = unit_cube();
    y[4] = y[0];
    y[5] = y[1];
    assert!(ReferenceHex::new(&y).is_err());
    let mut z = unit_cube();
    z[6][0] = f64::NAN;
    assert!(ReferenceHex::new(&z).is_err());
}
