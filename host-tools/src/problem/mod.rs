//! A scene resolved against its mesh: per-cell materials, node sets, constraints and loads,
//! all in `f64`. This is what the serial solver and the schedule compiler start from.

pub mod batched;
mod conditions;
pub mod contact;
pub mod curves;
pub mod elements;
pub mod frequency;
pub mod reference;

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use pe_firmware::physics::{LameParameters, MaterialLaw, ReferenceHex, ReferenceTet, Volumetric};

use crate::mesh::{as_tetrahedron, Mesh};
use crate::scene::{Law, MaterialSpec, RegionRef, Scene, Selector, SolverSpec};
use batched::{Batched, Isa};
use conditions::{constraints, gravity_of, gravity_ramp_of, nodal_loads, NodeSelector};
pub use curves::Path1;
pub use reference::CellReference;

/// Dilatational wave speeds of soft tissue in SI units, with a wide margin (gels to
/// nearly incompressible stiff tissue): outside it a material is probably in other units.
pub const PLAUSIBLE_WAVE_SPEED_M_PER_S: (f64, f64) = (0.1, 3000.0);

/// The critical step of a plausible soft-tissue mesh is about 1e-4 s; above this a scene
/// is probably mis-scaled.
pub const PLAUSIBLE_DT_MAX_S: f64 = 1e-2;

/// How a node moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NodeKind {
    Free,
    Fixed,
    /// Follows prescribed path number `k`.
    Prescribed(u32),
}

#[derive(Clone, Debug)]
pub struct Load {
    pub node: u32,
    pub force: [f64; 3],
    pub ramp: Option<Path1<1>>,
}

/// The scene resolved on its mesh.
#[derive(Clone, Debug)]
pub struct Problem {
    pub mesh: Mesh,
    /// Named node sets the mesh provides (built-in anatomy: "cervix", "probe").
    pub node_sets: BTreeMap<String, Vec<u32>>,
    pub laws: Vec<MaterialLaw<f64>>,
    pub densities: Vec<f64>,
    /// Material index of every cell.
    pub cell_material: Vec<u16>,
    pub reference: Vec<CellReference>,
    pub node_kind: Vec<NodeKind>,
    pub paths: Vec<Path1<3>>,
    pub loads: Vec<Load>,
    pub gravity: [f64; 3],
    /// Gravity's factor in time (`[gravity] ramp`; None: 1 throughout).
    pub gravity_ramp: Option<Path1<1>>,
    pub solver: SolverSpec,
    /// True (gravitational) lumped mass per node, kg.
    pub mass: Vec<f64>,
    /// Tools and contact pairs (None: the scene has no contact).
    pub contact: Option<crate::problem::contact::ContactSetup>,
    /// Mesh boundary faces (outward), the surface the graphics engine draws, and the cell
    /// each belongs to.
    pub surface_faces: Vec<[u32; 4]>,
    pub surface_face_cells: Vec<u32>,
    /// The time step every run and compilation of this problem uses, computed once when
    /// the problem is built.
    pub time_step: TimeStep,
    /// What the user should know about how the scene was read: the mesh's notes (prisms,
    /// boundary cells, unit conversion) and warnings of a scene that looks mis-scaled.
    /// The commands print them before they start ([`Problem::print_notes`]).
    pub notes: Vec<String>,
    /// How the host solver treats subnormal numbers: flushed as the boards do (the
    /// default), or kept (`pe solve --keep-subnormals`; [`crate::subnormals`]).
    pub subnormals: crate::subnormals::Subnormals,
}

/// A problem's time step and the stability limit it was chosen against.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct TimeStep {
    /// The step the scene asks for (`[solver] dt`, or `dt_safety ×` the critical step).
    pub dt_s: f64,
    pub critical: CriticalStep,
}

/// The stability limit of a problem's time step.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct CriticalStep {
    /// The step the solver treats as critical: min of the two below.
    pub dt_critical_s: f64,
    /// The seed's `min_e L_e / c_e`.
    pub dt_element_estimate_s: f64,
    /// `2 / ω_max` of the linearised mesh at rest.
    pub dt_power_iteration_s: f64,
    /// Cell with the smallest `L_e / c`.
    pub limiting_cell: usize,
}

