//! Scene files (TOML, SI units): mesh, materials, boundary conditions, loads and solver
//! settings. Every key is documented in docs/scene.md; unknown keys are errors.

pub mod args;
pub mod builders;
pub mod builtin;
pub mod mesh_source;
pub mod settings;

use std::path::{Path, PathBuf};

use pe_firmware::image::Segment;
pub use pe_firmware::image::{Integration, Precision};
use pe_firmware::physics::HourglassControl;
use serde::{Deserialize, Serialize};

pub use args::SceneArgs;
pub use settings::Law;

/// A whole scene as read from a file (or built in code for the built-in scene).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    pub mesh: MeshSpec,
    #[serde(default, rename = "material", deserialize_with = "one_or_many")]
    pub materials: Vec<MaterialSpec>,
    #[serde(default)]
    pub fixed: Vec<FixedSpec>,
    #[serde(default)]
    pub prescribed: Vec<PrescribedSpec>,
    #[serde(default)]
    pub load: Vec<LoadSpec>,
    #[serde(default)]
    pub gravity: Option<GravitySpec>,
    #[serde(default)]
    pub solver: SolverSpec,
    /// `[contact]`: settings shared by every tool and contact pair.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact: Option<ContactSpec>,
    /// `[[surface]]`: named contact surfaces (boundary faces of the mesh).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub surface: Vec<SurfaceSpec>,
    /// `[[tool]]`: rigid instruments moving along a path.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tool: Vec<ToolSpec>,
    /// `[[contact_pair]]`: two surfaces that may touch (tissue against tissue).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub contact_pair: Vec<ContactPairSpec>,
}

/// `[contact]`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContactSpec {
    /// Penalty stiffness as a fraction β of each node's `m / Δt²` (the contact spring adds
    /// β to `(ω Δt)²`; at dt_safety 0.9 the stiffest mode leaves room for about 0.7).
    pub penalty: f64,
    /// Deepest penetration tolerated (m); deeper is an error naming the node and step.
    pub tolerance: f64,
    /// Fastest any contact-surface node moves (m/s); faster is an error.
    pub speed_bound: f64,
    /// Margin (m) the bounding-box checks cover: boxes are compared every
    /// `gap / (2 · speed_bound · Δt)` steps (the seed: 2 cm and 10 cm/s give 1000 steps).
    pub gap: f64,
}

impl Default for ContactSpec {
    fn default() -> Self {
        ContactSpec {
            penalty: 0.5,
            tolerance: 1e-3,
            speed_bound: 0.1,
            gap: 0.02,
        }
    }
}

/// `[[surface]]`: the boundary faces of the mesh's cells in `region` (default: all cells)
/// whose four nodes are all selected by `box`/`sphere`/`set` (default: no restriction).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfaceSpec {
    pub name: String,
    pub region: Option<RegionRef>,
    #[serde(rename = "box")]
    pub box_: Option<[[f64; 3]; 2]>,
    pub sphere: Option<SphereSpec>,
    pub set: Option<String>,
}

/// `[[tool]]`: a rigid capsule (`shape = "capsule"`: every point within `radius` of the
/// segment `a`–`b`, m) moved by the displacement `path = [[t, dx, dy, dz], ...]`
/// (piecewise linear, held after the last point), touching the nodes of `surface`. In a
/// live session (`pe live`) the poses a trainer gives replace the path; `trocar` (m), if
/// given, is the point the instrument pivots about (the page's controls keep its axis
/// through it).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ToolSpec {
    pub name: String,
    pub shape: String,
    pub a: [f64; 3],
    pub b: [f64; 3],
    pub radius: f64,
    pub path: Vec<[f64; 4]>,
    pub surface: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trocar: Option<[f64; 3]>,
}

/// `[[contact_pair]]`: the nodes of each surface against the faces of the other.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactPairSpec {
    pub surfaces: [String; 2],
    /// Deepest penetration still taken as contact (m); default: a third of the thinnest
    /// cell of either surface (a node deeper than that is on the far side of a thin body).
    pub depth: Option<f64>,
}

