//! The tetrahedra in lanes: packs of `N` consecutive tetrahedra whose laws are of one kind
//! ([`TetPack`], the firmware's lane functions), T4ANP's nodal passes included. The
//! results are added lane by lane in element order, so the nodal sums and forces are those
//! of the scalar loop ([`TetLoop::accumulate`](pe_firmware::physics::TetLoop::accumulate)).
//! A failed pack (an inverted element in some lane) is rerun by the scalar code, which
//! names the element.

use pe_firmware::physics::element::tet_lanes::TetPack;
use pe_firmware::physics::element::Scratch;
use pe_firmware::physics::{LaneReal, MaterialLaw, Pack, PhysicsError, Real, Tet4, TetPressure};

use super::lanes::HostLanes;
use super::pack::pack_runs;
use crate::problem::elements::Tetrahedra;

/// Packs `tets` (laws indexed by material) `N` at a time, in order, each pack's laws of
/// one kind.
pub(super) fn pack_tets<S: Real, L: LaneReal<S, N>, const N: usize>(
    tets: &[Tet4<S>],
    laws: &[MaterialLaw<S>],
) -> Result<Vec<TetPack<L, N>>, PhysicsError> {
    pack_runs(
        tets,
        laws,
        |t| t.material as usize,
        |pick, law, active, first| {
            Some(TetPack {
                tet: <Tet4<S> as Pack<S, L, N>>::pack(pick)?,
                law,
                nodes: pick.map(|t| t.nodes),
                active,
                first,
            })
        },
    )
}

/// What a run over the packs does with each lane's result.
pub enum TetPass<'a, S> {
    /// T4ANP's first pass: each lane's `V J / 4` added to its nodes' entries.
    Weights(&'a mut [S]),
    /// The stress pass: each lane's forces added into `f` (`pressure`: T4ANP's nodal
    /// pressures, None for plain T4).
    Forces {
        pressure: Option<&'a [S]>,
        f: &'a mut [[S; 3]],
    },
}

/// The packs in order through `pass`; the index of the first pack that fails (nothing
/// of it added), if any.
#[inline(always)]
pub(super) fn run_tet_packs_body<S: Real, L: LaneReal<S, N>, const N: usize>(
    packs: &[TetPack<L, N>],
    pass: &mut TetPass<'_, S>,
    u: &[[S; 3]],
) -> Option<usize> {
    match pass {
        TetPass::Weights(ratio) => {
            let len = u.len().min(ratio.len());
            for (k, b) in packs.iter().enumerate() {
                let Some(w) = b.volume_weights(len, u) else {
                    return Some(k);
                };
                for (nodes, w) in b.nodes.iter().zip(w).take(b.active) {
                    for &n in nodes {
                        if let Some(r) = ratio.get_mut(n as usize) {
                            *r += w;
                        }
                    }
                }
            }
        }
        TetPass::Forces { pressure, f } => {
            let len = u.len().min(f.len());
            for (k, b) in packs.iter().enumerate() {
                let add = |n: usize, v: [S; 3]| {
                    if let Some(d) = f.get_mut(n) {
                        for i in 0..3 {
                            d[i] += v[i];
                        }
                    }
                };
                let done = b.forces(len, *pressure, u, add);
                if done.is_none() {
                    return Some(k);
                }
            }
        }
    }
    None
}

/// Adds the tetrahedra's internal forces at `u` into `f` from their packs: the bits and
/// errors of [`Tetrahedra::add_forces`].
pub(super) fn run_tets<S: Real, L: HostLanes<S, N>, const N: usize>(
    packs: &[TetPack<L, N>],
    tets: &Tetrahedra<S>,
    laws: &[MaterialLaw<S>],
    u: &[[S; 3]],
    f: &mut [[S; 3]],
) -> Result<(), PhysicsError> {
    if tets.is_empty() {
        return Ok(());
    }
    let covered = packs.last().map(|b| b.first + b.active) == Some(tets.len());
    if !covered || u.len() != f.len() {
        return tets.add_forces(laws, u, f);
    }
    tets.with_loop(laws, |tl, scratch| {
        let Scratch { ratio, pressure } = scratch;
        let pressure = match tl.form {
            TetPressure::Element => None,
            TetPressure::Nodal => {
                ratio.fill(S::ZERO);
                if L::run_tet_packs(packs, &mut TetPass::Weights(&mut *ratio), u).is_none() {
                    tl.finish_nodal_pressures(ratio, &mut *pressure)?;
                } else {
                    // A pack failed: the scalar pass names the element.
                    tl.nodal_pressures(ratio, &mut *pressure, u)?;
                }
                Some(&*pressure)
            }
        };
        let mut from = 0;
        loop {
            let rest = packs.get(from..).unwrap_or(&[]);
            let failed = L::run_tet_packs(rest, &mut TetPass::Forces { pressure, f }, u);
            let Some(j) = failed else { return Ok(()) };
            // The scalar code on the failed pack's elements: the error, named as the
            // scalar loop names it (or, should it pass, the pack's forces).
            let b = &rest[j];
            for k in b.first..b.first + b.active {
                tl.element_forces(k, pressure, u, f)?;
            }
            from += j + 1;
        }
    })
}
