//! The corner basis the one-point kernels ([`super::HexReduced`], [`super::HexBox`],
//! [`super::HexCuboid`]) work in: the corner transform of the displacements and the
//! synthesis of the forces, where a kernel reads and writes ([`Corners`]: the element's own
//! arrays, the board's, or a batch's lanes), and the shared [`HexElement`] and
//! [`LaneKernel`] implementations of a corner-basis kernel.

use super::super::lanes::LaneReal;
use super::super::material::{MaterialLaw, NonPositiveJacobian};
use super::super::real::{array, Real};
use super::super::tensor::Mat3;
use super::kernel::{gather_lanes, lanes_out, KernelFault};

/// Node (Gmsh order) at binary corner `p = b_ξ + 2 b_η + 4 b_ζ` (`b = 1` where the
/// natural coordinate is +1).
pub(super) const CORNER: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];

/// Corner masks of the linear fields ξ, η, ζ and of the hourglass base vectors
/// `h_α` = ξη, ηζ, ζξ, ξηζ ([`super::hourglass_base`] order).
pub(super) const LINEAR: [usize; 3] = [1, 2, 4];
pub(super) const HOURGLASS: [usize; 4] = [3, 6, 5, 7];

/// Corner transform of one component (a Walsh-Hadamard transform, 24 additions):
/// `c_k = Σ_p (Π_{j ∈ k} ξ_pj) v_p` for every mask `k` of the natural axes, `v` in corner
/// order. `c_0` is the sum, `c_LINEAR[j]` the linear moments `Σ ξ_j v`, `c_HOURGLASS[α]`
/// the hourglass moments `Σ h_α v`. The corner basis is orthogonal: `Σ_p v_p w_p =
/// (1/8) Σ_k c_k(v) c_k(w)`.
#[inline(always)]
pub(super) fn transform8<T: Real>(mut w: [T; 8]) -> [T; 8] {
    for bit in [1, 2, 4] {
        for p in 0..8 {
            if p & bit == 0 {
                let (lo, hi) = (w[p], w[p | bit]);
                w[p] = lo + hi;
                w[p | bit] = hi - lo;
            }
        }
    }
    w
}

/// The transpose of [`transform8`] for moments whose sum `c_0` is zero (those of the
/// corner-basis kernels' forces: a gradient's corner values sum to zero), corner 0
/// negated: `[-v_0, v_1, .., v_7]` with `v_p = Σ_{k ≠ 0} (Π_{j ∈ k} ξ_pj) c_k`; `w[0]` is
/// not read. The butterflies of the full transpose (three stages of `s ∓ d` over the
/// bits 4, 2, 1) with the zero folded in: the first stage's pair `(0, 4)` gives `∓c_4`
/// without an addition, and the sign carried to corner 0 is left to the caller (it
/// subtracts), so 22 additions instead of 24. Each value is the full transpose's to the
/// bit (negation is exact and `a + (−b) = a − b`), except that the full one turns a
/// zero's sign where it adds `0 ± 0`.
#[inline(always)]
pub(super) fn synthesis8_mean_free<T: Real>(c: [T; 8]) -> [T; 8] {
    // Stage bit 4: (0, 4) gives (−c_4, c_4); the others s ∓ d.
    let (a1, a5) = (c[1] - c[5], c[1] + c[5]);
    let (a2, a6) = (c[2] - c[6], c[2] + c[6]);
    let (a3, a7) = (c[3] - c[7], c[3] + c[7]);
    // Stage bit 2: (0, 2) is (−c_4 − a2, −c_4 + a2) = (−t, a2 − c_4), t = c_4 + a2.
    let t = c[4] + a2;
    let b2 = a2 - c[4];
    let (b1, b3) = (a1 - a3, a1 + a3);
    let (b4, b6) = (c[4] - a6, c[4] + a6);
    let (b5, b7) = (a5 - a7, a5 + a7);
    // Stage bit 1: (0, 1) is (−t − b1, −t + b1) = (−(t + b1), b1 − t).
    [
        t + b1,
        b1 - t,
        b2 - b3,
        b2 + b3,
        b4 - b5,
        b4 + b5,
        b6 - b7,
        b6 + b7,
    ]
}

