//! Robust orientation predicates: the sign of a 2×2 or 3×3 determinant of point differences,
//! exact for every finite `f64` input.
//!
//! - [`orient3d`]`(a, b, c, d)` is the sign of `det[b − a, c − a, d − a] = ((b − a) × (c − a))·(d − a)`:
//!   positive when `d` lies on the side the right-hand normal of the triangle `(a, b, c)` points
//!   to, zero when the four points are coplanar.
//! - [`orient2d`]`(a, b, c)` is the sign of `(b − a) × (c − a)` in the plane: positive when
//!   `(a, b, c)` turn counter-clockwise, zero when collinear. [`orient2d_projected`] evaluates it on
//!   the coordinate plane that drops one axis (the projection the coplanar triangle tests use).
//!
//! Each predicate is a **filtered fast path with an exact fallback**. The fast path evaluates the
//! determinant in `f64` and accepts its sign when `|det|` exceeds Shewchuk's static forward error
//! bound (`(3 + 16ε)ε·permanent` for the 2×2, `(7 + 56ε)ε·permanent` for the 3×3, `ε = 2⁻⁵³`, the
//! permanent being the same expression with every term made non-negative). The bound assumes that
//! no operation underflows or overflows, so the fast path is taken only when every non-zero
//! coordinate difference lies in `[2⁻³³⁰, 2³³⁰]` (3×3) or `[2⁻⁵⁰⁰, 2⁵⁰⁰]` (2×2); with those limits
//! no product overflows and an underflow can only happen in the last multiplication of a 3×3 term,
//! where it adds at most `2⁻¹⁰⁷⁵` per term (covered by an absolute slack of `2⁻¹⁰⁷⁰`). A zero
//! permanent means every term has an exactly zero factor, so the determinant is exactly zero.
//!
//! Otherwise, when the coordinate differences are exact in `f64` (as they are for nearby points)
//! and within `[2⁻²⁵⁰, 2²⁵⁰]` (or 0), an **expansion stage** decides without allocating:
//! [`orient3d_expansion`] splits each of the determinant's six products of three differences
//! exactly into four `f64`s (Dekker's `two_product`) and takes the sign of the exact sum of those
//! 24 terms (Shewchuk's nonoverlapping expansions); [`orient2d_expansion`] likewise.
//!
//! Otherwise — near-degenerate input with inexact differences, or coordinates outside those
//! ranges — the determinant is evaluated **exactly**: every finite `f64` is `m·2ᵉ` with an integer `m < 2⁵³` and
//! `−1074 ≤ e ≤ 971`, so all inputs of one call are integers after scaling by `2^(−e_min)`
//! (`e_min` the smallest exponent of a lowest set bit among them). The differences, products and
//! sums are then computed in arbitrary-precision integers (at most about 6,300 bits for the 3×3,
//! so the fallback's time and memory are bounded). There is no dependency: the integer
//! arithmetic is [`BigInt`]'s, a few schoolbook routines.
//!
//! **Guaranteed range:** every finite `f64` (subnormals, `±0` and values up to `f64::MAX`
//! included); the answer is always the sign of the exact determinant of the given numbers. The
//! checked entry points ([`orient3d`], [`orient2d`]) refuse NaN and infinities with
//! [`NonFiniteInput`]; the `*_unchecked` forms are for callers that validated already (a
//! non-finite input there gives an unspecified sign, never a panic).

/// The sign of a determinant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Sign {
    /// Negative.
    Negative = -1,
    /// Exactly zero (degenerate: coplanar or collinear).
    Zero = 0,
    /// Positive.
    Positive = 1,
}

impl Sign {
    /// −1, 0 or 1.
    #[inline]
    pub fn as_i8(self) -> i8 {
        self as i8
    }

    /// The opposite sign.
    #[inline]
    pub fn flip(self) -> Sign {
        match self {
            Sign::Negative => Sign::Positive,
            Sign::Zero => Sign::Zero,
            Sign::Positive => Sign::Negative,
        }
    }