fn law_from_spec(m: &MaterialSpec, what: &str) -> Result<MaterialLaw<f64>> {
    let need = |v: Option<f64>, key: &str| {
        v.ok_or_else(|| anyhow!("{what}: law \"{}\" needs `{key}`", m.law))
    };
    let positive = |v: f64, key: &str| {
        if v > 0.0 && v.is_finite() {
            Ok(v)
        } else {
            Err(anyhow!("{what}: `{key}` must be positive, got {v}"))
        }
    };
    if !(m.density > 0.0 && m.density.is_finite()) {
        bail!("{what}: `density` must be positive, got {}", m.density);
    }
    match m.law {
        Law::NeoHookean | Law::NeoHookeanDecoupled => {
            let e = positive(need(m.youngs_modulus, "youngs_modulus")?, "youngs_modulus")?;
            let nu = need(m.poisson_ratio, "poisson_ratio")?;
            if !(-1.0 < nu && nu < 0.5) {
                bail!("{what}: `poisson_ratio` must lie in (-1, 0.5), got {nu}");
            }
            let l = LameParameters::from_young_poisson(e, nu);
            Ok(if m.law == Law::NeoHookean {
                MaterialLaw::NeoHookean(l)
            } else {
                MaterialLaw::NeoHookeanDecoupled {
                    mu: l.mu,
                    kappa: l.bulk_modulus(),
                }
            })
        }
        Law::MooneyRivlin => {
            let c10 = need(m.c10, "c10")?;
            let c01 = need(m.c01, "c01")?;
            if !(c10 + c01 > 0.0) {
                bail!("{what}: c10 + c01 must be positive");
            }
            let kappa = positive(need(m.bulk_modulus, "bulk_modulus")?, "bulk_modulus")?;
            let volumetric = match m.volumetric.as_deref().unwrap_or("quadratic") {
                "quadratic" => Volumetric::Quadratic,
                "log" => Volumetric::Log,
                other => bail!("{what}: unknown volumetric \"{other}\" (quadratic | log)"),
            };
            Ok(MaterialLaw::MooneyRivlin {
                c10,
                c01,
                kappa,
                volumetric,
            })
        }
    }
}

fn region_tag(mesh: &Mesh, r: &RegionRef) -> Option<i32> {
    match r {
        RegionRef::Tag(t) => Some(*t),
        RegionRef::Name(n) => mesh
            .region_names
            .iter()
            .find(|(_, v)| *v == n)
            .map(|(k, _)| *k),
    }
}

/// The materials of a problem: the laws, their densities and each cell's material index.
struct Materials {
    laws: Vec<MaterialLaw<f64>>,
    densities: Vec<f64>,
    cell_material: Vec<u16>,
}

/// Resolves the scene's materials on the mesh: region-specific first, the default (no
/// region) for the rest.
fn assign_materials(scene: &Scene, mesh: &Mesh) -> Result<Materials> {
    if scene.materials.is_empty() {
        bail!("the scene has no [material]");
    }
    let mut laws = Vec::new();
    let mut densities = Vec::new();
    let mut cell_material = vec![u16::MAX; mesh.cells.len()];
    let mut default = None;
    for (k, m) in scene.materials.iter().enumerate() {
        let what = match &m.region {
            Some(r) => format!("material {k} (region {r})"),
            None => format!("material {k}"),
        };
        laws.push(law_from_spec(m, &what)?);
        densities.push(m.density);
        match &m.region {
            None => {
                if default.is_some() {
                    bail!("{what}: two materials without `region`");
                }
                default = Some(k as u16);
            }
            Some(r) => {
                let tag = region_tag(mesh, r).ok_or_else(|| {
                    anyhow!(
                        "{what}: mesh {} has no region {r} (regions: {:?})",
                        mesh.source,
                        mesh.region_names
                    )
                })?;
                let mut hit = 0;
                for (c, reg) in mesh.cell_regions.iter().enumerate() {
                    if *reg == tag {
                        cell_material[c] = k as u16;
                        hit += 1;
                    }
                }
                if hit == 0 {
                    bail!("{what}: region {r} has no cells in mesh {}", mesh.source);
                }
            }
        }
    }
    for (c, m) in cell_material.iter_mut().enumerate() {
        if *m == u16::MAX {
            *m = default.ok_or_else(|| {
                let reg = mesh.cell_regions.get(c).copied().unwrap_or(0);
                let name = mesh.region_names.get(&reg).cloned().unwrap_or_default();
                anyhow!(
                    "cell {c} of mesh {} is in region {reg} {name:?}, which has no material (add a [[material]] with region = {reg} or one without region)",
                    mesh.source
                )
            })?;
        }
    }
    Ok(Materials {
        laws,
        densities,
        cell_material,
    })
}

