//! Poses as a live session takes them: from a client's numbers (checked and normalised,
//! [`from_wire`]) and one step's motion toward a pose the tool may not reach in one step
//! ([`step_toward`]: the contact search's speed bound caps how far a capsule end moves).
//!
//! A pose is the rigid motion `x' = R(q) x + p` of the tool from where the scene places it
//! ([`Pose`]). Between two poses the tool moves about its pivot `c` (the trocar when the
//! scene names one, else the capsule's midpoint): the pivot's image `R(q) c + p` moves
//! linearly and the rotation by spherical linear interpolation (slerp), so a motion that
//! keeps the axis through the trocar keeps it at every intermediate step.

use super::engine::{Pose, ToolInfo};

/// How far `|q|` may be from 1 for a client's orientation to be taken (then normalised).
pub const UNIT_QUATERNION_TOLERANCE: f64 = 1e-3;

/// A client's pose (`position_m` in metres, `orientation` the unit quaternion `[w, x, y,
/// z]`), checked: every number finite and `|q|` within [`UNIT_QUATERNION_TOLERANCE`] of 1;
/// the quaternion is normalised. Err: what is wrong, in words for the client.
pub fn from_wire(position_m: [f64; 3], orientation: [f64; 4]) -> Result<Pose, String> {
    if position_m.iter().any(|v| !v.is_finite()) {
        return Err(format!(
            "position_m {position_m:?} is not finite (metres, three finite numbers)"
        ));
    }
    if orientation.iter().any(|v| !v.is_finite()) {
        return Err(format!(
            "orientation {orientation:?} is not finite (a unit quaternion [w, x, y, z])"
        ));
    }
    let norm = orientation.iter().map(|v| v * v).sum::<f64>().sqrt();
    if (norm - 1.0).abs() > UNIT_QUATERNION_TOLERANCE {
        return Err(format!(
            "orientation {orientation:?} has |q| = {norm:.6}, not within {UNIT_QUATERNION_TOLERANCE:e} of 1 (a unit quaternion [w, x, y, z])"
        ));
    }
    Ok(Pose {
        q: orientation.map(|v| v / norm),
        p_m: position_m,
    })
}

/// The farthest a point of the tool's capsule moves from `from` to `to` (m): the larger of
/// its two ends' travel (a point's displacement is affine along the axis, so its length is
/// largest at an end).
pub fn end_travel_m(tool: &ToolInfo, from: &Pose, to: &Pose) -> f64 {
    [tool.a_m, tool.b_m]
        .iter()
        .map(|&x| dist(from.apply(x), to.apply(x)))
        .fold(0.0, f64::max)
}

/// The point the tool turns about between poses: its trocar, or its capsule's midpoint.
pub fn pivot_m(tool: &ToolInfo) -> [f64; 3] {
    tool.trocar_m
        .unwrap_or_else(|| std::array::from_fn(|i| 0.5 * (tool.a_m[i] + tool.b_m[i])))
}

/// The pose a fraction `f` (0..=1) of the way from `from` to `to`: the pivot's image moved
/// linearly, the rotation by slerp (the shorter way round).
pub fn interpolate(pivot: [f64; 3], from: &Pose, to: &Pose, f: f64) -> Pose {
    let q = slerp(from.q, to.q, f);
    let (c0, c1) = (from.apply(pivot), to.apply(pivot));
    let c: [f64; 3] = std::array::from_fn(|i| c0[i] + f * (c1[i] - c0[i]));
    // p = c − R(q) pivot, so that the pivot maps to c.
    let turned = Pose { q, p_m: [0.0; 3] }.apply(pivot);
    Pose {
        q,
        p_m: std::array::from_fn(|i| c[i] - turned[i]),
    }
}

/// The next step's pose from `from` toward `to` with no capsule point moving more than
/// `bound_m`: `to` itself when it is within the bound (`true`: reached), else the farthest
/// pose along the interpolation that is.
pub fn step_toward(tool: &ToolInfo, from: &Pose, to: &Pose, bound_m: f64) -> (Pose, bool) {
    let travel = end_travel_m(tool, from, to);
    if travel <= bound_m || !(bound_m > 0.0) {
        return (*to, true);
    }
    let pivot = pivot_m(tool);
    let mut f = bound_m / travel;
    for _ in 0..32 {
        let next = interpolate(pivot, from, to, f);
        let t = end_travel_m(tool, from, &next);
        if t <= bound_m {
            return (next, false);
        }
        // The interpolated path bends (a rotation): shorten in proportion, with a margin.
        f *= 0.99 * bound_m / t;
    }
    (*from, false)
}