/// `[mesh]`: one of `file`, `generate` or `builtin`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshSpec {
    /// A mesh file relative to the scene file: Gmsh MSH 4.1 or 2.2, legacy VTK (up to 5.1)
    /// or VTK XML `.vtu`; hexahedra and prisms, its physical groups or point tags as node sets.
    pub file: Option<PathBuf>,
    /// Length unit of the mesh's coordinates (the file's, or `generate`/`blocks` sizes):
    /// "m" (default), "cm" or "mm"; they are converted to metres on reading. Everything
    /// else in the scene is SI (metres, seconds, newtons, pascals).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    pub generate: Option<GenerateSpec>,
    /// Built-in anatomy: "uterus" (uterus and both tubes) or "uterus_ovary" (plus the
    /// right ovary under the right tube, region `right_ovary`, its lower part the node set
    /// `right_ovary_base`).
    pub builtin: Option<String>,
    /// Level of the built-in anatomy: "coarse" (~300), "medium" (~2000), "fine" (~20000).
    pub level: Option<String>,
    /// `[[mesh.blocks]]`: separate boxes of hexahedra (one body and one region each,
    /// region tag k + 1 named `name`): test bodies for contact.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub blocks: Vec<BlockSpec>,
}

/// One box of `[[mesh.blocks]]`: from `origin` to `origin + size`, `cells` per axis.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlockSpec {
    pub name: String,
    pub origin: [f64; 3],
    pub size: [f64; 3],
    pub cells: [usize; 3],
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GenerateSpec {
    /// "box": spans from the origin to `size`.
    pub kind: String,
    pub size: [f64; 3],
    pub cells: [usize; 3],
}

/// A region by physical-group tag or name.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum RegionRef {
    Tag(i32),
    Name(String),
}

impl std::fmt::Display for RegionRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RegionRef::Tag(t) => write!(f, "{t}"),
            RegionRef::Name(n) => write!(f, "\"{n}\""),
        }
    }
}

/// `[material]` or `[[material]]` (with `region`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Physical group this material applies to; omitted: every cell not otherwise covered.
    pub region: Option<RegionRef>,
    /// "neo-hookean" | "neo-hookean-decoupled" | "mooney-rivlin"
    pub law: Law,
    pub youngs_modulus: Option<f64>,
    pub poisson_ratio: Option<f64>,
    pub c10: Option<f64>,
    pub c01: Option<f64>,
    pub bulk_modulus: Option<f64>,
    /// "quadratic" | "log" (Mooney-Rivlin volumetric energy)
    pub volumetric: Option<String>,
    pub density: f64,
}

/// Which nodes a boundary condition or load applies to: the union of a box, a sphere and a
/// named node set (the keys `box`, `sphere`, `set` of `[[fixed]]`, `[[prescribed]]`, `[[load]]`).
#[derive(Clone, Copy, Debug)]
pub struct Selector<'a> {
    pub box_: Option<&'a [[f64; 3]; 2]>,
    pub sphere: Option<&'a SphereSpec>,
    pub set: Option<&'a str>,
}

macro_rules! selector {
    ($t:ty) => {
        impl $t {
            pub fn selector(&self) -> Selector<'_> {
                Selector {
                    box_: self.box_.as_ref(),
                    sphere: self.sphere.as_ref(),
                    set: self.set.as_deref(),
                }
            }
        }
    };
}
selector!(FixedSpec);
selector!(PrescribedSpec);
selector!(LoadSpec);
selector!(SurfaceSpec);

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereSpec {
    pub center: [f64; 3],
    pub radius: f64,
}

/// `[[fixed]]`: clamped nodes.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixedSpec {
    #[serde(rename = "box")]
    pub box_: Option<[[f64; 3]; 2]>,
    pub sphere: Option<SphereSpec>,
    pub set: Option<String>,
}

/// `[[prescribed]]`: nodes moved along a displacement path, piecewise linear in time
/// through `path = [[t, ux, uy, uz], ...]` and held at the last point afterwards.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PrescribedSpec {
    #[serde(rename = "box")]
    pub box_: Option<[[f64; 3]; 2]>,
    pub sphere: Option<SphereSpec>,
    pub set: Option<String>,
    pub path: Vec<[f64; 4]>,
    /// How the path goes from one point to the next: `"linear"` (default) or `"poly345"`
    /// (NiftySim's smooth step: no jump in velocity or acceleration at the points).
    pub shape: Option<Segment>,
}