/// Reference geometry of every cell: refuses inverted/degenerate cells by name.
fn reference_geometry(mesh: &Mesh) -> Result<Vec<CellReference>> {
    let mut reference = Vec::with_capacity(mesh.cells.len());
    for c in 0..mesh.cells.len() {
        let r = match as_tetrahedron(&mesh.cells[c]) {
            Some(t) => {
                ReferenceTet::new(&t.map(|n| mesh.nodes[n as usize])).map(CellReference::Tet)
            }
            None => {
                ReferenceHex::new(&mesh.cell_coords(c)).map(|r| CellReference::Hex(Box::new(r)))
            }
        };
        let r = r.map_err(|e| {
            anyhow!(
                "mesh {}: cell {c} (nodes {:?}): {e}",
                mesh.source,
                mesh.cells[c].map(|n| mesh.node_tags.get(n as usize).copied().unwrap_or(n as u64))
            )
        })?;
        reference.push(r);
    }
    Ok(reference)
}

/// Lumped mass per node: an eighth of each hexahedron's mass on each of its corners, a
/// quarter of each tetrahedron's on each of its nodes ([`CellReference::mass_shares`]).
fn lumped_mass(mesh: &Mesh, reference: &[CellReference], m: &Materials) -> Vec<f64> {
    let mut mass = vec![0.0; mesh.nodes.len()];
    for (c, r) in reference.iter().enumerate() {
        let cm = m.densities[m.cell_material[c] as usize] * r.volume();
        for (&n, share) in mesh.cells[c].iter().zip(r.mass_shares()) {
            mass[n as usize] += cm * share;
        }
    }
    mass
}

/// The `[solver]` settings' ranges (and no `adapt_dt` with contact).
fn check_solver(s: &SolverSpec, has_contact: bool) -> Result<()> {
    if !(s.graphics_interval > 0.0) || s.graphics_spread_steps == 0 {
        bail!("[solver] graphics_interval must be positive and graphics_spread_steps at least 1");
    }
    if !(s.mass_scaling >= 1.0) {
        bail!("[solver] mass_scaling must be >= 1, got {}", s.mass_scaling);
    }
    for (key, value, least, strict) in [
        ("dt_safety", s.dt_safety, 0.0, true),
        ("damping", s.damping, 0.0, false),
        ("output_interval", s.output_interval, 0.0, true),
    ] {
        let ok = if strict {
            value > least
        } else {
            value >= least
        };
        if !ok {
            let bound = if strict { ">" } else { ">=" };
            bail!("[solver] {key} must be {bound} {least}, got {value}");
        }
    }
    if has_contact && s.adapt_dt == Some(true) {
        bail!("[solver] adapt_dt with contact is not supported: the contact penalty and search interval follow from the step (lower dt_safety instead)");
    }
    if s.dt_recheck_interval == Some(0) {
        bail!("[solver] dt_recheck_interval must be at least 1 (or left out)");
    }
    if s.dt_recheck_interval.is_some() && s.dt_recheck_iterations == 0 {
        bail!("[solver] dt_recheck_iterations must be at least 1");
    }
    if !(s.speed_limit > 0.0) {
        bail!(
            "[solver] speed_limit must be positive, got {}",
            s.speed_limit
        );
    }
    if let Some(d) = s.duration {
        if !(d > 0.0 && d.is_finite()) {
            bail!("[solver] duration must be a positive number of seconds, got {d}");
        }
    }
    if s.steps == Some(0) {
        bail!("[solver] steps (or --steps) must be at least 1, got 0");
    }
    Ok(())
}

