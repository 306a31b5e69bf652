//! board-sim's emulated array as a live [`Engine`] (`board-sim live DIR`): the compiled
//! machine's boards run open-ended ([`OpenArray`]) and the host steps them, as a real
//! array's host does, through the same session code as `pe live`
//! (`host_tools::live::session`).
//!
//! - [`Engine::step`] opens the pose gate one step further and waits until every board has
//!   finished that step; the host sink then holds every board's share of that step's tool
//!   forces (a board sends its share before its step ends; a zero share is not sent), which
//!   are summed per tool in board-address order, as `board-sim run` sums them: a session
//!   recorded here and replayed by `board-sim run DIR --replay FILE` gives the same tool
//!   forces bit for bit.
//! - [`Engine::set_pose`] schedules a ToolPose packet to the boards holding the tool; it goes
//!   out [`POSE_DELAY_STEPS`] steps ahead of its step at most (the boards' queue), never
//!   after any board may have started that step. [`EngineInfo::pose_delay_steps`] is
//!   [`POSE_DELAY_STEPS`], so the session gives poses that far ahead.
//! - [`Engine::surface_positions`] is the latest surface frame the graphics sink completed:
//!   the images' graphics stream, one frame every graphics interval of simulated time (the
//!   scene's `graphics_interval`, 40 ms in the built-in scene: 25 frames per simulated
//!   second, so fewer per wall second when the array runs slower than real time), surface
//!   nodes in the order of `mesh.json`'s surface faces (first appearance; two triangles a
//!   quad, `host_tools::live::solver_engine::surface_of_faces`).
//! - The time step is the compiled one (boards do not track dt); tools have no trocar
//!   (`mesh.json` names none).

mod surface;

use std::path::Path;

use anyhow::{anyhow, bail, Result};
use host_tools::compile::{read_manifest, OutputMesh};
use host_tools::live::engine::{Engine, EngineInfo, Pose, ToolInfo};
use host_tools::live::solver_engine::surface_of_faces;
use link_proto::payload::ToolForcePayload;
use link_proto::tool_pose::POSE_DELAY_STEPS;
use link_proto::{PacketKind, PacketRepr};

use crate::runner::{start_open, OpenArray, SimOptions};
pub use surface::SurfaceStream;

/// A compiled array on emulated boards, stepped by a live session.
pub struct BoardSimEngine {
    array: OpenArray,
    info: EngineInfo,
    dt_s: f64,
    step: u64,
    /// Poses given and not yet sent: `(step, tool, pose)`, one per step and tool (the last
    /// given), as `board-sim run --replay` sends a record's.
    pending: Vec<(u64, usize, Pose)>,
    forces: Vec<[f64; 3]>,
    surface: SurfaceStream,
}

impl BoardSimEngine {
    /// Starts the boards of the compiled directory `dir` (its manifest, images and
    /// `mesh.json`), run as `opts` says (recovery, workers, kernels, storage).
    pub fn start(dir: &Path, opts: &SimOptions) -> Result<BoardSimEngine> {
        let manifest = read_manifest(dir)?;
        let mesh = OutputMesh::read(dir)?;
        let array = start_open(dir, opts)?;
        let header = *array.header();
        if mesh.tools.len() != array.tools() {
            bail!(
                "{}: mesh.json names {} tools, the images hold {}",
                dir.display(),
                mesh.tools.len(),
                array.tools()
            );
        }
        let (surface, mesh_nodes) = surface_of_faces(
            &mesh.mesh(&dir.display().to_string()),
            &mesh.surface_faces,
            &mesh.surface_face_cells,
        );
        let tools = mesh
            .tools
            .iter()
            .map(|t| ToolInfo {
                name: t.name.clone(),
                a_m: t.capsule.a,
                b_m: t.capsule.b,
                radius_m: t.capsule.radius_m,
                trocar_m: t.trocar_m,
            })
            .collect();
        let c = header.contact;
        let m = array.machine();
        let info = EngineInfo {
            scene: manifest.scene.clone(),
            model: format!(
                "{} boards ({m}) emulated by board-sim, {} elements, {} nodes, {:?}",
                m.count(),
                header.scene_elements,
                header.scene_nodes,
                header.precision
            ),
            tools,
            surface: surface.clone(),
            pose_delay_steps: POSE_DELAY_STEPS,
            tool_travel_max_m: c.travel_max_m / f64::from(c.check_interval_steps.max(1)),
        };
        Ok(BoardSimEngine {
            surface: SurfaceStream::new(&surface, &mesh_nodes, mesh.nodes.len()),
            forces: vec![[0.0; 3]; array.tools()],
            array,
            info,
            dt_s: manifest.dt_s,
            step: 0,
            pending: Vec::new(),
        })
    }

