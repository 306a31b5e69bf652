//! The tetrahedron against closed forms and independent computations: the gradients
//! reproduce linear fields, the critical step bound against the element's eigenvalues,
//! the patch test for T4 and T4ANP against the closed-form neo-Hookean stress, and the
//! forces as the derivatives of the energy (central differences).

extern crate std;
use std::vec;
use std::vec::Vec;

use super::super::tet_pressure::{add_nodal_volumes, TetLoop};
use super::super::{Scratch, TetPressure};
use super::*;
use crate::physics::material::{LameParameters, MaterialLaw};

fn neo_hookean(e: f64, nu: f64) -> MaterialLaw<f64> {
    MaterialLaw::NeoHookean(LameParameters::from_young_poisson(e, nu))
}

/// A few shapes: the corner of a cube, a regular one, a Kuhn tetrahedron of the unit
/// cube, a flat one and a needle.
fn shapes() -> Vec<[[f64; 3]; 4]> {
    vec![
        [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
        [[1., 1., 1.], [-1., 1., -1.], [1., -1., -1.], [-1., -1., 1.]],
        [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [1., 1., 1.]],
        [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0.3, 0.3, 0.1]],
        [[0., 0., 0.], [0.1, 0., 0.], [0., 0.1, 0.], [0., 0., 1.]],
    ]
}

#[test]
fn gradients_reproduce_linear_fields_and_volume() {
    for x in shapes() {
        let r = ReferenceTet::new(&x).unwrap_or_else(|e| panic!("{x:?}: {e}"));
        // Σ_a X_a ⊗ B_a = I: a linear field's gradient is exact (to round-off).
        for i in 0..3 {
            for j in 0..3 {
                let s: f64 = (0..4).map(|a| x[a][i] * r.gradients[a][j]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((s - want).abs() < 1e-12, "{x:?}: ({i},{j}) = {s}");
            }
        }
        // The volume from the faces: V = A_face h / 3 for face 1-2-3 and node 0.
        let n = vec3::cross(vec3::sub(x[2], x[1]), vec3::sub(x[3], x[1]));
        let area = 0.5 * vec3::norm(n);
        let h = vec3::dot(vec3::sub(x[0], x[1]), n).abs() / vec3::norm(n);
        assert!(r.volume > 0.0 && (r.volume - area * h / 3.0).abs() < 1e-12 * area * h);
    }
    let corner = ReferenceTet::new(&shapes()[0]).unwrap();
    assert!((corner.volume - 1.0 / 6.0).abs() < 1e-15);
}

#[test]
fn inverted_flat_and_non_finite_cells_are_refused() {
    let mut x = shapes()[0];
    x.swap(1, 2);
    assert!(matches!(
        ReferenceTet::new(&x),
        Err(GeometryError::NonPositiveJacobian { det_j, .. }) if det_j < 0.0
    ));
    let flat = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0.5, 0.5, 0.]];
    assert!(ReferenceTet::new(&flat).is_err());
    let mut nan = shapes()[0];
    nan[3][2] = f64::NAN;
    assert_eq!(
        ReferenceTet::new(&nan),
        Err(GeometryError::NonFiniteCoordinate)
    );
}

/// The element's stiffness at rest by central differences of its forces (columns), and
/// the largest eigenvalue of `M⁻¹ K` (`M = ρV/4` per node) by power iteration.
fn largest_frequency_sq(r: &ReferenceTet, law: &MaterialLaw<f64>, density: f64) -> f64 {
    let t: Tet4<f64> = r.record([0, 1, 2, 3], 0);
    let h = 1e-7 * r.characteristic_length;
    let mut k = [[0.0; 12]; 12];
    for col in 0..12 {
        let mut up = [[0.0; 3]; 4];
        let mut down = [[0.0; 3]; 4];
        up[col / 3][col % 3] = h;
        down[col / 3][col % 3] = -h;
        let fp = t.internal_forces(law, &up).unwrap();
        let fm = t.internal_forces(law, &down).unwrap();
        for row in 0..12 {
            k[row][col] = (fp[row / 3][row % 3] - fm[row / 3][row % 3]) / (2.0 * h);
        }
    }
    let m = density * r.volume / 4.0;
    // Power iteration on the symmetric M^-1/2 K M^-1/2 = K / m.
    let mut v = [1.0; 12];
    for (i, x) in v.iter_mut().enumerate() {
        *x += 0.1 * i as f64;
    }
    let mut lambda = 0.0;
    for _ in 0..2000 {
        let w: Vec<f64> = (0..12)
            .map(|i| (0..12).map(|j| k[i][j] * v[j]).sum::<f64>() / m)
            .collect();
        let norm = libm::sqrt(w.iter().map(|x| x * x).sum());
        lambda = norm / libm::sqrt(v.iter().map(|x| x * x).sum());
        for (x, y) in v.iter_mut().zip(&w) {
            *x = y / norm;
        }
    }
    lambda
}