/// Spherical linear interpolation of unit quaternions, the shorter way; normalised.
fn slerp(a: [f64; 4], b: [f64; 4], f: f64) -> [f64; 4] {
    let mut dot: f64 = (0..4).map(|i| a[i] * b[i]).sum();
    let b = if dot < 0.0 {
        dot = -dot;
        b.map(|v| -v)
    } else {
        b
    };
    let (wa, wb) = if dot > 0.9995 {
        // Nearly equal: linear interpolation, normalised below, is exact enough.
        (1.0 - f, f)
    } else {
        let theta = dot.min(1.0).acos();
        let s = theta.sin();
        (((1.0 - f) * theta).sin() / s, (f * theta).sin() / s)
    };
    let q: [f64; 4] = std::array::from_fn(|i| wa * a[i] + wb * b[i]);
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    q.map(|v| v / n)
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3)
        .map(|i| (a[i] - b[i]) * (a[i] - b[i]))
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn probe(trocar: Option<[f64; 3]>) -> ToolInfo {
        ToolInfo {
            name: "probe".into(),
            a_m: [0.0, 0.0, 0.0],
            b_m: [0.0, 0.0, 0.1],
            radius_m: 0.002,
            trocar_m: trocar,
        }
    }

    #[test]
    fn a_wire_pose_is_checked_and_normalised() {
        let p = from_wire([0.0, 0.0, 0.01], [1.0005, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(p.q, [1.0, 0.0, 0.0, 0.0]);
        let e = from_wire([0.0; 3], [1.1, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(e.contains("|q| = 1.1"), "{e}");
        let e = from_wire([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(e.contains("position_m"), "{e}");
        let e = from_wire([0.0; 3], [f64::INFINITY, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(e.contains("orientation"), "{e}");
    }

    /// A 10 mm translation at 0.1 mm per step: exactly 100 steps of equal length, each
    /// within the bound (a translation's interpolation is linear: f = bound / travel).
    #[test]
    fn a_long_translation_is_cut_into_bounded_steps() {
        let tool = probe(None);
        let target = Pose::translation([0.01, 0.0, 0.0]);
        let mut now = Pose::IDENTITY;
        let mut steps = 0;
        loop {
            let (next, reached) = step_toward(&tool, &now, &target, 1e-4);
            let t = end_travel_m(&tool, &now, &next);
            assert!(t <= 1e-4 * (1.0 + 1e-12), "step {steps}: {t}");
            now = next;
            steps += 1;
            if reached {
                break;
            }
            assert!(steps < 200);
        }
        assert!((99..=101).contains(&steps), "{steps}");
        assert_eq!(now, target);
    }

    /// A pivot about the trocar (90° about x through the trocar at the top of the shaft):
    /// every intermediate pose keeps the trocar point fixed (to 1e-15 m) and every step is
    /// within the bound; the tip travels a quarter circle of radius 0.1 m (157 mm), so the
    /// steps number at least 157 / 2 mm.
    #[test]
    fn a_pivot_about_the_trocar_keeps_the_trocar_fixed() {
        let trocar = [0.0, 0.0, 0.1];
        let tool = probe(Some(trocar));
        let h = 0.5f64.sqrt();
        // Rotation about x through the trocar: p = trocar − R trocar.
        let q = [h, h, 0.0, 0.0];
        let rt = Pose { q, p_m: [0.0; 3] }.apply(trocar);
        let target = Pose {
            q,
            p_m: std::array::from_fn(|i| trocar[i] - rt[i]),
        };
        let mut now = Pose::IDENTITY;
        let mut steps = 0;
        loop {
            let (next, reached) = step_toward(&tool, &now, &target, 2e-3);
            assert!(end_travel_m(&tool, &now, &next) <= 2e-3);
            assert!(dist(next.apply(trocar), trocar) < 1e-15);
            now = next;
            steps += 1;
            if reached {
                break;
            }
        }
        assert!(steps >= 79, "{steps}");
        assert!(dist(now.apply(tool.a_m), target.apply(tool.a_m)) < 1e-15);
    }
}
