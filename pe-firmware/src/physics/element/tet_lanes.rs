//! Tetrahedra `N` at a time in lanes ([`LaneReal`]): the host's batched tetrahedra run the
//! scalar kernels' code ([`Tet4`], [`MaterialLaw`]) on a packed record, so every lane
//! computes what [`TetLoop`](super::TetLoop) computes for its element, operation for
//! operation; the results are handed out lane by lane, each element's nodes in the scalar
//! loop's order, so sums over them are the scalar loop's bits.
//!
//! A pack fails (`None`, nothing handed out) when a node of some lane is out of range or
//! `J ≤ 0` in some lane; the caller then runs the scalar loop on its elements, which names
//! the element as a board would. Nothing here panics.

use super::super::lanes::{lanes, lanes_3, LaneReal, Pack};
use super::super::material::MaterialLaw;
use super::super::real::{array, Real};
use super::tet::Tet4;

impl<S: Real, L: LaneReal<S, N>, const N: usize> Pack<S, L, N> for Tet4<S> {
    type Packed = Tet4<L>;
    /// The lanes' volumes and gradients (nodes and material: lane 0's, unused).
    fn pack(items: [&Self; N]) -> Option<Self::Packed> {
        let first = items.first()?;
        Some(Tet4 {
            nodes: first.nodes,
            material: first.material,
            volume: lanes(&items, |t| t.volume),
            gradients: lanes_3(&items, |t| &t.gradients),
        })
    }
}

/// The lanes' displacements at their four nodes, every index checked against `len` (at
/// most `u`'s length).
#[inline(always)]
fn gather<S: Real, L: LaneReal<S, N>, const N: usize>(
    nodes: &[[u32; 4]; N],
    len: usize,
    u: &[[S; 3]],
) -> Option<[[L; 3]; 4]> {
    let mut ue = [[[S::ZERO; 3]; 4]; N];
    for (l, row) in ue.iter_mut().enumerate() {
        for (a, v) in row.iter_mut().enumerate() {
            let n = nodes[l][a] as usize;
            if n >= len {
                return None;
            }
            *v = *u.get(n)?;
        }
    }
    Some(array(
        #[inline(always)]
        |a| {
            array(
                #[inline(always)]
                |i| {
                    L::from_lanes(array(
                        #[inline(always)]
                        |l| ue[l][a][i],
                    ))
                },
            )
        },
    ))
}

/// Up to `N` consecutive tetrahedra, packed: the lanes' records, their laws (of one
/// kind), their nodes; lanes from `active` on repeat the last element (results dropped).
pub struct TetPack<L, const N: usize> {
    pub tet: Tet4<L>,
    pub law: MaterialLaw<L>,
    pub nodes: [[u32; 4]; N],
    /// Lanes that hold tetrahedra.
    pub active: usize,
    /// Index of lane 0's tetrahedron in its list.
    pub first: usize,
}

impl<L, const N: usize> TetPack<L, N> {
    /// T4ANP's first pass: each lane's `V J / 4` ([`Tet4::volume_weight`]) for the lanes'
    /// nodes (all below `len`); `None` when an index is out of range or `J ≤ 0` in some
    /// lane.
    #[inline(always)]
    pub fn volume_weights<S: Real>(&self, len: usize, u: &[[S; 3]]) -> Option<[S; N]>
    where
        L: LaneReal<S, N>,
    {
        let ue = gather::<S, L, N>(&self.nodes, len, u)?;
        Some(self.tet.volume_weight(&ue).ok()?.to_lanes())
    }

    /// The stress pass ([`TetLoop::element_forces`](super::TetLoop::element_forces) in
    /// every lane): forces `f_a = V P B_a` with `P = P(F)` (`pressure` None) or
    /// `P_iso(F) + p̄ cof F` (`p̄` the mean of the lane's nodes' `pressure`), handed to
    /// `scatter(node, force)` for the lanes `l < active`, lane by lane, nodes in order;
    /// `None` (nothing handed out) when a node is not below `len` (nor within `pressure`)
    /// or `J ≤ 0` in some lane.
    #[inline(always)]
    pub fn forces<S: Real>(
        &self,
        len: usize,
        pressure: Option<&[S]>,
        u: &[[S; 3]],
        mut scatter: impl FnMut(usize, [S; 3]),
    ) -> Option<()>
    where
        L: LaneReal<S, N>,
    {
        let TetPack {
            tet,
            law,
            nodes,
            active,
            ..
        } = self;
        let len = len.min(pressure.map_or(usize::MAX, <[S]>::len));
        let ue = gather::<S, L, N>(nodes, len, u)?;
        let fm = tet.deformation_gradient(&ue);
        let stress = match pressure {
            None => law.first_piola_kirchhoff(&fm),
            Some(p) => {
                let sum = L::from_lanes(array(
                    #[inline(always)]
                    |l| {
                        let n = &nodes[l];
                        p[n[0] as usize] + p[n[1] as usize] + p[n[2] as usize] + p[n[3] as usize]
                    },
                ));
                law.isochoric_stress_with_pressure(&fm, L::from_f64(0.25) * sum)
            }
        }
        .ok()?;
        let fe = tet.forces_of_stress(&stress);
        let mut by_lane = [[[S::ZERO; N]; 3]; 4];
        for (out, f) in by_lane.iter_mut().zip(&fe) {
            for (o, v) in out.iter_mut().zip(f) {
                *o = v.to_lanes();
            }
        }
        for (l, node) in nodes.iter().enumerate().take((*active).min(N)) {
            for (a, &n) in node.iter().enumerate() {
                let f = &by_lane[a];
                scatter(n as usize, [f[0][l], f[1][l], f[2][l]]);
            }
        }
        Some(())
    }
}
