//! The schedule compiler (`pe compile`): partitions a scene onto the board mesh and emits one
//! static schedule image per board (the seed's section 4).
//!
//! Per board: its elements in four batches (x border, y border, z border, inner), the nodes
//! it holds (own nodes and replicas), and exchange lists per face and round. A node is held
//! by every board in the bounding box of the boards whose elements touch it (see
//! [`partition`]); across a face both boards list the shared nodes in ascending global
//! order, so frames carry no addresses. The step (both ends know it,
//! [`pe_firmware::runtime::Program`]):
//!
//! recover batch x; send ±x; recover batch y; send ±y round 0; add from ±x; send ±y round
//! 1; recover batch z; send ±z round 0; add from ±y; send ±z round 1; recover inner; add
//! from ±z; the broadcasts along y, then x; update positions.
//!
//! A node's partial sums are reduced along x, then y, exchanged along z, and the total is
//! broadcast back along y, then x (`trees`; the root of each line chosen to spread
//! the links' loads), so every holder of a node has
//! the same total force and all replicas compute identical positions (two-term sums
//! `a + b = b + a` are exact in IEEE).
//! Gravity and loads are applied once, by the node's owner (the lowest-numbered board whose
//! elements touch it), into its partial sum just before the node is first sent (or before
//! the update, if it is never sent).
//!
//! Rooms: [`partition`] (elements onto boards), `trees` (the exchange's summation trees,
//! which the partition's objective and the plan share), `plan` (batches, replicas, exchange
//! rounds), `image` (one image per board, through
//! [`pe_firmware::image::write_image`]), `fit` (the images against the board profile's
//! capacity table), `parts` (the firmware parts the images need), `report` (figures, the
//! verdict and the console summary: `report/`), [`timing`] (the step model), `decode` (an
//! image read back through the firmware's own codec, for `pe inspect`, board-sim's timing
//! model and tests), `manifest` (`DIR/manifest.json`, the whole `pe compile`, and reading a
//! compiled directory back as the types that wrote it), `output_mesh` (`DIR/mesh.json`: what
//! a run's outputs write and draw), `inspect`.

mod decode;
mod fit;
mod image;
mod inspect;
mod manifest;
mod output_mesh;
pub mod partition;
mod parts;
mod plan;
mod report;
mod tables;
pub mod timing;
mod trees;

pub use decode::{decode_image, DecodedImage, DecodedRound};
pub use fit::{check_fit, fit_problems};
pub use image::{
    compilation_id, compile_images, contact_tables, graphics_params, image_file_name, write_images,
    BoardImage,
};
pub use inspect::inspect;
pub use manifest::{
    check_image_set, compile_to_dir, read_manifest, ImageFile, Manifest, ManifestBoard,
};
pub use output_mesh::{OutputMesh, ToolTrack, OUTPUT_MESH_FILE};
pub use parts::{feature_names, parts_needed, parts_of};
pub use plan::refuse_tetrahedra;
pub use plan::{plan, plan_balanced, Balance, BoardPlan, Plan, RoundPlan, FACE_NAMES};
pub use report::{
    plan_for_real_time, real_time_of, report, summary, verdict, BalanceTried, BoardSummary,
    Capacity, CompileReport, ContactCompileReport, GraphicsReport, LinkLoad, RealTimeVerdict,
    COMPUTE_MARGIN,
};
pub use tables::ImageTables;
pub use trees::line_rounds;
