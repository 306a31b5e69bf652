//! What a live session drives: an [`Engine`] steps the tissue, takes tool poses and reports
//! tool forces and the surface. The host solver ([`super::solver_engine::SolverEngine`]) is
//! one; board-sim's emulated array is another. The session ([`super::session`]) paces it.

use anyhow::Result;
pub use pe_firmware::physics::Pose;

/// A tool as the scene places it.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ToolInfo {
    pub name: String,
    /// The capsule's axis ends and radius (m), at the identity pose.
    pub a_m: [f64; 3],
    pub b_m: [f64; 3],
    pub radius_m: f64,
    /// The point the instrument pivots about (its trocar), if the scene names one (m).
    pub trocar_m: Option<[f64; 3]>,
}

/// The surface the graphics engine draws: its nodes, triangles and body of each node.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceInfo {
    /// Reference positions of the surface nodes (m).
    pub reference_m: Vec<[f32; 3]>,
    /// Triangles, as surface-node indices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    /// Body (region) of each surface node, for colours.
    pub body: Vec<u16>,
    /// Body names, by body id.
    pub body_names: Vec<String>,
}

/// What an engine runs.
#[derive(Clone, Debug)]
pub struct EngineInfo {
    /// The scene's name (file or `builtin:medium`).
    pub scene: String,
    /// The model run, in words the page shows (e.g. "full model, 2192 elements, f64").
    pub model: String,
    pub tools: Vec<ToolInfo>,
    pub surface: SurfaceInfo,
    /// Steps between the step a pose is given for and the first step that can take it:
    /// 1 on the host (the next step), more on boards (the packet's travel).
    pub pose_delay_steps: u64,
    /// Farthest a tool's capsule end may move in one step (m): the contact search's speed
    /// bound. A session moves a tool that jumps farther at this bound over several steps.
    pub tool_travel_max_m: f64,
}

/// A simulation a live session can pace.
pub trait Engine {
    fn info(&self) -> &EngineInfo;
    /// Schedules `pose` for tool `tool` from step `step` on (`step ≥ step_index() +
    /// pose_delay_steps − 1`; earlier is an error).
    fn set_pose(&mut self, tool: usize, pose: Pose, step: u64) -> Result<()>;
    /// Advances one step. Err: the run cannot go on (the step, element or node named).
    fn step(&mut self) -> Result<()>;
    /// Steps taken.
    fn step_index(&self) -> u64;
    /// Simulated time of the state (s).
    fn time_s(&self) -> f64;
    /// The current step (s); it may fall as the tissue deforms.
    fn dt_s(&self) -> f64;
    /// Force of the tissue on each tool at the last step (N), one per tool.
    fn tool_forces(&self) -> &[[f64; 3]];
    /// The surface nodes' current positions (m), [`SurfaceInfo`] order, `3n` values.
    fn surface_positions(&mut self, out: &mut Vec<f32>);
}
