//! The parallelepiped one-point hexahedron (an affine image of the cube).

use serde::{Deserialize, Serialize};

use super::super::lanes::{lanes, lanes_3, LaneReal, Pack};
use super::super::material::{MaterialLaw, NonPositiveJacobian};
use super::super::real::{array, Real};
use super::super::tensor::Mat3;
use super::corner::*;
use super::hex::{cast2, ReferenceHex};
use super::hourglass::{pack_framed, FramedStiffness};
use super::kernel::{Connectivity, Element, HexElement, Hourglass, KernelFault, LaneKernel};
use super::ElementKind;

/// One-point element on a parallelepiped (an affine image of the cube: the seed's
/// undistorted element), the cheap kernel: the general kernel ([`HexReduced`]) where the
/// hourglass geometry `γ` and the gradient moments off the linear masks vanish, so
/// `F = I + Σ_j c_j ⊗ b_j` (27 products instead of 63), `Γ = h` (`q_α = c_α`), and the
/// forces are the synthesis of `(P V₀ b_j)` on the linear masks and `k c_α` on the
/// hourglass ones. To round-off it gives the general kernel's forces on the same cell.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexBox<T> {
    pub connectivity: Connectivity,
    /// `b_j = β_LINEAR[j]` (1/m), see [`ReferenceHex::gradient_basis`].
    pub basis: [[T; 3]; 3],
    /// `V₀ b_j` (m²).
    pub basis_volume: [[T; 3]; 3],
    pub volume: T,
    /// The hourglass stiffness with the cell's frame ([`super::hourglass`]).
    pub hourglass: FramedStiffness<T>,
}

impl<T: Real> HexBox<T> {
    /// `F = I + Σ_j c_j ⊗ b_j` and the hourglass moments `q_α = c_α` (`q[α][i]`), one
    /// displacement component (row of `F`) at a time.
    #[inline(always)]
    fn deformation(&self, corners: &impl Corners<T>) -> (Mat3<T>, [[T; 3]; 4]) {
        let b = &self.basis;
        let mut h = [[T::ZERO; 3]; 3];
        let mut q = [[T::ZERO; 3]; 4];
        for i in 0..3 {
            let c = moments_of(corners, i);
            let (c0, c1, c2) = (c[LINEAR[0]], c[LINEAR[1]], c[LINEAR[2]]);
            h[i] = array(
                #[inline(always)]
                |j| c0 * b[0][j] + c1 * b[1][j] + c2 * b[2][j],
            );
            for alpha in 0..4 {
                q[alpha][i] = c[HOURGLASS[alpha]];
            }
        }
        (plus_identity(h), q)
    }

    /// The hourglass forces `Q_α = R K Rᵀ q_α`.
    #[inline(always)]
    fn hourglass_forces(&self, q: &[[T; 3]; 4]) -> [[T; 3]; 4] {
        self.hourglass.forces(q)
    }
}

impl<T: Real> CornerKernel<T> for HexBox<T> {
    #[inline(always)]
    fn kernel(
        &self,
        law: &MaterialLaw<T>,
        corners: &mut impl Corners<T>,
    ) -> Result<(), NonPositiveJacobian> {
        let (f, q) = self.deformation(corners);
        let khg = self.hourglass_forces(&q);
        let p = law.first_piola_kirchhoff(&f)?;
        // Each component's moments written out in the loop, not by a closure: a closure
        // cannot be marked `inline(always)` here, and one left out of line keeps the
        // host's SIMD lanes out of their registers (see `real::array`).
        for i in 0..3 {
            let row = &p[i];
            let mut m = [T::ZERO; 8];
            for (j, bv) in self.basis_volume.iter().enumerate() {
                m[LINEAR[j]] = row[0] * bv[0] + row[1] * bv[1] + row[2] * bv[2];
            }
            for alpha in 0..4 {
                m[HOURGLASS[alpha]] = khg[alpha][i];
            }
            add_synthesis_of_component(corners, i, m);
        }
        Ok(())
    }
}

corner_element!(HexBox);

corner_lane_kernel!(HexBox);

impl<S: Real, L: LaneReal<S, N>, const N: usize> Pack<S, L, N> for HexBox<S> {
    type Packed = HexBox<L>;
    fn pack(items: [&Self; N]) -> Option<Self::Packed> {
        let first = items.first()?;
        Some(HexBox {
            connectivity: first.connectivity,
            basis: lanes_3(&items, |e| &e.basis),
            basis_volume: lanes_3(&items, |e| &e.basis_volume),
            volume: lanes(&items, |e| e.volume),
            hourglass: pack_framed(&items.map(|e| &e.hourglass)),
        })
    }
}

impl<T: Real> Element<T> for HexBox<T> {
    const KIND: ElementKind = ElementKind::HexBox;
    /// The parallelepiped kernel's record (meaningful when [`Self::is_parallelepiped`]):
    /// the gradient basis `b_j`, the same scaled by `V₀`, and the hourglass stiffness with
    /// the cell's frame.
    fn from_reference(r: &ReferenceHex, connectivity: Connectivity, hourglass: Hourglass) -> Self {
        let b = r.gradient_basis();
        HexBox {
            connectivity,
            basis: cast2(&b),
            basis_volume: core::array::from_fn(|j| {
                core::array::from_fn(|i| T::from_f64(b[j][i] * r.volume))
            }),
            volume: T::from_f64(r.volume),
            hourglass: FramedStiffness::cast(&hourglass.of_cell(r)),
        }
    }
}

impl ReferenceHex {
    /// [`HexBox`]'s record of this cell ([`Element::from_reference`]) with the scalar hourglass
    /// form (`K = k I`: modulus `2μ`, coefficient `κ_hg`).
    pub fn parallelepiped<T: Real>(
        &self,
        nodes: [u32; 8],
        material: u16,
        hourglass_modulus: f64,
        hourglass_coefficient: f64,
    ) -> HexBox<T> {
        let hourglass = Hourglass::scalar(hourglass_modulus, hourglass_coefficient);
        HexBox::from_reference(self, Connectivity { nodes, material }, hourglass)
    }
}