/// `[[load]]`: a total force (N) split equally over the selected nodes, scaled in time by
/// the optional `ramp = [[t, factor], ...]` (default: constant 1), straight from point to
/// point or along `shape = "poly345"`, NiftySim's smooth step.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSpec {
    #[serde(rename = "box")]
    pub box_: Option<[[f64; 3]; 2]>,
    pub sphere: Option<SphereSpec>,
    pub set: Option<String>,
    pub force: [f64; 3],
    pub ramp: Option<Vec<[f64; 2]>>,
    /// How the ramp goes from one point to the next (`"linear"`, the default, or
    /// `"poly345"`).
    pub shape: Option<Segment>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GravitySpec {
    pub acceleration: [f64; 3],
    /// Gravity scaled in time by `ramp = [[t, factor], ...]` like a `[[load]]`'s (default:
    /// constant 1, gravity from the first step), e.g. `[[0.0, 0.0], [0.5, 1.0]]` with
    /// `shape = "poly345"` to bring a soft organ to its sagged state without the overshoot
    /// of sudden gravity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ramp: Option<Vec<[f64; 2]>>,
    /// How the ramp goes from one point to the next (`"linear"`, the default, or
    /// `"poly345"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shape: Option<Segment>,
}

/// `[solver]`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolverSpec {
    /// "f64" | "f32"
    #[serde(with = "settings::precision_text")]
    pub precision: Precision,
    /// "reduced" | "full"
    #[serde(with = "settings::integration_text")]
    pub integration: Integration,
    /// Hourglass control of reduced integration: `"physical"` (the default: a stiffness per
    /// mode and direction from each cell and its material) or a number, the coefficient
    /// κ_hg of the seed's scalar form (`pe_firmware::physics::element::hourglass`).
    #[serde(with = "settings::hourglass_text")]
    pub hourglass: HourglassControl,
    /// How tetrahedra take their volumetric response: `"nodal-pressure"` (the default:
    /// averaged over each node's tetrahedra, T4ANP, which does not lock as ν → 0.5) or
    /// `"plain"` (each element's own, T4).
    pub tetrahedron: pe_firmware::physics::TetPressure,
    /// Mass-proportional damping α (1/s).
    pub damping: f64,
    /// dt = dt_safety × dt_critical, unless `dt` is given.
    pub dt_safety: f64,
    /// Explicit time step (s); refused above the critical step unless `force_dt = true`.
    pub dt: Option<f64>,
    pub force_dt: bool,
    /// Inertia (not gravity) scaled by this factor; raises the critical step by its root.
    pub mass_scaling: f64,
    /// Simulated seconds (or `steps`).
    pub duration: Option<f64>,
    pub steps: Option<u64>,
    /// Speed above which a node is reported as unstable (m/s); the tissue moves at most
    /// ~0.1 m/s, so the default 100 m/s only trips on a blow-up.
    pub speed_limit: f64,
    /// Seconds of simulated time between ParaView frames (with --vtk).
    pub output_interval: f64,
    /// Seconds of simulated time between the boards' surface updates to the graphics
    /// engine (the seed: 40 ms).
    pub graphics_interval: f64,
    /// Each update is spread over at most this many steps (the seed: 20).
    pub graphics_spread_steps: u32,
    /// Every this many steps, bound the critical step of the current (deformed) state
    /// element by element (`solver::stable_step`), a few percent of a step's cost; `0`:
    /// never (the step found at rest is kept). Large deformation shrinks the stable step.
    pub dt_track_interval: u64,
    /// Every this many steps, re-estimate the critical step about the current (deformed)
    /// state by a warm-started power iteration, which also recalibrates the element
    /// tracker; `None`: never.
    pub dt_recheck_interval: Option<u64>,
    /// Power iterations per re-check (warm-started from the previous estimate's vector).
    pub dt_recheck_iterations: usize,
    /// When a check finds `dt` above `dt_safety ×` the new critical step: `false` stops
    /// the run with an error naming the step, the cell and the new critical step; `true`
    /// lowers `dt` to `dt_safety ×` the new critical step (the central-difference history
    /// is rescaled). Default (`None`): lower it, except with contact (whose penalty follows
    /// from the step), which stops.
    pub adapt_dt: Option<bool>,
}

