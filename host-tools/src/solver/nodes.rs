//! The serial solver's node update over whole arrays: the board's [`update_node`], node by
//! node the same operations in the same order, but run component-wise over runs of nodes
//! so the compiler vectorises it.
//!
//! A run of [`RUN`] nodes goes in three passes: (1) every component as if the node were
//! free, [`CentralDifference::advance_component`] (`du⁺ = B du + gain r`, `u⁺ = u + du⁺`)
//! and [`speed_component_squared`], into scratch arrays (vectorised: the components are
//! independent); (2) node by node, in order, a held node's `u⁺`, increment
//! ([`held_increment`]) and speed replaced by its path's, the reactions, the guards
//! ([`check_node`]) and the kinetic energy summed in node order; (3) `du := du⁺`,
//! `u := u⁺`, and `f_int` zeroed for the next step's element phase.
//! A node that fails its guards stops the block with its error before (3): the nodes of
//! earlier runs are updated, the rest are not.
//!
//! [`update_node`]: pe_firmware::physics::explicit::update_node

use multiversion::multiversion;
use pe_firmware::physics::explicit::{check_node, held_increment, speed_component_squared};
use pe_firmware::physics::{CentralDifference, PhysicsError, Real};

use crate::problem::{NodeKind, Problem};

/// Nodes per run of the three passes (their scratch stays in the L1 cache).
const RUN: usize = 64;

/// What one step's node update needs besides the arrays it updates.
pub(super) struct NodeStep<'a, T: Real> {
    pub problem: &'a Problem,
    pub cd: CentralDifference<T>,
    /// `C / m_inertial` per node, repeated for its three components.
    pub gain: &'a [T],
    /// `0.5 · m · mass_scaling` per node: the kinetic energy is `Σ ke_mass · v²`.
    pub ke_mass: &'a [f64],
    pub f_ext: &'a [[T; 3]],
    /// Each prescribed path's value at the step's `t_{n+1}` (evaluated once per step, not
    /// per node).
    pub path_at: &'a [[T; 3]],
    pub inv_2dt_per_s: f64,
    pub speed_limit_m_per_s: f64,
}

/// What one block of the node update found.
#[derive(Default)]
pub(super) struct BlockSums {
    pub kinetic_energy: f64,
    pub reaction_prescribed: [f64; 3],
    pub reaction_fixed: [f64; 3],
    pub error: Option<PhysicsError>,
}

impl<T: Real> NodeStep<'_, T> {
    /// Updates the nodes `first..first + u.len()` (`u`, their last increments `du`, `f_int`
    /// are theirs) and zeroes their `f_int`.
    pub fn block(
        &self,
        first: usize,
        u: &mut [[T; 3]],
        du: &mut [[T; 3]],
        f_int: &mut [[T; 3]],
    ) -> BlockSums {
        let mut sums = BlockSums::default();
        let mut next = [[T::ZERO; 3]; RUN];
        let mut next_du = [[T::ZERO; 3]; RUN];
        let mut sq = [[0.0f64; 3]; RUN];
        let runs = u
            .chunks_mut(RUN)
            .zip(du.chunks_mut(RUN))
            .zip(f_int.chunks_mut(RUN));
        for (r, ((u, du), f_int)) in runs.enumerate() {
            let first = first + r * RUN;
            let len = u.len();
            let (next, next_du, sq) = (&mut next[..len], &mut next_du[..len], &mut sq[..len]);
            let range = first..first + len;
            // (1) Every component as if free.
            advance_flat(
                &self.cd,
                u.as_flattened(),
                du.as_flattened(),
                self.gain[3 * first..3 * (first + len)].as_ref(),
                self.f_ext[range.clone()].as_flattened(),
                f_int.as_flattened(),
                self.inv_2dt_per_s,
                next.as_flattened_mut(),
                next_du.as_flattened_mut(),
                sq.as_flattened_mut(),
            );
            // (2) Node by node, in order.
            for (j, n) in range.enumerate() {
                let held: Option<(&mut [f64; 3], [T; 3])> = match self.problem.node_kind[n] {
                    NodeKind::Free => None,
                    NodeKind::Fixed => Some((&mut sums.reaction_fixed, [T::ZERO; 3])),
                    NodeKind::Prescribed(p) => {
                        Some((&mut sums.reaction_prescribed, self.path_at[p as usize]))
                    }
                };
                let free = held.is_none();
                if let Some((reaction, at)) = held {
                    let (fi, fe) = (f_int[j], self.f_ext[n]);
                    for i in 0..3 {
                        reaction[i] += (fi[i] - fe[i]).to_f64();
                    }
                    next[j] = at;
                    next_du[j] = held_increment(&at, &u[j]);
                    sq[j] = core::array::from_fn(|i| {
                        speed_component_squared(next_du[j][i], du[j][i], self.inv_2dt_per_s)
                    });
                }
                let v2 = sq[j][0] + sq[j][1] + sq[j][2];
                let node = n as u32;
                if let Err(e) = check_node(&next[j], free, v2, self.speed_limit_m_per_s, node) {
                    sums.error = Some(e);
                    return sums;
                }
                sums.kinetic_energy += self.ke_mass[n] * v2;
            }
            // (3) The new state.
            du.copy_from_slice(next_du);
            u.copy_from_slice(next);
            f_int.fill([T::ZERO; 3]);
        }
        sums
    }
}

/// Pass (1) over components: `next_du = B du + gain (f_ext − f_int)`, `next = u + next_du`
/// and the squared speed component of each, the board's operations in its order (no FMA:
/// Rust does not contract), vectorised by the compiler for the instruction sets below.
#[multiversion(targets(
    "x86_64+avx512f+avx512vl+avx2+avx",
    "x86_64+avx2+avx",
    "x86_64+avx",
    "aarch64+neon"
))]
#[allow(clippy::too_many_arguments)]
fn advance_flat<T: Real>(
    cd: &CentralDifference<T>,
    u: &[T],
    du: &[T],
    gain: &[T],
    f_ext: &[T],
    f_int: &[T],
    inv_2dt_per_s: f64,
    next: &mut [T],
    next_du: &mut [T],
    sq: &mut [f64],
) {
    let n = u.len();
    let (du, gain, f_ext, f_int) = (&du[..n], &gain[..n], &f_ext[..n], &f_int[..n]);
    let (next, next_du, sq) = (&mut next[..n], &mut next_du[..n], &mut sq[..n]);
    for k in 0..n {
        let (x, d) = cd.advance_component(u[k], du[k], gain[k], f_ext[k] - f_int[k]);
        next[k] = x;
        next_du[k] = d;
        sq[k] = speed_component_squared(d, du[k], inv_2dt_per_s);
    }
}
