//! Physics shared by the board and the host: scalar type, tensors, hyperelastic laws, the
//! Total Lagrangian hexahedron and explicit time integration. Physics never touches links.
pub mod contact;
pub mod explicit;
pub mod hex;
pub mod lanes;
pub mod material;
pub mod real;
pub mod tensor;

pub use explicit::{accumulate_internal_forces, CentralDifference, PhysicsError};
pub use hex::{
    Connectivity, GaussPoint, GeometryError, HexBox, HexCuboid, HexElement, HexFull, HexReduced,
    Kernel, LaneKernel, ReferenceHex,
};
pub use lanes::{LaneReal, Lanes, Pack};
pub use material::{LameParameters, MaterialLaw, Volumetric};
pub use real::Real;