/// `L_e / c ≤ 2/ω_max` on every shape (the step it allows is stable), and within 3% of it
/// at `ν = 0.49` (the bound is tight where tissue lives): the element's own eigenvalues,
/// not the formula, are the reference.
#[test]
fn characteristic_length_bounds_the_critical_step() {
    let density = 1000.0;
    for nu in [0.0, 0.3, 0.49] {
        let law = neo_hookean(3000.0, nu);
        let modulus = MaterialLaw::<f64>::dilatational_modulus(&law);
        let c = libm::sqrt(modulus / density);
        for x in shapes() {
            let r = ReferenceTet::new(&x).unwrap();
            let dt_crit = 2.0 / libm::sqrt(largest_frequency_sq(&r, &law, density));
            let dt = r.characteristic_length / c;
            assert!(
                dt <= dt_crit * (1.0 + 1e-5),
                "nu {nu}, {x:?}: {dt} > {dt_crit}"
            );
            if nu == 0.49 {
                assert!(dt >= 0.97 * dt_crit, "nu {nu}, {x:?}: {dt} << {dt_crit}");
            }
        }
    }
}

/// A unit cube cut into `6 n³` Kuhn tetrahedra ([`super::kuhn`]), the inner nodes moved by
/// `jitter` (a distorted patch).
fn kuhn_cube(n: usize, jitter: f64) -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
    let mut x = vec![[0.0; 3]; super::kuhn::node_count(n)];
    let mut tets = vec![[0; 4]; super::kuhn::tet_count(n)];
    super::kuhn::nodes(n, 1.0 / n as f64, jitter, &mut x).unwrap();
    super::kuhn::tetrahedra(n, &x, &mut tets).unwrap();
    (x, tets)
}

fn records(x: &[[f64; 3]], tets: &[[u32; 4]], material: impl Fn(usize) -> u16) -> Vec<Tet4<f64>> {
    tets.iter()
        .enumerate()
        .map(|(e, t)| {
            let r = ReferenceTet::new(&t.map(|a| x[a as usize])).unwrap();
            r.record(*t, material(e))
        })
        .collect()
}

fn forces(
    tets: &[Tet4<f64>],
    laws: &[MaterialLaw<f64>],
    form: TetPressure,
    u: &[[f64; 3]],
) -> Vec<[f64; 3]> {
    let n = u.len();
    let mut vn = vec![0.0; n];
    add_nodal_volumes(tets, &mut vn);
    let (mut ratio, mut pressure) = (vec![0.0; n], vec![0.0; n]);
    let mut f = vec![[0.0; 3]; n];
    let scratch = Scratch {
        ratio: &mut ratio,
        pressure: &mut pressure,
    };
    let tl = TetLoop {
        tets,
        first: 0,
        laws,
        form,
        nodal_volume: &vn,
    };
    tl.accumulate(scratch, u, &mut f).unwrap();
    f
}

fn energy(tets: &[Tet4<f64>], laws: &[MaterialLaw<f64>], form: TetPressure, u: &[[f64; 3]]) -> f64 {
    let n = u.len();
    let mut vn = vec![0.0; n];
    add_nodal_volumes(tets, &mut vn);
    let (mut ratio, mut pressure) = (vec![0.0; n], vec![0.0; n]);
    let scratch = Scratch {
        ratio: &mut ratio,
        pressure: &mut pressure,
    };
    let tl = TetLoop {
        tets,
        first: 0,
        laws,
        form,
        nodal_volume: &vn,
    };
    tl.stored_energy(scratch, u).unwrap()
}

/// The closed-form compressible neo-Hookean stress `P = μ (F − F⁻ᵀ) + λ ln J F⁻ᵀ`,
/// written out here independently of the material module.
fn closed_form_stress(mu: f64, lambda: f64, f: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let det = f[0][0] * (f[1][1] * f[2][2] - f[1][2] * f[2][1])
        - f[0][1] * (f[1][0] * f[2][2] - f[1][2] * f[2][0])
        + f[0][2] * (f[1][0] * f[2][1] - f[1][1] * f[2][0]);
    // F⁻ᵀ = cof F / J.
    let cof = |i: usize, j: usize| {
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        let (j1, j2) = ((j + 1) % 3, (j + 2) % 3);
        f[i1][j1] * f[i2][j2] - f[i1][j2] * f[i2][j1]
    };
    core::array::from_fn(|i| {
        core::array::from_fn(|j| {
            let fit = cof(i, j) / det;
            mu * (f[i][j] - fit) + lambda * libm::log(det) * fit
        })
    })
}

