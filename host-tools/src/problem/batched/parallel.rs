//! The batched loop shared among threads with the scalar loop's bits ([`Plan`]).

use std::ops::Range;

use pe_firmware::physics::{LaneKernel, LaneReal, Real};

use super::{run_with, Batch, HostLanes, Loop, Packs};
use crate::team::Team;

/// A block's runs of packs of one kernel list, in order: each a pack index range and
/// whether it checks who owns each node.
type Runs = Vec<(Range<usize>, bool)>;

/// Elements shared among threads with the scalar loop's bits. The elements (kernel order)
/// are cut into blocks of whole packs; a node belongs to the first block that touches
/// it. Each block's thread adds its forces straight into the nodes it owns (in element
/// order: no earlier block touches them), and keeps its forces on other nodes aside, in
/// order; these are added after all blocks finished, block by block (in parallel over the
/// owners: each owner's nodes take their kept forces in block order, then in the order
/// they were produced). So every node sums its elements' forces from zero in kernel
/// order, as one thread does.
///
/// A pack all of whose nodes its block owns (most of them) adds its forces without
/// asking who owns each node: only the runs of packs that touch an earlier block's node
/// pay that check.
pub struct Plan {
    /// Per block, the runs of packs of each kernel list (general, parallelepipeds,
    /// cuboids; full integration uses the first), in order: each a pack index range and
    /// whether a pack of it touches a node the block does not own.
    blocks: Vec<[Runs; 3]>,
    /// Owning block of each node (`u16::MAX`: no element).
    owner: Vec<u16>,
    /// Per block, the nodes of its forces kept aside, in the order it produces them.
    aside: Vec<Vec<u32>>,
    /// Per owning block, the kept forces on its nodes as (block, index in `aside[block]`),
    /// in block order, then in the order each block produced them.
    aside_by_owner: Vec<Vec<(u32, u32)>>,
}

impl Plan {
    /// The blocks' packs, and how many of them are in runs that check each node's owner
    /// (runs touching a node another block owns): `(checked, all)`.
    pub fn checked_packs(&self) -> (usize, usize) {
        let runs = self.blocks.iter().flatten().flatten();
        runs.fold((0, 0), |(c, a), (r, shared)| {
            (c + if *shared { r.len() } else { 0 }, a + r.len())
        })
    }

    /// The number of blocks.
    pub fn blocks(&self) -> usize {
        self.blocks.len()
    }

    /// Room for each block's forces kept aside.
    pub fn kept_buffers<T>(&self) -> Vec<Vec<[T; 3]>> {
        self.aside
            .iter()
            .map(|a| Vec::with_capacity(a.len()))
            .collect()
    }
}

/// The force array, written by several threads at nodes each owns alone.
struct SharedForces<T>(*mut [T; 3], usize);

// SAFETY: threads only write through it at nodes their block owns (a node has one owner),
// and nothing reads the array until they have all finished (`Plan`).
unsafe impl<T: Send> Sync for SharedForces<T> {}

impl<T: Real> SharedForces<T> {
    /// The same array, for another closure to own.
    fn copy(&self) -> Self {
        SharedForces(self.0, self.1)
    }

    /// Adds `v` at node `n`.
    ///
    /// # Safety
    /// Only the block that owns `n` calls this for `n`, while no one else accesses it.
    #[inline(always)]
    unsafe fn add(&self, n: usize, v: [T; 3]) {
        if n < self.1 {
            // SAFETY: in bounds (checked), and exclusive to this thread (the caller).
            let d = unsafe { &mut *self.0.add(n) };
            for i in 0..3 {
                d[i] += v[i];
            }
        }
    }
}

impl<L, const N: usize> Loop<L, N> {
    /// [`super::ElementLoop::plan`]: the packs in kernel order cut into `parts` blocks.
    pub(super) fn plan_blocks<S: Real>(&self, parts: usize, node_count: usize) -> Option<Plan>
    where
        L: HostLanes<S, N>,
    {
        let lists: [Vec<([[u32; 8]; N], usize)>; 3] = match &self.packs {
            Packs::Reduced {
                general,
                boxes,
                cuboids,
            } => [listed(general), listed(boxes), listed(cuboids)],
            Packs::Full(p) => [listed(p), Vec::new(), Vec::new()],
        };
        // Packs in kernel order as (list, index), cut into `parts` runs of about equal
        // element counts.
        let order: Vec<(usize, usize)> = (0..3)
            .flat_map(|k| (0..lists[k].len()).map(move |i| (k, i)))
            .collect();
        let parts = parts
            .clamp(1, order.len().max(1))
            .min(u16::MAX as usize - 1);
        let elements: usize = order.iter().map(|&(k, i)| lists[k][i].1).sum();
        let mut blocks: Vec<[Runs; 3]> = vec![[Vec::new(), Vec::new(), Vec::new()]; parts];
        let mut owner = vec![u16::MAX; node_count];
        let mut aside = vec![Vec::new(); parts];
        let (mut done, mut block) = (0, 0);
        for &(k, i) in &order {
            let (nodes, active) = &lists[k][i];
            while block + 1 < parts && done * parts >= (block + 1) * elements {
                block += 1;
            }
            let kept_before = aside[block].len();
            for at in nodes.iter().take(*active) {
                for &n in at {
                    match owner.get_mut(n as usize) {
                        Some(o) if *o == u16::MAX => *o = block as u16,
                        Some(o) if *o == block as u16 => {}
                        Some(_) => aside[block].push(n),
                        None => return None,
                    }
                }
            }
            let shared = aside[block].len() > kept_before;
            let runs = &mut blocks[block][k];
            match runs.last_mut() {
                Some((r, s)) if *s == shared && r.end == i => r.end = i + 1,
                _ => runs.push((i..i + 1, shared)),
            }
            done += active;
        }
        let mut aside_by_owner = vec![Vec::new(); parts];
        for (b, nodes) in aside.iter().enumerate() {
            for (i, &n) in nodes.iter().enumerate() {
                let o = *owner.get(n as usize)? as usize;
                aside_by_owner.get_mut(o)?.push((b as u32, i as u32));
            }
        }
        Some(Plan {
            blocks,
            owner,
            aside,
            aside_by_owner,
        })
    }

