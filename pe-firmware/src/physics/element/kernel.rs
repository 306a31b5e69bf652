//! What every element kind implements: its record built from its cell ([`Element`], with
//! its [`Connectivity`] and its [`ElementKind`]), the scalar kernel ([`HexElement`]:
//! internal forces and energy of one element, fused into the element loop) and the lane
//! kernel ([`LaneKernel`]: `N` elements side by side on the host).

use serde::{Deserialize, Serialize};

use super::super::lanes::LaneReal;
use super::super::material::{MaterialLaw, NonPositiveJacobian};
use super::super::real::Real;
use super::hex::ReferenceHex;
use super::ElementKind;

/// What every element kind shares: its nodes (local indices, reference order) and its
/// material. (Serialised inline: an element record's bytes start with these fields.)
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Connectivity {
    pub nodes: [u32; 8],
    pub material: u16,
}

/// An element kind's record: the kind it is in the registry ([`ElementKind`]) and how its
/// cell's reference geometry becomes the record the kernels run on (in `f64`, rounded once
/// to `T`). The compiler and the serial solver build every record through it.
pub trait Element<T: Real>: HexElement<T> + Copy {
    const KIND: ElementKind;
    /// The record of the cell whose reference data is `r`, with its nodes and material.
    fn from_reference(r: &ReferenceHex, connectivity: Connectivity, hourglass: Hourglass) -> Self;
}

pub use super::hourglass::Hourglass;

/// An element that turns nodal displacements into internal nodal forces.
pub trait HexElement<T: Real> {
    fn connectivity(&self) -> &Connectivity;
    #[inline(always)]
    fn nodes(&self) -> &[u32; 8] {
        &self.connectivity().nodes
    }
    #[inline(always)]
    fn material(&self) -> usize {
        self.connectivity().material as usize
    }
    /// Internal nodal forces for the element's nodal displacements `u` (reference order).
    fn internal_forces(
        &self,
        law: &MaterialLaw<T>,
        u: &[[T; 3]; 8],
    ) -> Result<[[T; 3]; 8], NonPositiveJacobian>;
    /// Stored energy (J): strain energy plus hourglass energy.
    fn energy(&self, law: &MaterialLaw<T>, u: &[[T; 3]; 8]) -> Result<T, NonPositiveJacobian>;
    /// Gathers the element's displacements from `u`, computes its internal forces and adds
    /// them into `f` (the element loop's body; a kernel may fuse the three). The per-node
    /// values added are bit for bit those of [`Self::internal_forces`].
    #[inline(always)]
    fn accumulate(
        &self,
        law: &MaterialLaw<T>,
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), KernelFault> {
        let nodes = checked_nodes(self.nodes(), u.len().min(f.len()))?;
        let ue = nodes.map(|n| u[n]);
        let fe = self
            .internal_forces(law, &ue)
            .map_err(KernelFault::Inverted)?;
        for (a, &n) in nodes.iter().enumerate() {
            for i in 0..3 {
                f[n][i] += fe[a][i];
            }
        }
        Ok(())
    }
}

/// Why [`HexElement::accumulate`] failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum KernelFault {
    /// `J ≤ 0`.
    Inverted(NonPositiveJacobian),
    /// A node index outside the displacement or force array.
    BadIndex,
}

/// The element's node indices as `usize`, all checked against `len` (one comparison each,
/// before any access).
#[inline(always)]
pub(super) fn checked_nodes(nodes: &[u32; 8], len: usize) -> Result<[usize; 8], KernelFault> {
    let mut max = 0;
    for &n in nodes {
        max = max.max(n);
    }
    if (max as usize) < len {
        Ok(nodes.map(|n| n as usize))
    } else {
        Err(KernelFault::BadIndex)
    }
}

/// `N` elements of one kernel run side by side ([`LaneReal`]): the host's batched element
/// loop. Every lane performs exactly the operations of the scalar kernel on its element,
/// in the same order, and the forces are handed out in the order the scalar
/// [`HexElement::accumulate`] adds them, so a caller that adds them in that order gets the
/// scalar loop's bits.
pub trait LaneKernel<S: Real, L: LaneReal<S, N>, const N: usize> {
    /// The element's nodes (Gmsh positions) in the order `scatter` receives them.
    const SCATTER_ORDER: [usize; 8];
    /// Internal forces of the batch's elements, whose nodes (Gmsh order) are `nodes[l]`,
    /// at the displacements `u`: `scatter(l, node, force)` is called for the lanes
    /// `l < active`, lane by lane, each lane's nodes in the scalar kernel's order.
    /// [`KernelFault::BadIndex`] when a node of any lane is outside `u`, before any
    /// computation; [`KernelFault::Inverted`] when `J ≤ 0` in some lane (which one is not
    /// said: run the scalar kernel on the batch's elements to find it), before any call to
    /// `scatter`.
    fn lane_forces(
        &self,
        law: &MaterialLaw<L>,
        nodes: &[[u32; 8]; N],
        active: usize,
        u: &[[S; 3]],
        scatter: impl FnMut(usize, usize, [S; 3]),
    ) -> Result<(), KernelFault>;
}

/// The batch's displacements, gathered (Gmsh order) and every index checked.
#[inline(always)]
pub(super) fn gather_lanes<S: Real, L: LaneReal<S, N>, const N: usize>(
    nodes: &[[u32; 8]; N],
    u: &[[S; 3]],
) -> Result<[[L; 3]; 8], KernelFault> {
    L::gather_corners(u, nodes).ok_or(KernelFault::BadIndex)
}

/// Per corner and component, the lanes as an array.
#[inline(always)]
pub(super) fn lanes_out<S: Real, L: LaneReal<S, N>, const N: usize>(
    f: &[[L; 3]; 8],
) -> [[[S; N]; 3]; 8] {
    let mut out = [[[S::ZERO; N]; 3]; 8];
    for (o, v) in out.iter_mut().zip(f) {
        for (o, v) in o.iter_mut().zip(v) {
            *o = v.to_lanes();
        }
    }
    out
}
