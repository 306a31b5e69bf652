//! The tetrahedra's element loop, plain (T4) or with averaged nodal pressure (T4ANP).
//!
//! T4ANP (Bonet and Burton 1998; Joldes, Wittek and Miller 2008 for soft tissue) takes the
//! volumetric response from each node's patch of tetrahedra instead of each element:
//!
//! * the nodal volume ratio `J_n = v_n / V_n`, with `V_n = Σ_{e∋n} V_e/4` (reference) and
//!   `v_n = Σ_{e∋n} V_e J_e/4` (current);
//! * the nodal pressure `p_n = (1/V_n) Σ_{e∋n} (V_e/4) U_e'(J_n)` (`U_e` the volumetric
//!   energy of element `e`'s law: [`MaterialLaw::volumetric_pressure`]; one law per patch
//!   gives `p_n = U'(J_n)`);
//! * each element's stress `P = P_iso(F) + p̄_e cof F` with `p̄_e` the mean of its four
//!   nodes' pressures, and forces `f_a = V_e P B_a` ([`Tet4::forces_of_stress`]).
//!
//! These are the exact derivatives of the energy `Σ_e V_e W_iso(F_e) + Σ_e (V_e/4)
//! Σ_{n∈e} U_e(J_n)` ([`stored_energy`]), so the scheme conserves energy like the
//! element's own and a load cycle returns to rest. About one pressure per node instead
//! of one per element: the constraint count that locks plain T4 near `ν = 0.5` falls
//! below the degrees of freedom. Every linear displacement field gives every element the
//! same `J`, hence `J_n = J_e` and the plain element's forces: the patch test holds.
//!
//! Everything here works on caller-owned slices (no allocation): `nodal_volume` from
//! [`add_nodal_volumes`], and a [`Scratch`] as long as the displacements.

use serde::{Deserialize, Serialize};

use super::super::explicit::PhysicsError;
use super::super::material::MaterialLaw;
use super::super::real::Real;
use super::kernel::KernelFault;
use super::tet::Tet4;

/// How the tetrahedra take their volumetric response (a scene's `[solver] tetrahedron`:
/// `"nodal-pressure"`, the default, or `"plain"`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum TetPressure {
    /// Each element's own `J` (plain T4: locks as `ν → 0.5`).
    #[serde(rename = "plain")]
    Element,
    /// The nodal average (T4ANP).
    #[default]
    #[serde(rename = "nodal-pressure")]
    Nodal,
}

impl TetPressure {
    /// The name scenes and reports use.
    pub const fn name(self) -> &'static str {
        match self {
            TetPressure::Element => "plain",
            TetPressure::Nodal => "nodal-pressure",
        }
    }
}

/// Per-node work arrays of the nodal pass, each at least as long as the displacements.
pub struct Scratch<'a, T> {
    /// `J_n` (after the first pass).
    pub ratio: &'a mut [T],
    /// `p_n` (Pa).
    pub pressure: &'a mut [T],
}

/// Adds each tetrahedron's quarter volume `V_e/4` to its nodes: `V_n` (m³).
pub fn add_nodal_volumes<T: Real>(tets: &[Tet4<T>], nodal_volume: &mut [T]) {
    let quarter = T::from_f64(0.25);
    for t in tets {
        for &n in &t.nodes {
            if let Some(v) = nodal_volume.get_mut(n as usize) {
                *v += quarter * t.volume;
            }
        }
    }
}

fn fault(k: usize, first: u32, e: KernelFault) -> PhysicsError {
    let element = first + k as u32;
    match e {
        KernelFault::Inverted(j) => PhysicsError::InvertedElement {
            element,
            jacobian: j.jacobian,
        },
        KernelFault::BadIndex => PhysicsError::BadIndex { element },
    }
}

/// The law of element `t`, or [`PhysicsError::BadIndex`].
#[inline(always)]
fn law_of<'l, T: Real>(
    laws: &'l [MaterialLaw<T>],
    t: &Tet4<T>,
    k: usize,
    first: u32,
) -> Result<&'l MaterialLaw<T>, PhysicsError> {
    laws.get(t.material as usize)
        .ok_or(fault(k, first, KernelFault::BadIndex))
}

/// The tetrahedra of a model (or a board) as the loop takes them: the records, the
/// number of the first in errors, the laws, the form, and `V_n` ([`add_nodal_volumes`]
/// over the same tetrahedra; only read by [`TetPressure::Nodal`]).
#[derive(Clone, Copy)]
pub struct TetLoop<'a, T> {
    pub tets: &'a [Tet4<T>],
    pub first: u32,
    pub laws: &'a [MaterialLaw<T>],
    pub form: TetPressure,
    pub nodal_volume: &'a [T],
}

