//! Physics shared by the board and the host: scalar type, 3-vectors and tensors, hyperelastic
//! laws, SIMD lanes, the finite elements (`element/`, one file per kind), contact
//! (`contact/`) and explicit time integration. Physics never touches links.
//!
//! Layers, lowest first: `real`, `vec3`, `tensor`, `material`, `lanes` (the lane
//! abstraction), `element` (each kind with its lane packing), `contact`, `explicit`.
pub mod contact;
pub mod element;
pub mod explicit;
pub mod lanes;
pub mod material;
pub mod pose;
pub mod real;
pub mod tensor;
pub mod vec3;

pub use element::{
    Connectivity, Element, ElementKind, GaussPoint, GeometryError, HexBox, HexCuboid, HexElement,
    HexFull, HexReduced, Hourglass, HourglassControl, Integration, LaneKernel, ReferenceHex,
    ReferenceTet, Tet4, TetLoop, TetPressure,
};
pub use explicit::{accumulate_internal_forces, CentralDifference, PhysicsError};
pub use lanes::{LaneReal, Lanes, Pack};
pub use material::{LameParameters, MaterialLaw, Volumetric};
pub use pose::Pose;
pub use real::Real;