/// The patch test on a distorted patch under a finite homogeneous deformation, T4 and
/// T4ANP alike: every inner node's net force vanishes (to 1e-11 of the boundary's), and
/// the boundary forces' first moment `Σ_a f_a ⊗ X_a` is `V P` with `P` the closed-form
/// stress (1e-11 relative): the elements carry the exact stress of the linear field.
#[test]
fn patch_test_is_exact_for_t4_and_t4anp() {
    let (x, t) = kuhn_cube(3, 1.0);
    let (e, nu) = (3000.0, 0.49);
    let law = neo_hookean(e, nu);
    let tets = records(&x, &t, |_| 0);
    let grad = [[0.12, 0.05, -0.03], [0.02, -0.08, 0.04], [-0.06, 0.01, 0.1]];
    let u: Vec<[f64; 3]> = x
        .iter()
        .map(|p| core::array::from_fn(|i| (0..3).map(|j| grad[i][j] * p[j]).sum()))
        .collect();
    let fm: [[f64; 3]; 3] =
        core::array::from_fn(|i| core::array::from_fn(|j| grad[i][j] + f64::from(i == j)));
    let MaterialLaw::NeoHookean(l) = law else {
        unreachable!()
    };
    let p = closed_form_stress(l.mu, l.lambda, &fm);
    let scale = p.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(scale > 100.0, "a trivial stress: {scale}");
    for form in [TetPressure::Element, TetPressure::Nodal] {
        let f = forces(&tets, &[law], form, &u);
        assert_eq!(f.len(), x.len());
        let mut inner = 0;
        for (a, p) in x.iter().enumerate() {
            if p.iter().all(|&c| c > 1e-9 && c < 1.0 - 1e-9) {
                inner += 1;
                let m = f[a].iter().map(|v| v.abs()).fold(0.0, f64::max);
                assert!(m < 1e-11 * scale, "{form:?}: inner node {a}: {:?}", f[a]);
            }
        }
        assert_eq!(inner, 8);
        for i in 0..3 {
            for j in 0..3 {
                let moment: f64 = (0..x.len()).map(|a| f[a][i] * x[a][j]).sum();
                let want = p[i][j]; // V = 1
                assert!(
                    (moment - want).abs() < 1e-11 * scale,
                    "{form:?}: ({i},{j}) {moment} against {want}"
                );
            }
        }
    }
}

/// Both forms' forces are the derivatives of their energies (central differences,
/// step 1e-7, relative 1e-6) at a random large deformation of a distorted patch: of two
/// materials, and of each of the three laws alone (the nodal pressures' one-law path,
/// and each law's isochoric stress with the pressure): the nodal averaging is
/// consistent, so energy is conserved.
#[test]
fn forces_are_the_energy_gradient() {
    let (x, t) = kuhn_cube(2, 1.0);
    let laws = [
        neo_hookean(3000.0, 0.49),
        MaterialLaw::NeoHookeanDecoupled {
            mu: 1500.0,
            kappa: 2.0e5,
        },
        MaterialLaw::MooneyRivlin {
            c10: 500.0,
            c01: 250.0,
            kappa: 1.0e5,
            volumetric: crate::physics::Volumetric::Log,
        },
    ];
    let mut seed = 0x2545_f491_u64;
    let mut rand = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let u: Vec<[f64; 3]> = x
        .iter()
        .map(|_| [0.06 * rand(), 0.06 * rand(), 0.06 * rand()])
        .collect();
    let patches = [
        ("two laws", records(&x, &t, |e| (e % 3 == 0) as u16)),
        ("neo-Hookean alone", records(&x, &t, |_| 0)),
        ("decoupled alone", records(&x, &t, |_| 1)),
        ("Mooney-Rivlin alone", records(&x, &t, |_| 2)),
    ];
    for (patch, tets) in &patches {
        gradient_check(patch, tets, &laws, &x, &u);
    }
}

fn gradient_check(
    patch: &str,
    tets: &[Tet4<f64>],
    laws: &[MaterialLaw<f64>],
    x: &[[f64; 3]],
    u: &[[f64; 3]],
) {
    let (tets, laws, u) = (tets.to_vec(), laws.to_vec(), u.to_vec());
    for form in [TetPressure::Element, TetPressure::Nodal] {
        let f = forces(&tets, &laws, form, &u);
        let scale = f.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
        assert!(scale > 10.0, "{patch}, {form:?}: trivial forces {scale}");
        for a in 0..x.len() {
            for i in 0..3 {
                let h = 1e-7;
                let (mut up, mut down) = (u.clone(), u.clone());
                up[a][i] += h;
                down[a][i] -= h;
                let d = (energy(&tets, &laws, form, &up) - energy(&tets, &laws, form, &down))
                    / (2.0 * h);
                assert!(
                    (d - f[a][i]).abs() < 1e-6 * scale,
                    "{patch}, {form:?}: node {a} component {i}: dE/du {d} against f {}",
                    f[a][i]
                );
            }
        }
    }
}