impl<T: Real> TetLoop<'_, T> {
    /// Adds the tetrahedra's internal forces at `u` into `f` (`scratch` is overwritten):
    /// with the nodal form, [`Self::nodal_pressures`] first; then each tetrahedron's
    /// [`Self::element_forces`], in order.
    pub fn accumulate(
        &self,
        scratch: Scratch<'_, T>,
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        let Scratch { ratio, pressure } = scratch;
        let pressure = match self.form {
            TetPressure::Element => None,
            TetPressure::Nodal => {
                self.nodal_pressures(ratio, &mut *pressure, u)?;
                Some(&*pressure)
            }
        };
        let len = forces_len(pressure, u, f);
        // One loop per form, so neither tests the form per element.
        match pressure {
            None => {
                for (k, t) in self.tets.iter().enumerate() {
                    self.forces_of(k, t, len, None, u, f)?;
                }
            }
            Some(p) => {
                for (k, t) in self.tets.iter().enumerate() {
                    self.forces_of(k, t, len, Some(p), u, f)?;
                }
            }
        }
        Ok(())
    }

    /// Adds tetrahedron `k`'s forces `f_a = V P B_a` into `f`: `P = P(F)` of its law
    /// (`pressure` None: plain), or `P = P_iso(F) + p̄ cof F` with `p̄` the mean of its
    /// nodes' `pressure` (T4ANP). Its nodes are checked against `u`, `f` and `pressure`.
    #[inline(always)]
    pub fn element_forces(
        &self,
        k: usize,
        pressure: Option<&[T]>,
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        let t = self
            .tets
            .get(k)
            .ok_or(fault(k, self.first, KernelFault::BadIndex))?;
        self.forces_of(k, t, forces_len(pressure, u, f), pressure, u, f)
    }

    /// [`Self::element_forces`] of `t` (number `k`), its nodes checked against `len`.
    #[inline(always)]
    fn forces_of(
        &self,
        k: usize,
        t: &Tet4<T>,
        len: usize,
        pressure: Option<&[T]>,
        u: &[[T; 3]],
        f: &mut [[T; 3]],
    ) -> Result<(), PhysicsError> {
        let first = self.first;
        let nodes = t.checked_nodes(len).map_err(|e| fault(k, first, e))?;
        let law = law_of(self.laws, t, k, first)?;
        let fm = t.deformation_gradient(&Tet4::gather(&nodes, u));
        let stress = match pressure {
            None => law.first_piola_kirchhoff(&fm),
            Some(p) => {
                let sum = p[nodes[0]] + p[nodes[1]] + p[nodes[2]] + p[nodes[3]];
                law.isochoric_stress_with_pressure(&fm, T::from_f64(0.25) * sum)
            }
        }
        .map_err(|j| fault(k, first, KernelFault::Inverted(j)))?;
        scatter(&nodes, &t.forces_of_stress(&stress), f);
        Ok(())
    }

    /// The first passes of T4ANP: `ratio[n] = J_n` and `pressure[n] = p_n` for every node
    /// with `V_n > 0` (the others' entries are left zero): each tetrahedron's `V_e J_e / 4`
    /// added to its nodes in order ([`Tet4::volume_weight`]), then
    /// [`Self::finish_nodal_pressures`].
    pub fn nodal_pressures(
        &self,
        ratio: &mut [T],
        pressure: &mut [T],
        u: &[[T; 3]],
    ) -> Result<(), PhysicsError> {
        let first = self.first;
        let len = u.len().min(ratio.len());
        ratio.fill(T::ZERO);
        for (k, t) in self.tets.iter().enumerate() {
            let nodes = t.checked_nodes(len).map_err(|e| fault(k, first, e))?;
            let w = t
                .volume_weight(&Tet4::gather(&nodes, u))
                .map_err(|j| fault(k, first, KernelFault::Inverted(j)))?;
            for &n in &nodes {
                ratio[n] += w;
            }
        }
        self.finish_nodal_pressures(ratio, pressure)
    }

    /// From `ratio[n] = Σ_{e∋n} V_e J_e / 4` (summed in element order), `ratio[n] = J_n`
    /// and `pressure[n] = p_n`: with one law over the tetrahedra (the usual case)
    /// `p_n = U'(J_n)` once per node, else `Σ_{e∋n} (V_e/4) U_e'(J_n) / V_n`.
    pub fn finish_nodal_pressures(
        &self,
        ratio: &mut [T],
        pressure: &mut [T],
    ) -> Result<(), PhysicsError> {
        let TetLoop {
            tets,
            first,
            laws,
            nodal_volume,
            ..
        } = *self;
        for (r, &v) in ratio.iter_mut().zip(nodal_volume) {
            if v > T::ZERO {
                *r = *r / v;
            }
        }
        pressure.fill(T::ZERO);
        if let Some(law) = single_law(tets, laws) {
            for ((p, &r), &v) in pressure.iter_mut().zip(&*ratio).zip(nodal_volume) {
                if v > T::ZERO {
                    *p = law.volumetric_pressure(r);
                }
            }
            return Ok(());
        }
        let len = ratio.len().min(pressure.len());
        let quarter = T::from_f64(0.25);
        for (k, t) in tets.iter().enumerate() {
            let nodes = t.checked_nodes(len).map_err(|e| fault(k, first, e))?;
            let law = law_of(laws, t, k, first)?;
            let w = quarter * t.volume;
            for n in nodes {
                pressure[n] += w * law.volumetric_pressure(ratio[n]);
            }
        }
        for (p, &v) in pressure.iter_mut().zip(nodal_volume) {
            if v > T::ZERO {
                *p = *p / v;
            }
        }
        Ok(())
    }
}

