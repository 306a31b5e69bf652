//! The general one-point hexahedron: any cell, reduced integration with hourglass control.

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

/// The corner masks 1..=7 (`c_0` of a gradient is zero: gradients sum to zero).
const MASKS: [usize; 7] = [1, 2, 3, 4, 5, 6, 7];

/// One-point (reduced) element with hourglass control, any hexahedron (the general kernel),
/// in the corner basis.
///
/// The gradients are kept as their corner moments `β_k = (1/8) Σ_a (Π_{j∈k} ξ_aj) B_a`, so
/// `B_a = Σ_k (Π ξ_a) β_k` and, with the displacement moments `c_k` ([`transform8`]),
/// `H = Σ_a u_a ⊗ B_a = Σ_k c_k ⊗ β_k` (`F = I + H`). The hourglass displacements are
/// `q_α = Σ_a Γ_aα u_a = c_α − H γ_α` (`c_α` the hourglass moments, `γ_α = Σ_b h_bα X_b`),
/// and the forces `f_a = Σ_k (Π ξ_a) m_k`: the synthesis of the moments
/// `m_k = (V₀ P − M) β_k (+ Q_α on the hourglass masks)`, with `Q_α = K q_α` and
/// `M = Σ_α Q_α ⊗ γ_α`. Gathering, the transforms and scattering are fused
/// ([`HexElement::accumulate`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexReduced<T> {
    pub connectivity: Connectivity,
    pub volume: T,
    /// `β_k` for the masks 1..=7 (1/m).
    pub gradient_moments: [[T; 3]; 7],
    /// `γ_α = Σ_b h_bα X_b` (m), see [`ReferenceHex::hourglass_geometry`].
    pub hourglass_geometry: [[T; 3]; 4],
    /// The hourglass stiffness with the cell's frame ([`super::hourglass`]).
    pub hourglass: FramedStiffness<T>,
}

impl<T: Real> HexReduced<T> {
    /// `F = I + H` and the hourglass displacements `q_α`, one displacement component (row
    /// of `H`) at a time: with [`Real::FORCES_BY_COMPONENT`], each component's `q_α` with
    /// its row, otherwise all `q_α` after `H` (the same values; the shape the board's
    /// compiler serves best).
    #[inline(always)]
    fn deformation(&self, corners: &impl Corners<T>) -> (Mat3<T>, [[T; 3]; 4]) {
        let mut h = [[T::ZERO; 3]; 3];
        let mut q = [[T::ZERO; 3]; 4];
        if T::FORCES_BY_COMPONENT {
            for i in 0..3 {
                let c = moments_of(corners, i);
                h[i] = self.gradient_row(&c);
                for alpha in 0..4 {
                    q[alpha][i] = self.hourglass_displacement(c[HOURGLASS[alpha]], &h[i], alpha);
                }
            }
        } else {
            let mut hg = [[T::ZERO; 4]; 3];
            for i in 0..3 {
                let c = moments_of(corners, i);
                h[i] = self.gradient_row(&c);
                hg[i] = array(
                    #[inline(always)]
                    |a| c[HOURGLASS[a]],
                );
            }
            q = array(
                #[inline(always)]
                |alpha| {
                    array(
                        #[inline(always)]
                        |i| self.hourglass_displacement(hg[i][alpha], &h[i], alpha),
                    )
                },
            );
        }
        (plus_identity(h), q)
    }

    /// The hourglass forces `Q_α = R K Rᵀ q_α`.
    #[inline(always)]
    fn hourglass_forces(&self, q: &[[T; 3]; 4]) -> [[T; 3]; 4] {
        self.hourglass.forces(q)
    }

    /// A row of `H`: `Σ_k c_k β_k` over the displacement moments `c` of one component.
    #[inline(always)]
    fn gradient_row(&self, c: &[T; 8]) -> [T; 3] {
        let beta = &self.gradient_moments;
        array(
            #[inline(always)]
            |j| {
                let mut s = c[MASKS[0]] * beta[0][j];
                for k in 1..7 {
                    s += c[MASKS[k]] * beta[k][j];
                }
                s
            },
        )
    }

