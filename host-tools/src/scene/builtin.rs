//! The built-in scene (the seed's Figure 3: uterus with both fallopian tubes, held at the
//! cervix, a blunt probe pushing one tube onto the right ovary) and the quantities its
//! summary reports.

use anyhow::{anyhow, Result};

use crate::geom::norm;
use crate::mesh::builtin::{self, Level, REGION_RIGHT_OVIDUCT};
use crate::mesh::ovary::REGION_RIGHT_OVARY;
use crate::mesh::Mesh;
use crate::scene::*;

/// Probe tip radius (m): a blunt 5 mm laparoscopic probe.
pub const PROBE_TIP_RADIUS_M: f64 = 0.0025;
/// How far the probe pushes the tube (m) and over what time (s).
pub const PROBE_PUSH_M: f64 = 0.0035;
pub const PROBE_PUSH_S: f64 = 0.5;
/// The probe starts this far above the tube (m).
pub const PROBE_START_GAP_M: f64 = 0.001;

/// The built-in scene at a mesh level.
pub fn builtin_scene(level: &str) -> Result<Scene> {
    let lv: Level = level.parse().map_err(|e| anyhow!("--level: {e}"))?;
    let probe = builtin::generate(lv).probe;
    let up = probe.push_direction.map(|v| -v);
    // The blunt probe: a capsule of the tip's radius, its end just above the tube, its
    // shaft leaning back 30 degrees from the vertical, 40 mm of it modelled.
    let r = PROBE_TIP_RADIUS_M;
    let tip: [f64; 3] =
        core::array::from_fn(|i| probe.contact_point[i] + (r + PROBE_START_GAP_M) * up[i]);
    let lean = [0.5, 0.0, 0.866];
    let tail: [f64; 3] = core::array::from_fn(|i| tip[i] + 0.04 * lean[i]);
    let travel = PROBE_PUSH_M + PROBE_START_GAP_M;
    let d = probe.push_direction.map(|v| v * travel);
    let mat = |region: Option<&str>, e: f64| MaterialSpec {
        region: region.map(|r| RegionRef::Name(r.into())),
        law: Law::NeoHookean,
        youngs_modulus: Some(e),
        poisson_ratio: Some(0.45),
        c10: None,
        c01: None,
        bulk_modulus: None,
        volumetric: None,
        density: 1000.0,
    };
    Ok(Scene {
        mesh: MeshSpec {
            file: None,
            generate: None,
            builtin: Some("uterus_ovary".into()),
            level: Some(level.into()),
            blocks: vec![],
            unit: None,
        },
        // Uterine wall ~ 10 kPa; the oviducts are softer (3 kPa).
        materials: vec![
            mat(None, 10.0e3),
            mat(Some("left_oviduct"), 3.0e3),
            mat(Some("right_oviduct"), 3.0e3),
            mat(Some("right_ovary"), 5.0e3),
        ],
        // Held at the cervix; the tubes' far ends are held by their ligaments, the ovary's
        // lower part by its own.
        fixed: [
            "cervix",
            "left_tube_end",
            "right_tube_end",
            "right_ovary_base",
        ]
        .map(|s| FixedSpec {
            box_: None,
            sphere: None,
            set: Some(s.into()),
        })
        .to_vec(),
        prescribed: vec![],
        load: vec![],
        // The organs rest on their neighbours in the pelvis, which carry their weight; a
        // 3 kPa tube 3.5 mm across could not carry its own over 10 cm, so gravity is off.
        gravity: None,
        solver: SolverSpec {
            damping: 20.0,
            duration: Some(0.6),
            ..SolverSpec::default()
        },
        // The probe moves at 1 cm/s; 5 mm of gap at the 10 cm/s bound checks the boxes
        // every 25 ms (the seed's 2 cm would list every tube node within 2 cm of the ovary
        // as a candidate).
        contact: Some(ContactSpec {
            penalty: 0.3,
            gap: 0.005,
            ..ContactSpec::default()
        }),
        // Only what the scene needs takes part: the tube within 25 mm of the probe site
        // (the ovary reaches 15 mm from it), and the ovary.
        surface: vec![
            SurfaceSpec {
                name: "right_tube".into(),
                region: Some(RegionRef::Name("right_oviduct".into())),
                box_: None,
                sphere: Some(SphereSpec {
                    center: probe.contact_point,
                    radius: 0.025,
                }),
                set: None,
            },
            SurfaceSpec {
                name: "right_ovary".into(),
                region: Some(RegionRef::Name("right_ovary".into())),
                box_: None,
                sphere: None,
                set: None,
            },
        ],
        tool: vec![ToolSpec {
            name: "probe".into(),
            shape: "capsule".into(),
            a: tip,
            b: tail,
            radius: r,
            path: vec![[0.0, 0.0, 0.0, 0.0], [PROBE_PUSH_S, d[0], d[1], d[2]]],
            surface: "right_tube".into(),
            // The trocar in the abdominal wall, 15 cm up the shaft from the tip.
            trocar: Some(core::array::from_fn(|i| tip[i] + 0.15 * lean[i])),
        }],
        // The pushed tube presses on the ovary and slides over its curved top.
        contact_pair: vec![ContactPairSpec {
            surfaces: ["right_tube".into(), "right_ovary".into()],
            depth: None,
        }],
    })
}

/// What the built-in scene's summary reports about a displacement field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuiltinSummary {
    /// Largest displacement of the right tube (the one the probe pushes), m.
    pub right_tube_max_displacement_m: f64,
    /// Largest displacement of the right ovary (moved only through the tube-ovary contact
    /// pair), m.
    pub right_ovary_max_displacement_m: f64,
}

/// The built-in scene's summary quantities of the displacements `u` on `mesh`.
pub fn builtin_summary(mesh: &Mesh, u: &[[f64; 3]]) -> BuiltinSummary {
    let region_max = |region: i32| {
        mesh.cells
            .iter()
            .zip(&mesh.cell_regions)
            .filter(|(_, r)| **r == region)
            .flat_map(|(c, _)| c.iter().map(|&n| n as usize))
            .map(|n| norm(u[n]))
            .fold(0.0, f64::max)
    };
    BuiltinSummary {
        right_tube_max_displacement_m: region_max(REGION_RIGHT_OVIDUCT),
        right_ovary_max_displacement_m: region_max(REGION_RIGHT_OVARY),
    }
}