/// Steps between two element-by-element bounds of the stable step (`dt_track_interval`).
pub const DEFAULT_DT_TRACK_INTERVAL: u64 = 20;

impl Default for SolverSpec {
    fn default() -> Self {
        SolverSpec {
            precision: Precision::F64,
            integration: Integration::Reduced,
            hourglass: HourglassControl::DEFAULT,
            tetrahedron: pe_firmware::physics::TetPressure::Nodal,
            damping: 0.0,
            dt_safety: 0.9,
            dt: None,
            force_dt: false,
            mass_scaling: 1.0,
            duration: None,
            steps: None,
            speed_limit: 100.0,
            output_interval: 0.04,
            graphics_interval: 0.04,
            graphics_spread_steps: 20,
            dt_track_interval: DEFAULT_DT_TRACK_INTERVAL,
            dt_recheck_interval: None,
            dt_recheck_iterations: 20,
            adapt_dt: None,
        }
    }
}

fn one_or_many<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<MaterialSpec>, D::Error> {
    // Through a `toml::Value` rather than an untagged enum, so that an error inside a
    // material (an unknown law, say) reaches the user instead of "no variant matched".
    use serde::de::Error;
    let value = toml::Value::deserialize(d)?;
    match value {
        toml::Value::Array(_) => Vec::<MaterialSpec>::deserialize(value).map_err(D::Error::custom),
        _ => MaterialSpec::deserialize(value)
            .map(|m| vec![m])
            .map_err(D::Error::custom),
    }
}

/// Errors on the first number under `value` that is not finite, naming where it is as
/// `head key` (`[solver] dt`, `[[load]] 0 force[1]`, `[mesh] generate.size[0]`).
fn first_non_finite(value: &toml::Value, head: &str, key: &str) -> anyhow::Result<()> {
    match value {
        toml::Value::Float(v) if !v.is_finite() => anyhow::bail!(
            "{} = {v}: not a finite number (every number in a scene must be finite)",
            format!("{head} {key}").trim()
        ),
        toml::Value::Table(t) => t.iter().try_for_each(|(k, v)| {
            let key = if key.is_empty() {
                k.clone()
            } else {
                format!("{key}.{k}")
            };
            first_non_finite(v, head, &key)
        }),
        toml::Value::Array(a) => a
            .iter()
            .enumerate()
            .try_for_each(|(i, v)| first_non_finite(v, head, &format!("{key}[{i}]"))),
        _ => Ok(()),
    }
}

impl Scene {
    /// Reads and parses a scene file; errors name the file and (from the TOML parser) the line.
    pub fn from_file(path: &Path) -> anyhow::Result<Scene> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("cannot read scene file {}: {e}", path.display()))?;
        Self::from_toml(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
    }

    pub fn from_toml(text: &str) -> anyhow::Result<Scene> {
        let scene: Scene = toml::from_str(text).map_err(|e| anyhow::anyhow!("{e}"))?;
        // Every number of a scene is a length, time, modulus, force...: a NaN or an infinity
        // would only show up later as a node gone non-finite (or not at all). Refused here,
        // naming the table and key as written.
        let table: toml::Table = text.parse().map_err(|e| anyhow::anyhow!("{e}"))?;
        for (key, value) in &table {
            match value {
                toml::Value::Table(_) => first_non_finite(value, &format!("[{key}]"), "")?,
                toml::Value::Array(a) if a.iter().all(toml::Value::is_table) => {
                    for (i, t) in a.iter().enumerate() {
                        first_non_finite(t, &format!("[[{key}]] {i}"), "")?;
                    }
                }
                _ => first_non_finite(value, "", key)?,
            }
        }
        if let (Some(n), Some(d)) = (scene.solver.steps, scene.solver.duration) {
            anyhow::bail!(
                "[solver] steps = {n} and duration = {d} both given: give one (steps counts time steps, duration simulated seconds)"
            );
        }
        Ok(scene)
    }

    pub fn to_toml(&self) -> anyhow::Result<String> {
        Ok(toml::to_string_pretty(self)?)
    }
}
