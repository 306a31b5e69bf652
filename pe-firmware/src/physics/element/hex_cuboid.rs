//! The axis-aligned cuboid one-point hexahedron, the cheapest kernel.

use serde::{Deserialize, Serialize};

use super::super::lanes::{lanes, lanes_1, LaneReal, Pack};
use super::super::material::{MaterialLaw, NonPositiveJacobian};
use super::super::real::{array, Real};
use super::super::tensor::Mat3;
use super::corner::*;
use super::hex::ReferenceHex;
use super::hourglass::{pack_modes, ModeStiffness};
use super::kernel::{Connectivity, Element, HexElement, Hourglass, KernelFault, LaneKernel};
use super::ElementKind;

/// One-point element with hourglass control on a rectangular cuboid aligned with the axes
/// (the seed's undistorted element), in the corner basis: the [`HexBox`] kernel with a
/// diagonal gradient basis `b_j = d_j e_j`, so `F_ij = δ_ij + d_j c_j[i]` (9 products
/// instead of 27 and no sums) and the linear force moments are `m_j[i] = V₀ d_j P_ij`
/// (9 products instead of 27). The hourglass moments are [`HexBox`]'s (`q_α = c_α`). It
/// gives [`HexBox`]'s forces on the same cell to round-off (the terms it drops are the
/// basis's off-diagonal round-off, within 1e-13 of its diagonal; where they are exact zeros
/// it gives [`HexBox`]'s bits), and so the general kernel's.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexCuboid<T> {
    pub connectivity: Connectivity,
    /// `d_j = b_jj` (1/m), see [`ReferenceHex::gradient_basis`].
    pub scale: [T; 3],
    /// `V₀ d_j` (m²).
    pub scale_volume: [T; 3],
    pub volume: T,
    /// The hourglass stiffness in the axes ([`super::hourglass`]).
    pub hourglass: ModeStiffness<T>,
}

impl<T: Real> HexCuboid<T> {
    /// `F = I + [d_j c_j[i]]` and the hourglass moments `q_α = c_α` (`q[α][i]`), one
    /// displacement component (row of `F`) at a time.
    #[inline(always)]
    fn deformation(&self, corners: &impl Corners<T>) -> (Mat3<T>, [[T; 3]; 4]) {
        let d = &self.scale;
        let mut h = [[T::ZERO; 3]; 3];
        let mut q = [[T::ZERO; 3]; 4];
        for i in 0..3 {
            let c = moments_of(corners, i);
            h[i] = array(
                #[inline(always)]
                |j| c[LINEAR[j]] * d[j],
            );
            for alpha in 0..4 {
                q[alpha][i] = c[HOURGLASS[alpha]];
            }
        }
        (plus_identity(h), q)
    }

    /// The hourglass forces `Q_α = K q_α`.
    #[inline(always)]
    fn hourglass_forces(&self, q: &[[T; 3]; 4]) -> [[T; 3]; 4] {
        self.hourglass.forces(q)
    }
}

impl<T: Real> CornerKernel<T> for HexCuboid<T> {
    #[inline(always)]
    fn kernel(
        &self,
        law: &MaterialLaw<T>,
        corners: &mut impl Corners<T>,
    ) -> Result<(), NonPositiveJacobian> {
        let (f, q) = self.deformation(corners);
        // The hourglass moments' forces `K c_α` before the law, kept (see `kept_in_memory`).
        let khg: [[T; 3]; 4] = kept_in_memory(self.hourglass_forces(&q));
        let p = law.first_piola_kirchhoff(&f)?;
        // Each component's moments written out in the loop (see `HexBox`'s kernel).
        for i in 0..3 {
            let row = &p[i];
            let mut m = [T::ZERO; 8];
            for j in 0..3 {
                m[LINEAR[j]] = row[j] * self.scale_volume[j];
            }
            for alpha in 0..4 {
                m[HOURGLASS[alpha]] = khg[alpha][i];
            }
            add_synthesis_of_component(corners, i, m);
        }
        Ok(())
    }
}

corner_element!(HexCuboid);

corner_lane_kernel!(HexCuboid);

impl<S: Real, L: LaneReal<S, N>, const N: usize> Pack<S, L, N> for HexCuboid<S> {
    type Packed = HexCuboid<L>;
    fn pack(items: [&Self; N]) -> Option<Self::Packed> {
        let first = items.first()?;
        Some(HexCuboid {
            connectivity: first.connectivity,
            scale: lanes_1(&items, |e| &e.scale),
            scale_volume: lanes_1(&items, |e| &e.scale_volume),
            volume: lanes(&items, |e| e.volume),
            hourglass: pack_modes(&items.map(|e| &e.hourglass)),
        })
    }
}

impl<T: Real> Element<T> for HexCuboid<T> {
    const KIND: ElementKind = ElementKind::HexCuboid;
    /// The cuboid kernel's record (meaningful when [`Self::is_cuboid`]): the diagonal of
    /// the gradient basis `d_j = b_jj`, the same scaled by `V₀`, and the hourglass
    /// stiffness in the axes.
    fn from_reference(r: &ReferenceHex, connectivity: Connectivity, hourglass: Hourglass) -> Self {
        let b = r.gradient_basis();
        HexCuboid {
            connectivity,
            scale: core::array::from_fn(|j| T::from_f64(b[j][j])),
            scale_volume: core::array::from_fn(|j| T::from_f64(b[j][j] * r.volume)),
            volume: T::from_f64(r.volume),
            hourglass: ModeStiffness::cast(&hourglass.of_cuboid(r)),
        }
    }
}

impl ReferenceHex {
    /// [`HexCuboid`]'s record of this cell ([`Element::from_reference`]) with the scalar hourglass
    /// form (`K = k I`: modulus `2μ`, coefficient `κ_hg`).
    pub fn cuboid<T: Real>(
        &self,
        nodes: [u32; 8],
        material: u16,
        hourglass_modulus: f64,
        hourglass_coefficient: f64,
    ) -> HexCuboid<T> {
        let hourglass = Hourglass::scalar(hourglass_modulus, hourglass_coefficient);
        HexCuboid::from_reference(self, Connectivity { nodes, material }, hourglass)
    }
}
