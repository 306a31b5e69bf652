//! The physical hourglass form (`physics::element::hourglass`) against closed forms: the
//! energy one cell stores under a pure bending field and under a twist is the continuum's
//! (the fields' nodal values hold no linear part, so the one-point part stores nothing and
//! the hourglass energy is all there is); the same on a turned cell (the parallelepiped and
//! general kernels carry the cell's edges); the forces are the energy's gradient (a
//! symmetric stiffness); linear fields give no hourglass force; and the scalar form is
//! `K = k I` on every kernel.

#![allow(clippy::needless_range_loop)] // index loops follow the formulas

use pe_firmware::physics::element::hex::NODE_XI;
use pe_firmware::physics::{
    Connectivity, Element, HexBox, HexCuboid, HexElement, HexReduced, Hourglass, HourglassControl,
    LameParameters, MaterialLaw, ReferenceHex,
};

const NODES: [u32; 8] = [0, 1, 2, 3, 4, 5, 6, 7];
/// Half-sides of the box (m): a cell 5 times longer than deep, as MacNeal-Harder's.
const HALF: [f64; 3] = [0.5, 0.1, 0.05];

fn law() -> (MaterialLaw<f64>, f64, f64) {
    let (e, nu) = (1.0e7, 0.3);
    let l = LameParameters::from_young_poisson(e, nu);
    (MaterialLaw::NeoHookean(l), e, l.mu)
}

/// The box `[-a, a] x [-b, b] x [-c, c]` turned by `r` (rows: the turned axes).
fn cell(r: &[[f64; 3]; 3]) -> [[f64; 3]; 8] {
    core::array::from_fn(|n| {
        let local: [f64; 3] = core::array::from_fn(|j| HALF[j] * NODE_XI[n][j]);
        core::array::from_fn(|i| (0..3).map(|j| r[j][i] * local[j]).sum())
    })
}

/// A rotation about the axis (1, 2, 3) by 0.7 rad (Rodrigues), rows the turned axes.
fn turned() -> [[f64; 3]; 3] {
    let n = (14.0f64).sqrt();
    let k = [1.0 / n, 2.0 / n, 3.0 / n];
    let (s, c) = (0.7f64.sin(), 0.7f64.cos());
    core::array::from_fn(|i| {
        core::array::from_fn(|j| {
            let cross = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]][i][j];
            c * f64::from(u8::from(i == j)) + s * cross + (1.0 - c) * k[i] * k[j]
        })
    })
}

const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The displacement `g(local)` given in the cell's axes, at its nodes, in the global axes.
fn field(r: &[[f64; 3]; 3], g: impl Fn([f64; 3]) -> [f64; 3]) -> [[f64; 3]; 8] {
    core::array::from_fn(|n| {
        let local: [f64; 3] = core::array::from_fn(|j| HALF[j] * NODE_XI[n][j]);
        let v = g(local);
        core::array::from_fn(|i| (0..3).map(|j| r[j][i] * v[j]).sum())
    })
}

/// The three kernels' energies of `u` on the cell turned by `r` (the cuboid kernel only
/// unturned).
fn energies(
    r: &[[f64; 3]; 3],
    u: &[[f64; 3]; 8],
    hourglass: Hourglass,
) -> Vec<(&'static str, f64)> {
    let (law, _, _) = law();
    let x = cell(r);
    let reference = ReferenceHex::new(&x).expect("a box");
    let c = Connectivity {
        nodes: NODES,
        material: 0,
    };
    let mut out = vec![
        (
            "general",
            HexReduced::<f64>::from_reference(&reference, c, hourglass)
                .energy(&law, u)
                .unwrap(),
        ),
        (
            "parallelepiped",
            HexBox::<f64>::from_reference(&reference, c, hourglass)
                .energy(&law, u)
                .unwrap(),
        ),
    ];
    if r == &IDENTITY {
        out.push((
            "cuboid",
            HexCuboid::<f64>::from_reference(&reference, c, hourglass)
                .energy(&law, u)
                .unwrap(),
        ));
    }
    out
}

