//! The tetrahedra's batched loop (`problem::batched`, the firmware's lane functions) against
//! the scalar loop (`Elements::internal_forces`, `TetLoop` one element at a time): the same
//! bits, in f64 and f32, plain T4 and T4ANP, on Gmsh's tetrahedral beam (3480 tetrahedra,
//! a count that is a multiple of no lane count but 4 and 8: 3480 = 8 * 435) and on the beam of
//! prisms and tetrahedra (886 tetrahedra after 420 prisms), with one law (T4ANP's one-law
//! path) and three laws of three kinds in runs of different lengths (packs split where the
//! kind changes; T4ANP's general path), and with an inverted tetrahedron (the same error,
//! naming the same mesh cell, and the same forces up to it).
//!
//! Bit-identity is the property (the board computes the scalar loop's bits), so the
//! tolerance is zero; each comparison first checks that the forces are far from trivial.

use host_tools::compare::nan_max;
use host_tools::problem::batched::{Batched, Isa};
use host_tools::problem::elements::Elements;
use host_tools::problem::Problem;
use pe_firmware::physics::{MaterialLaw, PhysicsError, Real, Volumetric};

use crate::batched::Rng;
use crate::tetrahedra::beam;

/// The beam's law, and with `mixed` two more of other kinds.
fn laws(p: &Problem, mixed: bool) -> Vec<MaterialLaw<f64>> {
    let mut laws = vec![p.laws[0]];
    if mixed {
        laws.push(MaterialLaw::MooneyRivlin {
            c10: 5.0e5,
            c01: 1.0e5,
            kappa: 2.0e7,
            volumetric: Volumetric::Log,
        });
        laws.push(MaterialLaw::NeoHookeanDecoupled {
            mu: 1.0e6,
            kappa: 3.0e7,
        });
    }
    laws
}

/// The scalar and the batched loop's results and forces at `u`.
#[allow(clippy::type_complexity)]
fn both<T: Real>(
    elements: &Elements<T>,
    laws: &[MaterialLaw<T>],
    u: &[[T; 3]],
    isa: Isa,
) -> (
    (Result<(), PhysicsError>, Vec<[T; 3]>),
    (Result<(), PhysicsError>, Vec<[T; 3]>),
) {
    let mut fs = vec![[T::ZERO; 3]; u.len()];
    let rs = elements.internal_forces(laws, u, &mut fs);
    let b = Batched::build(elements, laws, isa).expect("packs");
    let mut fb = vec![[T::ZERO; 3]; u.len()];
    let rb = b.internal_forces(elements, laws, u, &mut fb);
    ((rs, fs), (rb, fb))
}