    /// [`super::ElementLoop::parallel_forces`]: the plan's blocks on `team`.
    pub(super) fn plan_forces<S: Real>(
        &self,
        plan: &Plan,
        kept: &mut [Vec<[S; 3]>],
        team: &Team,
        u: &[[S; 3]],
        f: &mut [[S; 3]],
    ) -> bool
    where
        L: HostLanes<S, N>,
    {
        if kept.len() != plan.blocks.len() || plan.owner.len() != f.len() || u.len() != f.len() {
            return false;
        }
        let shared = SharedForces(f.as_mut_ptr(), f.len());
        let ok = team.map_mut(kept, |b, kept| {
            kept.clear();
            let Some(runs) = plan.blocks.get(b) else {
                return false;
            };
            // Plain copies (not references) in the closures, so the force stores, through
            // a raw pointer, do not make the loop reload them.
            let (owner, block) = (plan.owner.as_slice(), b as u16);
            let (own, mine) = (shared.copy(), shared.copy());
            let mut checked = move |n: usize, v: [S; 3]| {
                if owner.get(n) == Some(&block) {
                    // SAFETY: block `b` owns node `n` (see `Plan`).
                    unsafe { own.add(n, v) }
                } else {
                    kept.push(v);
                }
            };
            let mut owned = move |n: usize, v: [S; 3]| {
                // SAFETY: the plan found every node of these packs owned by block `b` (a
                // run not marked shared).
                unsafe { mine.add(n, v) }
            };
            match &self.packs {
                Packs::Reduced {
                    general,
                    boxes,
                    cuboids,
                } => {
                    run_runs(general, &runs[0], u, &mut checked, &mut owned)
                        && run_runs(boxes, &runs[1], u, &mut checked, &mut owned)
                        && run_runs(cuboids, &runs[2], u, &mut checked, &mut owned)
                }
                Packs::Full(p) => run_runs(p, &runs[0], u, &mut checked, &mut owned),
            }
        });
        if !ok.iter().all(|&k| k) {
            return false;
        }
        // The forces kept aside, each owner's on its nodes, block by block, each block's
        // in the order it produced them.
        if plan
            .aside
            .iter()
            .zip(kept.iter())
            .any(|(n, v)| n.len() != v.len())
        {
            return false;
        }
        let kept = &*kept;
        team.for_each(plan.aside_by_owner.len(), |o| {
            for &(b, i) in &plan.aside_by_owner[o] {
                let (b, i) = (b as usize, i as usize);
                let node = plan.aside.get(b).and_then(|a| a.get(i));
                let value = kept.get(b).and_then(|k| k.get(i));
                if let (Some(&n), Some(&v)) = (node, value) {
                    // SAFETY: node `n` is owned by this list's block (`Plan::plan` files a
                    // kept force under its node's owner), and no other list holds that
                    // block's nodes.
                    unsafe { shared.add(n as usize, v) }
                }
            }
        });
        true
    }
}

/// The runs of `packs` in order, each on [`run_with`] with `checked` (a run touching
/// nodes another block owns) or `owned`; false if a pack failed.
fn run_runs<K, S, L, const N: usize>(
    packs: &[Batch<K, L, N>],
    runs: &[(Range<usize>, bool)],
    u: &[[S; 3]],
    checked: &mut impl FnMut(usize, [S; 3]),
    owned: &mut impl FnMut(usize, [S; 3]),
) -> bool
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: HostLanes<S, N>,
{
    runs.iter().all(|(r, shared)| {
        let Some(p) = packs.get(r.clone()) else {
            return false;
        };
        if *shared {
            run_with(p, u, checked).is_none()
        } else {
            run_with(p, u, owned).is_none()
        }
    })
}

/// Each pack's nodes in scatter order (per lane) and its active count.
fn listed<K, S, L, const N: usize>(packs: &[Batch<K, L, N>]) -> Vec<([[u32; 8]; N], usize)>
where
    K: LaneKernel<S, L, N>,
    S: Real,
    L: LaneReal<S, N>,
{
    packs
        .iter()
        .map(|b| (b.nodes.map(|at| K::SCATTER_ORDER.map(|a| at[a])), b.active))
        .collect()
}