fn physical() -> Hourglass {
    let (_, e, mu) = law();
    let kappa = e / (3.0 * (1.0 - 2.0 * 0.3));
    Hourglass::of_moduli(mu, kappa, HourglassControl::Physical)
}

/// Pure bending about the cell's z axis, curvature κ, the continuum's field with its sides
/// free: `u_x = −κ x y`, `u_y = κ (x² + ν (y² − z²)) / 2` (constant on the nodes),
/// `u_z = ν κ y z` (the anticlastic contraction). The continuum stores
/// `½ E κ² ∫ y² dV = ½ E κ² V b²/3`; the physical form stores exactly that (to 1e-6: the
/// strain energy of the one-point part is zero to round-off, the hourglass energy is a
/// closed form of the same numbers), on every kernel and with the cell turned. Held
/// without its anticlastic contraction (`u_z = 0`) the cell stores the plane-strain
/// `½ E/(1−ν²) κ² V b²/3`. The scalar form at 0.1 stores 24 times more: the locking it had.
#[test]
fn pure_bending_of_one_cell_stores_the_continuum_energy() {
    let (_, e, mu) = law();
    // The law's Poisson ratio, from its moduli (`E = 2μ(1 + ν)`).
    let nu = e / (2.0 * mu) - 1.0;
    let kappa = 1e-3;
    let volume = 8.0 * HALF[0] * HALF[1] * HALF[2];
    let exact = 0.5 * e * kappa * kappa * volume * HALF[1] * HALF[1] / 3.0;
    assert!(exact > 1e-6, "a field too small to tell: {exact:e} J");
    for r in [IDENTITY, turned()] {
        let u = field(&r, |p| {
            [
                -kappa * p[0] * p[1],
                0.5 * kappa * (p[0] * p[0] + nu * (p[1] * p[1] - p[2] * p[2])),
                nu * kappa * p[1] * p[2],
            ]
        });
        let got = energies(&r, &u, physical());
        assert_eq!(got.len(), if r == IDENTITY { 3 } else { 2 });
        for (kernel, w) in got {
            assert!(
                (w / exact - 1.0).abs() < 1e-6,
                "{kernel}: {w:e} J against {exact:e} J"
            );
        }
        let held = field(&r, |p| {
            [-kappa * p[0] * p[1], 0.5 * kappa * p[0] * p[0], 0.0]
        });
        for (kernel, w) in energies(&r, &held, physical()) {
            let plane = exact / (1.0 - nu * nu);
            assert!(
                (w / plane - 1.0).abs() < 1e-6,
                "{kernel}, contraction held: {w:e} J against {plane:e} J"
            );
        }
        let (law, _, _) = law();
        let scalar = Hourglass::scalar(law.hourglass_modulus(), 0.1);
        for (kernel, w) in energies(&r, &u, scalar) {
            assert!(w > 10.0 * exact, "{kernel}: the scalar form's {w:e} J");
        }
    }
}

/// A uniform twist about the cell's long axis, rate θ′: `u_y = −θ′ x z`, `u_z = θ′ x y`.
/// Without warping the continuum stores `½ μ θ′² ∫ (y² + z²) dV = ½ μ θ′² V (b² + c²)/3`:
/// the twisting components' coupling leaves out the shear `γ_yz`, which cancels (to
/// 1e-6, every kernel, turned or not).
#[test]
fn twist_of_one_cell_stores_the_continuum_energy() {
    let (_, _, mu) = law();
    let rate = 1e-3;
    let volume = 8.0 * HALF[0] * HALF[1] * HALF[2];
    let exact = 0.5 * mu * rate * rate * volume * (HALF[1] * HALF[1] + HALF[2] * HALF[2]) / 3.0;
    assert!(exact > 1e-6, "a field too small to tell: {exact:e} J");
    for r in [IDENTITY, turned()] {
        let u = field(&r, |p| [0.0, -rate * p[0] * p[2], rate * p[0] * p[1]]);
        for (kernel, w) in energies(&r, &u, physical()) {
            assert!(
                (w / exact - 1.0).abs() < 1e-6,
                "{kernel}: {w:e} J against {exact:e} J"
            );
        }
    }
}

