//! Scenes built as values, for the analyses and tests: the box cantilever every benchmark
//! and stability case starts from, and the builder methods that add solver settings,
//! gravity, loads, prescribed motion and per-region materials to it.

use crate::scene::{
    FixedSpec, GenerateSpec, GravitySpec, Law, LoadSpec, MaterialSpec, MeshSpec, PrescribedSpec,
    RegionRef, Scene, SolverSpec,
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
            unit: None,
        },
        materials: vec![neo_hookean(youngs_modulus_pa, poisson_ratio)],
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
        ramp: None,
        shape: None,
    }
}

/// Standard gravity along −z brought in by NiftySim's smooth step (POLY345) from 0 at
/// `t = 0` to 1 at `t = ramp_s`, held after.
pub fn gravity_down_ramped(ramp_s: f64) -> GravitySpec {
    GravitySpec {
        ramp: Some(vec![[0.0, 0.0], [ramp_s, 1.0]]),
        shape: Some(pe_firmware::image::Segment::Poly345),
        ..gravity_down()
    }
}

/// A neo-Hookean material for every cell (Young's modulus `youngs_modulus_pa`, Poisson
/// ratio `poisson_ratio`, ρ = 1000 kg/m³).
pub fn neo_hookean(youngs_modulus_pa: f64, poisson_ratio: f64) -> MaterialSpec {
    MaterialSpec {
        region: None,
        law: Law::NeoHookean,
        youngs_modulus: Some(youngs_modulus_pa),
        poisson_ratio: Some(poisson_ratio),
        c10: None,
        c01: None,
        bulk_modulus: None,
        volumetric: None,
        density: 1000.0,
    }
}

impl MaterialSpec {
    /// This material for the cells of the named region only.
    pub fn in_region(mut self, name: &str) -> MaterialSpec {
        self.region = Some(RegionRef::Name(name.to_string()));
        self
    }
}

impl Scene {
    /// The scene with its `[solver]` settings changed by `f`.
    pub fn with_solver(mut self, f: impl FnOnce(&mut SolverSpec)) -> Scene {
        f(&mut self.solver);
        self
    }

    /// The scene under gravity `g`.
    pub fn with_gravity(mut self, g: GravitySpec) -> Scene {
        self.gravity = Some(g);
        self
    }

    /// The scene with the materials `materials` instead of its own.
    pub fn with_materials(mut self, materials: Vec<MaterialSpec>) -> Scene {
        self.materials = materials;
        self
    }

    /// The scene with the total force `force_n` (N) shared by the nodes in the box `within`,
    /// scaled in time by the piecewise-linear `ramp` (`[t, factor]` points; None: 1).
    pub fn with_load(
        mut self,
        within: [[f64; 3]; 2],
        force_n: [f64; 3],
        ramp: Option<Vec<[f64; 2]>>,
    ) -> Scene {
        self.load.push(LoadSpec {
            box_: Some(within),
            sphere: None,
            set: None,
            force: force_n,
            ramp,
            shape: None,
        });
        self
    }

    /// The scene with the nodes in the box `within` moved along `path`
    /// (`[t, ux, uy, uz]` points).
    pub fn with_prescribed(mut self, within: [[f64; 3]; 2], path: Vec<[f64; 4]>) -> Scene {
        self.prescribed.push(PrescribedSpec {
            box_: Some(within),
            sphere: None,
            set: None,
            path,
            shape: None,
        });
        self
    }
}
