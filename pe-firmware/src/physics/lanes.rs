//! Lanes: `N` scalars side by side, one per element of a batch, as a [`Real`] whose every
//! operation is the scalar's, lane by lane.
//!
//! The element kernels are generic over [`Real`], so running them on `Lanes<S, N>` runs
//! `N` elements at once with, in every lane, exactly the operations of the scalar kernel in
//! the same order: the host's batched kernel computes the board's bits by construction.
//! Arithmetic is element-wise IEEE 754 (a compiler may pack it into SIMD registers, which
//! round the same way; no fused multiply-add is ever formed); `ln`, `cbrt` and `sqrt` call
//! the scalar's function once per lane.
//!
//! Comparisons order two lane vectors only when every lane agrees (`a > b` holds when it
//! holds in every lane), so a kernel's test `J > 0` passes only when it passes for all of
//! the batch's elements. When it does not, the kernel reports a failure for the batch and
//! the caller runs the scalar kernel on its elements one by one, which names the element
//! and its Jacobian exactly as a board would. `to_f64` gives lane 0 (for error payloads).
//!
//! Nothing here panics.

use core::cmp::Ordering;
use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

use super::material::{LameParameters, MaterialLaw};
use super::real::{array, Real};

/// `N` values of scalar type `S`, lane `l` belonging to element `l` of a batch.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(transparent)]
pub struct Lanes<S, const N: usize>(pub [S; N]);

impl<S: Real, const N: usize> Lanes<S, N> {
    /// Every lane `x`.
    #[inline(always)]
    pub const fn splat(x: S) -> Self {
        Lanes([x; N])
    }

    // Plain loops rather than `array::map`/`from_fn`, which the optimiser does not always
    // see through at this depth of inlining.
    #[inline(always)]
    fn map(mut self, f: impl Fn(S) -> S) -> Self {
        for v in self.0.iter_mut() {
            *v = f(*v);
        }
        self
    }

    #[inline(always)]
    fn zip(mut self, o: Self, f: impl Fn(S, S) -> S) -> Self {
        for (v, w) in self.0.iter_mut().zip(o.0) {
            *v = f(*v, w);
        }
        self
    }
}

impl<S: Real, const N: usize> Default for Lanes<S, N> {
    #[inline(always)]
    fn default() -> Self {
        Self::splat(S::ZERO)
    }
}

/// Ordered only when every lane is: `Less` when all lanes are less, and so on.
impl<S: Real, const N: usize> PartialOrd for Lanes<S, N> {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        let first = self.0.first()?.partial_cmp(o.0.first()?)?;
        let all = self
            .0
            .iter()
            .zip(&o.0)
            .all(|(a, b)| a.partial_cmp(b) == Some(first));
        all.then_some(first)
    }
}

macro_rules! lane_op {
    ($tr:ident, $f:ident, $as_tr:ident, $as_f:ident, $op:tt) => {
        impl<S: Real, const N: usize> $tr for Lanes<S, N> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                self.zip(o, #[inline(always)] |a, b| a $op b)
            }
        }
        impl<S: Real, const N: usize> $as_tr for Lanes<S, N> {
            #[inline(always)]
            fn $as_f(&mut self, o: Self) {
                *self = self.zip(o, #[inline(always)] |a, b| a $op b);
            }
        }
    };
}
lane_op!(Add, add, AddAssign, add_assign, +);
lane_op!(Sub, sub, SubAssign, sub_assign, -);
lane_op!(Mul, mul, MulAssign, mul_assign, *);

impl<S: Real, const N: usize> Div for Lanes<S, N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        self.zip(
            o,
            #[inline(always)]
            |a, b| a / b,
        )
    }
}

impl<S: Real, const N: usize> Neg for Lanes<S, N> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.map(
            #[inline(always)]
            |a| -a,
        )
    }
}

impl<S: Real, const N: usize> Real for Lanes<S, N> {
    const ZERO: Self = Lanes([S::ZERO; N]);
    const ONE: Self = Lanes([S::ONE; N]);
    const NAME: &'static str = S::NAME;
    #[inline(always)]
    fn from_f64(x: f64) -> Self {
        Self::splat(S::from_f64(x))
    }
    /// Lane 0.
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self.0.first().map_or(0.0, |v| v.to_f64())
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        self.map(S::sqrt)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        self.map(S::ln)
    }
    #[inline(always)]
    fn cbrt(self) -> Self {
        self.map(S::cbrt)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        self.map(S::abs)
    }
    /// Every lane finite.
    #[inline(always)]
    fn is_finite(self) -> bool {
        self.0.iter().all(|v| v.is_finite())
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        self.zip(o, S::max)
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        self.zip(o, S::min)
    }
}

