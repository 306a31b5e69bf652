//! The fully integrated (2x2x2 Gauss) hexahedron: no hourglass control needed.

use serde::{Deserialize, Serialize};

use super::super::lanes::{lanes, lanes_3, LaneReal, Pack};
use super::super::material::{MaterialLaw, NonPositiveJacobian};
use super::super::real::Real;
use super::super::tensor::Mat3;
use super::hex::{cast2, deformation_gradient, ReferenceHex};
use super::kernel::{
    gather_lanes, lanes_out, Connectivity, Element, HexElement, Hourglass, KernelFault, LaneKernel,
};
use super::ElementKind;

/// One Gauss point of a fully integrated element.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GaussPoint<T> {
    pub gradients: [[T; 3]; 8],
    /// `w_g det J_g` (m³).
    pub volume: T,
}

/// Fully integrated (2x2x2 Gauss) element.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HexFull<T> {
    pub connectivity: Connectivity,
    pub gauss: [GaussPoint<T>; 8],
}

impl<T: Real> HexElement<T> for HexFull<T> {
    #[inline(always)]
    fn connectivity(&self) -> &Connectivity {
        &self.connectivity
    }
    #[inline(always)]
    fn internal_forces(
        &self,
        law: &MaterialLaw<T>,
        u: &[[T; 3]; 8],
    ) -> Result<[[T; 3]; 8], NonPositiveJacobian> {
        let mut out = [[T::ZERO; 3]; 8];
        for gp in &self.gauss {
            let f = deformation_gradient(u, &gp.gradients);
            let p = law.first_piola_kirchhoff(&f)?;
            add_stress_forces(&mut out, &p, &gp.gradients, gp.volume);
        }
        Ok(out)
    }
    fn energy(&self, law: &MaterialLaw<T>, u: &[[T; 3]; 8]) -> Result<T, NonPositiveJacobian> {
        let mut w = T::ZERO;
        for gp in &self.gauss {
            let f = deformation_gradient(u, &gp.gradients);
            w += law.strain_energy_density(&f)? * gp.volume;
        }
        Ok(w)
    }
}

/// Adds `vol · P g_a` to every nodal force, `P` the first Piola-Kirchhoff stress.
#[inline(always)]
fn add_stress_forces<T: Real>(out: &mut [[T; 3]; 8], p: &Mat3<T>, g: &[[T; 3]; 8], vol: T) {
    let mut p = *p;
    for row in p.iter_mut() {
        for v in row.iter_mut() {
            *v *= vol;
        }
    }
    for a in 0..8 {
        for i in 0..3 {
            out[a][i] += p[i][0] * g[a][0] + p[i][1] * g[a][1] + p[i][2] * g[a][2];
        }
    }
}

impl<S: Real, L: LaneReal<S, N>, const N: usize> LaneKernel<S, L, N> for HexFull<L> {
    const SCATTER_ORDER: [usize; 8] = [0, 1, 2, 3, 4, 5, 6, 7];
    /// Gmsh order, as the default [`HexElement::accumulate`].
    #[inline(always)]
    fn lane_forces(
        &self,
        law: &MaterialLaw<L>,
        nodes: &[[u32; 8]; N],
        active: usize,
        u: &[[S; 3]],
        mut scatter: impl FnMut(usize, usize, [S; 3]),
    ) -> Result<(), KernelFault> {
        let ue = gather_lanes(nodes, u)?;
        let fe = self
            .internal_forces(law, &ue)
            .map_err(KernelFault::Inverted)?;
        let fe = lanes_out::<S, L, N>(&fe);
        for (l, at) in nodes.iter().enumerate().take(active) {
            for (a, v) in fe.iter().enumerate() {
                scatter(l, at[a] as usize, [v[0][l], v[1][l], v[2][l]]);
            }
        }
        Ok(())
    }
}

impl<S: Real, L: LaneReal<S, N>, const N: usize> Pack<S, L, N> for HexFull<S> {
    type Packed = HexFull<L>;
    fn pack(items: [&Self; N]) -> Option<Self::Packed> {
        let first = items.first()?;
        Some(HexFull {
            connectivity: first.connectivity,
            gauss: core::array::from_fn(|g| GaussPoint {
                gradients: lanes_3(&items, |e| &e.gauss[g].gradients),
                volume: lanes(&items, |e| e.gauss[g].volume),
            }),
        })
    }
}

impl<T: Real> Element<T> for HexFull<T> {
    const KIND: ElementKind = ElementKind::HexFull;
    /// Fully integrated (2x2x2) element.
    fn from_reference(r: &ReferenceHex, connectivity: Connectivity, _hourglass: Hourglass) -> Self {
        HexFull {
            connectivity,
            gauss: core::array::from_fn(|g| GaussPoint {
                gradients: cast2(&r.gauss_gradients[g]),
                volume: T::from_f64(r.gauss_volumes[g]),
            }),
        }
    }
}

impl ReferenceHex {
    /// [`HexFull`]'s record of this cell ([`Element::from_reference`]).
    pub fn full<T: Real>(&self, nodes: [u32; 8], material: u16) -> HexFull<T> {
        let none = Hourglass::scalar(0.0, 0.0);
        HexFull::from_reference(self, Connectivity { nodes, material }, none)
    }
}
