//! TRANSFORM: the upper three rows of a 4×4 homogeneous matrix as 12 big-endian f32, the
//! rotation's columns then the translation in millimetres (OpenIGTLink
//! `Documents/Protocol/transform.md`; pyigtl `TransformMessage._pack_content`, which writes
//! `matrix[0,0], matrix[1,0], matrix[2,0], matrix[0,1], …, matrix[0,3], matrix[1,3],
//! matrix[2,3]`):
//!
//! | offset | field                     |
//! |--------|---------------------------|
//! | 0      | R11 R21 R31 (column 1)    |
//! | 12     | R12 R22 R32 (column 2)    |
//! | 24     | R13 R23 R33 (column 3)    |
//! | 36     | TX TY TZ (mm)             |
//!
//! A tool's TRANSFORM is its pose: the rigid motion `x' = R x + t` from where the scene
//! places it ([`Pose`]), so the identity leaves the tool there. [`TransformRepr::pose`]
//! refuses a non-finite or non-rigid matrix (`|RᵀR − I|` over 1e-3 in any entry, or a
//! reflection) and turns the rotation into a unit quaternion.
//!
//! # Panics
//! [`Transform::new_checked`], [`TransformRepr::parse`], [`TransformRepr::emit`] and
//! [`TransformRepr::pose`] never panic. The accessors of a [`Transform`] made with
//! [`Transform::new_unchecked`] panic on fewer than [`TRANSFORM_LEN`] bytes.

use super::error::{Error, Result};
use crate::live::engine::Pose;

/// Bytes of a TRANSFORM content.
pub const TRANSFORM_LEN: usize = 48;
/// Largest `|RᵀR − I|` entry of a rotation taken as rigid.
pub const RIGID_TOLERANCE: f64 = 1e-3;
/// Millimetres per metre (the wire's unit against the session's).
pub const MM_PER_M: f64 = 1000.0;

/// A zero-copy view of a TRANSFORM content.
#[derive(Debug, Clone)]
pub struct Transform<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Transform<T> {
    pub const fn new_unchecked(buffer: T) -> Transform<T> {
        Transform { buffer }
    }

    /// A view of exactly [`TRANSFORM_LEN`] bytes.
    pub fn new_checked(buffer: T) -> Result<Transform<T>> {
        let len = buffer.as_ref().len();
        if len != TRANSFORM_LEN {
            return Err(Error::BadLength {
                what: "TRANSFORM content",
                len,
                expected: "48 (12 float32)",
            });
        }
        Ok(Transform { buffer })
    }

    /// The `i`-th of the 12 values in wire order.
    pub fn value(&self, i: usize) -> f32 {
        let b = &self.buffer.as_ref()[4 * i..4 * i + 4];
        f32::from_be_bytes([b[0], b[1], b[2], b[3]])
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Transform<T> {
    pub fn set_value(&mut self, i: usize, v: f32) {
        self.buffer.as_mut()[4 * i..4 * i + 4].copy_from_slice(&v.to_be_bytes());
    }
}

/// A TRANSFORM's matrix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransformRepr {
    /// The rotation (or any linear part), row-major: `r[i][j]` = R(i+1, j+1).
    pub r: [[f32; 3]; 3],
    /// The translation (mm).
    pub t_mm: [f32; 3],
}

impl TransformRepr {
    pub fn parse<T: AsRef<[u8]>>(v: &Transform<T>) -> TransformRepr {
        TransformRepr {
            r: core::array::from_fn(|i| core::array::from_fn(|j| v.value(3 * j + i))),
            t_mm: core::array::from_fn(|i| v.value(9 + i)),
        }
    }

    pub fn parse_bytes(content: &[u8]) -> Result<TransformRepr> {
        Ok(Self::parse(&Transform::new_checked(content)?))
    }

    pub fn buffer_len(&self) -> usize {
        TRANSFORM_LEN
    }

    pub fn emit(&self, buf: &mut [u8]) -> Result<()> {
        let mut v = Transform::new_checked(buf)?;
        for j in 0..3 {
            for i in 0..3 {
                v.set_value(3 * j + i, self.r[i][j]);
            }
        }
        for i in 0..3 {
            v.set_value(9 + i, self.t_mm[i]);
        }
        Ok(())
    }

    /// The matrix of `pose` (m → mm, f64 → f32).
    pub fn of_pose(pose: &Pose) -> TransformRepr {
        let r = pose.rotation();
        TransformRepr {
            r: r.map(|row| row.map(|x| x as f32)),
            t_mm: pose.p_m.map(|x| (x * MM_PER_M) as f32),
        }
    }

    /// The pose this matrix describes (mm → m): refused if a value is not finite or the
    /// rotation is not rigid within [`RIGID_TOLERANCE`].
    pub fn pose(&self) -> Result<Pose> {
        let values: Vec<f32> = self.r.iter().flatten().chain(&self.t_mm).copied().collect();
        if values.iter().any(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "TRANSFORM",
                values,
            });
        }
        let r = self.r.map(|row| row.map(f64::from));
        let deviation = gram_deviation(&r);
        let det = det3(&r);
        if deviation > RIGID_TOLERANCE || det <= 0.0 {
            return Err(Error::NotRigid {
                deviation,
                det,
                tolerance: RIGID_TOLERANCE,
            });
        }
        Ok(Pose {
            q: quaternion_of(&r),
            p_m: self.t_mm.map(|x| f64::from(x) / MM_PER_M),
        })
    }
}

/// `max |RᵀR − I|` over the entries.
fn gram_deviation(r: &[[f64; 3]; 3]) -> f64 {
    let mut worst = 0.0f64;
    for i in 0..3 {
        for j in 0..3 {
            let d: f64 = (0..3).map(|k| r[k][i] * r[k][j]).sum();
            let want = if i == j { 1.0 } else { 0.0 };
            worst = worst.max((d - want).abs());
        }
    }
    worst
}