/// Where a reduced kernel reads displacements and puts forces, by corner (binary order)
/// and component: the element's own arrays ([`HexElement::internal_forces`]) or the
/// board's, fused with the gather and scatter ([`HexElement::accumulate`]). Both see the
/// same values, so both give the same bits.
pub(super) trait Corners<T> {
    fn get(&self, p: usize, i: usize) -> T;
    /// Adds `v` to the force at corner `p` (all three components at once: one lookup of
    /// the node per corner).
    fn add(&mut self, p: usize, v: [T; 3]);
    /// Subtracts `v` from the force at corner `p` (adds `−v`, to the bit).
    fn sub(&mut self, p: usize, v: [T; 3]);
    /// Adds `v` to component `i` of the force at corner `p`.
    fn add_one(&mut self, p: usize, i: usize, v: T);
    /// Subtracts `v` from component `i` of the force at corner `p`.
    fn sub_one(&mut self, p: usize, i: usize, v: T);
}

/// A kernel in the corner basis: reads the displacements from and adds the forces to
/// `corners` (each corner's force added once).
pub(super) trait CornerKernel<T: Real> {
    fn kernel(
        &self,
        law: &MaterialLaw<T>,
        corners: &mut impl Corners<T>,
    ) -> Result<(), NonPositiveJacobian>;
}

