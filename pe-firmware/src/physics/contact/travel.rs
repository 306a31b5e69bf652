//! The travel check behind the search interval.

use super::super::explicit::PhysicsError;
use super::super::vec3::{dot, sub};
use super::{ContactModel, V3};

/// The speed bound behind the search interval: no node of a pair surface with `apply(c)`
/// may have moved farther than `travel_max_m` from where it was at the last check
/// (`at_check`). A faster node could reach a face the search did not list, so a violation
/// is an error naming the node.
pub(super) fn check_travel(
    m: &ContactModel<'_>,
    pos: impl Fn(usize) -> Option<V3>,
    at_check: &[V3],
    apply: impl Fn(usize) -> bool,
    pair_surfaces: u8,
    travel_max_m: f64,
) -> Result<(), PhysicsError> {
    // A surface moving at exactly the bound covers `travel_max_m` up to round-off.
    let lim = travel_max_m * (1.0 + 1e-9);
    let lim2 = lim * lim;
    for (c, node) in m.nodes.iter().enumerate() {
        if node.surfaces & pair_surfaces == 0 || !apply(c) {
            continue;
        }
        let (Some(x), Some(x0)) = (pos(c), at_check.get(c)) else {
            continue;
        };
        let d = sub(x, *x0);
        let d2 = dot(d, d);
        if !(d2 <= lim2) {
            return Err(PhysicsError::ContactSpeedBound {
                node: node.global,
                moved_m: libm::sqrt(d2),
                allowed_m: travel_max_m,
            });
        }
    }
    Ok(())
}