    fn of_f64(x: f64) -> Sign {
        if x > 0.0 {
            Sign::Positive
        } else if x < 0.0 {
            Sign::Negative
        } else {
            Sign::Zero
        }
    }
}

/// A predicate was given a NaN or infinite coordinate (the only input refused).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("orientation predicate: non-finite coordinate {value} (every finite f64 is supported)")]
pub struct NonFiniteInput {
    /// The offending coordinate.
    pub value: f64,
}

fn check(points: &[&[f64]]) -> Result<(), NonFiniteInput> {
    for p in points {
        for &c in p.iter() {
            if !c.is_finite() {
                return Err(NonFiniteInput { value: c });
            }
        }
    }
    Ok(())
}

const EPS: f64 = 1.0 / 9_007_199_254_740_992.0; // 2^-53
const O3D_ERRBOUND_A: f64 = (7.0 + 56.0 * EPS) * EPS;
const CCW_ERRBOUND_A: f64 = (3.0 + 16.0 * EPS) * EPS;
/// 2^-330 and 2^330: the range of differences the 3×3 filter accepts.
const O3D_TINY: f64 = f64::from_bits((1023 - 330) << 52);
const O3D_HUGE: f64 = f64::from_bits((1023 + 330) << 52);
/// 2^-500 and 2^500: the range of differences the 2×2 filter accepts.
const CCW_TINY: f64 = f64::from_bits((1023 - 500) << 52);
const CCW_HUGE: f64 = f64::from_bits((1023 + 500) << 52);
/// Covers the underflow of the last product of each 3×3 term (≤ 2^-1075 each).
const UNDERFLOW_SLACK: f64 = f64::from_bits(16); // 2^-1070 (a subnormal)

/// Every `|x|` is 0 or in `[tiny, huge]` (branch-free, so it inlines and vectorizes).
#[inline(always)]
fn all_in_range<const N: usize>(xs: [f64; N], tiny: f64, huge: f64) -> bool {
    let mut ok = true;
    for x in xs {
        let m = x.abs();
        ok &= (m == 0.0) | ((m >= tiny) & (m <= huge));
    }
    ok
}

/// [`orient3d_unchecked`] after refusing non-finite input.
pub fn orient3d(
    a: [f64; 3],
    b: [f64; 3],
    c: [f64; 3],
    d: [f64; 3],
) -> Result<Sign, NonFiniteInput> {
    check(&[&a, &b, &c, &d])?;
    Ok(orient3d_unchecked(a, b, c, d))
}

/// The sign of `((b − a) × (c − a))·(d − a)` (see the [module docs](self)).
#[inline]
pub fn orient3d_unchecked(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> Sign {
    match orient3d_filter(a, b, c, d) {
        Some(s) => s,
        None => orient3d_expansion(a, b, c, d).unwrap_or_else(|| orient3d_exact(a, b, c, d)),
    }
}

/// 2⁻²⁵⁰ and 2²⁵⁰: the differences the expansion stages accept.
const EXPANSION_TINY: f64 = f64::from_bits((1023 - 250) << 52);
const EXPANSION_HUGE: f64 = f64::from_bits((1023 + 250) << 52);

/// `a − b` when it is exact in `f64` and 0 or of magnitude in `[2⁻²⁵⁰, 2²⁵⁰]` (Shewchuk's
/// `Two_Diff` with a zero tail).
#[inline]
fn exact_difference(a: f64, b: f64) -> Option<f64> {
    let x = a - b;
    let b_virtual = a - x;
    let a_virtual = x + b_virtual;
    let tail = (a - a_virtual) + (b_virtual - b);
    let m = x.abs();
    (tail == 0.0 && (m == 0.0 || (EXPANSION_TINY..=EXPANSION_HUGE).contains(&m))).then_some(x)
}

/// `(x, y)` with `x = fl(a + b)` and `x + y = a + b` exactly (Knuth's `Two_Sum`).
#[inline]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let x = a + b;
    let b_virtual = x - a;
    let a_virtual = x - b_virtual;
    (x, (a - a_virtual) + (b - b_virtual))
}

