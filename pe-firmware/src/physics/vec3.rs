//! 3-vectors as plain arrays, generic over [`Real`]: the one home of the small vector
//! helpers (the element geometry, the contact kernels, and the host's mesh tools through
//! `pe_firmware::physics::vec3`). Each is written out component by component, so a value
//! is the same bits wherever it is computed.

use super::real::Real;

/// A point or vector in 3D.
pub type Vec3<T> = [T; 3];

/// `a + b`.
#[inline(always)]
pub fn add<T: Real>(a: Vec3<T>, b: Vec3<T>) -> Vec3<T> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `a − b`.
#[inline(always)]
pub fn sub<T: Real>(a: Vec3<T>, b: Vec3<T>) -> Vec3<T> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `s a`.
#[inline(always)]
pub fn scale<T: Real>(a: Vec3<T>, s: T) -> Vec3<T> {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a · b`.
#[inline(always)]
pub fn dot<T: Real>(a: Vec3<T>, b: Vec3<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a × b`.
#[inline(always)]
pub fn cross<T: Real>(a: Vec3<T>, b: Vec3<T>) -> Vec3<T> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Euclidean length `√(a · a)` (the scalar's correctly rounded square root).
#[inline(always)]
pub fn norm<T: Real>(a: Vec3<T>) -> T {
    dot(a, a).sqrt()
}
