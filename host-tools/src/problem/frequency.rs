//! The highest natural frequency of a problem's mesh, linearised about a state: power
//! iteration on `M⁻¹K`. It sets the stability limit `2/ω_max` of the central difference.

use anyhow::{anyhow, Result};
use pe_firmware::physics::{MaterialLaw, Real};

use crate::problem::batched::Batched;
use crate::problem::elements::Elements;
use crate::problem::{NodeKind, Problem};

/// The mesh in one state: its elements and laws in scalar `T` and the displacements `u`.
pub struct Linearised<'a, T: Real> {
    pub problem: &'a Problem,
    pub elements: &'a Elements<T>,
    pub laws: &'a [MaterialLaw<T>],
    pub u: &'a [[T; 3]],
    /// The elements packed for the batched kernel, when they are: the same forces bit for
    /// bit ([`Batched::internal_forces`]), several times faster. `None`: the scalar loop.
    pub batched: Option<&'a Batched<T>>,
}

impl<T: Real> Linearised<'_, T> {
    /// Adds the internal forces at `u` into `f`.
    fn internal_forces(&self, u: &[[T; 3]], f: &mut [[T; 3]]) -> Result<()> {
        match self.batched {
            Some(b) => b.internal_forces(self.elements, self.laws, u, f),
            None => self.elements.internal_forces(self.laws, u, f),
        }
        .map_err(|e| anyhow!("{e}"))
    }
}

/// Deterministic start vector of the power iteration, every free component excited.
pub fn start_vector(problem: &Problem) -> Vec<[f64; 3]> {
    problem
        .node_kind
        .iter()
        .enumerate()
        .map(|(k, kind)| {
            core::array::from_fn(|i| {
                if *kind == NodeKind::Free {
                    (((k * 3 + i) as f64) * 0.7548776662).fract() - 0.5
                } else {
                    0.0
                }
            })
        })
        .collect()
}

