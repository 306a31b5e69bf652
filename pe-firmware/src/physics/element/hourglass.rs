//! Hourglass stiffness of the one-point hexahedra: the generalised forces `Q_α = K q_α` of
//! the hourglass displacements `q_α` (the four modes `h_α` = ξη, ηζ, ζξ, ξηζ, each with
//! three components), in one of two forms the scene chooses ([`HourglassControl`]):
//!
//! * **Physical** (the default): a stiffness per mode and direction from the cell's
//!   geometry and material, after Belytschko and Bindeman's assumed-strain stabilisation
//!   (1993, the "quintessential bending" element; LS-DYNA's hourglass type 6), written on
//!   the cell's own edges: with `g_i` the centre Jacobian's columns (`J₀ = [g_ξ g_η g_ζ]`,
//!   half an edge), `t_i = g_i/|g_i|` the edge directions and `a_i = |g_i|`, a mode's field
//!   `u = d h_α` has the edge components `d_i = d · t_i`, and only its physical strains are
//!   given energy:
//!   - the **bending** components (mode `ξ_jξ_k`, edge `i ∈ {j, k}`): the normal strain of
//!     the fibre along edge `i`, `e_i = d_i ξ_other / a_i` (linear across the cell). Two
//!     such strains vary along each coordinate (along η: the ξ fibre of ξη and the ζ fibre
//!     of ηζ), and the strain along that coordinate cannot vary in it, so the pair is in
//!     plane stress: `W = ½ E/(1−ν²) (V/3) (e_i² + e_j² + 2ν e_i e_j)`. A bent fibre with
//!     its anticlastic partner free stores `½ E e_i²`, beam theory's; with the pair
//!     uncoupled a nearly incompressible beam came out 6% stiff at ν = 0.499 on two cells
//!     through the depth (it could not contract across without paying for it). The mode's
//!     shear, which a bent continuum does not have, is left out: that parasitic shear is
//!     what makes elongated cells lock under a stiffness set by their short sides. On a skewed
//!     cell the edge fibres are what cancel: a pure bending field's components along the
//!     slanted edge add to zero, so it is not stiffened;
//!   - the **twisting** components (mode `ξ_jξ_k`, the third edge): their shear strains,
//!     coupled as a twisted prism couples them (the torsion `u_z = θ′xy, u_y = −θ′xz` has
//!     no shear `γ_yz`): with `a, b, c` the third-edge components of ξη, ηζ, ζξ,
//!     `W = ½ μ (V/3) [(a/a_ξ + b/a_ζ)² + (a/a_η + c/a_ζ)² + (b/a_η + c/a_ξ)²]`;
//!   - the **ξηζ** mode, edge `i`: `W = ½ (V/9) (E/a_i² + μ Σ_{m≠i} 1/a_m²) d_i²`.
//!
//!   With `q_α = 8 d` (the moments of the code, `q_α = Σ_a Γ_aα u_a`), `K = ∂²W/∂q²` is
//!   the above divided by 64, applied as `Q_α = Tᵀ K' (T q_α)` with `T`'s rows the `t_i`.
//!   No term holds the bulk modulus, so nearly incompressible tissue does not lock; on a
//!   box, a pure bending field is carried exactly (one cell through the depth gives beam
//!   theory's curvature). `K` acts on the displacements against the initial configuration
//!   (the seed's eq. 7): nothing accumulates.
//! * **Scalar** (the seed's form, kept for comparison): `K = k I`,
//!   `k = κ_hg 2μ V Σ_a |B_a|² / 8` ([`ReferenceHex::hourglass_stiffness`]).
//!
//! The cuboid kernel keeps the stiffness in the axes ([`ModeStiffness`], `t_i = e_i`); the
//! parallelepiped and general kernels carry the edge directions ([`FramedStiffness`]; the
//! scalar form's are the axes). Both apply it
//! with the same operations in the same order on the board and in the host's lanes.

use serde::{Deserialize, Serialize};

use super::super::lanes::{lanes_1, lanes_3, LaneReal};
use super::super::material::MaterialLaw;
use super::super::real::{array, Real};
use super::super::tensor::{det, inverse, transpose, Mat3};
use super::hex::ReferenceHex;

/// The hourglass control a scene chooses (`[solver] hourglass = "physical"` or a
/// coefficient `κ_hg` of the scalar form, e.g. `0.1`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum HourglassControl {
    /// A stiffness per mode and direction from the cell and the material (see the module).
    Physical,
    /// `K = k I` with coefficient `κ_hg` (the seed's form).
    Scalar(f64),
}