impl Problem {
    /// Resolves `scene` on `mesh`. `node_sets` are the mesh's named node sets.
    pub fn new(
        scene: &Scene,
        mesh: Mesh,
        node_sets: BTreeMap<String, Vec<u32>>,
    ) -> Result<Problem> {
        if mesh.cells.is_empty() {
            bail!("mesh {} has no hexahedra", mesh.source);
        }
        crate::mesh::seams::check_nodes(&mesh)?;
        let materials = assign_materials(scene, &mesh)?;
        let reference = reference_geometry(&mesh)?;
        let mass = lumped_mass(&mesh, &reference, &materials);
        let sel = NodeSelector {
            mesh: &mesh,
            node_sets: &node_sets,
        };
        let (node_kind, mut paths) = constraints(scene, &sel)?;
        let loads = nodal_loads(scene, &sel)?;
        let mut add_path = |points: Vec<(f64, [f64; 3])>| {
            paths.push(Path1::linear(points));
            (paths.len() - 1) as u32
        };
        let (surface_faces, surface_face_cells): (Vec<[u32; 4]>, Vec<u32>) =
            crate::problem::contact::boundary_faces_with_cells(&mesh)
                .into_iter()
                .unzip();
        let contact = crate::problem::contact::resolve(
            scene,
            &mesh,
            &surface_faces,
            &surface_face_cells,
            &|sp| sel.surface(sp),
            &|r| region_tag(&mesh, r),
            &mut add_path,
            &|c| reference[c as usize].characteristic_length(),
        )?;
        check_solver(&scene.solver, contact.is_some())?;
        let Materials {
            laws,
            densities,
            cell_material,
        } = materials;
        let mut problem = Problem {
            mesh,
            node_sets,
            laws,
            densities,
            cell_material,
            reference,
            node_kind,
            paths,
            loads,
            gravity: gravity_of(scene)?,
            gravity_ramp: gravity_ramp_of(scene)?,
            solver: scene.solver.clone(),
            mass,
            contact,
            surface_faces,
            surface_face_cells,
            time_step: TimeStep::default(),
            notes: Vec::new(),
            subnormals: Default::default(),
        };
        problem.time_step = problem.choose_time_step()?;
        problem.notes = problem.mesh.notes.clone();
        problem.notes.extend(problem.scale_warnings());
        Ok(problem)
    }

    /// Fixes `scene`'s simulated time rather than its step count, for studies whose runs
    /// change `dt`: a scene given by `steps` gets the `duration` those steps cover, and
    /// `steps` is cleared.
    pub fn hold_duration(scene: &mut Scene, scene_dir: &Path) -> Result<()> {
        if scene.solver.duration.is_none() {
            let p = Problem::from_scene(scene, scene_dir)?;
            let dt = p.time_step.dt_s;
            scene.solver.duration = Some(p.steps(dt) as f64 * dt);
        }
        scene.solver.steps = None;
        Ok(())
    }

    /// The nodes the selector `s` picks on this problem's mesh, as `[[fixed]]`,
    /// `[[prescribed]]`, `[[load]]` and `[[surface]]` pick them (`what` names it in errors).
    pub fn select_nodes(&self, s: Selector<'_>, what: &str) -> Result<Vec<u32>> {
        NodeSelector {
            mesh: &self.mesh,
            node_sets: &self.node_sets,
        }
        .select(s, what)
    }

    /// True for the nodes on the mesh's boundary (the surface the graphics engine draws).
    pub fn surface_node_mask(&self) -> Vec<bool> {
        let mut m = vec![false; self.mesh.nodes.len()];
        for q in &self.surface_faces {
            for &n in q {
                m[n as usize] = true;
            }
        }
        m
    }

    /// Reads the scene's mesh (file, generated box or built-in anatomy) and resolves it.
    pub fn from_scene(scene: &Scene, scene_dir: &Path) -> Result<Problem> {
        let (mesh, sets) = crate::scene::mesh_source::load(&scene.mesh, scene_dir)
            .context("loading the scene's mesh")?;
        crate::scene::mesh_source::check_memory(
            &format!("mesh {}", mesh.source),
            mesh.cells.len() as f64,
        )?;
        Problem::new(scene, mesh, sets)
    }

    /// Wave speed `c = √(M / (ρ · mass_scaling))` of cell `c`'s material.
    pub fn wave_speed(&self, cell: usize) -> f64 {
        let m = self.cell_material[cell] as usize;
        (self.laws[m].dilatational_modulus() / (self.densities[m] * self.solver.mass_scaling))
            .sqrt()
    }

    /// The seed's estimate `min_e L_e / c_e` (`L_e = V/A_max`) and the cell that sets it.
    pub fn element_dt_estimate(&self) -> (f64, usize) {
        let mut best = (f64::INFINITY, 0);
        for (c, r) in self.reference.iter().enumerate() {
            let dt = r.characteristic_length() / self.wave_speed(c);
            if dt < best.0 {
                best = (dt, c);
            }
        }
        best
    }