/// [`HexElement::internal_forces`] of a corner-basis kernel: the kernel on the element's
/// own arrays (Gmsh order), through [`Global`] with the nodes `0..8`, so the element's
/// forces are the board's to the bit.
#[inline(always)]
pub(super) fn local_forces<T: Real>(
    u: &[[T; 3]; 8],
    kernel: impl FnOnce(&mut Global<'_, T>) -> Result<(), NonPositiveJacobian>,
) -> Result<[[T; 3]; 8], NonPositiveJacobian> {
    let mut f = [[T::ZERO; 3]; 8];
    kernel(&mut Global::of_element(u, &mut f))?;
    Ok(f)
}

/// [`HexElement::accumulate`] of a corner-basis kernel: the kernel on the board's arrays.
#[inline(always)]
pub(super) fn global_forces<T: Real>(
    nodes: &[u32; 8],
    u: &[[T; 3]],
    f: &mut [[T; 3]],
    kernel: impl FnOnce(&mut Global<'_, T>) -> Result<(), NonPositiveJacobian>,
) -> Result<(), KernelFault> {
    let mut g = Global::new(nodes, u, f)?;
    kernel(&mut g).map_err(KernelFault::Inverted)
}

/// The board's arrays at the element's nodes: [`Global::new`] checks every node against
/// both arrays (equal lengths), so the force additions below always land.
pub(super) struct Global<'a, T> {
    /// Displacement of each corner (binary order).
    u: [&'a [T; 3]; 8],
    f: &'a mut [[T; 3]],
    /// Node of each corner (binary order).
    at: [usize; 8],
}

impl<'a, T: Real> Global<'a, T> {
    #[inline(always)]
    fn new(nodes: &[u32; 8], u: &'a [[T; 3]], f: &'a mut [[T; 3]]) -> Result<Self, KernelFault> {
        if u.len() != f.len() {
            return Err(KernelFault::BadIndex);
        }
        let at = CORNER.map(|a| nodes[a] as usize);
        let get = |p: usize| u.get(at[p]).ok_or(KernelFault::BadIndex);
        let u = [
            get(0)?,
            get(1)?,
            get(2)?,
            get(3)?,
            get(4)?,
            get(5)?,
            get(6)?,
            get(7)?,
        ];
        Ok(Global { u, f, at })
    }

    /// An element's own arrays (Gmsh order), as the board's arrays of its 8 nodes
    /// `0..8`: nothing to check.
    #[inline(always)]
    pub(super) fn of_element(u: &'a [[T; 3]; 8], f: &'a mut [[T; 3]; 8]) -> Self {
        Global {
            u: CORNER.map(|a| &u[a]),
            f,
            at: CORNER,
        }
    }
}

impl<T: Real> Corners<T> for Global<'_, T> {
    #[inline(always)]
    fn get(&self, p: usize, i: usize) -> T {
        self.u[p][i]
    }
    #[inline(always)]
    fn add_one(&mut self, p: usize, i: usize, v: T) {
        // Always in range (see `Global::new`).
        if let Some(d) = self.f.get_mut(self.at[p]) {
            d[i] += v;
        }
    }
    #[inline(always)]
    fn sub_one(&mut self, p: usize, i: usize, v: T) {
        // Always in range (see `Global::new`).
        if let Some(d) = self.f.get_mut(self.at[p]) {
            d[i] -= v;
        }
    }
    #[inline(always)]
    fn add(&mut self, p: usize, v: [T; 3]) {
        // Always in range (see `Global::new`).
        if let Some(d) = self.f.get_mut(self.at[p]) {
            for i in 0..3 {
                d[i] += v[i];
            }
        }
    }
    #[inline(always)]
    fn sub(&mut self, p: usize, v: [T; 3]) {
        // Always in range (see `Global::new`).
        if let Some(d) = self.f.get_mut(self.at[p]) {
            for i in 0..3 {
                d[i] -= v[i];
            }
        }
    }
}

/// The corner moments of component `i` of the displacements ([`transform8`]).
#[inline(always)]
pub(super) fn moments_of<T: Real>(c: &impl Corners<T>, i: usize) -> [T; 8] {
    transform8(array(
        #[inline(always)]
        |p| c.get(p, i),
    ))
}

/// Adds the nodal vectors of the moments `m[i]` (component `i`, `m[i][0]` zero and not
/// read: see [`synthesis8_mean_free`]) to the corners.
#[inline(always)]
pub(super) fn add_synthesis<T: Real>(c: &mut impl Corners<T>, m: [[T; 8]; 3]) {
    let v: [[T; 8]; 3] = array(
        #[inline(always)]
        |i| synthesis8_mean_free(m[i]),
    );
    c.sub(0, [v[0][0], v[1][0], v[2][0]]);
    for p in 1..8 {
        c.add(p, [v[0][p], v[1][p], v[2][p]]);
    }
}

/// Adds the nodal values of the moments `m` of component `i` (`m[0]` zero and not read:
/// see [`synthesis8_mean_free`]) to the corners' forces, one component at a time.
#[inline(always)]
pub(super) fn add_synthesis_of_component<T: Real>(c: &mut impl Corners<T>, i: usize, m: [T; 8]) {
    let v = synthesis8_mean_free(m);
    c.sub_one(0, i, v[0]);
    for p in 1..8 {
        c.add_one(p, i, v[p]);
    }
}

/// `v`, computed here and kept in memory until it is used (on the board; elsewhere `v`
/// itself): an optimisation barrier that changes no value. A reduced kernel's hourglass
/// moments are computed with `F` but used only after the material law; without it, LLVM
/// sinks their last butterfly stage past the law's branches and keeps that stage's 18
/// inputs live across the law instead of the 12 moments, spilling them. Measured on the
/// Cortex-M7 (exact instruction counts, the bench of `scripts/board-cost.sh`), per
/// element-step: cuboid kernel f64 595 -> 589, f32 516 -> 489; general kernel f32 842 ->
/// 815 (f64 unchanged). The parallelepiped kernel is faster without it (f64 688 against
/// 711), so it does not use it.
#[inline(always)]
pub(super) fn kept_in_memory<T>(v: T) -> T {
    #[cfg(target_arch = "arm")]
    {
        core::hint::black_box(v)
    }
    #[cfg(not(target_arch = "arm"))]
    {
        v
    }
}

/// `I + H`.
#[inline(always)]
pub(super) fn plus_identity<T: Real>(mut h: Mat3<T>) -> Mat3<T> {
    for (i, row) in h.iter_mut().enumerate() {
        row[i] += T::ONE;
    }
    h
}

/// [`HexElement`] of a corner-basis kernel whose `deformation` gives `F` and the hourglass
/// displacements `q[α][i]` (`q_α` of the general kernel, the moments `c_α` of the
/// parallelepiped and cuboid ones) and whose `hourglass_forces` their forces: the same
/// energy and the same fused loop.
macro_rules! corner_element {
    ($kernel:ident) => {
        impl<T: Real> HexElement<T> for $kernel<T> {
            #[inline(always)]
            fn connectivity(&self) -> &Connectivity {
                &self.connectivity
            }
            #[inline]
            fn internal_forces(
                &self,
                law: &MaterialLaw<T>,
                u: &[[T; 3]; 8],
            ) -> Result<[[T; 3]; 8], NonPositiveJacobian> {
                local_forces(u, |c| self.kernel(law, c))
            }
            fn energy(
                &self,
                law: &MaterialLaw<T>,
                u: &[[T; 3]; 8],
            ) -> Result<T, NonPositiveJacobian> {
                let mut unused = [[T::ZERO; 3]; 8];
                let (f, q) = self.deformation(&Global::of_element(u, &mut unused));
                let w = law.strain_energy_density(&f)? * self.volume;
                let forces = self.hourglass_forces(&q);
                Ok(w + super::hourglass::hourglass_energy(&q, &forces))
            }
            #[inline(always)]
            fn accumulate(
                &self,
                law: &MaterialLaw<T>,
                u: &[[T; 3]],
                f: &mut [[T; 3]],
            ) -> Result<(), KernelFault> {
                global_forces(self.nodes(), u, f, |c| self.kernel(law, c))
            }
        }
    };
}
pub(super) use corner_element;

/// A batch's corners for the corner-basis kernels: the gathered displacements and the
/// forces the kernel's synthesis produces (each corner written once).
struct LaneCorners<L> {
    u: [[L; 3]; 8],
    f: [[L; 3]; 8],
}

impl<L: Real> Corners<L> for LaneCorners<L> {
    #[inline(always)]
    fn get(&self, p: usize, i: usize) -> L {
        self.u[CORNER[p]][i]
    }
    /// [`add_synthesis`] adds to each corner once: a store, as the scalar kernel's
    /// addition into a zeroed array gives the same value (`0 + v = v`, up to the sign
    /// of a zero, which cannot change a later sum that starts from `+0`).
    #[inline(always)]
    fn add(&mut self, p: usize, v: [L; 3]) {
        self.f[p] = v;
    }
    /// As [`Corners::add`] of `−v` (`0 − v = −v` up to the sign of a zero).
    #[inline(always)]
    fn sub(&mut self, p: usize, v: [L; 3]) {
        self.f[p] = array(
            #[inline(always)]
            |i| -v[i],
        );
    }
    /// As [`Corners::add`], one component.
    #[inline(always)]
    fn add_one(&mut self, p: usize, i: usize, v: L) {
        self.f[p][i] = v;
    }
    /// As [`Corners::sub`], one component.
    #[inline(always)]
    fn sub_one(&mut self, p: usize, i: usize, v: L) {
        self.f[p][i] = -v;
    }
}

/// [`LaneKernel::lane_forces`] of a corner-basis kernel: gather, kernel, then the forces
/// lane by lane in binary corner order (the scalar [`Global`] scatter's order).
#[inline(always)]
pub(super) fn lane_corner_forces<S: Real, L: LaneReal<S, N>, const N: usize>(
    kernel: &impl CornerKernel<L>,
    law: &MaterialLaw<L>,
    nodes: &[[u32; 8]; N],
    active: usize,
    u: &[[S; 3]],
    mut scatter: impl FnMut(usize, usize, [S; 3]),
) -> Result<(), KernelFault> {
    let mut c = LaneCorners {
        u: gather_lanes(nodes, u)?,
        f: [[L::ZERO; 3]; 8],
    };
    kernel.kernel(law, &mut c).map_err(KernelFault::Inverted)?;
    let f = lanes_out::<S, L, N>(&c.f);
    for (l, at) in nodes.iter().enumerate().take(active) {
        for p in 0..8 {
            scatter(
                l,
                at[CORNER[p]] as usize,
                [f[p][0][l], f[p][1][l], f[p][2][l]],
            );
        }
    }
    Ok(())
}

/// [`LaneKernel`] of the corner-basis kernels: [`lane_corner_forces`].
macro_rules! corner_lane_kernel {
    ($($kernel:ident),*) => {$(
        impl<S: Real, L: LaneReal<S, N>, const N: usize> LaneKernel<S, L, N> for $kernel<L> {
            const SCATTER_ORDER: [usize; 8] = CORNER;
            #[inline(always)]
            fn lane_forces(
                &self,
                law: &MaterialLaw<L>,
                nodes: &[[u32; 8]; N],
                active: usize,
                u: &[[S; 3]],
                scatter: impl FnMut(usize, usize, [S; 3]),
            ) -> Result<(), KernelFault> {
                lane_corner_forces(self, law, nodes, active, u, scatter)
            }
        }
    )*};
}
pub(super) use corner_lane_kernel;

#[cfg(test)]
mod tests {
    use super::*;

    /// The transpose of [`transform8`] with all 8 moments, three stages of `s ∓ d` over the
    /// bits 4, 2, 1 (the butterflies [`synthesis8_mean_free`] folds the zero into).
    fn full_synthesis(mut w: [f64; 8]) -> [f64; 8] {
        for bit in [4, 2, 1] {
            for p in 0..8 {
                if p & bit == 0 {
                    let (s, d) = (w[p], w[p | bit]);
                    w[p] = s - d;
                    w[p | bit] = s + d;
                }
            }
        }
        w
    }

    /// `Π_{j ∈ k} ξ_pj`: −1 for each axis of mask `k` on which corner `p` is at −1.
    fn sign(p: usize, k: usize) -> f64 {
        if (!p & k).count_ones() % 2 == 1 {
            -1.0
        } else {
            1.0
        }
    }

    /// Moments in [−1, 1) with `c_0 = 0`, from a fixed linear congruential sequence.
    fn moments(seed: u64) -> [f64; 8] {
        let mut x = seed;
        let mut c = [0.0; 8];
        for v in c.iter_mut().skip(1) {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            *v = (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0;
        }
        c
    }

    /// The folded butterflies give the full transpose's bits (corner 0 negated), and both
    /// the transpose by its definition `v_p = Σ_k (Π_{j ∈ k} ξ_pj) c_k` to round-off
    /// (|v_p| ≤ 7, seven roundings of at most 2⁻⁵³·8 each: 1e-14 absolute).
    #[test]
    fn mean_free_synthesis_is_the_transpose_of_the_transform() {
        for seed in 1..200 {
            let c = moments(seed);
            let largest = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(
                largest > 0.1,
                "seed {seed}: moments {c:?} too small to tell"
            );
            let folded = synthesis8_mean_free(c);
            let full = full_synthesis(c);
            assert_eq!(folded.len(), full.len());
            assert_eq!((-folded[0]).to_bits(), full[0].to_bits(), "seed {seed}");
            for p in 1..8 {
                assert_eq!(
                    folded[p].to_bits(),
                    full[p].to_bits(),
                    "seed {seed}, corner {p}"
                );
            }
            for p in 0..8 {
                let direct: f64 = (1..8).map(|k| sign(p, k) * c[k]).sum();
                assert!(
                    (full[p] - direct).abs() <= 1e-14,
                    "seed {seed}, corner {p}: {} against {direct}",
                    full[p]
                );
            }
        }
        // And the transform it is the transpose of: synthesis of the transform is 8 times
        // the identity (the basis is orthogonal), on values whose sum is zero.
        let v = moments(7);
        let mut corners = full_synthesis(v);
        let mean = corners.iter().sum::<f64>() / 8.0;
        corners.iter_mut().for_each(|x| *x -= mean);
        let back = transform8(corners);
        let again = synthesis8_mean_free(back);
        for p in 0..8 {
            let got = if p == 0 { -again[0] } else { again[p] };
            assert!((got - 8.0 * corners[p]).abs() <= 1e-13, "corner {p}");
        }
    }
}
