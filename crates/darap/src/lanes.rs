//! Lane arithmetic for the batched local step: `W` independent f64 values processed together, one
//! vertex per lane (structure of arrays).
//!
//! Every operation is the lane-wise IEEE operation (`+ − × ÷ √`, comparisons, selects) — no fused
//! multiply-add, no approximate reciprocal — so a lane computes bit for bit what the same scalar
//! expression computes, whatever the instruction set. The helpers are `#[inline(always)]` plain
//! array loops that the compiler vectorizes; [`dispatch`] runs a kernel with the widest SIMD
//! instruction set the CPU has (AVX2 where available, detected at run time, safely, by `pulp`).

/// Lanes per batch: two AVX2 registers of f64 (two independent dependency chains hide the latency
/// of the divisions and square roots).
pub(crate) const W: usize = 8;

/// `W` f64 lanes.
pub(crate) type F = [f64; W];
/// `W` lane conditions, each all ones (true) or all zeros (false) — the layout of a SIMD compare
/// result, so that [`select`] is a bitwise blend and no lane needs widening from a `bool`.
pub(crate) type Mask = [u64; W];

/// The all-false mask.
pub(crate) const FALSE: Mask = [0; W];

/// The mask word of one condition: all ones for `true`, zero for `false`.
#[inline(always)]
pub(crate) fn mask_bit(b: bool) -> u64 {
    (b as u64).wrapping_neg()
}

/// Whether lane `l` of `m` is set.
#[inline(always)]
pub(crate) fn lane(m: Mask, l: usize) -> bool {
    m[l] != 0
}
/// A 3-vector of lanes.
pub(crate) type V3 = [F; 3];
/// A row-major 3×3 matrix of lanes (`m[row][col]`).
pub(crate) type M3 = [[F; 3]; 3];

/// Runs `f` compiled for the best SIMD instruction set the CPU supports (the results do not
/// depend on which: every lane operation is exactly rounded).
#[inline(always)]
///
/// Pass a [`pulp::WithSimd`] kernel whose `with_simd` calls `inline(always)` code: a closure
/// body is compiled as its own function, for the baseline instruction set (SSE2 on x86-64), and
/// is not inlined into the dispatched one (measured: the local step ran on 128-bit registers only).
pub(crate) fn dispatch<Op: pulp::WithSimd>(op: Op) -> Op::Output {
    pulp::Arch::new().dispatch(op)
}

#[inline(always)]
pub(crate) fn splat(x: f64) -> F {
    [x; W]
}

#[inline(always)]
pub(crate) fn add(a: F, b: F) -> F {
    let mut r = a;
    for i in 0..W {
        r[i] = a[i] + b[i];
    }
    r
}

#[inline(always)]
pub(crate) fn sub(a: F, b: F) -> F {
    let mut r = a;
    for i in 0..W {
        r[i] = a[i] - b[i];
    }
    r
}

#[inline(always)]
pub(crate) fn mul(a: F, b: F) -> F {
    let mut r = a;
    for i in 0..W {
        r[i] = a[i] * b[i];
    }
    r
}

#[inline(always)]
pub(crate) fn div(a: F, b: F) -> F {
    let mut r = a;
    for i in 0..W {
        r[i] = a[i] / b[i];
    }
    r
}

#[inline(always)]
pub(crate) fn sqrt(a: F) -> F {
    let mut r = a;
    for i in 0..W {
        r[i] = a[i].sqrt();
    }
    r
}

#[inline(always)]
pub(crate) fn abs(a: F) -> F {
    let mut r = a;
    for i in 0..W {
        r[i] = a[i].abs();
    }
    r
}

#[inline(always)]
pub(crate) fn neg(a: F) -> F {
    let mut r = a;
    for i in 0..W {
        r[i] = -a[i];
    }
    r
}

#[inline(always)]
pub(crate) fn gt(a: F, b: F) -> Mask {
    let mut r = FALSE;
    for i in 0..W {
        r[i] = mask_bit(a[i] > b[i]);
    }
    r
}

#[inline(always)]
pub(crate) fn ge(a: F, b: F) -> Mask {
    let mut r = FALSE;
    for i in 0..W {
        r[i] = mask_bit(a[i] >= b[i]);
    }
    r
}

#[inline(always)]
pub(crate) fn le(a: F, b: F) -> Mask {
    let mut r = FALSE;
    for i in 0..W {
        r[i] = mask_bit(a[i] <= b[i]);
    }
    r
}