    /// One component of `q_α = c_α − H γ_α`, from that component's `c_α` and row of `H`.
    #[inline(always)]
    fn hourglass_displacement(&self, c_alpha: T, h_row: &[T; 3], alpha: usize) -> T {
        let g = &self.hourglass_geometry[alpha];
        c_alpha - (h_row[0] * g[0] + h_row[1] * g[1] + h_row[2] * g[2])
    }

    /// Row `i` of `V₀ P − Σ_α Q_α ⊗ γ_α`.
    #[inline(always)]
    fn stress_row(&self, p: &Mat3<T>, big_q: &[[T; 3]; 4], i: usize) -> [T; 3] {
        array(
            #[inline(always)]
            |j| {
                let mut m = self.volume * p[i][j];
                for alpha in 0..4 {
                    m -= big_q[alpha][i] * self.hourglass_geometry[alpha][j];
                }
                m
            },
        )
    }

    /// The force moments of component `i` from its stress row: `row · β_k`, plus `Q_α` on
    /// the hourglass masks.
    #[inline(always)]
    fn force_moments(&self, row: &[T; 3], big_q: &[[T; 3]; 4], i: usize) -> [T; 8] {
        let mut m = [T::ZERO; 8];
        for (k, b) in self.gradient_moments.iter().enumerate() {
            m[MASKS[k]] = row[0] * b[0] + row[1] * b[1] + row[2] * b[2];
        }
        for alpha in 0..4 {
            m[HOURGLASS[alpha]] += big_q[alpha][i];
        }
        m
    }
}

impl<T: Real> CornerKernel<T> for HexReduced<T> {
    #[inline(always)]
    fn kernel(
        &self,
        law: &MaterialLaw<T>,
        corners: &mut impl Corners<T>,
    ) -> Result<(), NonPositiveJacobian> {
        let (f, q) = self.deformation(corners);
        let big_q = kept_in_memory(self.hourglass_forces(&q));
        let p = law.first_piola_kirchhoff(&f)?;
        let rows: Mat3<T> = array(
            #[inline(always)]
            |i| self.stress_row(&p, &big_q, i),
        );
        if T::FORCES_BY_COMPONENT {
            for i in 0..3 {
                add_synthesis_of_component(corners, i, self.force_moments(&rows[i], &big_q, i));
            }
        } else {
            let m = array(
                #[inline(always)]
                |i| self.force_moments(&rows[i], &big_q, i),
            );
            add_synthesis(corners, m);
        }
        Ok(())
    }
}

corner_element!(HexReduced);

corner_lane_kernel!(HexReduced);

impl<S: Real, L: LaneReal<S, N>, const N: usize> Pack<S, L, N> for HexReduced<S> {
    type Packed = HexReduced<L>;
    fn pack(items: [&Self; N]) -> Option<Self::Packed> {
        let first = items.first()?;
        Some(HexReduced {
            connectivity: first.connectivity,
            volume: lanes(&items, |e| e.volume),
            gradient_moments: lanes_3(&items, |e| &e.gradient_moments),
            hourglass_geometry: lanes_3(&items, |e| &e.hourglass_geometry),
            hourglass: pack_framed(&items.map(|e| &e.hourglass)),
        })
    }
}

impl<T: Real> Element<T> for HexReduced<T> {
    const KIND: ElementKind = ElementKind::HexReduced;
    /// One-point element with the hourglass stiffness of the cell's frame (the general
    /// kernel).
    fn from_reference(r: &ReferenceHex, connectivity: Connectivity, hourglass: Hourglass) -> Self {
        HexReduced {
            connectivity,
            volume: T::from_f64(r.volume),
            gradient_moments: cast2(&r.gradient_moments()),
            hourglass_geometry: cast2(&r.hourglass_geometry),
            hourglass: FramedStiffness::cast(&hourglass.of_cell(r)),
        }
    }
}

impl ReferenceHex {
    /// [`HexReduced`]'s record of this cell ([`Element::from_reference`]) with the scalar hourglass
    /// form (`K = k I`: modulus `2μ`, coefficient `κ_hg`).
    pub fn reduced<T: Real>(
        &self,
        nodes: [u32; 8],
        material: u16,
        hourglass_modulus: f64,
        hourglass_coefficient: f64,
    ) -> HexReduced<T> {
        let hourglass = Hourglass::scalar(hourglass_modulus, hourglass_coefficient);
        HexReduced::from_reference(self, Connectivity { nodes, material }, hourglass)
    }
}
