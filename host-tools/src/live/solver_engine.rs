//! The host solver as a live [`Engine`]: `pe solve`'s step sequence ([`Stepper`]) with the
//! poses a session gives, applied from the next step.

use anyhow::{anyhow, bail, Result};
use pe_firmware::image::Precision;
use pe_firmware::physics::Real;

use super::engine::{Engine, EngineInfo, Pose, SurfaceInfo, ToolInfo};
use crate::problem::Problem;
use crate::solver::Stepper;

/// `pe solve`'s model of a problem, stepped by a live session.
pub struct SolverEngine<'p, T: Real> {
    stepper: Stepper<'p, T>,
    info: EngineInfo,
    /// Mesh node of each surface node.
    surface_nodes: Vec<u32>,
    /// Poses given for later steps: `(step, tool, pose)` in the order given.
    pending: Vec<(u64, usize, Pose)>,
    no_forces: Vec<[f64; 3]>,
}

/// The engine for `problem` in its scene's precision, on `threads` threads, open-ended;
/// `note` (which model and why, [`super::model`]) heads its model line when not empty.
pub fn solver_engine<'p>(
    problem: &'p Problem,
    name: &str,
    threads: usize,
    note: &str,
) -> Result<Box<dyn Engine + Send + 'p>> {
    Ok(match problem.solver.precision {
        Precision::F32 => Box::new(SolverEngine::<f32>::new(problem, name, threads, note)?),
        Precision::F64 => Box::new(SolverEngine::<f64>::new(problem, name, threads, note)?),
    })
}

impl<'p, T: Real> SolverEngine<'p, T> {
    pub fn new(problem: &'p Problem, name: &str, threads: usize, note: &str) -> Result<Self> {
        let mut stepper = Stepper::<T>::new(problem, name, threads)?;
        stepper.steps = u64::MAX;
        let (surface, surface_nodes) = surface_of(problem);
        let tools = tools_of(problem);
        let dt = problem.time_step.dt_s;
        let speed = problem
            .contact
            .as_ref()
            .map_or(0.0, |c| c.settings.speed_bound);
        let info = EngineInfo {
            scene: name.to_string(),
            model: format!(
                "{note}{}host solver, {} elements, {} nodes, {} {}",
                if note.is_empty() { "" } else { ": " },
                problem.mesh.cells.len(),
                problem.mesh.nodes.len(),
                T::NAME,
                problem.solver.integration.name()
            ),
            tools,
            surface,
            pose_delay_steps: 1,
            tool_travel_max_m: speed * dt,
        };
        Ok(SolverEngine {
            stepper,
            info,
            surface_nodes,
            pending: Vec::new(),
            no_forces: Vec::new(),
        })
    }
}

impl<T: Real> SolverEngine<'_, T> {
    /// Every mesh node's displacement now (m): what a replay of the session must reproduce.
    pub fn displacements(&self) -> Vec<[f64; 3]> {
        self.stepper.model.displacements()
    }
}

impl<T: Real> Engine for SolverEngine<'_, T> {
    fn info(&self) -> &EngineInfo {
        &self.info
    }

    fn set_pose(&mut self, tool: usize, pose: Pose, step: u64) -> Result<()> {
        let now = self.stepper.model.step;
        if step < now {
            bail!("a pose for step {step} came at step {now}: too late");
        }
        if tool >= self.info.tools.len() {
            bail!("no tool {tool}: the scene has {}", self.info.tools.len());
        }
        self.pending.push((step, tool, pose));
        Ok(())
    }

    fn step(&mut self) -> Result<()> {
        let now = self.stepper.model.step;
        let mut k = 0;
        while k < self.pending.len() {
            if self.pending[k].0 <= now {
                let (_, tool, pose) = self.pending.remove(k);
                self.stepper.set_pose(tool, pose)?;
            } else {
                k += 1;
            }
        }
        self.stepper.step()
    }

    fn step_index(&self) -> u64 {
        self.stepper.model.step
    }

    fn time_s(&self) -> f64 {
        self.stepper.model.time_s()
    }

    fn dt_s(&self) -> f64 {
        self.stepper.model.dt_s
    }

    fn tool_forces(&self) -> &[[f64; 3]] {
        match &self.stepper.model.contact {
            Some(c) => &c.tool_force,
            None => &self.no_forces,
        }
    }

    fn surface_positions(&mut self, out: &mut Vec<f32>) {
        let m = &self.stepper.model;
        let x = &m.problem.mesh.nodes;
        out.clear();
        for &n in &self.surface_nodes {
            let (x, u) = (x[n as usize], m.u[n as usize]);
            out.extend((0..3).map(|i| (x[i] + u[i].to_f64()) as f32));
        }
    }
}