#[inline(always)]
pub(crate) fn lt(a: F, b: F) -> Mask {
    let mut r = FALSE;
    for i in 0..W {
        r[i] = mask_bit(a[i] < b[i]);
    }
    r
}

#[inline(always)]
pub(crate) fn eq(a: F, b: F) -> Mask {
    let mut r = FALSE;
    for i in 0..W {
        r[i] = mask_bit(a[i] == b[i]);
    }
    r
}

#[inline(always)]
pub(crate) fn is_nan(a: F) -> Mask {
    let mut r = FALSE;
    for i in 0..W {
        r[i] = mask_bit(a[i].is_nan());
    }
    r
}

#[inline(always)]
pub(crate) fn is_finite(a: F) -> Mask {
    let mut r = FALSE;
    for i in 0..W {
        r[i] = mask_bit(a[i].is_finite());
    }
    r
}

#[inline(always)]
pub(crate) fn and(a: Mask, b: Mask) -> Mask {
    let mut r = a;
    for i in 0..W {
        r[i] = a[i] & b[i];
    }
    r
}

#[inline(always)]
pub(crate) fn or(a: Mask, b: Mask) -> Mask {
    let mut r = a;
    for i in 0..W {
        r[i] = a[i] | b[i];
    }
    r
}

#[inline(always)]
pub(crate) fn not(a: Mask) -> Mask {
    let mut r = a;
    for i in 0..W {
        r[i] = !a[i];
    }
    r
}

#[inline(always)]
pub(crate) fn all(a: Mask) -> bool {
    a.iter().fold(u64::MAX, |acc, &x| acc & x) != 0
}

#[inline(always)]
pub(crate) fn any(a: Mask) -> bool {
    a.iter().fold(0, |acc, &x| acc | x) != 0
}

/// `m ? a : b`, lane-wise.
#[inline(always)]
pub(crate) fn select(m: Mask, a: F, b: F) -> F {
    let mut r = b;
    for i in 0..W {
        r[i] = f64::from_bits((a[i].to_bits() & m[i]) | (b[i].to_bits() & !m[i]));
    }
    r
}

#[inline(always)]
pub(crate) fn select3(m: Mask, a: V3, b: V3) -> V3 {
    [
        select(m, a[0], b[0]),
        select(m, a[1], b[1]),
        select(m, a[2], b[2]),
    ]
}

/// `a·b`, evaluated as `(a0 b0 + a1 b1) + a2 b2` like `mat3::dot`.
#[inline(always)]
pub(crate) fn dot(a: V3, b: V3) -> F {
    add(add(mul(a[0], b[0]), mul(a[1], b[1])), mul(a[2], b[2]))
}

/// `a × b`, evaluated like `mat3::cross`.
#[inline(always)]
pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [
        sub(mul(a[1], b[2]), mul(a[2], b[1])),
        sub(mul(a[2], b[0]), mul(a[0], b[2])),
        sub(mul(a[0], b[1]), mul(a[1], b[0])),
    ]
}

/// Column `j` of a lane matrix.
#[inline(always)]
pub(crate) fn col(m: &M3, j: usize) -> V3 {
    [m[0][j], m[1][j], m[2][j]]
}

/// `a·b` for lane matrices, evaluated like `mat3::mul`.
#[inline(always)]
pub(crate) fn matmul(a: &M3, b: &M3) -> M3 {
    let mut c = [[[0.0; W]; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = add(
                add(mul(a[i][0], b[0][j]), mul(a[i][1], b[1][j])),
                mul(a[i][2], b[2][j]),
            );
        }
    }
    c
}

/// `aᵀ`.
#[inline(always)]
pub(crate) fn transpose(a: &M3) -> M3 {
    let mut t = *a;
    for i in 0..3 {
        for j in 0..3 {
            t[i][j] = a[j][i];
        }
    }
    t
}

/// `det(m)`, evaluated like `mat3::det`.
#[inline(always)]
pub(crate) fn det(m: &M3) -> F {
    add(
        sub(
            mul(m[0][0], sub(mul(m[1][1], m[2][2]), mul(m[1][2], m[2][1]))),
            mul(m[0][1], sub(mul(m[1][0], m[2][2]), mul(m[1][2], m[2][0]))),
        ),
        mul(m[0][2], sub(mul(m[1][0], m[2][1]), mul(m[1][1], m[2][0]))),
    )
}

/// The lane-wise identity matrix.
#[inline(always)]
pub(crate) fn identity() -> M3 {
    let mut m = [[[0.0; W]; 3]; 3];
    for i in 0..3 {
        m[i][i] = splat(1.0);
    }
    m
}