impl HourglassControl {
    /// The default: the physical form.
    pub const DEFAULT: HourglassControl = HourglassControl::Physical;
}

impl core::fmt::Display for HourglassControl {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            HourglassControl::Physical => f.write_str("physical"),
            HourglassControl::Scalar(k) => write!(f, "{k}"),
        }
    }
}

/// The twisting component (direction) of each bilinear mode: ξη → ζ, ηζ → ξ, ζξ → η.
const TWIST: [usize; 3] = [2, 0, 1];

/// A hourglass stiffness in the cell's frame (N/m), the fifteen numbers its structure
/// needs: the bending components of the bilinear modes share their edge's stiffness (ξη's
/// ξ and ζξ's ξ take `bend[0]`, and so on) and are coupled in pairs, the twisting components a, b, c (ξη's ζ, ηζ's
/// ξ, ζξ's η) have a diagonal and three couplings, the ξηζ mode one stiffness per
/// direction.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModeStiffness<T> {
    /// The bending stiffness of each edge's fibre.
    pub bend: [T; 3],
    /// The couplings of the two bending components whose strains vary along the same
    /// natural coordinate ξ, η, ζ ([`POISSON_PAIRS`]).
    pub poisson: [T; 3],
    /// `K_aa`, `K_bb`, `K_cc` of the twisting components.
    pub twist_diagonal: [T; 3],
    /// The couplings `K_ab`, `K_ac`, `K_bc` of the twisting components.
    pub twist: [T; 3],
    /// The ξηζ mode's, per direction.
    pub cubic: [T; 3],
}

/// The two bending components (mode, edge) whose strains vary along ξ, η and ζ: along ξ
/// the η fibre of ξη and the ζ fibre of ζξ; along η the ξ fibre of ξη and the ζ fibre of
/// ηζ; along ζ the η fibre of ηζ and the ξ fibre of ζξ.
pub const POISSON_PAIRS: [[(usize, usize); 2]; 3] =
    [[(0, 1), (2, 2)], [(0, 0), (1, 2)], [(1, 1), (2, 0)]];

/// Which of a [`ModeStiffness`]'s bending stiffnesses (`Some(edge)`) or twisting diagonals
/// (`None`) each component of the bilinear modes takes.
const BILINEAR: [[Option<usize>; 3]; 3] = [
    [Some(0), Some(1), None],
    [None, Some(1), Some(2)],
    [Some(0), None, Some(2)],
];

impl<T: Real> ModeStiffness<T> {
    /// `Q = K q`, `q[α][i]` in the frame.
    #[inline(always)]
    pub fn forces(&self, q: &[[T; 3]; 4]) -> [[T; 3]; 4] {
        let mut out: [[T; 3]; 4] = array(
            #[inline(always)]
            |alpha| {
                array(
                    #[inline(always)]
                    |i| self.diagonal(alpha, i) * q[alpha][i],
                )
            },
        );
        let (a, b, c) = (q[0][TWIST[0]], q[1][TWIST[1]], q[2][TWIST[2]]);
        let t = &self.twist;
        out[0][TWIST[0]] += t[0] * b + t[1] * c;
        out[1][TWIST[1]] += t[0] * a + t[2] * c;
        out[2][TWIST[2]] += t[1] * a + t[2] * b;
        for (m, [(a1, i1), (a2, i2)]) in POISSON_PAIRS.iter().copied().enumerate() {
            let (x, y) = (q[a1][i1], q[a2][i2]);
            out[a1][i1] += self.poisson[m] * y;
            out[a2][i2] += self.poisson[m] * x;
        }
        out
    }

    /// `K_(α i)(α i)`: mode α (ξη, ηζ, ζξ, ξηζ), direction `i` of the frame.
    #[inline(always)]
    pub fn diagonal(&self, alpha: usize, i: usize) -> T {
        if alpha == 3 {
            return self.cubic[i];
        }
        match BILINEAR[alpha][i] {
            Some(edge) => self.bend[edge],
            None => self.twist_diagonal[alpha],
        }
    }
}

/// A [`ModeStiffness`] of scalars `S` packed into lanes `L`.
pub(crate) fn pack_modes<S: Real, L: LaneReal<S, N>, const N: usize>(
    items: &[&ModeStiffness<S>; N],
) -> ModeStiffness<L> {
    ModeStiffness {
        bend: lanes_1(items, |m| &m.bend),
        poisson: lanes_1(items, |m| &m.poisson),
        twist_diagonal: lanes_1(items, |m| &m.twist_diagonal),
        twist: lanes_1(items, |m| &m.twist),
        cubic: lanes_1(items, |m| &m.cubic),
    }
}