/// Highest angular frequency `ω_max` (rad/s) of the free nodes, linearised about `state`,
/// by power iteration on `M⁻¹K` (`K v` by a central difference of the internal forces)
/// from the start vector `v` (warm start: the dominant mode of an earlier call); leaves
/// the last iterate in `v` for the next call. The stable central-difference step is
/// `2/ω_max` (undamped). Costs two force evaluations per iteration, `K(u + εv)` and
/// `K(u − εv)`, run side by side on rayon's global pool: each is one serial loop, so the
/// result has the same bits on any number of threads.
pub fn max_frequency_from<T: Real>(
    state: &Linearised<'_, T>,
    v: &mut Vec<[f64; 3]>,
    iterations: usize,
) -> Result<f64> {
    let problem = state.problem;
    let n = state.u.len();
    let free: Vec<bool> = problem
        .node_kind
        .iter()
        .map(|k| *k == NodeKind::Free)
        .collect();
    let m: Vec<f64> = problem
        .mass
        .iter()
        .map(|m| m * problem.solver.mass_scaling)
        .collect();
    if v.len() != n {
        *v = start_vector(problem);
    }
    let scale = problem
        .reference
        .iter()
        .map(|r| r.characteristic_length())
        .fold(f64::INFINITY, f64::min);
    // The finite-difference probe must stand well above the scalar's resolution of the
    // displacements: 1e-7 of the smallest element in f64, 1e-3 in f32 (ε_f32 ≈ 6e-8).
    let low_precision = T::from_f64(1.0 + 1e-10).to_f64() == 1.0;
    let eps = if low_precision { 1e-3 } else { 1e-7 } * scale;
    let mut lambda = 0.0;
    let mut fp = vec![[T::ZERO; 3]; n];
    let mut fm = vec![[T::ZERO; 3]; n];
    for _ in 0..iterations {
        let norm = v
            .iter()
            .zip(&m)
            .map(|(a, mm)| mm * (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]))
            .sum::<f64>()
            .sqrt();
        if !(norm > 0.0) {
            // No free node (or a lost vector): no mode to limit the step.
            return Ok(0.0);
        }
        v.iter_mut()
            .for_each(|a| a.iter_mut().for_each(|x| *x /= norm));
        let up: Vec<[T; 3]> = state
            .u
            .iter()
            .zip(v.iter())
            .map(|(u, d)| core::array::from_fn(|i| T::from_f64(u[i].to_f64() + eps * d[i])))
            .collect();
        let um: Vec<[T; 3]> = state
            .u
            .iter()
            .zip(v.iter())
            .map(|(u, d)| core::array::from_fn(|i| T::from_f64(u[i].to_f64() - eps * d[i])))
            .collect();
        fp.iter_mut().for_each(|f| *f = [T::ZERO; 3]);
        fm.iter_mut().for_each(|f| *f = [T::ZERO; 3]);
        let (rp, rm) = rayon::join(
            || state.internal_forces(&up, &mut fp),
            || state.internal_forces(&um, &mut fm),
        );
        rp?;
        rm?;
        let mut vkv = 0.0;
        let mut w = vec![[0.0; 3]; n];
        for k in 0..n {
            if !free[k] {
                continue;
            }
            for i in 0..3 {
                let kv = (fp[k][i].to_f64() - fm[k][i].to_f64()) / (2.0 * eps);
                vkv += v[k][i] * kv;
                w[k][i] = kv / m[k];
            }
        }
        lambda = vkv; // v is M-normalised: Rayleigh quotient
        *v = w;
    }
    Ok(lambda.max(0.0).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::batched::Isa;
    use pe_firmware::physics::element::ElementKind;

    /// The batched kernel (and the two evaluations side by side) changes no bit of `ω_max`,
    /// so of the critical step every command derives from it, against the scalar loop,
    /// which evaluates the same terms one by one: at rest and at a deformed state, on the
    /// built-in coarse scene's anatomy (distorted hexahedra: the general kernel only) and on
    /// a box whose cells take all three kernels (cuboids, sheared parallelepipeds, and
    /// general cells between them, counted below).
    #[test]
    fn batched_power_iteration_gives_the_scalar_bits() {
        let scene = crate::scene::builtin::builtin_scene("coarse").expect("built-in scene");
        let anatomy = Problem::from_scene(&scene, std::path::Path::new(".")).expect("problem");
        assert_same_bits(&anatomy);
        // 6 x 3 x 3 cells of 1 cm: x' = x + s(x) z with s = 0 up to x = 2 cm (cuboids), 0.3
        // from 4 cm (an affine shear: parallelepipeds), linear between (general cells).
        let boxed = crate::scene::Scene::from_toml(
            "[mesh]\ngenerate = { kind = \"box\", size = [0.06, 0.03, 0.03], cells = [6, 3, 3] }\n\
             [material]\nlaw = \"neo-hookean\"\nyoungs_modulus = 3.0e5\npoisson_ratio = 0.45\n\
             density = 1000.0\n[[fixed]]\nbox = [[-1.0, -1.0, -1.0], [1e-9, 1.0, 1.0]]\n",
        )
        .expect("the box scene");
        let mut mesh = crate::mesh::grid::generate_box([0.06, 0.03, 0.03], [6, 3, 3]);
        for x in &mut mesh.nodes {
            let s = (0.3 * (x[0] - 0.02) / 0.02).clamp(0.0, 0.3);
            x[0] += s * x[2];
        }
        let mixed = Problem::new(&boxed, mesh, Default::default()).expect("the sheared box");
        let count = |k: ElementKind| {
            (0..54)
                .filter(|&e| crate::problem::elements::kind_of(&mixed, e) == Some(k))
                .count()
        };
        assert_eq!(
            [
                ElementKind::HexCuboid,
                ElementKind::HexBox,
                ElementKind::HexReduced
            ]
            .map(count),
            [18, 18, 18],
            "cuboids, parallelepipeds and general cells"
        );
        assert_same_bits(&mixed);
    }

    /// `ω_max` of `problem`, batched and scalar, at rest and at a smooth deformation: the
    /// same bits.
    fn assert_same_bits(problem: &Problem) {
        let elements = Elements::<f64>::build(problem);
        let laws: Vec<MaterialLaw<f64>> = problem.laws.iter().map(|l| l.cast()).collect();
        let batched = Batched::build(&elements, &laws, Isa::detect()).expect("packs");
        let n = problem.mesh.nodes.len();
        assert!(n > 100, "a mesh of {n} nodes is too small to tell");
        let rest = vec![[0.0; 3]; n];
        // A smooth deformation, a few percent strain: the law's nonlinear terms count.
        let bent: Vec<[f64; 3]> = (problem.mesh.nodes.iter())
            .map(|x| [0.02 * x[1], -0.03 * x[0] * x[2] / 0.05, 0.01 * x[2]])
            .collect();
        for u in [&rest, &bent] {
            let omega = |b: Option<&Batched<f64>>| {
                let state = Linearised {
                    problem,
                    elements: &elements,
                    laws: &laws,
                    u,
                    batched: b,
                };
                let mut v = start_vector(problem);
                max_frequency_from(&state, &mut v, 30).expect("power iteration")
            };
            let (scalar, fast) = (omega(None), omega(Some(&batched)));
            assert!(
                scalar.is_finite() && scalar > 1e3,
                "ω_max = {scalar} rad/s: not a stiff mesh's highest mode"
            );
            assert_eq!(scalar.to_bits(), fast.to_bits(), "{scalar} != {fast}");
        }
    }
}
