//! Explicit central-difference time integration with lumped mass and mass-proportional
//! damping, and the element loop that gathers internal forces.
//!
//! With `M ü + α M u̇ + f_int(u) = f_ext` and central differences
//! `ü = (u⁺ − 2u + u⁻)/Δt²`, `u̇ = (u⁺ − u⁻)/(2Δt)`:
//!
//! `u⁺ = A u − B u⁻ + (C / m) (f_ext − f_int)`, with `A = 2/(1 + αΔt/2)`,
//! `B = (1 − αΔt/2)/(1 + αΔt/2)`, `C = Δt²/(1 + αΔt/2)`.
//!
//! Since `A = 1 + B`, it is run in increment form: the state is `u` and the increment
//! `Δu = u − u⁻` of the last step, and a step is `Δu⁺ = B Δu + (C / m)(f_ext − f_int)`,
//! `u⁺ = u + Δu⁺`. The `A u − B u⁻` form rounds each step at the scale of `u` (f32: 6e-8
//! of `u`, with `A − B ≠ 1` once `A` and `B` are rounded), an error force of
//! `~ε |u| m/Δt²` that biases the static answer by `~ε/(ω₁Δt)²` (ω₁ the lowest mode): 0.4%
//! to 1.9% of a soft cantilever's tip in f32. The increment keeps what `u` cannot resolve,
//! so a state at rest is one where the residual is zero to the kernel's round-off
//! (measured: 1e-7 of the tip in f32; `docs/measurements/f32-statics.md`).
//!
//! `m` here is the inertial mass (the true mass times the mass-scaling factor); gravity is
//! applied with the true mass by whoever builds `f_ext`, so static answers do not change.
//! Nothing here panics: bad indices and numerical failure come back as [`PhysicsError`].

use super::element::{HexElement, KernelFault};
use super::material::MaterialLaw;
use super::real::Real;

/// Numerical or structural failure in a step, naming the element or node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PhysicsError {
    /// `J = det F ≤ 0` in `element` (local index on this board / in this model).
    InvertedElement { element: u32, jacobian: f64 },
    /// A displacement became NaN or infinite at `node`.
    NonFinite { node: u32 },
    /// A displacement's speed exceeded the configured bound at `node` (m/s).
    SpeedLimit { node: u32, speed_m_per_s: f64 },
    /// An element names a node or material outside the model (a corrupted model).
    BadIndex { element: u32 },
    /// A contact record names a node, face, pair or tool outside the contact tables.
    BadContactIndex { index: u32 },
    /// A node sank deeper into a tool or a master surface than the scene's tolerance (m):
    /// the penalty is too soft for the load (raise `penalty`, or slow the tool).
    Penetration {
        node: u32,
        depth_m: f64,
        tolerance_m: f64,
    },
    /// A contact-surface node moved farther between two bounding-box checks than the
    /// scene's speed bound allows: a contact could be missed (raise `speed_bound`).
    ContactSpeedBound {
        node: u32,
        moved_m: f64,
        allowed_m: f64,
    },
}

impl core::fmt::Display for PhysicsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            PhysicsError::InvertedElement { element, jacobian } => {
                write!(f, "element {element} inverted (J = {jacobian:.3e} <= 0)")
            }
            PhysicsError::NonFinite { node } => {
                write!(f, "node {node}: displacement is not finite")
            }
            PhysicsError::SpeedLimit {
                node,
                speed_m_per_s,
            } => write!(
                f,
                "node {node}: speed {speed_m_per_s:.3e} m/s exceeds the bound (unstable step?)"
            ),
            PhysicsError::BadIndex { element } => {
                write!(
                    f,
                    "element {element} refers to a node or material outside the model"
                )
            }
            PhysicsError::BadContactIndex { index } => {
                write!(f, "contact record refers to index {index} outside the contact tables")
            }
            PhysicsError::Penetration {
                node,
                depth_m,
                tolerance_m,
            } => write!(
                f,
                "node {node}: penetration {depth_m:.3e} m exceeds the contact tolerance {tolerance_m:.3e} m (penalty too soft for the load: raise penalty or slow the tool)"
            ),
            PhysicsError::ContactSpeedBound {
                node,
                moved_m,
                allowed_m,
            } => write!(
                f,
                "node {node}: moved {moved_m:.3e} m since the last bounding-box check, more than the {allowed_m:.3e} m the contact speed bound allows (a contact could be missed: raise speed_bound)"
            ),
        }
    }
}