    /// The critical step: the smaller of the seed's estimate `min_e L_e/c` and `2/ω_max`,
    /// the exact stability limit of the undamped central difference for the linearised
    /// mesh (power iteration on `M⁻¹K`, 200 iterations, at rest). On regular hexahedral
    /// meshes `2/ω_max` is 0.86–0.89 of `L_e/c` (measured; a 3D mesh has modes above the
    /// 1D bound `2c/h`), so the seed's formula alone would let a 0.9 safety factor blow up.
    /// Computed once, when the problem is built (see [`Problem::time_step`]).
    fn critical_step(&self) -> Result<CriticalStep> {
        let (estimate, cell) = self.element_dt_estimate();
        // At rest, in f64, from the deterministic start vector: the solver's
        // `Model::<f64>::max_frequency(200)` without building the model.
        let elements = elements::Elements::<f64>::build(self);
        let laws: Vec<MaterialLaw<f64>> = self.laws.iter().map(|l| l.cast::<f64>()).collect();
        let u = vec![[0.0; 3]; self.mesh.nodes.len()];
        let batched = Batched::build(&elements, &laws, Isa::detect()).ok();
        let state = frequency::Linearised {
            problem: self,
            elements: &elements,
            laws: &laws,
            u: &u,
            batched: batched.as_ref(),
        };
        let mut v = frequency::start_vector(self);
        let omega = frequency::max_frequency_from(&state, &mut v, 200)?;
        let power = if omega > 0.0 {
            2.0 / omega
        } else {
            f64::INFINITY
        };
        Ok(CriticalStep {
            dt_critical_s: estimate.min(power),
            dt_element_estimate_s: estimate,
            dt_power_iteration_s: power,
            limiting_cell: cell,
        })
    }

    /// Recomputes [`Problem::time_step`] after the problem was edited by hand (node kinds,
    /// materials, masses: what the critical step depends on). A problem built from a scene
    /// needs no call.
    pub fn update_time_step(&mut self) -> Result<()> {
        self.time_step = self.choose_time_step()?;
        Ok(())
    }

    /// The time step the scene asks for, refusing one above critical unless forced.
    fn choose_time_step(&self) -> Result<TimeStep> {
        let critical = self.critical_step()?;
        let (dt_crit, cell) = (critical.dt_critical_s, critical.limiting_cell);
        let dt = match self.solver.dt {
            Some(dt) => {
                if !(dt > 0.0) {
                    bail!("[solver] dt must be positive, got {dt}");
                }
                if dt > dt_crit && !self.solver.force_dt {
                    bail!(
                        "[solver] dt = {dt:.4e} s exceeds the critical step {dt_crit:.4e} s (set by cell {cell}, L_e = {:.3e} m): the explicit scheme would be unstable; lower dt or set force_dt = true",
                        self.reference[cell].characteristic_length()
                    );
                }
                dt
            }
            None => {
                if self.solver.dt_safety > 1.0 && !self.solver.force_dt {
                    bail!(
                        "[solver] dt_safety = {} > 1 gives a step above critical ({dt_crit:.4e} s); set force_dt = true to run it anyway",
                        self.solver.dt_safety
                    );
                }
                self.solver.dt_safety * dt_crit
            }
        };
        Ok(TimeStep { dt_s: dt, critical })
    }

    /// Warnings when the wave speed or the stable step is far outside what soft tissue in
    /// SI units gives (a mesh in millimetres read as metres makes the step 1000 times too
    /// long; a density in g/cm³ makes the waves 30 times too fast).
    fn scale_warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        let (lo, hi) = PLAUSIBLE_WAVE_SPEED_M_PER_S;
        for (m, (law, rho)) in self.laws.iter().zip(&self.densities).enumerate() {
            let c = (law.dilatational_modulus() / rho).sqrt();
            if !(lo..=hi).contains(&c) {
                out.push(format!(
                    "warning: material {m} has a wave speed of {c:.3e} m/s (soft tissue: {lo}-{hi}): check that its moduli are in Pa and its density in kg/m³"
                ));
            }
        }
        let dt = self.time_step.critical.dt_critical_s;
        if dt > PLAUSIBLE_DT_MAX_S {
            out.push(format!(
                "warning: the critical step is {dt:.3e} s, far above a soft-tissue mesh's (about 1e-4 s): is the mesh in metres? (see [mesh] unit)"
            ));
        }
        out
    }

    /// Prints [`Problem::notes`] on standard error, one per line, prefixed "note: " unless
    /// they are warnings.
    pub fn print_notes(&self) {
        for n in &self.notes {
            if n.starts_with("warning:") {
                eprintln!("{n}");
            } else {
                eprintln!("note: {n}");
            }
        }
    }

    /// Number of steps the scene runs.
    pub fn steps(&self, dt: f64) -> u64 {
        match (self.solver.steps, self.solver.duration) {
            (Some(n), _) => n,
            (None, Some(d)) => (d / dt).ceil() as u64,
            (None, None) => (1.0 / dt).ceil() as u64,
        }
    }
}
