//! Small dense 3×3 helpers. `Mat3` is row-major: `m[i][j]` is row `i`, column `j`; vectors are
//! columns (a rotation acts as `R·x`). Crate-internal; the public type is [`crate::Mat3`].

/// A 3×3 matrix, row-major (`m[row][col]`).
pub type Mat3 = [[f64; 3]; 3];

/// The identity.
pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The zero matrix.
pub const ZERO: Mat3 = [[0.0; 3]; 3];

/// `a·b`.
#[inline]
pub fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut c = ZERO;
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    c
}

/// `aᵀ`.
#[inline]
pub fn transpose(a: &Mat3) -> Mat3 {
    [
        [a[0][0], a[1][0], a[2][0]],
        [a[0][1], a[1][1], a[2][1]],
        [a[0][2], a[1][2], a[2][2]],
    ]
}

/// `aᵀ·b`.
#[inline]
pub fn mul_tn(a: &Mat3, b: &Mat3) -> Mat3 {
    mul(&transpose(a), b)
}

/// `a·bᵀ`.
#[inline]
pub fn mul_nt(a: &Mat3, b: &Mat3) -> Mat3 {
    mul(a, &transpose(b))
}

/// `mᵀ·x`.
#[inline]
pub fn mul_tvec(m: &Mat3, x: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * x[0] + m[1][0] * x[1] + m[2][0] * x[2],
        m[0][1] * x[0] + m[1][1] * x[1] + m[2][1] * x[2],
        m[0][2] * x[0] + m[1][2] * x[1] + m[2][2] * x[2],
    ]
}

/// Outer product `a·bᵀ`.
#[inline]
pub fn outer(a: [f64; 3], b: [f64; 3]) -> Mat3 {
    [
        [a[0] * b[0], a[0] * b[1], a[0] * b[2]],
        [a[1] * b[0], a[1] * b[1], a[1] * b[2]],
        [a[2] * b[0], a[2] * b[1], a[2] * b[2]],
    ]
}

/// Determinant.
#[inline]
pub fn det(m: &Mat3) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

#[inline]
pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
