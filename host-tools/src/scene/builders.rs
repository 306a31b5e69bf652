//! Scenes built as values, for the analyses and tests: the box cantilever every benchmark
//! and stability case starts from.

use crate::scene::{
    FixedSpec, GenerateSpec, GravitySpec, Law, MaterialSpec, MeshSpec, Scene, SolverSpec,
};

/// A box of `cells` hexahedra from the origin to `size_m`, one neo-Hookean material
/// (Young's modulus `youngs_modulus_pa`, Poisson ratio `poisson_ratio`, ρ = 1000 kg/m³),
/// clamped at x = 0 when `clamped` (every node within 1e-9 m of that face); default solver
/// settings, no gravity, no loads.
pub fn box_cantilever(
    size_m: [f64; 3],
    cells: [usize; 3],
    youngs_modulus_pa: f64,
    poisson_ratio: f64,
    clamped: bool,
) -> Scene {
    Scene {
        mesh: MeshSpec {
            file: None,
            generate: Some(GenerateSpec {
                kind: "box".into(),
                size: size_m,
                cells,
            }),
            builtin: None,
            level: None,
            blocks: vec![],
        },
        materials: vec![MaterialSpec {
            region: None,
            law: Law::NeoHookean,
            youngs_modulus: Some(youngs_modulus_pa),
            poisson_ratio: Some(poisson_ratio),
            c10: None,
            c01: None,
            bulk_modulus: None,
            volumetric: None,
            density: 1000.0,
        }],
        fixed: if clamped {
            vec![FixedSpec {
                box_: Some([[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]),
                sphere: None,
                set: None,
            }]
        } else {
            vec![]
        },
        prescribed: vec![],
        load: vec![],
        gravity: None,
        solver: SolverSpec::default(),
        contact: None,
        surface: vec![],
        tool: vec![],
        contact_pair: vec![],
    }
}

/// Standard gravity along −z.
pub fn gravity_down() -> GravitySpec {
    GravitySpec {
        acceleration: [0.0, 0.0, -9.81],
    }
}
