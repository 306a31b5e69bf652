//! The element kernels against each other and against an independent computation: the
//! general reduced kernel (corner transforms, `q = c − H γ`) against the textbook formula
//! (`f_a = V₀ F S B_a + k Σ_α Γ_aα Σ_b Γ_bα u_b` with `Γ` stored per node), the
//! parallelepiped kernel against the general one on parallelepipeds, the cuboid kernel
//! against both on axis-aligned boxes, and the forces against the energy's gradient.

#![allow(clippy::needless_range_loop)] // index loops follow the formulas

use pe_firmware::physics::element::hex::NODE_XI;
use pe_firmware::physics::element::KernelFault;
use pe_firmware::physics::real::nan_max;
use pe_firmware::physics::{
    tensor, vec3, HexElement, LameParameters, MaterialLaw, ReferenceHex, Volumetric,
};

/// Deterministic pseudo-random numbers in [-1, 1) (a 64-bit LCG; the seed is in each test).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

fn laws() -> [MaterialLaw<f64>; 3] {
    let l = LameParameters::from_young_poisson(3.0e3, 0.45);
    [
        MaterialLaw::NeoHookean(l),
        MaterialLaw::NeoHookeanDecoupled {
            mu: l.mu,
            kappa: l.bulk_modulus(),
        },
        MaterialLaw::MooneyRivlin {
            c10: 0.3 * l.mu,
            c01: 0.2 * l.mu,
            kappa: l.bulk_modulus(),
            volumetric: Volumetric::Log,
        },
    ]
}

/// A parallelepiped: the cube [-1,1]³ mapped by `X = X0 + A ξ` (A random, well conditioned).
fn parallelepiped(rng: &mut Lcg, h: f64) -> [[f64; 3]; 8] {
    let a: [[f64; 3]; 3] = core::array::from_fn(|i| {
        core::array::from_fn(|j| h * (if i == j { 0.5 } else { 0.0 } + 0.15 * rng.next()))
    });
    let x0: [f64; 3] = core::array::from_fn(|_| 0.1 * rng.next());
    core::array::from_fn(|n| {
        core::array::from_fn(|i| x0[i] + (0..3).map(|j| a[i][j] * NODE_XI[n][j]).sum::<f64>())
    })
}

/// Displacements: a homogeneous part (strain up to `strain`) plus a random part.
fn displacements(rng: &mut Lcg, x: &[[f64; 3]; 8], strain: f64) -> [[f64; 3]; 8] {
    let g: [[f64; 3]; 3] = core::array::from_fn(|_| core::array::from_fn(|_| strain * rng.next()));
    let h = vec3::norm(vec3::sub(x[6], x[0]));
    core::array::from_fn(|n| {
        core::array::from_fn(|i| {
            (0..3).map(|j| g[i][j] * x[n][j]).sum::<f64>() + 0.3 * strain * h * rng.next()
        })
    })
}

/// The textbook reduced element, from the reference data alone.
fn textbook_forces(
    r: &ReferenceHex,
    law: &MaterialLaw<f64>,
    k: f64,
    u: &[[f64; 3]; 8],
) -> [[f64; 3]; 8] {
    let mut f = tensor::identity::<f64>();
    for a in 0..8 {
        for i in 0..3 {
            for j in 0..3 {
                f[i][j] += u[a][i] * r.mean_gradients[a][j];
            }
        }
    }
    let s = law.second_piola_kirchhoff(&f).unwrap();
    let p = tensor::mul(&f, &s);
    let mut out = [[0.0; 3]; 8];
    for a in 0..8 {
        for i in 0..3 {
            out[a][i] = r.volume
                * (0..3)
                    .map(|j| p[i][j] * r.mean_gradients[a][j])
                    .sum::<f64>();
            for al in 0..4 {
                let q: f64 = (0..8).map(|b| r.hourglass[b][al] * u[b][i]).sum();
                out[a][i] += k * r.hourglass[a][al] * q;
            }
        }
    }
    out
}

/// Largest difference relative to the largest force; asserts the forces are far from zero
/// (a field of zeros would equal anything).
fn rel_diff(a: &[[f64; 3]; 8], b: &[[f64; 3]; 8]) -> f64 {
    let scale = a.iter().flatten().fold(0.0, |m, v| nan_max(m, v.abs()));
    assert!(scale > 1e-6, "forces are trivial ({scale:e} N)");
    assert_eq!(a.len(), b.len());
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, nan_max)
        / scale
}