fn assert_same_bits<T: Real>(a: &[[T; 3]], b: &[[T; 3]], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
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

/// The beam of `mesh` in `form`, its tetrahedra's materials cycling through three laws
/// with `mixed`, at seeded displacements of up to 0.1 mm (strains of a few percent on
/// cells of about 4 mm); with `fold`, tetrahedron `fold` (of the tetrahedra's list) is
/// turned inside out (its first node reflected through its opposite face).
fn case<T: Real>(
    mesh: &str,
    form: &str,
    mixed: bool,
    fold: Option<usize>,
) -> (Elements<T>, Vec<MaterialLaw<T>>, Vec<[T; 3]>) {
    let p = beam(mesh, form, 0.49, "");
    let mut elements = Elements::<T>::build(&p);
    assert!(
        elements.tets.len() > 800,
        "{mesh}: {} tetrahedra",
        elements.tets.len()
    );
    if mixed {
        // Runs of 6, 2 and 3: packs of 4, 8 or 16 lanes split where the kind changes.
        for (k, t) in elements.tets.records.iter_mut().enumerate() {
            t.material = match k % 11 {
                0..=5 => 0,
                6 | 7 => 1,
                _ => 2,
            };
        }
    }
    let mut rng = Rng(0x7e7 + mixed as u64);
    let mut u: Vec<[f64; 3]> = (0..p.mesh.nodes.len())
        .map(|_| core::array::from_fn(|_| 1e-4 * rng.next()))
        .collect();
    if let Some(k) = fold {
        let n = elements.tets.records[k].nodes.map(|n| n as usize);
        let x: [[f64; 3]; 4] =
            core::array::from_fn(|a| core::array::from_fn(|i| p.mesh.nodes[n[a]][i] + u[n[a]][i]));
        let c: [f64; 3] = core::array::from_fn(|i| (x[1][i] + x[2][i] + x[3][i]) / 3.0);
        // x0 -> 2c - x0: the first node through the opposite face.
        for i in 0..3 {
            u[n[0]][i] += 2.0 * (c[i] - x[0][i]);
        }
    }
    let laws = laws(&p, mixed).iter().map(|l| l.cast::<T>()).collect();
    let u = u.iter().map(|v| v.map(T::from_f64)).collect();
    (elements, laws, u)
}

fn same_bits_for<T: Real>() {
    for mesh in ["beam_tet.msh", "beam_prism_tet.msh"] {
        for form in ["plain", "nodal-pressure"] {
            for mixed in [false, true] {
                let (elements, laws, u) = case::<T>(mesh, form, mixed, None);
                for isa in Isa::available() {
                    let what = format!("{} {mesh} {form} mixed {mixed} {isa:?}", T::NAME);
                    let ((rs, fs), (rb, fb)) = both(&elements, &laws, &u, isa);
                    assert_eq!(rs, Ok(()), "{what}: scalar");
                    assert_eq!(rb, Ok(()), "{what}: batched");
                    let max = fs
                        .iter()
                        .flatten()
                        .fold(0.0, |m, v| nan_max(m, v.to_f64().abs()));
                    let nonzero = fs.iter().flatten().filter(|v| v.to_f64() != 0.0).count();
                    // 0.1 mm on 4 mm cells of E = 3 MPa: stresses of some 1e5 Pa on faces of
                    // some 1e-5 m², forces of order 1 N.
                    assert!(max > 1e-2, "{what}: forces are trivial (max {max:e})");
                    assert!(
                        nonzero * 10 >= 9 * 3 * fs.len(),
                        "{what}: {nonzero} of {} components non-zero",
                        3 * fs.len()
                    );
                    assert_same_bits(&fs, &fb, &what);
                }
            }
        }
    }
}

#[test]
fn batched_tetrahedra_give_the_scalar_loops_bits_f64() {
    same_bits_for::<f64>();
}

#[test]
fn batched_tetrahedra_give_the_scalar_loops_bits_f32() {
    same_bits_for::<f32>();
}

/// Tetrahedron 9 turned inside out (lane 1 of the third pack of 4, lane 1 of the second
/// of 8, lane 9 of the first of 16): both loops stop with the same error naming the same
/// mesh cell (T4ANP finds it in its nodal pass, plain T4 in its stress pass, after adding
/// the forces of the elements before it, which must be the same too).
#[test]
fn an_inverted_tetrahedron_is_named_alike() {
    for form in ["plain", "nodal-pressure"] {
        let (elements, laws, u) = case::<f64>("beam_tet.msh", form, false, Some(9));
        for isa in Isa::available() {
            let what = format!("{form} {isa:?}");
            let ((rs, fs), (rb, fb)) = both(&elements, &laws, &u, isa);
            let Err(PhysicsError::InvertedElement { element, jacobian }) = rs else {
                panic!("{what}: the scalar loop gave {rs:?}");
            };
            assert!(jacobian < 0.0, "{what}: J = {jacobian}");
            assert_eq!(element, elements.tets.cells[9], "{what}: the folded cell");
            assert_eq!(rb, rs, "{what}: batched");
            assert_same_bits(&fs, &fb, &what);
        }
    }
}