#[inline(always)]
fn scatter<T: Real>(nodes: &[usize; 4], fe: &[[T; 3]; 4], f: &mut [[T; 3]]) {
    for (&n, fa) in nodes.iter().zip(fe) {
        for i in 0..3 {
            f[n][i] += fa[i];
        }
    }
}

/// How far the stress pass may index: `u`, `f` and the nodal pressures.
#[inline(always)]
fn forces_len<T>(pressure: Option<&[T]>, u: &[[T; 3]], f: &[[T; 3]]) -> usize {
    u.len()
        .min(f.len())
        .min(pressure.map_or(usize::MAX, <[T]>::len))
}

/// How far the nodal form's energy may index the ratios (no bound for the plain form).
fn ratio_len<T>(scratch: &Scratch<'_, T>, form: TetPressure) -> usize {
    match form {
        TetPressure::Element => usize::MAX,
        TetPressure::Nodal => scratch.ratio.len(),
    }
}

/// The law of every tetrahedron when they share one (`None`: several, or none).
fn single_law<'l, T: Real>(
    tets: &[Tet4<T>],
    laws: &'l [MaterialLaw<T>],
) -> Option<&'l MaterialLaw<T>> {
    let m = tets.first()?.material;
    if tets.iter().all(|t| t.material == m) {
        laws.get(m as usize)
    } else {
        None
    }
}

impl<T: Real> TetLoop<'_, T> {
    /// Stored energy (J) of the tetrahedra at `u`: `Σ_e V_e W(F_e)` (plain) or
    /// `Σ_e V_e W_iso(F_e) + Σ_e (V_e/4) Σ_{n∈e} U_e(J_n)` (nodal), the energy whose
    /// derivatives [`Self::accumulate`] returns. Accumulated in `f64`.
    pub fn stored_energy(
        &self,
        scratch: Scratch<'_, T>,
        u: &[[T; 3]],
    ) -> Result<f64, PhysicsError> {
        let mut sum = 0.0;
        self.for_each_energy(scratch, u, |_, w| sum += w)?;
        Ok(sum)
    }

    /// Each tetrahedron's share of [`Self::stored_energy`] (J), in order, to `each(k, w)`:
    /// its own `V_e W(F_e)` (plain), or `V_e W_iso(F_e) + (V_e/4) Σ_{n∈e} U_e(J_n)` (nodal).
    pub fn for_each_energy(
        &self,
        scratch: Scratch<'_, T>,
        u: &[[T; 3]],
        mut each: impl FnMut(usize, f64),
    ) -> Result<(), PhysicsError> {
        let TetLoop {
            tets,
            first,
            laws,
            form,
            ..
        } = *self;
        let len = u.len().min(ratio_len(&scratch, form));
        let Scratch { ratio, pressure } = scratch;
        if form == TetPressure::Nodal {
            self.nodal_pressures(&mut *ratio, pressure, u)?;
        }
        for (k, t) in tets.iter().enumerate() {
            let nodes = t.checked_nodes(len).map_err(|e| fault(k, first, e))?;
            let law = law_of(laws, t, k, first)?;
            let ue = Tet4::gather(&nodes, u);
            let inverted = |j| fault(k, first, KernelFault::Inverted(j));
            let w = if form == TetPressure::Nodal {
                let iso = t.energy(&law.isochoric(), &ue).map_err(inverted)?;
                let vol: f64 = nodes
                    .iter()
                    .map(|&n| law.volumetric_energy(ratio[n]).to_f64())
                    .sum();
                iso.to_f64() + 0.25 * t.volume.to_f64() * vol
            } else {
                t.energy(law, &ue).map_err(inverted)?.to_f64()
            };
            each(k, w);
        }
        Ok(())
    }
}