/// A [`FramedStiffness`] of scalars `S` packed into lanes `L`.
pub(crate) fn pack_framed<S: Real, L: LaneReal<S, N>, const N: usize>(
    items: &[&FramedStiffness<S>; N],
) -> FramedStiffness<L> {
    let modes: [&ModeStiffness<S>; N] = core::array::from_fn(|l| &items[l].modes);
    FramedStiffness {
        frame: lanes_3(items, |m| &m.frame),
        modes: pack_modes(&modes),
    }
}

/// A hourglass stiffness on the cell's edge directions: `Q_α = Tᵀ K' (T q_α)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FramedStiffness<T> {
    /// The rows of `T`: unit vectors in the reference configuration (the edge directions
    /// `t_i` of the physical form, the axes of the scalar one).
    pub frame: [[T; 3]; 3],
    pub modes: ModeStiffness<T>,
}

impl<T: Real> FramedStiffness<T> {
    /// `Q_α = Tᵀ K' T q_α`, `q[α][i]` in the reference axes.
    #[inline(always)]
    pub fn forces(&self, q: &[[T; 3]; 4]) -> [[T; 3]; 4] {
        let e = &self.frame;
        let local: [[T; 3]; 4] = array(
            #[inline(always)]
            |alpha| {
                array(
                    #[inline(always)]
                    |i| e[i][0] * q[alpha][0] + e[i][1] * q[alpha][1] + e[i][2] * q[alpha][2],
                )
            },
        );
        let r = self.modes.forces(&local);
        array(
            #[inline(always)]
            |alpha| {
                array(
                    #[inline(always)]
                    |j| e[0][j] * r[alpha][0] + e[1][j] * r[alpha][1] + e[2][j] * r[alpha][2],
                )
            },
        )
    }
}

/// `½ Σ_α q_α · Q_α`: the hourglass energy (J) of the moments `q` and their forces.
#[inline(always)]
pub fn hourglass_energy<T: Real>(q: &[[T; 3]; 4], forces: &[[T; 3]; 4]) -> T {
    let mut s = T::ZERO;
    for alpha in 0..4 {
        for i in 0..3 {
            s += q[alpha][i] * forces[alpha][i];
        }
    }
    T::from_f64(0.5) * s
}

/// What the hourglass stiffness of a cell takes besides its geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hourglass {
    /// Shear modulus μ (Pa).
    pub shear_modulus_pa: f64,
    /// Young's modulus E at small strain (Pa).
    pub young_modulus_pa: f64,
    pub control: HourglassControl,
}

impl Hourglass {
    /// The moduli of a material with shear modulus `mu_pa` and bulk modulus `kappa_pa`:
    /// `E = 9κμ / (3κ + μ)`.
    pub fn of_moduli(mu_pa: f64, kappa_pa: f64, control: HourglassControl) -> Self {
        Hourglass {
            shear_modulus_pa: mu_pa,
            young_modulus_pa: 9.0 * kappa_pa * mu_pa / (3.0 * kappa_pa + mu_pa),
            control,
        }
    }

    /// The hourglass of material `law` under `control`.
    pub fn of_law(law: &MaterialLaw<f64>, control: HourglassControl) -> Self {
        Self::of_moduli(law.shear_modulus(), law.bulk_modulus(), control)
    }

    /// The scalar form with hourglass modulus `modulus_pa` (`2μ`) and coefficient `κ_hg`.
    pub fn scalar(modulus_pa: f64, coefficient: f64) -> Self {
        Hourglass {
            shear_modulus_pa: 0.5 * modulus_pa,
            young_modulus_pa: 1.5 * modulus_pa,
            control: HourglassControl::Scalar(coefficient),
        }
    }

    /// The stiffness `K'` of cell `r` on edges of half-lengths `a` (m).
    fn modes(&self, r: &ReferenceHex, a: [f64; 3]) -> ModeStiffness<f64> {
        match self.control {
            HourglassControl::Scalar(kappa) => {
                let k = r.hourglass_stiffness(2.0 * self.shear_modulus_pa, kappa);
                ModeStiffness {
                    bend: [k; 3],
                    poisson: [0.0; 3],
                    twist_diagonal: [k; 3],
                    twist: [0.0; 3],
                    cubic: [k; 3],
                }
            }
            HourglassControl::Physical => {
                physical_modes(r.volume, self.young_modulus_pa, self.shear_modulus_pa, a)
            }
        }
    }

