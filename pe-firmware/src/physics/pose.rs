//! A tool's pose: the rigid motion `x' = R(q) x + p` applied to the tool as the scene
//! places it, with `R(q)` the rotation of the unit quaternion `q = (w, x, y, z)`:
//!
//! ```text
//!        | 1 − 2(y² + z²)   2(xy − wz)       2(xz + wy)     |
//! R(q) = | 2(xy + wz)       1 − 2(x² + z²)   2(yz − wx)     |
//!        | 2(xz − wy)       2(yz + wx)       1 − 2(x² + y²) |
//! ```
//!
//! The identity pose (`q = (1, 0, 0, 0)`, `p = 0`) leaves the tool where the scene placed
//! it; a scripted path's displacement `d(t)` is the pose `(identity, d(t))`. The host and
//! the boards compute `R(q)` and the moved capsule with these functions only, so they get
//! the same bits. A pure translation takes [`Capsule::translated`]'s operations exactly (a
//! scripted run's bits do not depend on whether its displacement came as a pose).

use serde::{Deserialize, Serialize};

use super::contact::{Capsule, V3};

/// A rigid motion: unit quaternion `q = [w, x, y, z]` and translation `p_m` (m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub q: [f64; 4],
    pub p_m: V3,
}

impl Default for Pose {
    fn default() -> Self {
        Pose::IDENTITY
    }
}

impl Pose {
    /// The scene's placement.
    pub const IDENTITY: Pose = Pose {
        q: [1.0, 0.0, 0.0, 0.0],
        p_m: [0.0; 3],
    };

    /// A translation by `d` (m).
    pub const fn translation(d: V3) -> Pose {
        Pose {
            q: [1.0, 0.0, 0.0, 0.0],
            p_m: d,
        }
    }

    /// Whether the rotation is exactly the identity (`q = (1, 0, 0, 0)`, bit for bit).
    pub fn is_translation(&self) -> bool {
        self.q == [1.0, 0.0, 0.0, 0.0]
    }

    /// `R(q)` (the module doc's matrix), row-major. `q` is taken as given (unit length is
    /// the caller's: the host checks and normalises a pose before it is applied or sent).
    pub fn rotation(&self) -> [[f64; 3]; 3] {
        let [w, x, y, z] = self.q;
        let (xx, yy, zz) = (x * x, y * y, z * z);
        let (xy, xz, yz) = (x * y, x * z, y * z);
        let (wx, wy, wz) = (w * x, w * y, w * z);
        [
            [1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)],
            [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)],
            [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)],
        ]
    }

    /// `R x + p`, for a rotation `r` of this pose ([`Pose::rotation`]).
    pub fn apply_with(&self, r: &[[f64; 3]; 3], x: V3) -> V3 {
        core::array::from_fn(|i| r[i][0] * x[0] + r[i][1] * x[1] + r[i][2] * x[2] + self.p_m[i])
    }

    /// `R x + p`.
    pub fn apply(&self, x: V3) -> V3 {
        self.apply_with(&self.rotation(), x)
    }
}

impl Capsule {
    /// The capsule moved by `pose`: both axis ends moved rigidly, the radius kept. A pure
    /// translation is [`Capsule::translated`] exactly.
    pub fn posed(&self, pose: &Pose) -> Capsule {
        if pose.is_translation() {
            return self.translated(pose.p_m);
        }
        let r = pose.rotation();
        Capsule {
            a: pose.apply_with(&r, self.a),
            b: pose.apply_with(&r, self.b),
            radius_m: self.radius_m,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dist(a: V3, b: V3) -> f64 {
        libm::sqrt((0..3).map(|i| (a[i] - b[i]) * (a[i] - b[i])).sum())
    }

    #[test]
    fn a_quarter_turn_about_z_maps_x_to_y() {
        // q = (cos 45°, 0, 0, sin 45°): +90° about z.
        let h = libm::sqrt(0.5);
        let pose = Pose {
            q: [h, 0.0, 0.0, h],
            p_m: [0.0, 0.0, 1.0],
        };
        let x = pose.apply([1.0, 0.0, 0.0]);
        for (got, want) in x.iter().zip([0.0, 1.0, 1.0]) {
            assert!((got - want).abs() < 1e-15, "{x:?}");
        }
    }

    #[test]
    fn a_rotation_keeps_the_capsule_length_and_orthonormal_rows() {
        // A unit quaternion far from any axis: |q| = 1 to round-off.
        let q = [0.5, -0.5, 0.5, 0.5];
        let pose = Pose {
            q,
            p_m: [0.01, -0.02, 0.03],
        };
        let r = pose.rotation();
        for i in 0..3 {
            for j in 0..3 {
                let d: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((d - want).abs() < 1e-15, "R R^T [{i}][{j}] = {d}");
            }
        }
        let c = Capsule {
            a: [0.1, 0.2, 0.3],
            b: [0.15, 0.25, 0.1],
            radius_m: 0.0025,
        };
        let m = c.posed(&pose);
        assert!((dist(m.a, m.b) - dist(c.a, c.b)).abs() < 1e-15);
        assert!(dist(m.a, c.a) > 0.05, "the rotation moved it: {m:?}");
        assert_eq!(m.radius_m, c.radius_m);
    }

    #[test]
    fn a_translation_pose_is_translated_bit_for_bit() {
        let c = Capsule {
            a: [0.1, -0.0, 0.3],
            b: [0.15, 0.25, 1e-9],
            radius_m: 0.0025,
        };
        let d = [1e-3, -2.5e-3, 7e-5];
        let t = c.translated(d);
        assert_ne!(t.a, c.a);
        assert_eq!(c.posed(&Pose::translation(d)), t);
    }
}