const NODES: [u32; 8] = [0, 1, 2, 3, 4, 5, 6, 7];
const KAPPA_HG: f64 = 0.1;

/// The general kernel equals the textbook formula to round-off (1e-12 of the largest force:
/// the two orders of summation differ by a few ulps of terms as large as the forces) on
/// distorted cells and parallelepipeds, for each law, at strains up to 30%.
#[test]
fn general_kernel_equals_the_textbook_formula() {
    let mut rng = Lcg(0x5eed_0001);
    let distorted = [
        [0.0, 0.0, 0.0],
        [1.1, 0.1, -0.05],
        [1.2, 0.9, 0.1],
        [-0.1, 1.0, 0.0],
        [0.05, -0.1, 0.9],
        [1.0, 0.0, 1.2],
        [0.9, 1.1, 1.0],
        [0.1, 0.8, 1.1],
    ]
    .map(|v: [f64; 3]| v.map(|c| 0.01 * c));
    let mut cells = vec![distorted];
    for _ in 0..4 {
        cells.push(parallelepiped(&mut rng, 0.01));
    }
    let mut checked = 0;
    for x in &cells {
        let r = ReferenceHex::new(x).unwrap();
        for law in laws() {
            let k = r.hourglass_stiffness(law.hourglass_modulus(), KAPPA_HG);
            let e = r.reduced::<f64>(NODES, 0, law.hourglass_modulus(), KAPPA_HG);
            for strain in [1e-4, 0.3] {
                let u = displacements(&mut rng, x, strain);
                let got = e.internal_forces(&law, &u).unwrap();
                let want = textbook_forces(&r, &law, k, &u);
                let d = rel_diff(&want, &got);
                // The stress is a difference of terms of order μ (P = μ (F − F⁻ᵀ) + ...),
                // so round-off relative to forces of order μ·strain is ~1e-16/strain.
                let tol = 1e-13 / strain;
                assert!(d < tol, "law {law:?}, strain {strain}: {d:e} > {tol:e}");
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 5 * 3 * 2);
}

/// Cells are classified by their hourglass geometry: a cube, a sheared and rotated
/// parallelepiped and a generated grid cell are parallelepipeds; a node moved by 1e-9 of
/// the cell size (far above the 1e-13 tolerance) and the distorted cells are not.
#[test]
fn parallelepipeds_are_recognised() {
    let mut rng = Lcg(0x5eed_0002);
    let cube = NODE_XI.map(|v| v.map(|c| 0.005 * (c + 1.0)));
    assert!(ReferenceHex::new(&cube).unwrap().is_parallelepiped());
    for _ in 0..20 {
        let x = parallelepiped(&mut rng, 0.01);
        assert!(ReferenceHex::new(&x).unwrap().is_parallelepiped());
        let mut y = x;
        y[6][1] += 1e-9 * 0.01;
        assert!(!ReferenceHex::new(&y).unwrap().is_parallelepiped());
    }
    // A cell of a generated grid far from the origin (coordinates with round-off).
    let (h, o) = (0.2 / 20.0, [0.13, -0.07, 0.05]);
    let grid = NODE_XI.map(|v| core::array::from_fn(|i| o[i] + (7.0 + (v[i] + 1.0) / 2.0) * h));
    assert!(ReferenceHex::new(&grid).unwrap().is_parallelepiped());
}

/// On parallelepipeds the box kernel gives the general kernel's forces to round-off (1e-12
/// of the largest force in f64, 1e-4 in f32, where the two summation orders differ by a
/// few ulps), and the same energy (1e-12 relative).
#[test]
fn box_kernel_equals_the_general_kernel_on_parallelepipeds() {
    let mut rng = Lcg(0x5eed_0003);
    let mut checked = 0;
    for _ in 0..10 {
        let x = parallelepiped(&mut rng, 0.01);
        let r = ReferenceHex::new(&x).unwrap();
        assert!(r.is_parallelepiped());
        for law in laws() {
            let g = law.hourglass_modulus();
            let general = r.reduced::<f64>(NODES, 0, g, KAPPA_HG);
            let boxed = r.parallelepiped::<f64>(NODES, 0, g, KAPPA_HG);
            let general32 = r.reduced::<f32>(NODES, 0, g, KAPPA_HG);
            let boxed32 = r.parallelepiped::<f32>(NODES, 0, g, KAPPA_HG);
            let law32 = law.cast::<f32>();
            for strain in [1e-4, 0.3] {
                let u = displacements(&mut rng, &x, strain);
                let a = general.internal_forces(&law, &u).unwrap();
                let b = boxed.internal_forces(&law, &u).unwrap();
                let d = rel_diff(&a, &b);
                // The same stress from F summed in another order: a few ulps of the
                // largest force (measured up to 1.1e-14).
                let tol = 1e-13;
                assert!(
                    d < tol,
                    "f64, law {law:?}, strain {strain}: {d:e} > {tol:e}"
                );
                let ea = general.energy(&law, &u).unwrap();
                let eb = boxed.energy(&law, &u).unwrap();
                assert!(ea.abs() > 0.0 && (ea - eb).abs() <= 1e-12 * ea.abs());
                let u32_ = u.map(|v| v.map(|c| c as f32));
                let a32 = general32.internal_forces(&law32, &u32_).unwrap();
                let b32 = boxed32.internal_forces(&law32, &u32_).unwrap();
                let up = |f: [[f32; 3]; 8]| f.map(|v| v.map(|c| c as f64));
                let d32 = rel_diff(&up(a32), &up(b32));
                // f32: a few ulps (6e-8) of terms up to ~100x the forces (measured 6.4e-6).
                let tol32 = 3e-5;
                assert!(d32 < tol32, "f32, law {law:?}, strain {strain}: {d32:e}");
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 10 * 3 * 2);
}

/// The box kernel's forces are the gradient of its energy: central differences with step
/// 1e-7 of the cell size agree to 1e-6 of the largest force (truncation ~1e-10, round-off
/// of the energy difference ~1e-16/1e-7 relative).
#[test]
fn box_kernel_forces_are_the_energy_gradient() {
    let mut rng = Lcg(0x5eed_0004);
    let x = parallelepiped(&mut rng, 0.01);
    let r = ReferenceHex::new(&x).unwrap();
    for law in laws() {
        let e = r.parallelepiped::<f64>(NODES, 0, law.hourglass_modulus(), KAPPA_HG);
        let u = displacements(&mut rng, &x, 0.2);
        let f = e.internal_forces(&law, &u).unwrap();
        let step = 1e-7 * 0.01;
        let mut fd = [[0.0; 3]; 8];
        for a in 0..8 {
            for i in 0..3 {
                let (mut up, mut dn) = (u, u);
                up[a][i] += step;
                dn[a][i] -= step;
                fd[a][i] =
                    (e.energy(&law, &up).unwrap() - e.energy(&law, &dn).unwrap()) / (2.0 * step);
            }
        }
        let d = rel_diff(&fd, &f);
        assert!(d < 1e-6, "law {law:?}: {d:e}");
    }
}

/// An inverted state is an error, not a force, in both kernels.
#[test]
fn both_kernels_refuse_an_inverted_state() {
    let mut rng = Lcg(0x5eed_0005);
    let x = parallelepiped(&mut rng, 0.01);
    let r = ReferenceHex::new(&x).unwrap();
    // u = −2 (X − X̄): F = −I, J = −1.
    let c: [f64; 3] = core::array::from_fn(|i| x.iter().map(|v| v[i]).sum::<f64>() / 8.0);
    let u = x.map(|v| core::array::from_fn(|i| -2.0 * (v[i] - c[i])));
    for law in laws() {
        let g = law.hourglass_modulus();
        let e1 = r
            .reduced::<f64>(NODES, 0, g, KAPPA_HG)
            .internal_forces(&law, &u);
        let e2 = r
            .parallelepiped::<f64>(NODES, 0, g, KAPPA_HG)
            .internal_forces(&law, &u);
        let j1 = e1.unwrap_err().jacobian;
        let j2 = e2.unwrap_err().jacobian;
        assert!(
            (j1 + 1.0).abs() < 1e-9 && (j2 + 1.0).abs() < 1e-9,
            "{j1} {j2}"
        );
    }
}

/// The fused element loop (gather, kernel, scatter in one) adds bit for bit the forces
/// `internal_forces` returns, for both kernels (the host's and the board's loops use the
/// former, the kernel tests the latter); a node index outside the arrays is an error.
#[test]
fn fused_accumulation_adds_exactly_the_kernel_forces() {
    let mut rng = Lcg(0x5eed_0006);
    let x = parallelepiped(&mut rng, 0.01);
    let r = ReferenceHex::new(&x).unwrap();
    let law = laws()[0];
    let g = law.hourglass_modulus();
    // Nodes scattered over a larger array, in a shuffled order.
    let nodes: [u32; 8] = [11, 3, 7, 0, 14, 9, 5, 12];
    let general = r.reduced::<f64>(nodes, 0, g, KAPPA_HG);
    let boxed = r.parallelepiped::<f64>(nodes, 0, g, KAPPA_HG);
    let ue = displacements(&mut rng, &x, 0.2);
    let mut u = vec![[0.0; 3]; 16];
    for (a, &n) in nodes.iter().enumerate() {
        u[n as usize] = ue[a];
    }
    type Accumulate<'a> = &'a dyn Fn(&mut [[f64; 3]]) -> Result<(), KernelFault>;
    let check = |fe: [[f64; 3]; 8], acc: Accumulate| {
        let mut f = vec![[0.0; 3]; 16];
        acc(&mut f).unwrap();
        assert!(
            fe.iter().flatten().any(|v| v.abs() > 1e-6),
            "trivial forces"
        );
        assert_eq!(f.len(), u.len());
        for (a, &n) in nodes.iter().enumerate() {
            for i in 0..3 {
                assert_eq!(f[n as usize][i].to_bits(), fe[a][i].to_bits());
            }
        }
        let mut short = vec![[0.0; 3]; 14];
        assert_eq!(acc(&mut short), Err(KernelFault::BadIndex));
    };
    check(general.internal_forces(&law, &ue).unwrap(), &|f| {
        general.accumulate(&law, &u, f)
    });
    check(boxed.internal_forces(&law, &ue).unwrap(), &|f| {
        boxed.accumulate(&law, &u, f)
    });
}

/// An axis-aligned box of random edge lengths (2 to 12 mm) at a random place far from the
/// origin (coordinates with round-off).
fn cuboid(rng: &mut Lcg) -> [[f64; 3]; 8] {
    let o: [f64; 3] = core::array::from_fn(|_| 0.1 * rng.next());
    let h: [f64; 3] = core::array::from_fn(|_| 0.007 + 0.005 * rng.next());
    NODE_XI.map(|v| core::array::from_fn(|i| o[i] + (v[i] + 1.0) / 2.0 * h[i]))
}

/// Cuboids are the axis-aligned parallelepipeds: a cube, random boxes and a generated grid
/// cell are; the random sheared parallelepipeds, a box turned by 1e-6 rad about z (an
/// off-diagonal gradient term 1e-6 of the diagonal, far above the 1e-13 tolerance) and a
/// box with one node moved by 1e-9 of its size are not.
#[test]
fn cuboids_are_recognised() {
    let mut rng = Lcg(0x5eed_0010);
    let cube = NODE_XI.map(|v| v.map(|c| 0.005 * (c + 1.0)));
    assert!(ReferenceHex::new(&cube).unwrap().is_cuboid());
    for _ in 0..20 {
        let x = cuboid(&mut rng);
        assert!(ReferenceHex::new(&x).unwrap().is_cuboid());
        let (s, c) = (1e-6f64.sin(), 1e-6f64.cos());
        let turned = x.map(|p| [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]);
        let r = ReferenceHex::new(&turned).unwrap();
        assert!(r.is_parallelepiped() && !r.is_cuboid());
        let mut y = x;
        y[6][1] += 1e-9 * 0.01;
        assert!(!ReferenceHex::new(&y).unwrap().is_cuboid());
        let p = parallelepiped(&mut rng, 0.01);
        assert!(!ReferenceHex::new(&p).unwrap().is_cuboid());
    }
    let (h, o) = (0.2 / 20.0, [0.13, -0.07, 0.05]);
    let grid = NODE_XI.map(|v| core::array::from_fn(|i| o[i] + (7.0 + (v[i] + 1.0) / 2.0) * h));
    assert!(ReferenceHex::new(&grid).unwrap().is_cuboid());
}

/// On cuboids the cuboid kernel gives the parallelepiped kernel's forces: bit for bit
/// where the gradient basis is exactly diagonal (a cube at the origin: the dropped terms
/// are products with zero, which add nothing to a finite sum), in f64 and f32, and to
/// round-off on random boxes far from the origin, whose basis has off-diagonal round-off
/// (1e-13 of the largest force in f64, as the parallelepiped kernel against the general
/// one; 3e-5 in f32); so the general kernel's forces to 1e-13 in f64. The energies agree
/// to 1e-13.
#[test]
fn cuboid_kernel_gives_the_box_kernels_forces_on_cuboids() {
    let mut rng = Lcg(0x5eed_0011);
    let mut checked = 0;
    let cube = NODE_XI.map(|v| v.map(|c| 0.004 * (c + 1.0)));
    let cells: Vec<[[f64; 3]; 8]> = core::iter::once(cube)
        .chain((0..10).map(|_| cuboid(&mut rng)))
        .collect();
    for (k, x) in cells.iter().enumerate() {
        let r = ReferenceHex::new(x).unwrap();
        assert!(r.is_cuboid());
        let b = r.gradient_basis();
        let exact = (0..3).all(|j| (0..3).all(|i| i == j || b[j][i] == 0.0));
        assert!(k > 0 || exact, "the cube's basis is exactly diagonal");
        for law in laws() {
            let g = law.hourglass_modulus();
            let general = r.reduced::<f64>(NODES, 0, g, KAPPA_HG);
            let boxed = r.parallelepiped::<f64>(NODES, 0, g, KAPPA_HG);
            let cub = r.cuboid::<f64>(NODES, 0, g, KAPPA_HG);
            let boxed32 = r.parallelepiped::<f32>(NODES, 0, g, KAPPA_HG);
            let cub32 = r.cuboid::<f32>(NODES, 0, g, KAPPA_HG);
            let law32 = law.cast::<f32>();
            for strain in [1e-4, 0.3] {
                let u = displacements(&mut rng, x, strain);
                let a = boxed.internal_forces(&law, &u).unwrap();
                let q = cub.internal_forces(&law, &u).unwrap();
                let largest = q.iter().flatten().fold(0.0, |m, v| nan_max(m, v.abs()));
                assert!(largest > 1e-9, "forces far from zero: {largest:e}");
                assert_eq!(a.len(), q.len());
                let u32_ = u.map(|v| v.map(|c| c as f32));
                let a32 = boxed32.internal_forces(&law32, &u32_).unwrap();
                let q32 = cub32.internal_forces(&law32, &u32_).unwrap();
                assert!(q32.iter().flatten().any(|v| v.abs() > 1e-9));
                let up = |f: [[f32; 3]; 8]| f.map(|v| v.map(|c| c as f64));
                if exact {
                    for (p, (fa, fq)) in a.iter().zip(&q).enumerate() {
                        for i in 0..3 {
                            assert_eq!(fa[i].to_bits(), fq[i].to_bits(), "f64 node {p} {i}");
                            let (b32, c32) = (a32[p][i], q32[p][i]);
                            assert_eq!(b32.to_bits(), c32.to_bits(), "f32 node {p} {i}");
                        }
                    }
                }
                let d = rel_diff(&a, &q);
                assert!(d < 1e-13, "f64 against the parallelepiped kernel: {d:e}");
                let d = rel_diff(&general.internal_forces(&law, &u).unwrap(), &q);
                assert!(d < 1e-13, "f64 against the general kernel: {d:e}");
                let d32 = rel_diff(&up(a32), &up(q32));
                assert!(d32 < 3e-5, "f32 against the parallelepiped kernel: {d32:e}");
                let (ea, eq) = (
                    boxed.energy(&law, &u).unwrap(),
                    cub.energy(&law, &u).unwrap(),
                );
                assert!(ea.abs() > 0.0 && (ea - eq).abs() <= 1e-13 * ea.abs());
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 11 * 3 * 2);
}

/// The cuboid kernel's forces are the gradient of its energy (central differences, as for
/// the parallelepiped kernel: 1e-6 of the largest force).
#[test]
fn cuboid_kernel_forces_are_the_energy_gradient() {
    let mut rng = Lcg(0x5eed_0012);
    let x = cuboid(&mut rng);
    let r = ReferenceHex::new(&x).unwrap();
    for law in laws() {
        let e = r.cuboid::<f64>(NODES, 0, law.hourglass_modulus(), KAPPA_HG);
        let u = displacements(&mut rng, &x, 0.2);
        let f = e.internal_forces(&law, &u).unwrap();
        let step = 1e-7 * 0.01;
        let mut fd = [[0.0; 3]; 8];
        for a in 0..8 {
            for i in 0..3 {
                let (mut up, mut dn) = (u, u);
                up[a][i] += step;
                dn[a][i] -= step;
                fd[a][i] =
                    (e.energy(&law, &up).unwrap() - e.energy(&law, &dn).unwrap()) / (2.0 * step);
            }
        }
        let d = rel_diff(&fd, &f);
        assert!(d < 1e-6, "law {law:?}: {d:e}");
    }
}