    /// Steps between the boards' surface frames (the images' graphics interval).
    pub fn graphics_interval_steps(&self) -> u32 {
        self.array.header().graphics.interval_steps
    }

    /// The compiled time step (s).
    pub fn dt(&self) -> f64 {
        self.dt_s
    }

    /// Sends the poses due: those for steps before `steps_done + POSE_DELAY_STEPS`, in
    /// step order.
    fn send_due(&mut self) -> Result<()> {
        let limit = self.step + POSE_DELAY_STEPS;
        self.pending.sort_by_key(|p| p.0);
        let due = self.pending.partition_point(|p| p.0 < limit);
        for (step, tool, pose) in self.pending.drain(..due) {
            self.array.send_pose(step, tool, &pose)?;
        }
        Ok(())
    }

    /// Step `step`'s tool forces from the host sink's packets: each board's share, summed
    /// per tool in board-address order (`board-sim run`'s order).
    fn file_forces(&mut self, step: u64) -> Result<()> {
        let mut shares: Vec<(u8, u8, [f64; 3])> = Vec::new();
        for p in self.array.take_host_packets() {
            let r = PacketRepr::parse_bytes(&p).map_err(|e| anyhow!("host: bad packet: {e}"))?;
            match r.kind {
                PacketKind::ToolForce => {}
                PacketKind::Hello => continue,
                k => bail!("host: unexpected packet {k:?} from address {}", r.src),
            }
            let t = ToolForcePayload::parse(r.payload)
                .map_err(|e| anyhow!("host: bad tool-force payload from {}: {e}", r.src))?;
            if u64::from(t.step) != step {
                bail!(
                    "host: address {} sent a tool force of step {} after step {step}",
                    r.src,
                    t.step
                );
            }
            shares.push((t.tool, r.src, t.force));
        }
        shares.sort_by_key(|a| (a.0, a.1));
        self.forces.iter_mut().for_each(|f| *f = [0.0; 3]);
        for (tool, src, f) in shares {
            let d = self
                .forces
                .get_mut(tool as usize)
                .ok_or_else(|| anyhow!("host: address {src} sent a force for tool {tool}"))?;
            for i in 0..3 {
                d[i] += f[i];
            }
        }
        Ok(())
    }
}

impl Engine for BoardSimEngine {
    fn info(&self) -> &EngineInfo {
        &self.info
    }

    fn set_pose(&mut self, tool: usize, pose: Pose, step: u64) -> Result<()> {
        let earliest = self.step + POSE_DELAY_STEPS - 1;
        if step < earliest {
            bail!("a pose for step {step} came at step {}: the boards take it from step {earliest} on", self.step);
        }
        if tool >= self.info.tools.len() {
            bail!("no tool {tool}: the scene has {}", self.info.tools.len());
        }
        match (self.pending.iter_mut()).find(|p| p.0 == step && p.1 == tool) {
            Some(p) => p.2 = pose,
            None => self.pending.push((step, tool, pose)),
        }
        Ok(())
    }

    fn step(&mut self) -> Result<()> {
        let k = self.step;
        self.send_due()?;
        self.array.run_to(k + 1)?;
        self.file_forces(k)?;
        self.surface.file(&self.array.take_graphics_packets())?;
        self.step = k + 1;
        Ok(())
    }

    fn step_index(&self) -> u64 {
        self.step
    }

    fn time_s(&self) -> f64 {
        self.step as f64 * self.dt_s
    }

    fn dt_s(&self) -> f64 {
        self.dt_s
    }

    fn tool_forces(&self) -> &[[f64; 3]] {
        &self.forces
    }

    fn surface_positions(&mut self, out: &mut Vec<f32>) {
        out.clear();
        out.extend_from_slice(self.surface.latest());
    }
}