/// `(x, y)` with `x = fl(a·b)` and `x + y = a·b` exactly (Dekker's product with Veltkamp's
/// split; no FMA needed).
#[inline]
fn two_product(a: f64, b: f64) -> (f64, f64) {
    const SPLITTER: f64 = 134_217_729.0; // 2²⁷ + 1
    let split = |v: f64| {
        let c = SPLITTER * v;
        let big = c - v;
        let hi = c - big;
        (hi, v - hi)
    };
    let x = a * b;
    let (ahi, alo) = split(a);
    let (bhi, blo) = split(b);
    let err = ((x - ahi * bhi) - alo * bhi) - ahi * blo;
    (x, alo * blo - err)
}

/// The sign of the exact sum of `terms` (a nonoverlapping expansion grown one term at a time,
/// zeros eliminated — Shewchuk's `Grow_Expansion`; its largest component has the sum's sign).
#[inline]
fn sign_of_exact_sum<const N: usize>(terms: [f64; N]) -> Sign {
    let mut h = [0.0f64; N];
    let mut n = 0;
    for b in terms {
        let mut q = b;
        let mut m = 0;
        for i in 0..n {
            let (s, e) = two_sum(q, h[i]);
            q = s;
            if e != 0.0 {
                h[m] = e;
                m += 1;
            }
        }
        if q != 0.0 {
            h[m] = q;
            m += 1;
        }
        n = m;
    }
    if n == 0 {
        Sign::Zero
    } else {
        Sign::of_f64(h[n - 1])
    }
}