    /// The cuboid kernel's stiffness: the edges are the axes, `a_j = 1 / (8 b_jj)`.
    pub fn of_cuboid(&self, r: &ReferenceHex) -> ModeStiffness<f64> {
        let b = r.gradient_basis();
        self.modes(r, core::array::from_fn(|j| 1.0 / (8.0 * b[j][j])))
    }

    /// The parallelepiped and general kernels' stiffness: on the cell's edge directions
    /// (physical form) or the axes (scalar form).
    pub fn of_cell(&self, r: &ReferenceHex) -> FramedStiffness<f64> {
        let (frame, a) = edges(r);
        match self.control {
            HourglassControl::Physical => FramedStiffness {
                frame,
                modes: self.modes(r, a),
            },
            HourglassControl::Scalar(_) => FramedStiffness {
                frame: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                modes: self.modes(r, a),
            },
        }
    }
}

/// The cell's edge directions `t_i` (rows) and half-lengths `a_i = |g_i|`: the columns of
/// its centre Jacobian `J₀`, the inverse of the dual vectors `g^m = 8 b_m` (the rows of
/// `J₀⁻¹`: `Σ_a ξ_a^m B_a`, exact on a parallelepiped).
pub fn edges(r: &ReferenceHex) -> (Mat3<f64>, [f64; 3]) {
    let b = r.gradient_basis();
    let dual: Mat3<f64> = core::array::from_fn(|m| core::array::from_fn(|i| 8.0 * b[m][i]));
    let jacobian = inverse(&dual, det(&dual));
    let g: Mat3<f64> = transpose(&jacobian);
    let a: [f64; 3] = core::array::from_fn(|i| libm::sqrt(g[i].iter().map(|v| v * v).sum()));
    let frame = core::array::from_fn(|i| core::array::from_fn(|k| g[i][k] / a[i]));
    (frame, a)
}

/// The physical form's stiffness `K'` (see the module) of a cell of volume `v` (m³) on
/// edges of half-lengths `a` (m), Young's modulus `e` and shear modulus `mu` (Pa).
fn physical_modes(v: f64, e: f64, mu: f64, a: [f64; 3]) -> ModeStiffness<f64> {
    let s = v / (3.0 * 64.0);
    let s4 = v / (9.0 * 64.0);
    let n = a.map(|a| 1.0 / a);
    let sq = |m: usize| n[m] * n[m];
    // Twisting: a = (ξη, ζ), b = (ηζ, ξ), c = (ζξ, η).
    let twist_diagonal = [
        mu * s * (sq(0) + sq(1)),
        mu * s * (sq(2) + sq(1)),
        mu * s * (sq(2) + sq(0)),
    ];
    let twist = [
        mu * s * n[0] * n[2],
        mu * s * n[1] * n[2],
        mu * s * n[1] * n[0],
    ];
    let cubic = core::array::from_fn(|i| {
        let others: f64 = (0..3).filter(|&m| m != i).map(sq).sum();
        s4 * (e * sq(i) + mu * others)
    });
    // Bending in plane stress: the two fibres whose strains vary along one coordinate,
    // with E' = E / (1 − ν²) and the coupling ν E'.
    let nu = e / (2.0 * mu) - 1.0;
    let e_plane = e / (1.0 - nu * nu);
    let poisson = core::array::from_fn(|m| {
        let [(_, i), (_, j)] = POISSON_PAIRS[m];
        nu * e_plane * s * n[i] * n[j]
    });
    ModeStiffness {
        bend: core::array::from_fn(|i| e_plane * s * sq(i)),
        poisson,
        twist_diagonal,
        twist,
        cubic,
    }
}

impl<T: Real> ModeStiffness<T> {
    /// Rounded from `f64`.
    pub fn cast(m: &ModeStiffness<f64>) -> Self {
        let cast = |v: &[f64; 3]| v.map(T::from_f64);
        ModeStiffness {
            bend: cast(&m.bend),
            poisson: cast(&m.poisson),
            twist_diagonal: cast(&m.twist_diagonal),
            twist: cast(&m.twist),
            cubic: cast(&m.cubic),
        }
    }
}

impl<T: Real> FramedStiffness<T> {
    /// Rounded from `f64`.
    pub fn cast(m: &FramedStiffness<f64>) -> Self {
        FramedStiffness {
            frame: core::array::from_fn(|a| core::array::from_fn(|i| T::from_f64(m.frame[a][i]))),
            modes: ModeStiffness::cast(&m.modes),
        }
    }
}