fn det3(r: &[[f64; 3]; 3]) -> f64 {
    r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
        - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
        + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0])
}

/// The unit quaternion `(w, x, y, z)`, `w ≥ 0`, of a rotation matrix (row-major), by
/// Shepperd's method: from the largest of `4w², 4x², 4y², 4z²` (the trace or a diagonal
/// entry), the others from the off-diagonal sums and differences of
/// [`Pose::rotation`]'s matrix (e.g. `R32 − R23 = 4wx`). Normalised, so a matrix rigid
/// within [`RIGID_TOLERANCE`] gives a unit quaternion to round-off.
pub fn quaternion_of(r: &[[f64; 3]; 3]) -> [f64; 4] {
    let trace = r[0][0] + r[1][1] + r[2][2];
    let q = if trace > 0.0 {
        let s = 2.0 * (1.0 + trace).sqrt(); // 4w
        [
            s / 4.0,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = 2.0 * (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt(); // 4x
        [
            (r[2][1] - r[1][2]) / s,
            s / 4.0,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] > r[2][2] {
        let s = 2.0 * (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt(); // 4y
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            s / 4.0,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = 2.0 * (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt(); // 4z
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            s / 4.0,
        ]
    };
    let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
    q.map(|c| sign * c / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(q: [f64; 4], p_m: [f64; 3]) -> Pose {
        let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        Pose {
            q: q.map(|c| c / n),
            p_m,
        }
    }

    #[test]
    fn the_wire_order_is_columns_then_translation() {
        // R = +90° about z: columns (0,1,0), (−1,0,0), (0,0,1); t = (10, 20, 30) mm.
        let mut b = [0u8; TRANSFORM_LEN];
        let want = [
            0.0f32, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 10.0, 20.0, 30.0,
        ];
        for (k, v) in want.iter().enumerate() {
            b[4 * k..4 * k + 4].copy_from_slice(&v.to_be_bytes());
        }
        let t = TransformRepr::parse_bytes(&b).unwrap();
        assert_eq!(t.r, [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]);
        assert_eq!(t.t_mm, [10.0, 20.0, 30.0]);
        let p = t.pose().unwrap();
        let h = 0.5f64.sqrt();
        for (got, want) in p.q.iter().zip([h, 0.0, 0.0, h]) {
            assert!((got - want).abs() < 1e-7, "{:?}", p.q);
        }
        assert_eq!(p.p_m, [0.01, 0.02, 0.03]);
        // And back to the same bytes.
        let mut out = [0u8; TRANSFORM_LEN];
        t.emit(&mut out).unwrap();
        assert_eq!(out, b);
    }

    #[test]
    fn poses_round_trip_through_the_matrix_in_every_branch_of_shepperd() {
        // One rotation per branch: trace > 0, and x, y, z largest (half turns about
        // tilted axes), plus a general one.
        let cases = [
            [0.9, 0.1, -0.3, 0.2],
            [0.05, 0.9, 0.3, -0.2],
            [0.05, 0.2, -0.9, 0.3],
            [0.02, -0.3, 0.2, 0.95],
            [0.5, -0.5, 0.5, 0.5],
        ];
        for q in cases {
            let want = pose(q, [0.012, -0.034, 0.056]);
            let got = TransformRepr::of_pose(&want).pose().unwrap();
            let n: f64 = got.q.iter().map(|c| c * c).sum();
            assert!((n - 1.0).abs() < 1e-12, "|q|² = {n}");
            // Same rotation: q or −q; compare with the sign that makes w ≥ 0.
            let s = if want.q[0] < 0.0 { -1.0 } else { 1.0 };
            for (g, w) in got.q.iter().zip(want.q) {
                assert!(
                    (g - s * w).abs() < 1e-6,
                    "{q:?}: {:?} vs {:?}",
                    got.q,
                    want.q
                );
            }
            for (g, w) in got.p_m.iter().zip(want.p_m) {
                assert!((g - w).abs() < 1e-9, "{:?}", got.p_m);
            }
        }
    }

    #[test]
    fn non_finite_and_non_rigid_matrices_are_refused() {
        let mut t = TransformRepr::of_pose(&Pose::IDENTITY);
        t.t_mm[1] = f32::NAN;
        let e = t.pose().unwrap_err();
        assert!(e.to_string().contains("non-finite"), "{e}");

        let mut scaled = TransformRepr::of_pose(&Pose::IDENTITY);
        scaled.r[0][0] = 1.01; // a 1% stretch: RᵀR − I = 0.0201
        let e = scaled.pose().unwrap_err();
        assert!(
            matches!(e, Error::NotRigid { deviation, .. } if (deviation - 0.0201).abs() < 1e-6),
            "{e}"
        );

        let mut mirror = TransformRepr::of_pose(&Pose::IDENTITY);
        mirror.r[2][2] = -1.0; // orthonormal, det −1
        let e = mirror.pose().unwrap_err();
        assert!(matches!(e, Error::NotRigid { det, .. } if det < 0.0), "{e}");
        assert!(e.to_string().contains("det R = -1"), "{e}");

        // Within the tolerance: taken, and the quaternion is unit.
        let mut near = TransformRepr::of_pose(&Pose::IDENTITY);
        near.r[0][1] = 4e-4;
        let p = near.pose().unwrap();
        assert!((p.q.iter().map(|c| c * c).sum::<f64>() - 1.0).abs() < 1e-12);

        let e = TransformRepr::parse_bytes(&[0u8; 47]).unwrap_err();
        assert!(matches!(e, Error::BadLength { len: 47, .. }));
    }
}