/// The forces are the energy's gradient (central differences, step 1e-7 of the cell, on
/// a distorted cell and a random hourglass-rich displacement of 1e-3 of the cell): the
/// physical stiffness is symmetric. Within 1e-6 of the largest force.
#[test]
fn physical_forces_are_the_energy_gradient_on_a_distorted_cell() {
    let (law, _, _) = law();
    let mut x = cell(&IDENTITY);
    x[6][0] += 0.12;
    x[5][1] -= 0.03;
    x[3][2] += 0.02;
    let reference = ReferenceHex::new(&x).expect("a valid distorted cell");
    assert!(!reference.is_parallelepiped());
    let c = Connectivity {
        nodes: NODES,
        material: 0,
    };
    let e = HexReduced::<f64>::from_reference(&reference, c, physical());
    let u: [[f64; 3]; 8] = core::array::from_fn(|a| {
        core::array::from_fn(|i| 1e-3 * (((a * 7 + i * 3) % 11) as f64 / 5.0 - 1.0))
    });
    let f = e.internal_forces(&law, &u).unwrap();
    let largest = f.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(largest > 1.0, "forces too small to tell: {largest:e} N");
    let h = 1e-7;
    for a in 0..8 {
        for i in 0..3 {
            let (mut up, mut down) = (u, u);
            up[a][i] += h;
            down[a][i] -= h;
            let g = (e.energy(&law, &up).unwrap() - e.energy(&law, &down).unwrap()) / (2.0 * h);
            assert!(
                (g - f[a][i]).abs() < 1e-6 * largest,
                "node {a} component {i}: dW/du {g:e} against force {:e}",
                f[a][i]
            );
        }
    }
}

/// A linear displacement field (rigid motion and uniform strain) gives the physical form's
/// hourglass no work: its forces are the one-point part's alone, the same as the scalar
/// form's at any coefficient (to 1e-9 of the largest force) on a distorted cell.
#[test]
fn linear_fields_give_no_hourglass_force() {
    let (law, _, _) = law();
    let mut x = cell(&IDENTITY);
    x[6][0] += 0.12;
    x[5][1] -= 0.03;
    let reference = ReferenceHex::new(&x).expect("a valid distorted cell");
    let c = Connectivity {
        nodes: NODES,
        material: 0,
    };
    let g = [
        [1e-3, 2e-4, -3e-4],
        [-1e-4, 2e-3, 5e-4],
        [3e-4, -2e-4, -1e-3],
    ];
    let u: [[f64; 3]; 8] = core::array::from_fn(|a| {
        core::array::from_fn(|i| 1e-4 + (0..3).map(|j| g[i][j] * x[a][j]).sum::<f64>())
    });
    let physical = HexReduced::<f64>::from_reference(&reference, c, physical())
        .internal_forces(&law, &u)
        .unwrap();
    let none = HexReduced::<f64>::from_reference(
        &reference,
        c,
        Hourglass::scalar(law.hourglass_modulus(), 0.0),
    )
    .internal_forces(&law, &u)
    .unwrap();
    let largest = none.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(largest > 1.0, "forces too small to tell: {largest:e} N");
    assert_eq!(physical.len(), none.len());
    for a in 0..8 {
        for i in 0..3 {
            assert!(
                (physical[a][i] - none[a][i]).abs() < 1e-9 * largest,
                "node {a} component {i}: {:e} against {:e}",
                physical[a][i],
                none[a][i]
            );
        }
    }
}