/// The update coefficients `A`, `B`, `C` of the damped central difference (the increment
/// form uses `B` and `C`; `A = 1 + B` is kept for reference).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CentralDifference<T> {
    pub a: T,
    pub b: T,
    pub c: T,
}

impl<T: Real> CentralDifference<T> {
    /// For time step `dt_s` and mass-proportional damping `alpha_per_s`.
    pub fn new(dt_s: f64, alpha_per_s: f64) -> Self {
        let h = 0.5 * alpha_per_s * dt_s;
        CentralDifference {
            a: T::from_f64(2.0 / (1.0 + h)),
            b: T::from_f64((1.0 - h) / (1.0 + h)),
            c: T::from_f64(dt_s * dt_s / (1.0 + h)),
        }
    }

    /// Per-node gain `C / m_inertial`, precomputed once.
    pub fn gain(&self, inertial_mass: f64) -> T {
        T::from_f64(self.c.to_f64() / inertial_mass)
    }

    /// One free node's step in increment form: from `u` and its last increment
    /// `du = u − u⁻`, returns `(u⁺, du⁺)` ([`CentralDifference::advance_component`] per
    /// component).
    #[inline(always)]
    pub fn advance(&self, u: &[T; 3], du: &[T; 3], gain: T, residual: &[T; 3]) -> ([T; 3], [T; 3]) {
        let du_next: [T; 3] =
            core::array::from_fn(|i| self.increment_component(du[i], gain, residual[i]));
        (core::array::from_fn(|i| u[i] + du_next[i]), du_next)
    }

    /// One component of the new increment: `du⁺ = B du + gain r`, evaluated left to right;
    /// then `u⁺ = u + du⁺` (the host's node update runs both over whole arrays of
    /// components). Algebraically `A u − B u⁻ + gain r − u`, since `A = 1 + B`.
    #[inline(always)]
    pub fn increment_component(&self, du: T, gain: T, residual: T) -> T {
        self.b * du + gain * residual
    }

    /// `(u⁺, du⁺)` for one component: [`CentralDifference::increment_component`], then
    /// `u⁺ = u + du⁺`.
    #[inline(always)]
    pub fn advance_component(&self, u: T, du: T, gain: T, residual: T) -> (T, T) {
        let du_next = self.increment_component(du, gain, residual);
        (u + du_next, du_next)
    }
}

/// One component of the squared half-step speed, m²/s²: `v_i²` with
/// `v_i = (u⁺_i − u⁻_i) / 2Δt = (du⁺_i + du_i) / 2Δt` (the sum in `T`, then `f64`;
/// `inv_2dt_per_s = 1/2Δt`). The squared speed is `(v_0² + v_1²) + v_2²`, in that order.
#[inline(always)]
pub fn speed_component_squared<T: Real>(du_next: T, du: T, inv_2dt_per_s: f64) -> f64 {
    let v = (du_next + du).to_f64() * inv_2dt_per_s;
    v * v
}

/// The guards of the node update on one node, given its squared half-step speed `v2`
/// (sum of [`speed_component_squared`]) and `u⁺`: a free node's `u⁺` must be finite and
/// the speed must not exceed `speed_limit_m_per_s`. One comparison decides the common
/// case: a squared speed below the squared limit is finite, so `du⁺` is and `u⁺ = u + du⁺`
/// is (`u` and `du` are, from the step before; a held node's `u⁺` is its path's); anything
/// else goes through the checks one by one, in their order.
#[inline(always)]
pub fn check_node<T: Real>(
    next: &[T; 3],
    free: bool,
    v2: f64,
    speed_limit_m_per_s: f64,
    node: u32,
) -> Result<(), PhysicsError> {
    if v2 < speed_limit_m_per_s * speed_limit_m_per_s {
        return Ok(());
    }
    // Components, not the array: they stay in registers on the common path.
    let [x, y, z] = *next;
    check_node_slow(
        [x, y, z].iter().all(|v| v.is_finite()) || !free,
        v2,
        speed_limit_m_per_s,
        node,
    )
}

/// Gathers the elements' nodal displacements, computes their internal forces and adds them
/// into `f_int` (element order, node order within an element: the summation order is fixed).
///
/// `first_element` is the index of `elements[0]` used in error reports.
#[inline]
pub fn accumulate_internal_forces<T: Real, E: HexElement<T>>(
    elements: &[E],
    first_element: u32,
    laws: &[MaterialLaw<T>],
    u: &[[T; 3]],
    f_int: &mut [[T; 3]],
) -> Result<(), PhysicsError> {
    for (k, e) in elements.iter().enumerate() {
        let element = first_element + k as u32;
        let law = laws
            .get(e.material())
            .ok_or(PhysicsError::BadIndex { element })?;
        e.accumulate(law, u, f_int).map_err(|fault| match fault {
            KernelFault::Inverted(j) => PhysicsError::InvertedElement {
                element,
                jacobian: j.jacobian,
            },
            KernelFault::BadIndex => PhysicsError::BadIndex { element },
        })?;
    }
    Ok(())
}