/// A [`Real`] that holds `N` lanes of scalar type `S` and computes, in every lane, what
/// `S` computes: [`Lanes`] (plain arrays, any target), or a host type over SIMD registers.
pub trait LaneReal<S: Real, const N: usize>: Real {
    fn from_lanes(v: [S; N]) -> Self;
    fn to_lanes(self) -> [S; N];
    /// The displacements `u[nodes[l][a]]` of the 8 corners `a` of each lane's element as
    /// lane values (a gather and a transpose); `None` when an index is outside `u`. Lane
    /// types with a faster shuffle override it.
    #[inline(always)]
    fn gather_corners(u: &[[S; 3]], nodes: &[[u32; 8]; N]) -> Option<[[Self; 3]; 8]> {
        let mut ue = [[[S::ZERO; 3]; 8]; N];
        for (l, row) in ue.iter_mut().enumerate() {
            for (a, v) in row.iter_mut().enumerate() {
                *v = *u.get(nodes[l][a] as usize)?;
            }
        }
        Some(array(
            #[inline(always)]
            |a| {
                array(
                    #[inline(always)]
                    |i| {
                        Self::from_lanes(array(
                            #[inline(always)]
                            |l| ue[l][a][i],
                        ))
                    },
                )
            },
        ))
    }
}

impl<S: Real, const N: usize> LaneReal<S, N> for Lanes<S, N> {
    #[inline(always)]
    fn from_lanes(v: [S; N]) -> Self {
        Lanes(v)
    }
    #[inline(always)]
    fn to_lanes(self) -> [S; N] {
        self.0
    }
}

/// Values of type `Self` for `N` elements packed into one with [`Lanes`] in place of the
/// lane type `L` in place of the scalar (a structure of arrays); `None` when the elements
/// cannot share a batch (laws of different kinds).
pub trait Pack<S: Real, L: LaneReal<S, N>, const N: usize>: Sized {
    type Packed;
    fn pack(items: [&Self; N]) -> Option<Self::Packed>;
}

pub(crate) fn lanes<S: Real, L: LaneReal<S, N>, X, const N: usize>(
    items: &[&X; N],
    f: impl Fn(&X) -> S,
) -> L {
    L::from_lanes(core::array::from_fn(|l| f(items[l])))
}

pub(crate) fn lanes_3<S: Real, L: LaneReal<S, N>, X, const N: usize, const M: usize>(
    items: &[&X; N],
    f: impl Fn(&X) -> &[[S; 3]; M],
) -> [[L; 3]; M] {
    core::array::from_fn(|k| core::array::from_fn(|i| lanes(items, |x| f(x)[k][i])))
}

pub(crate) fn lanes_1<S: Real, L: LaneReal<S, N>, X, const N: usize>(
    items: &[&X; N],
    f: impl Fn(&X) -> &[S; 3],
) -> [L; 3] {
    core::array::from_fn(|i| lanes(items, |x| f(x)[i]))
}

impl<S: Real, L: LaneReal<S, N>, const N: usize> Pack<S, L, N> for MaterialLaw<S> {
    type Packed = MaterialLaw<L>;
    fn pack(items: [&Self; N]) -> Option<Self::Packed> {
        let first = items.first()?;
        match **first {
            MaterialLaw::NeoHookean(_) => {
                let p = |x: &Self| match *x {
                    MaterialLaw::NeoHookean(l) => Some([l.mu, l.lambda]),
                    _ => None,
                };
                let all: [[S; 2]; N] = collect(items.map(p))?;
                Some(MaterialLaw::NeoHookean(LameParameters {
                    mu: L::from_lanes(all.map(|v| v[0])),
                    lambda: L::from_lanes(all.map(|v| v[1])),
                }))
            }
            MaterialLaw::NeoHookeanDecoupled { .. } => {
                let p = |x: &Self| match *x {
                    MaterialLaw::NeoHookeanDecoupled { mu, kappa } => Some([mu, kappa]),
                    _ => None,
                };
                let all: [[S; 2]; N] = collect(items.map(p))?;
                Some(MaterialLaw::NeoHookeanDecoupled {
                    mu: L::from_lanes(all.map(|v| v[0])),
                    kappa: L::from_lanes(all.map(|v| v[1])),
                })
            }
            MaterialLaw::MooneyRivlin { volumetric, .. } => {
                let p = |x: &Self| match *x {
                    MaterialLaw::MooneyRivlin {
                        c10,
                        c01,
                        kappa,
                        volumetric: v,
                    } if v == volumetric => Some([c10, c01, kappa]),
                    _ => None,
                };
                let all: [[S; 3]; N] = collect(items.map(p))?;
                Some(MaterialLaw::MooneyRivlin {
                    c10: L::from_lanes(all.map(|v| v[0])),
                    c01: L::from_lanes(all.map(|v| v[1])),
                    kappa: L::from_lanes(all.map(|v| v[2])),
                    volumetric,
                })
            }
        }
    }
}

/// `Some` of all when every item is `Some`.
fn collect<X: Copy + Default, const N: usize>(items: [Option<X>; N]) -> Option<[X; N]> {
    let mut out = [X::default(); N];
    for (o, i) in out.iter_mut().zip(items) {
        *o = i?;
    }
    Some(out)
}
