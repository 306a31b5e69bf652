//! Small dense 3x3 tensors as plain arrays (`m[row][col]`), generic over [`Real`].

use super::real::{array, Real};

pub type Mat3<T> = [[T; 3]; 3];

#[inline(always)]
pub fn identity<T: Real>() -> Mat3<T> {
    let (o, z) = (T::ONE, T::ZERO);
    [[o, z, z], [z, o, z], [z, z, o]]
}

/// `a * b`.
#[inline(always)]
pub fn mul<T: Real>(a: &Mat3<T>, b: &Mat3<T>) -> Mat3<T> {
    array(
        #[inline(always)]
        |i| {
            array(
                #[inline(always)]
                |j| a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j],
            )
        },
    )
}

/// `aᵀ * a` (symmetric): the right Cauchy-Green tensor `C = Fᵀ F` when `a = F`.
#[inline(always)]
pub fn gram<T: Real>(a: &Mat3<T>) -> Mat3<T> {
    let mut c = [[T::ZERO; 3]; 3];
    for i in 0..3 {
        for j in i..3 {
            let v = a[0][i] * a[0][j] + a[1][i] * a[1][j] + a[2][i] * a[2][j];
            c[i][j] = v;
            c[j][i] = v;
        }
    }
    c
}

#[inline(always)]
pub fn transpose<T: Real>(a: &Mat3<T>) -> Mat3<T> {
    array(
        #[inline(always)]
        |i| {
            array(
                #[inline(always)]
                |j| a[j][i],
            )
        },
    )
}

#[inline(always)]
pub fn det<T: Real>(a: &Mat3<T>) -> T {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// Cofactor matrix `cof A = det(A) A⁻ᵀ` (`cof_ij` = signed minor of `a_ij`).
#[inline(always)]
pub fn cofactor<T: Real>(a: &Mat3<T>) -> Mat3<T> {
    [
        [
            a[1][1] * a[2][2] - a[1][2] * a[2][1],
            a[1][2] * a[2][0] - a[1][0] * a[2][2],
            a[1][0] * a[2][1] - a[1][1] * a[2][0],
        ],
        [
            a[0][2] * a[2][1] - a[0][1] * a[2][2],
            a[0][0] * a[2][2] - a[0][2] * a[2][0],
            a[0][1] * a[2][0] - a[0][0] * a[2][1],
        ],
        [
            a[0][1] * a[1][2] - a[0][2] * a[1][1],
            a[0][2] * a[1][0] - a[0][0] * a[1][2],
            a[0][0] * a[1][1] - a[0][1] * a[1][0],
        ],
    ]
}

/// Inverse of a symmetric matrix `c` given its determinant (caller checks `det > 0`).
#[inline(always)]
pub fn inverse_symmetric<T: Real>(c: &Mat3<T>, det: T) -> Mat3<T> {
    let r = T::ONE / det;
    let i00 = (c[1][1] * c[2][2] - c[1][2] * c[1][2]) * r;
    let i01 = (c[0][2] * c[1][2] - c[0][1] * c[2][2]) * r;
    let i02 = (c[0][1] * c[1][2] - c[0][2] * c[1][1]) * r;
    let i11 = (c[0][0] * c[2][2] - c[0][2] * c[0][2]) * r;
    let i12 = (c[0][1] * c[0][2] - c[0][0] * c[1][2]) * r;
    let i22 = (c[0][0] * c[1][1] - c[0][1] * c[0][1]) * r;
    [[i00, i01, i02], [i01, i11, i12], [i02, i12, i22]]
}

/// General inverse given the determinant (caller checks it is not zero).
pub fn inverse<T: Real>(a: &Mat3<T>, det: T) -> Mat3<T> {
    let r = T::ONE / det;
    [
        [
            (a[1][1] * a[2][2] - a[1][2] * a[2][1]) * r,
            (a[0][2] * a[2][1] - a[0][1] * a[2][2]) * r,
            (a[0][1] * a[1][2] - a[0][2] * a[1][1]) * r,
        ],
        [
            (a[1][2] * a[2][0] - a[1][0] * a[2][2]) * r,
            (a[0][0] * a[2][2] - a[0][2] * a[2][0]) * r,
            (a[0][2] * a[1][0] - a[0][0] * a[1][2]) * r,
        ],
        [
            (a[1][0] * a[2][1] - a[1][1] * a[2][0]) * r,
            (a[0][1] * a[2][0] - a[0][0] * a[2][1]) * r,
            (a[0][0] * a[1][1] - a[0][1] * a[1][0]) * r,
        ],
    ]
}

#[inline(always)]
pub fn trace<T: Real>(a: &Mat3<T>) -> T {
    a[0][0] + a[1][1] + a[2][2]
}

/// Double contraction `a : b`.
#[inline(always)]
pub fn ddot<T: Real>(a: &Mat3<T>, b: &Mat3<T>) -> T {
    let mut s = T::ZERO;
    for i in 0..3 {
        for j in 0..3 {
            s += a[i][j] * b[i][j];
        }
    }
    s
}