/// The scene's tools at their placement.
fn tools_of(problem: &Problem) -> Vec<ToolInfo> {
    let Some(c) = &problem.contact else {
        return Vec::new();
    };
    c.tool_names
        .iter()
        .zip(&c.tools)
        .zip(&c.trocars)
        .map(|((name, t), trocar)| ToolInfo {
            name: name.clone(),
            a_m: t.capsule.a,
            b_m: t.capsule.b,
            radius_m: t.capsule.radius_m,
            trocar_m: *trocar,
        })
        .collect()
}

/// The drawn surface (the mesh's boundary faces, two triangles each) and the mesh node of
/// each surface node.
pub fn surface_of(problem: &Problem) -> (SurfaceInfo, Vec<u32>) {
    surface_of_faces(
        &problem.mesh,
        &problem.surface_faces,
        &problem.surface_face_cells,
    )
}

/// The surface of boundary quads `faces` of `mesh` (`face_cells`: the cell each bounds):
/// surface nodes numbered in order of first appearance, two triangles a quad (0 1 2,
/// 0 2 3), a body per cell region; and the mesh node of each surface node. Every engine
/// draws its surface by this one numbering.
pub fn surface_of_faces(
    mesh: &crate::mesh::Mesh,
    faces: &[[u32; 4]],
    face_cells: &[u32],
) -> (SurfaceInfo, Vec<u32>) {
    let mut index = vec![u32::MAX; mesh.nodes.len()];
    let mut nodes = Vec::new();
    let mut body = Vec::new();
    let mut regions: Vec<i32> = Vec::new();
    let mut triangles = Vec::with_capacity(2 * faces.len());
    for (q, &cell) in faces.iter().zip(face_cells) {
        let region = mesh.cell_regions.get(cell as usize).copied().unwrap_or(0);
        let b = match regions.iter().position(|&r| r == region) {
            Some(b) => b,
            None => {
                regions.push(region);
                regions.len() - 1
            }
        };
        let s = q.map(|n| {
            let slot = &mut index[n as usize];
            if *slot == u32::MAX {
                *slot = nodes.len() as u32;
                nodes.push(n);
                body.push(b as u16);
            }
            *slot
        });
        triangles.push([s[0], s[1], s[2]]);
        triangles.push([s[0], s[2], s[3]]);
    }
    let reference_m = nodes
        .iter()
        .map(|&n| mesh.nodes[n as usize].map(|v| v as f32))
        .collect();
    let body_names = regions
        .iter()
        .map(|r| {
            mesh.region_names
                .get(r)
                .cloned()
                .unwrap_or_else(|| format!("region {r}"))
        })
        .collect();
    (
        SurfaceInfo {
            reference_m,
            triangles,
            body,
            body_names,
        },
        nodes,
    )
}

/// The tool index of a name, or an error listing the scene's tools.
pub fn tool_index(info: &EngineInfo, name: &str) -> Result<usize> {
    info.tools
        .iter()
        .position(|t| t.name == name)
        .ok_or_else(|| {
            let known: Vec<&str> = info.tools.iter().map(|t| t.name.as_str()).collect();
            anyhow!("unknown tool {name:?}: the scene's tools are {known:?}")
        })
}