/// Stored energy (strain plus hourglass) of a set of elements, J.
pub fn stored_energy<T: Real, E: HexElement<T>>(
    elements: &[E],
    laws: &[MaterialLaw<T>],
    u: &[[T; 3]],
) -> Result<f64, PhysicsError> {
    let mut total = 0.0;
    for (k, e) in elements.iter().enumerate() {
        let element = k as u32;
        let law = laws
            .get(e.material())
            .ok_or(PhysicsError::BadIndex { element })?;
        let mut ue = [[T::ZERO; 3]; 8];
        for (a, &n) in e.nodes().iter().enumerate() {
            ue[a] = *u
                .get(n as usize)
                .ok_or(PhysicsError::BadIndex { element })?;
        }
        total += e
            .energy(law, &ue)
            .map_err(|j| PhysicsError::InvertedElement {
                element,
                jacobian: j.jacobian,
            })?
            .to_f64();
    }
    Ok(total)
}

/// How a node moves this step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NodeMove<T> {
    /// Free: `gain = C / m_inertial` and the residual `f_ext − f_int`.
    Free { gain: T, residual: [T; 3] },
    /// Fixed (zero) or prescribed: the displacement at `t_{n+1}`.
    Held([T; 3]),
}

/// The increment `du⁺ = u⁺ − u` of a held node (fixed or prescribed) whose `u⁺` is its
/// path's, component by component.
#[inline(always)]
pub fn held_increment<T: Real>(next: &[T; 3], u: &[T; 3]) -> [T; 3] {
    core::array::from_fn(|i| next[i] - u[i])
}

/// The node update of the serial solver and of every board (one function, so they compute
/// the same bits), in increment form: for a free node `du⁺ = B du + gain (f_ext − f_int)`,
/// `u⁺ = u + du⁺`; for a held one `u⁺` is the held value and `du⁺ = u⁺ − u`
/// ([`held_increment`]); then `du := du⁺`, `u := u⁺`. Refuses a non-finite `u⁺` and a
/// half-step speed `|du⁺ + du| / 2Δt` above `speed_limit_m_per_s`, naming `node`
/// ([`check_node`]). Returns the squared speed (m²/s², for the kinetic energy). The host
/// runs the same functions ([`CentralDifference::advance_component`],
/// [`held_increment`], [`speed_component_squared`], [`check_node`]) over whole arrays of
/// nodes.
#[inline(always)]
pub fn update_node<T: Real>(
    cd: &CentralDifference<T>,
    u: &mut [T; 3],
    du: &mut [T; 3],
    step: NodeMove<T>,
    inv_2dt_per_s: f64,
    speed_limit_m_per_s: f64,
    node: u32,
) -> Result<f64, PhysicsError> {
    let (cur, inc) = (*u, *du);
    let (next, inc_next, free) = match step {
        NodeMove::Free { gain, residual } => {
            let (next, inc_next) = cd.advance(&cur, &inc, gain, &residual);
            (next, inc_next, true)
        }
        NodeMove::Held(next) => (next, held_increment(&next, &cur), false),
    };
    let s = |i: usize| speed_component_squared(inc_next[i], inc[i], inv_2dt_per_s);
    let v2 = s(0) + s(1) + s(2);
    check_node(&next, free, v2, speed_limit_m_per_s, node)?;
    *du = inc_next;
    *u = next;
    Ok(v2)
}

/// The checks of [`check_node`] one by one: a free node's `u⁺` must be finite
/// (`finite`: it is, or the node is held, whose `u⁺` is the path's), and the squared speed
/// `v2` must not exceed the squared limit.
#[cold]
#[inline(never)]
fn check_node_slow(
    finite: bool,
    v2: f64,
    speed_limit_m_per_s: f64,
    node: u32,
) -> Result<(), PhysicsError> {
    if !finite {
        return Err(PhysicsError::NonFinite { node });
    }
    if v2 > speed_limit_m_per_s * speed_limit_m_per_s {
        return Err(PhysicsError::SpeedLimit {
            node,
            speed_m_per_s: libm::sqrt(v2),
        });
    }
    Ok(())
}
