//! The tool kernel: a rigid capsule against the nodes of a tissue surface.

use serde::{Deserialize, Serialize};

use super::super::explicit::PhysicsError;
use super::super::vec3::{cross, dot, scale, sub};
use super::{bad, ContactModel, ContactStats, V3};

/// A rigid capsule: every point within `radius_m` of the segment `a–b` (m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Capsule {
    pub a: V3,
    pub b: V3,
    pub radius_m: f64,
}

impl Capsule {
    /// The capsule moved by `d`.
    pub fn translated(&self, d: V3) -> Capsule {
        Capsule {
            a: [self.a[0] + d[0], self.a[1] + d[1], self.a[2] + d[2]],
            b: [self.b[0] + d[0], self.b[1] + d[1], self.b[2] + d[2]],
            radius_m: self.radius_m,
        }
    }

    /// The point of the axis segment closest to `x`: `a + t (b − a)`, `t` clamped to [0, 1].
    pub fn closest_axis_point(&self, x: V3) -> V3 {
        let ab = sub(self.b, self.a);
        let l2 = dot(ab, ab);
        let t = if l2 > 0.0 {
            (dot(sub(x, self.a), ab) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        [
            self.a[0] + t * ab[0],
            self.a[1] + t * ab[1],
            self.a[2] + t * ab[2],
        ]
    }

    /// Depth `p = r − |x − c| > 0` of a point inside the capsule and the outward unit
    /// normal; `None` outside (or on the surface). A point exactly on the axis is pushed
    /// out perpendicular to the axis, along the coordinate direction the axis leans on least.
    pub fn penetration(&self, x: V3) -> Option<(f64, V3)> {
        let c = self.closest_axis_point(x);
        let d = sub(x, c);
        let dist = libm::sqrt(dot(d, d));
        let depth = self.radius_m - dist;
        if !(depth > 0.0) {
            return None;
        }
        let n = if dist > 1e-300 {
            scale(d, 1.0 / dist)
        } else {
            let ab = sub(self.b, self.a);
            let k = (0..3)
                .min_by(|&i, &j| libm::fabs(ab[i]).total_cmp(&libm::fabs(ab[j])))
                .unwrap_or(0);
            let mut e = [0.0; 3];
            e[k] = 1.0;
            let p = cross(ab, e);
            let l = libm::sqrt(dot(p, p));
            if l > 0.0 {
                scale(p, 1.0 / l)
            } else {
                [0.0, 0.0, 1.0]
            }
        };
        Some((depth, n))
    }

    /// Axis-aligned bounding box.
    pub fn bounds(&self) -> [V3; 2] {
        let r = self.radius_m;
        [
            core::array::from_fn(|i| self.a[i].min(self.b[i]) - r),
            core::array::from_fn(|i| self.a[i].max(self.b[i]) + r),
        ]
    }
}

#[allow(clippy::too_many_arguments)]
/// Tool forces: every node of tool `t`'s surface with `apply(c)` (ascending) inside the
/// tool's capsule at its current place `capsules[t]` gets `k p n`; `tool_force[t]` takes
/// the sum of `−k p n` (the force of the tissue on the tool).
pub(super) fn evaluate_tools(
    m: &ContactModel<'_>,
    capsules: &[Capsule],
    pos: impl Fn(usize) -> Option<V3>,
    apply: impl Fn(usize) -> bool,
    tolerance_m: f64,
    force: &mut [V3],
    tool_force: &mut [V3],
    stats: &mut ContactStats,
) -> Result<(), PhysicsError> {
    for (t, tool) in m.tools.iter().enumerate() {
        let cap = capsules.get(t).ok_or(bad(t))?;
        let b = cap.bounds();
        for (c, node) in m.nodes.iter().enumerate() {
            if node.surfaces & (1 << tool.surface) == 0 || !apply(c) {
                continue;
            }
            let Some(x) = pos(c) else { continue };
            if (0..3).any(|i| x[i] < b[0][i] || x[i] > b[1][i]) {
                continue;
            }
            if let Some((depth, n)) = cap.penetration(x) {
                if depth > tolerance_m {
                    return Err(PhysicsError::Penetration {
                        node: node.global,
                        depth_m: depth,
                        tolerance_m,
                    });
                }
                let f = scale(n, node.penalty_n_per_m * depth);
                let dst = force.get_mut(c).ok_or(bad(c))?;
                let tf = tool_force.get_mut(t).ok_or(bad(t))?;
                for k in 0..3 {
                    dst[k] += f[k];
                    tf[k] -= f[k];
                }
                stats.active += 1;
                stats.max_depth_m = stats.max_depth_m.max(depth);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn capsule_depth_and_normal_match_the_geometry() {
        let c = Capsule {
            a: [0.0, 0.0, 0.0],
            b: [0.0, 0.0, 1.0],
            radius_m: 0.1,
        };
        // 0.04 from the axis beside the segment: depth 0.06, normal +x.
        let (d, n) = c.penetration([0.04, 0.0, 0.5]).expect("inside");
        assert!((d - 0.06).abs() < 1e-15 && (n[0] - 1.0).abs() < 1e-15);
        // Beyond the end cap: distance to the end point.
        let (d, n) = c.penetration([0.0, 0.0, 1.05]).expect("inside the cap");
        assert!((d - 0.05).abs() < 1e-15 && (n[2] - 1.0).abs() < 1e-15);
        assert!(c.penetration([0.2, 0.0, 0.5]).is_none());
        // On the axis: pushed out perpendicular to it.
        let (_, n) = c.penetration([0.0, 0.0, 0.5]).expect("on the axis");
        assert!(n[2].abs() < 1e-15 && (dot(n, n) - 1.0).abs() < 1e-15);
    }
}
