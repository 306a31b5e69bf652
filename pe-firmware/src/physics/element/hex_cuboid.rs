//! The axis-aligned cuboid one-point hexahedron, the cheapest kernel.

use serde::{Deserialize, Serialize};

use super::super::lanes::{lanes, lanes_1, LaneReal, Pack};
use super::super::material::{MaterialLaw, NonPositiveJacobian};
use super::super::real::{array, Real};
use super::super::tensor::Mat3;
use super::corner::*;
use super::hex::ReferenceHex;
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
    pub hourglass_stiffness: T,
}

impl<T: Real> HexCuboid<T> {
    /// `F = I + [d_j c_j[i]]` and the hourglass moments `c_α` (`hg[i][α]`), one
    /// displacement component (row of `F`) at a time.
    #[inline(always)]
    fn deformation(&self, corners: &impl Corners<T>) -> (Mat3<T>, [[T; 4]; 3]) {
        let d = &self.scale;
        let mut h = [[T::ZERO; 3]; 3];
        let mut hg = [[T::ZERO; 4]; 3];
        for i in 0..3 {
            let c = moments_of(corners, i);
            h[i] = array(
                #[inline(always)]
                |j| c[LINEAR[j]] * d[j],
            );
            hg[i] = array(
                #[inline(always)]
                |a| c[HOURGLASS[a]],
            );
        }
        (plus_identity(h), hg)
    }
}

impl<T: Real> CornerKernel<T> for HexCuboid<T> {
    #[inline(always)]
    fn kernel(
        &self,
        law: &MaterialLaw<T>,
        corners: &mut impl Corners<T>,
    ) -> Result<(), NonPositiveJacobian> {
        let (f, hg) = self.deformation(corners);
        let k = self.hourglass_stiffness;
        // The hourglass moments' forces `k c_α` before the law, kept (see `kept_in_memory`).
        let khg: [[T; 4]; 3] = kept_in_memory(array(
            #[inline(always)]
            |i| {
                array(
                    #[inline(always)]
                    |alpha| k * hg[i][alpha],
                )
            },
        ));
        let p = law.first_piola_kirchhoff(&f)?;
        // Each component's moments written out in the loop (see `HexBox`'s kernel).
        for i in 0..3 {
            let row = &p[i];
            let mut m = [T::ZERO; 8];
            for j in 0..3 {
                m[LINEAR[j]] = row[j] * self.scale_volume[j];
            }
            for alpha in 0..4 {
                m[HOURGLASS[alpha]] = khg[i][alpha];
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
            hourglass_stiffness: lanes(&items, |e| e.hourglass_stiffness),
        })
    }
}

impl<T: Real> Element<T> for HexCuboid<T> {
    const KIND: ElementKind = ElementKind::HexCuboid;
    /// The cuboid kernel's record (meaningful when [`Self::is_cuboid`]): the diagonal of
    /// the gradient basis `d_j = b_jj`, the same scaled by `V₀`, and `k`.
    fn from_reference(r: &ReferenceHex, connectivity: Connectivity, hourglass: Hourglass) -> Self {
        let k = r.hourglass_stiffness(hourglass.modulus_pa, hourglass.coefficient);
        let b = r.gradient_basis();
        HexCuboid {
            connectivity,
            scale: core::array::from_fn(|j| T::from_f64(b[j][j])),
            scale_volume: core::array::from_fn(|j| T::from_f64(b[j][j] * r.volume)),
            volume: T::from_f64(r.volume),
            hourglass_stiffness: T::from_f64(k),
        }
    }
}

impl ReferenceHex {
    /// [`HexCuboid`]'s record of this cell ([`Element::from_reference`]).
    pub fn cuboid<T: Real>(
        &self,
        nodes: [u32; 8],
        material: u16,
        hourglass_modulus: f64,
        hourglass_coefficient: f64,
    ) -> HexCuboid<T> {
        let hourglass = Hourglass {
            modulus_pa: hourglass_modulus,
            coefficient: hourglass_coefficient,
        };
        HexCuboid::from_reference(self, Connectivity { nodes, material }, hourglass)
    }
}
