//! Turns a scene's `[mesh]` into a mesh plus the named node sets it provides, and builds the
//! built-in scene (the seed's Figure 3: uterus with both fallopian tubes, held at the cervix,
//! a blunt probe pushing one tube).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Result};

use crate::builtin::{self, Level};
use crate::mesh::Mesh;
use crate::scene::*;

pub fn load(spec: &MeshSpec, scene_dir: &Path) -> Result<(Mesh, BTreeMap<String, Vec<u32>>)> {
    let given = [
        spec.file.is_some(),
        spec.generate.is_some(),
        spec.builtin.is_some(),
        !spec.blocks.is_empty(),
    ];
    if given.iter().filter(|g| **g).count() != 1 {
        bail!("[mesh] needs exactly one of `file`, `generate`, `builtin`, `blocks`");
    }
    if !spec.blocks.is_empty() {
        let mut mesh = Mesh {
            source: "[[mesh.blocks]]".into(),
            ..Mesh::default()
        };
        for (k, b) in spec.blocks.iter().enumerate() {
            if b.cells.contains(&0) || b.size.iter().any(|&s| !(s > 0.0)) {
                bail!(
                    "[[mesh.blocks]] {k} ({:?}): size and cells must be positive",
                    b.name
                );
            }
            let part = crate::mesh_io::generate_box(b.size, b.cells);
            let base = mesh.nodes.len() as u32;
            let region = k as i32 + 1;
            mesh.nodes.extend(
                part.nodes
                    .iter()
                    .map(|p| core::array::from_fn(|i| p[i] + b.origin[i])),
            );
            mesh.cells
                .extend(part.cells.iter().map(|c| c.map(|n| n + base)));
            mesh.cell_regions
                .extend(std::iter::repeat_n(region, part.cells.len()));
            mesh.region_names.insert(region, b.name.clone());
        }
        mesh.node_tags = (1..=mesh.nodes.len() as u64).collect();
        return Ok((mesh, BTreeMap::new()));
    }
    if let Some(f) = &spec.file {
        let path = scene_dir.join(f);
        return Ok((crate::mesh_io::load_mesh(&path)?, BTreeMap::new()));
    }
    if let Some(g) = &spec.generate {
        if g.kind != "box" {
            bail!(
                "[mesh] generate.kind = \"{}\": only \"box\" is known",
                g.kind
            );
        }
        if g.cells.contains(&0) || g.size.iter().any(|&s| !(s > 0.0)) {
            bail!("[mesh] generate: size and cells must be positive");
        }
        return Ok((
            crate::mesh_io::generate_box(g.size, g.cells),
            BTreeMap::new(),
        ));
    }
    let name = spec.builtin.as_deref().unwrap_or_default();
    if name != "uterus" && name != "uterus_ovary" {
        bail!("[mesh] builtin = \"{name}\": the built-in meshes are \"uterus\" (uterus and both tubes) and \"uterus_ovary\" (plus the right ovary under the right tube)");
    }
    let level: Level = spec
        .level
        .as_deref()
        .unwrap_or("medium")
        .parse()
        .map_err(|e| anyhow!("[mesh] level: {e}"))?;
    let mut a = builtin::generate(level);
    let mut sets = BTreeMap::new();
    if name == "uterus_ovary" {
        let site = crate::ovary::add_right_ovary(&mut a, level);
        sets.insert("right_ovary_base".to_string(), site.fixed_nodes);
    }
    sets.insert("cervix".to_string(), a.cervix_nodes.clone());
    sets.insert("probe".to_string(), probe_nodes(&a));
    for (region, name) in [
        (builtin::REGION_LEFT_OVIDUCT, "left_tube_end"),
        (builtin::REGION_RIGHT_OVIDUCT, "right_tube_end"),
    ] {
        sets.insert(name.to_string(), tube_end_nodes(&a.mesh, region));
    }
    Ok((a.mesh, sets))
}

/// Nodes of the last cross-section of a tube (the one farthest from the body along y).
fn tube_end_nodes(mesh: &Mesh, region: i32) -> Vec<u32> {
    let mut nodes: Vec<u32> = mesh
        .cells
        .iter()
        .zip(&mesh.cell_regions)
        .filter(|(_, r)| **r == region)
        .flat_map(|(c, _)| c.iter().copied())
        .collect();
    nodes.sort_unstable();
    nodes.dedup();
    let far = nodes
        .iter()
        .map(|&n| mesh.nodes[n as usize][1].abs())
        .fold(0.0, f64::max);
    nodes.retain(|&n| mesh.nodes[n as usize][1].abs() > far - 1e-4);
    nodes
}

/// Probe tip radius (m): a blunt 5 mm laparoscopic probe.
pub const PROBE_TIP_RADIUS_M: f64 = 0.0025;
/// How far the probe pushes the tube (m) and over what time (s).
pub const PROBE_PUSH_M: f64 = 0.0035;
pub const PROBE_PUSH_S: f64 = 0.5;
/// The probe starts this far above the tube (m).
pub const PROBE_START_GAP_M: f64 = 0.001;

/// The tube's nodes under the probe tip: every node of the tube's cross-section within the
/// tip radius of the tube axis point below the contact point (until contact exists, the
/// probe is a prescribed displacement of these nodes, so the whole section moves with it).
fn probe_nodes(a: &builtin::Anatomy) -> Vec<u32> {
    let p = &a.probe;
    let c: [f64; 3] =
        core::array::from_fn(|i| p.contact_point[i] + p.tube_radius_m * p.push_direction[i]);
    let mut r = PROBE_TIP_RADIUS_M;
    loop {
        let v: Vec<u32> = (0..a.mesh.nodes.len() as u32)
            .filter(|&n| {
                let p = a.mesh.nodes[n as usize];
                (0..3).map(|i| (p[i] - c[i]).powi(2)).sum::<f64>() <= r * r
            })
            .collect();
        if !v.is_empty() {
            return v;
        }
        r *= 1.5;
    }
}

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
        law: "neo-hookean".into(),
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
        }],
        // The pushed tube presses on the ovary and slides over its curved top.
        contact_pair: vec![ContactPairSpec {
            surfaces: ["right_tube".into(), "right_ovary".into()],
            depth: None,
        }],
    })
}