/// The exact stage between the filter and the big integers: `Some(sign)` when the nine
/// coordinate differences are exact in `f64` (as they are for nearby points) and each is 0 or
/// of magnitude in `[2⁻²⁵⁰, 2²⁵⁰]`; then the determinant is a sum of six products of three
/// `f64`s, each split exactly into four `f64`s (`two_product`), and the sign of the exact sum of
/// those 24 terms is returned. Every value involved is a multiple of `2⁻⁹⁰⁶` below `2⁷⁸⁰`, so
/// nothing underflows or overflows and every step is exact. `None`: leave it to
/// [`orient3d_exact`].
pub fn orient3d_expansion(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> Option<Sign> {
    let adx = exact_difference(a[0], d[0])?;
    let bdx = exact_difference(b[0], d[0])?;
    let cdx = exact_difference(c[0], d[0])?;
    let ady = exact_difference(a[1], d[1])?;
    let bdy = exact_difference(b[1], d[1])?;
    let cdy = exact_difference(c[1], d[1])?;
    let adz = exact_difference(a[2], d[2])?;
    let bdz = exact_difference(b[2], d[2])?;
    let cdz = exact_difference(c[2], d[2])?;
    // det[a − d, b − d, c − d] (minus ours) as ± x·y·z.
    let triple = |x: f64, y: f64, z: f64| {
        let (p, e) = two_product(x, y);
        let (p1, e1) = two_product(p, z);
        let (p2, e2) = two_product(e, z);
        [p1, e1, p2, e2]
    };
    let t = [
        triple(adz, bdx, cdy),
        triple(adz, cdx, bdy).map(|x| -x),
        triple(bdz, cdx, ady),
        triple(bdz, adx, cdy).map(|x| -x),
        triple(cdz, adx, bdy),
        triple(cdz, bdx, ady).map(|x| -x),
    ];
    let mut terms = [0.0; 24];
    for (k, q) in t.iter().flatten().enumerate() {
        terms[k] = *q;
    }
    Some(sign_of_exact_sum(terms).flip())
}

/// The 2×2 expansion stage (as [`orient3d_expansion`]: exact differences in `[2⁻²⁵⁰, 2²⁵⁰]` or
/// 0, then the exact sum of two exact products); `None`: leave it to [`orient2d_exact`].
pub fn orient2d_expansion(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> Option<Sign> {
    let acx = exact_difference(a[0], c[0])?;
    let bcx = exact_difference(b[0], c[0])?;
    let acy = exact_difference(a[1], c[1])?;
    let bcy = exact_difference(b[1], c[1])?;
    let (l, le) = two_product(acx, bcy);
    let (r, re) = two_product(acy, bcx);
    Some(sign_of_exact_sum([l, le, -r, -re]))
}

/// The fast path alone: `Some(sign)` when the `f64` evaluation is provably right, else `None`.
/// (Shewchuk's form `det[a − d, b − d, c − d]`, which is minus ours.)
#[inline]
pub fn orient3d_filter(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> Option<Sign> {
    let adx = a[0] - d[0];
    let bdx = b[0] - d[0];
    let cdx = c[0] - d[0];
    let ady = a[1] - d[1];
    let bdy = b[1] - d[1];
    let cdy = c[1] - d[1];
    let adz = a[2] - d[2];
    let bdz = b[2] - d[2];
    let cdz = c[2] - d[2];
    if !all_in_range(
        [adx, bdx, cdx, ady, bdy, cdy, adz, bdz, cdz],
        O3D_TINY,
        O3D_HUGE,
    ) {
        return None;
    }
    let bdxcdy = bdx * cdy;
    let cdxbdy = cdx * bdy;
    let cdxady = cdx * ady;
    let adxcdy = adx * cdy;
    let adxbdy = adx * bdy;
    let bdxady = bdx * ady;
    let det = adz * (bdxcdy - cdxbdy) + bdz * (cdxady - adxcdy) + cdz * (adxbdy - bdxady);
    let permanent = (bdxcdy.abs() + cdxbdy.abs()) * adz.abs()
        + (cdxady.abs() + adxcdy.abs()) * bdz.abs()
        + (adxbdy.abs() + bdxady.abs()) * cdz.abs();
    if permanent == 0.0 {
        return Some(Sign::Zero);
    }
    let err = O3D_ERRBOUND_A * permanent + UNDERFLOW_SLACK;
    if det > err {
        Some(Sign::Negative)
    } else if -det > err {
        Some(Sign::Positive)
    } else {
        None
    }
}

/// The plane of a triangle `(a, b, c)` prepared for many [`orient3d`]`(a, b, c, d)` signs against
/// it: the fast path of [`orient3d_filter`] with the triangle's half of the work done once.
///
/// With `u = fl(b − a)`, `v = fl(c − a)` and `w = fl(d − a)`, `orient3d(a, b, c, d)` is the sign
/// of `det[u, v, w]` (exactly, before rounding), and [`side`](Self::side) evaluates it as
/// `n·w` with the stored `n = fl(u × v)` (each component `u_y·v_z − u_z·v_y` etc.), summed
/// `n_x·w_x + n_y·w_y + n_z·w_z` left to right, and its permanent as `m·|w|` with the stored
/// `m_x = |fl(u_y·v_z)| + |fl(u_z·v_y)|` etc. That is Shewchuk's `orient3d` fast path term for
/// term — three rounded differences per row, 2×2 minors of two rows, the third row's entries
/// times those minors, summed in the same order — with rows `(u, v, w)` instead of
/// `(a − d, b − d, c − d)`, so the same static bound holds: the sign of the computed value is
/// exact when it exceeds `(7 + 56ε)ε·permanent + 2⁻¹⁰⁷⁰` (the slack covers the underflow of the
/// last product), provided every non-zero entry of `u`, `v`, `w` lies in `[2⁻³³⁰, 2³³⁰]`. A zero
/// permanent (all entries in range) means every term has an exactly zero factor: the sign is
/// exactly zero. When `u` or `v` has an entry out of range, `m` is stored as NaN, so every
/// comparison fails and [`side`](Self::side) answers `None` (leave it to [`orient3d_unchecked`]).
/// The cost per side: three differences, two dot products of three terms, no branch but the
/// answer's.
#[derive(Clone, Copy, Debug)]
pub struct PlaneFilter {
    /// `a`, the corner the differences are taken from.
    origin: [f64; 3],
    /// `fl(u × v)`.
    normal: [f64; 3],
    /// The minors' permanents `m` (NaN: `u` or `v` out of the filter's range).
    bound: [f64; 3],
}

impl PlaneFilter {
    /// The plane of `(a, b, c)` (any finite corners; a degenerate triangle gives a plane whose
    /// sides are all exactly zero or left undecided, as `orient3d` has them).
    #[inline(always)]
    pub fn new(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> PlaneFilter {
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let (uyvz, uzvy) = (u[1] * v[2], u[2] * v[1]);
        let (uzvx, uxvz) = (u[2] * v[0], u[0] * v[2]);
        let (uxvy, uyvx) = (u[0] * v[1], u[1] * v[0]);
        let normal = [uyvz - uzvy, uzvx - uxvz, uxvy - uyvx];
        let bound = if all_in_range([u[0], u[1], u[2], v[0], v[1], v[2]], O3D_TINY, O3D_HUGE) {
            [
                uyvz.abs() + uzvy.abs(),
                uzvx.abs() + uxvz.abs(),
                uxvy.abs() + uyvx.abs(),
            ]
        } else {
            [f64::NAN; 3]
        };
        PlaneFilter {
            origin: a,
            normal,
            bound,
        }
    }

    /// [`side`](Self::side) of each of `d` as two bit sets: bit `k` of the first set when
    /// `orient3d(a, b, c, d[k])` is certainly positive, of the second when certainly negative
    /// (neither: zero or undecided). Branch-free over the points.
    #[inline(always)]
    pub fn strict_sides<const N: usize>(&self, d: [&[f64; 3]; N]) -> (u8, u8) {
        let (o, n, m) = (self.origin, self.normal, self.bound);
        let (mut pos, mut neg) = (0u8, 0u8);
        for (k, dk) in d.iter().enumerate() {
            let w = [dk[0] - o[0], dk[1] - o[1], dk[2] - o[2]];
            let ok = all_in_range(w, O3D_TINY, O3D_HUGE);
            let det = n[0] * w[0] + n[1] * w[1] + n[2] * w[2];
            let permanent = m[0] * w[0].abs() + m[1] * w[1].abs() + m[2] * w[2].abs();
            let err = O3D_ERRBOUND_A * permanent + UNDERFLOW_SLACK;
            pos |= u8::from(ok & (det > err)) << k;
            neg |= u8::from(ok & (-det > err)) << k;
        }
        (pos, neg)
    }

    /// `Some(orient3d(a, b, c, d))` when the filter decides it (see [`PlaneFilter`]), else
    /// `None`.
    #[inline(always)]
    pub fn side(&self, d: [f64; 3]) -> Option<Sign> {
        let (o, n, m) = (self.origin, self.normal, self.bound);
        let w = [d[0] - o[0], d[1] - o[1], d[2] - o[2]];
        if !all_in_range(w, O3D_TINY, O3D_HUGE) {
            return None;
        }
        let det = n[0] * w[0] + n[1] * w[1] + n[2] * w[2];
        let permanent = m[0] * w[0].abs() + m[1] * w[1].abs() + m[2] * w[2].abs();
        if permanent == 0.0 {
            return Some(Sign::Zero);
        }
        let err = O3D_ERRBOUND_A * permanent + UNDERFLOW_SLACK;
        if det > err {
            Some(Sign::Positive)
        } else if -det > err {
            Some(Sign::Negative)
        } else {
            None
        }
    }
}

/// The exact path alone (slow; every finite input).
pub fn orient3d_exact(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> Sign {
    let all = [a, b, c, d];
    let e_min = min_exponent(all.iter().flatten().copied());
    let big = |x: f64| BigInt::from_f64_scaled(x, e_min);
    let p: Vec<[BigInt; 3]> = all
        .iter()
        .map(|q| [big(q[0]), big(q[1]), big(q[2])])
        .collect();
    let dif = |i: usize, k: usize| p[i][k].sub(&p[0][k]);
    // det[b − a, c − a, d − a]
    let (ux, uy, uz) = (dif(1, 0), dif(1, 1), dif(1, 2));
    let (vx, vy, vz) = (dif(2, 0), dif(2, 1), dif(2, 2));
    let (wx, wy, wz) = (dif(3, 0), dif(3, 1), dif(3, 2));
    let nx = uy.mul(&vz).sub(&uz.mul(&vy));
    let ny = uz.mul(&vx).sub(&ux.mul(&vz));
    let nz = ux.mul(&vy).sub(&uy.mul(&vx));
    nx.mul(&wx).add(&ny.mul(&wy)).add(&nz.mul(&wz)).sign()
}

/// [`orient2d_unchecked`] after refusing non-finite input.
pub fn orient2d(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> Result<Sign, NonFiniteInput> {
    check(&[&a, &b, &c])?;
    Ok(orient2d_unchecked(a, b, c))
}

/// The sign of `(b − a) × (c − a)` (positive: counter-clockwise).
#[inline]
pub fn orient2d_unchecked(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> Sign {
    match orient2d_filter(a, b, c) {
        Some(s) => s,
        None => orient2d_expansion(a, b, c).unwrap_or_else(|| orient2d_exact(a, b, c)),
    }
}

/// [`orient2d_unchecked`] on the coordinate plane that drops axis `drop` (0, 1 or 2): the plane
/// `(y, z)`, `(z, x)` or `(x, y)` respectively, oriented so that the sign equals the sign of
/// component `drop` of `(b − a) × (c − a)`.
#[inline]
pub fn orient2d_projected(a: [f64; 3], b: [f64; 3], c: [f64; 3], drop: usize) -> Sign {
    let (i, j) = match drop {
        0 => (1, 2),
        1 => (2, 0),
        _ => (0, 1),
    };
    orient2d_unchecked([a[i], a[j]], [b[i], b[j]], [c[i], c[j]])
}

/// A static bound for many 2-D orientations around one point `c` (a static version of
/// [`orient2d_filter`]): given the differences `p − c` of some points `p`, rounded in `f64` (as the
/// filter rounds them), returns `E` such that for any two of them `ac = a − c`, `bc = b − c`, the
/// `f64` value `det = ac₀·bc₁ − ac₁·bc₀` has the exact sign of `orient2d(a, b, c)` whenever
/// `|det| > E`. `E` bounds the filter's own bound `CCW_ERRBOUND_A·(|ac₀·bc₁| + |ac₁·bc₀|)` (all
/// rounding is monotone: each product is at most `fl(M²)`, `M` the largest component), so what
/// it decides is what the filter decides; `f64::INFINITY` (decide nothing) when a component is
/// outside the filter's range. A zero `det` is never decided (the caller asks the predicate).
#[inline]
pub fn orient2d_static_bound(diffs: &[[f64; 2]]) -> f64 {
    let mut ok = true;
    // Two running maxima (independent chains), by comparison: a NaN fails the range check, so
    // `f64::max`'s NaN handling would only lengthen the chain.
    let (mut m0, mut m1) = (0.0f64, 0.0f64);
    for d in diffs {
        ok &= all_in_range(*d, CCW_TINY, CCW_HUGE);
        let (a0, a1) = (d[0].abs(), d[1].abs());
        m0 = if a0 > m0 { a0 } else { m0 };
        m1 = if a1 > m1 { a1 } else { m1 };
    }
    let m = if m1 > m0 { m1 } else { m0 };
    if ok {
        CCW_ERRBOUND_A * (2.0 * (m * m))
    } else {
        f64::INFINITY
    }
}

/// The 2×2 fast path alone (`None`: not provably right).
#[inline]
pub fn orient2d_filter(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> Option<Sign> {
    let acx = a[0] - c[0];
    let bcx = b[0] - c[0];
    let acy = a[1] - c[1];
    let bcy = b[1] - c[1];
    if !all_in_range([acx, bcx, acy, bcy], CCW_TINY, CCW_HUGE) {
        return None;
    }
    let detleft = acx * bcy;
    let detright = acy * bcx;
    let det = detleft - detright;
    let permanent = detleft.abs() + detright.abs();
    if permanent == 0.0 {
        return Some(Sign::Zero);
    }
    let err = CCW_ERRBOUND_A * permanent;
    if det > err || -det > err {
        Some(Sign::of_f64(det))
    } else {
        None
    }
}

/// The exact 2×2 path alone (slow; every finite input).
pub fn orient2d_exact(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> Sign {
    let e_min = min_exponent([a, b, c].iter().flatten().copied());
    let big = |x: f64| BigInt::from_f64_scaled(x, e_min);
    let (ax, ay) = (big(a[0]), big(a[1]));
    let ux = big(b[0]).sub(&ax);
    let uy = big(b[1]).sub(&ay);
    let vx = big(c[0]).sub(&ax);
    let vy = big(c[1]).sub(&ay);
    ux.mul(&vy).sub(&uy.mul(&vx)).sign()
}

/// `(negative, odd mantissa, exponent)` with `|x| = mantissa·2^exponent`; `None` for zero.
fn decompose(x: f64) -> Option<(bool, u64, i32)> {
    let bits = x.to_bits();
    let neg = bits >> 63 == 1;
    let e = ((bits >> 52) & 0x7ff) as i32;
    let frac = bits & ((1u64 << 52) - 1);
    let (m, e) = if e == 0 {
        (frac, -1074)
    } else {
        (frac | (1u64 << 52), e - 1075)
    };
    if m == 0 {
        return None;
    }
    let tz = m.trailing_zeros();
    Some((neg, m >> tz, e + tz as i32))
}

fn min_exponent(xs: impl Iterator<Item = f64>) -> i32 {
    xs.filter_map(decompose)
        .map(|(_, _, e)| e)
        .min()
        .unwrap_or(0)
}

/// A signed arbitrary-precision integer (sign and little-endian `u32` magnitude without leading
/// zero limbs): the exact fallback's arithmetic. Only what the determinants need.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BigInt {
    neg: bool,
    mag: Vec<u32>,
}

impl BigInt {
    /// Zero.
    pub fn zero() -> BigInt {
        BigInt {
            neg: false,
            mag: Vec::new(),
        }
    }

    /// `x · 2^(−e_min)` for a finite `x` whose lowest set bit is at least `2^e_min` (exact).
    pub fn from_f64_scaled(x: f64, e_min: i32) -> BigInt {
        let Some((neg, m, e)) = decompose(x) else {
            return BigInt::zero();
        };
        let shift = (e - e_min).max(0) as usize;
        let (limbs, bits) = (shift / 32, shift % 32);
        let mut mag = vec![0u32; limbs];
        let wide = (m as u128) << bits;
        let mut w = wide;
        while w != 0 {
            mag.push(w as u32);
            w >>= 32;
        }
        let mut r = BigInt { neg, mag };
        r.trim();
        r
    }

    /// From an `i128` (for tests and small references).
    pub fn from_i128(x: i128) -> BigInt {
        let neg = x < 0;
        let mut u = x.unsigned_abs();
        let mut mag = Vec::new();
        while u != 0 {
            mag.push(u as u32);
            u >>= 32;
        }
        BigInt { neg, mag }
    }

    fn trim(&mut self) {
        while self.mag.last() == Some(&0) {
            self.mag.pop();
        }
        if self.mag.is_empty() {
            self.neg = false;
        }
    }

    /// The sign.
    pub fn sign(&self) -> Sign {
        if self.mag.is_empty() {
            Sign::Zero
        } else if self.neg {
            Sign::Negative
        } else {
            Sign::Positive
        }
    }

    fn cmp_mag(a: &[u32], b: &[u32]) -> std::cmp::Ordering {
        a.len()
            .cmp(&b.len())
            .then_with(|| a.iter().rev().cmp(b.iter().rev()))
    }

    fn add_mag(a: &[u32], b: &[u32]) -> Vec<u32> {
        let (long, short) = if a.len() >= b.len() { (a, b) } else { (b, a) };
        let mut out = Vec::with_capacity(long.len() + 1);
        let mut carry = 0u64;
        for (i, &x) in long.iter().enumerate() {
            let s = x as u64 + short.get(i).copied().unwrap_or(0) as u64 + carry;
            out.push(s as u32);
            carry = s >> 32;
        }
        if carry != 0 {
            out.push(carry as u32);
        }
        out
    }

    /// `a − b` for `|a| ≥ |b|`.
    fn sub_mag(a: &[u32], b: &[u32]) -> Vec<u32> {
        let mut out = Vec::with_capacity(a.len());
        let mut borrow = 0i64;
        for (i, &x) in a.iter().enumerate() {
            let mut s = x as i64 - b.get(i).copied().unwrap_or(0) as i64 - borrow;
            borrow = 0;
            if s < 0 {
                s += 1 << 32;
                borrow = 1;
            }
            out.push(s as u32);
        }
        out
    }

    /// `self + other`.
    pub fn add(&self, other: &BigInt) -> BigInt {
        let mut r = if self.neg == other.neg {
            BigInt {
                neg: self.neg,
                mag: Self::add_mag(&self.mag, &other.mag),
            }
        } else if Self::cmp_mag(&self.mag, &other.mag) != std::cmp::Ordering::Less {
            BigInt {
                neg: self.neg,
                mag: Self::sub_mag(&self.mag, &other.mag),
            }
        } else {
            BigInt {
                neg: other.neg,
                mag: Self::sub_mag(&other.mag, &self.mag),
            }
        };
        r.trim();
        r
    }

    /// `−self`.
    pub fn neg(&self) -> BigInt {
        let mut r = self.clone();
        if !r.mag.is_empty() {
            r.neg = !r.neg;
        }
        r
    }

    /// `self − other`.
    pub fn sub(&self, other: &BigInt) -> BigInt {
        self.add(&other.neg())
    }

    /// `self · other` (schoolbook).
    pub fn mul(&self, other: &BigInt) -> BigInt {
        if self.mag.is_empty() || other.mag.is_empty() {
            return BigInt::zero();
        }
        let mut out = vec![0u32; self.mag.len() + other.mag.len()];
        for (i, &x) in self.mag.iter().enumerate() {
            let mut carry = 0u64;
            for (j, &y) in other.mag.iter().enumerate() {
                let t = x as u64 * y as u64 + out[i + j] as u64 + carry;
                out[i + j] = t as u32;
                carry = t >> 32;
            }
            let mut k = i + other.mag.len();
            while carry != 0 {
                let t = out[k] as u64 + carry;
                out[k] = t as u32;
                carry = t >> 32;
                k += 1;
            }
        }
        let mut r = BigInt {
            neg: self.neg != other.neg,
            mag: out,
        };
        r.trim();
        r
    }
}

#[cfg(test)]
pub(crate) mod tests;
