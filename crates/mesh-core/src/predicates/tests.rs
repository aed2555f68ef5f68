use super::*;

/// splitmix64: a small deterministic generator for the randomized tests.
pub(crate) struct Rng(u64);

impl Rng {
    pub(crate) fn new(seed: u64) -> Rng {
        Rng(seed)
    }
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[-bound, bound]`.
    pub(crate) fn int(&mut self, bound: i64) -> i64 {
        (self.next_u64() % (2 * bound as u64 + 1)) as i64 - bound
    }
    pub(crate) fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Grid step of the reference points: coordinates are `k · 2⁻²⁰` with `|k| < 2⁴⁰`.
const STEP: f64 = 1.0 / 1_048_576.0;

fn to_int(x: f64) -> i128 {
    let k = x / STEP;
    assert_eq!(k.fract(), 0.0, "{x} is not on the grid");
    k as i128
}

/// A slow exact reference on grid points in `i128` (differences < 2⁴¹, products < 2¹²³), by the
/// cofactor expansion along the first row of `det[b − a, c − a, d − a]` — a different expansion
/// and different arithmetic from the predicate's.
fn reference3(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> Sign {
    let ia = a.map(to_int);
    let u: Vec<i128> = (0..3).map(|k| to_int(b[k]) - ia[k]).collect();
    let v: Vec<i128> = (0..3).map(|k| to_int(c[k]) - ia[k]).collect();
    let w: Vec<i128> = (0..3).map(|k| to_int(d[k]) - ia[k]).collect();
    let det = u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
        + u[2] * (v[0] * w[1] - v[1] * w[0]);
    match det.cmp(&0) {
        std::cmp::Ordering::Less => Sign::Negative,
        std::cmp::Ordering::Equal => Sign::Zero,
        std::cmp::Ordering::Greater => Sign::Positive,
    }
}

fn naive3(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> Sign {
    let u = crate::geometry::sub(b, a);
    let v = crate::geometry::sub(c, a);
    let w = crate::geometry::sub(d, a);
    Sign::of_f64(crate::geometry::dot(crate::geometry::cross(u, v), w))
}

fn grid_point(rng: &mut Rng, bound: i64) -> [f64; 3] {
    [0, 1, 2].map(|_| rng.int(bound) as f64 * STEP)
}

/// Exact powers of two (also subnormal ones).
fn pow2(e: i32) -> f64 {
    if e >= -1022 {
        f64::from_bits(((1023 + e) as u64) << 52)
    } else {
        f64::from_bits(1u64 << (e + 1074))
    }
}

/// Multiplies by `2^e` exactly for grid points (in two steps so that no step underflows).
fn scaled(p: [f64; 3], e: i32) -> [f64; 3] {
    let h = e / 2;
    p.map(|x| x * pow2(h) * pow2(e - h))
}

/// `d` within an ulp or two of the plane of `a, b, c`, with the exact sign known by
/// construction: `d₀ = a + s(b − a) + t(c − a)` is exactly on the plane (integer corners below
/// 2²⁵, `s, t` multiples of 2⁻²⁴, so `d₀` is exact in `f64`), then each coordinate of magnitude
/// ≥ 1 moves by −1, 0 or +1 ulp (`δ`). The determinant is linear in `d`, so its exact value is
/// `n·δ` with `n = (b − a) × (c − a)` — computed here in `i128`, independently of the predicate.
fn near_coplanar(rng: &mut Rng) -> ([[f64; 3]; 4], Sign) {
    let bound = (1i64 << 25) - 1;
    let ia = [0; 3].map(|_| rng.int(bound) as i128);
    let ib = [0; 3].map(|_| rng.int(bound) as i128);
    let ic = [0; 3].map(|_| rng.int(bound) as i128);
    let (ks, kt) = (
        (rng.next_u64() % (1 << 24)) as i128,
        (rng.next_u64() % (1 << 24)) as i128,
    );
    let scale = (1i128 << 24) as f64;
    let d0 = [0, 1, 2].map(|k| {
        let num = ia[k] * (1 << 24) + ks * (ib[k] - ia[k]) + kt * (ic[k] - ia[k]);
        num as f64 / scale
    });
    let mut d = d0;
    for x in d.iter_mut() {
        if x.abs() >= 1.0 {
            *x = match rng.int(1) {
                -1 => x.next_down(),
                1 => x.next_up(),
                _ => *x,
            };
        }
    }
    let u = [0, 1, 2].map(|k| ib[k] - ia[k]);
    let v = [0, 1, 2].map(|k| ic[k] - ia[k]);
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    // δ_k · 2⁸⁰ is an integer (|d_k| ≥ 1 has an ulp ≥ 2⁻⁵²).
    let dot: i128 = (0..3)
        .map(|k| n[k] * (((d[k] - d0[k]) * 2f64.powi(80)) as i128))
        .sum();
    let sign = match dot.cmp(&0) {
        std::cmp::Ordering::Less => Sign::Negative,
        std::cmp::Ordering::Equal => Sign::Zero,
        std::cmp::Ordering::Greater => Sign::Positive,
    };
    let f = |p: [i128; 3]| p.map(|x| x as f64);
    ([f(ia), f(ib), f(ic), d], sign)
}

#[test]
fn orient3d_agrees_with_the_exact_reference_on_random_points() {
    let mut rng = Rng::new(1);
    for _ in 0..20_000 {
        let bound = (1i64 << 39) - 1;
        let [a, b, c, d] = [0; 4].map(|_| grid_point(&mut rng, bound));
        let r = reference3(a, b, c, d);
        assert_eq!(orient3d(a, b, c, d), Ok(r));
        assert_eq!(orient3d_exact(a, b, c, d), r);
        if let Some(s) = orient3d_filter(a, b, c, d) {
            assert_eq!(s, r);
        }
    }
}

#[test]
fn orient3d_is_exact_where_plain_f64_gets_the_sign_wrong() {
    let mut rng = Rng::new(2);
    let (mut naive_wrong, mut fallback, mut zero) = (0, 0, 0);
    for _ in 0..20_000 {
        let ([a, b, c, d], r) = near_coplanar(&mut rng);
        assert_eq!(orient3d_unchecked(a, b, c, d), r, "{a:?} {b:?} {c:?} {d:?}");
        assert_eq!(orient3d_exact(a, b, c, d), r);
        match orient3d_filter(a, b, c, d) {
            Some(s) => assert_eq!(s, r),
            None => fallback += 1,
        }
        naive_wrong += usize::from(naive3(a, b, c, d) != r);
        zero += usize::from(r == Sign::Zero);
        // 1e±100 and the ends of the f64 range: scaling by a power of two keeps the sign.
        for e in [-1020, -332, 332, 960] {
            let [sa, sb, sc, sd] = [a, b, c, d].map(|p| scaled(p, e));
            assert_eq!(orient3d_unchecked(sa, sb, sc, sd), r, "scale 2^{e}");
        }
    }
    println!(
        "near-coplanar: {naive_wrong} naive f64 signs wrong, {fallback} exact fallbacks, {zero} exactly coplanar"
    );
    assert!(
        naive_wrong > 100,
        "the construction should defeat plain f64"
    );
    assert!(zero > 0);
}

#[test]
fn orient2d_is_exact_on_the_classic_near_collinear_grid() {
    // Shewchuk's example: a on a 2⁻⁵³ grid near (0.5, 0.5), b = (12, 12), c = (24, 24).
    let u = pow2(-53);
    let s = pow2(53) as i128;
    let (mut naive_wrong, mut total) = (0, 0);
    for i in 0..64 {
        for j in 0..64 {
            let a = [0.5 + i as f64 * u, 0.5 + j as f64 * u];
            let (b, c) = ([12.0, 12.0], [24.0, 24.0]);
            let ia = [s / 2 + i, s / 2 + j];
            let (ib, ic) = ([12 * s, 12 * s], [24 * s, 24 * s]);
            let det = (ib[0] - ia[0]) * (ic[1] - ia[1]) - (ib[1] - ia[1]) * (ic[0] - ia[0]);
            let r = match det.cmp(&0) {
                std::cmp::Ordering::Less => Sign::Negative,
                std::cmp::Ordering::Equal => Sign::Zero,
                std::cmp::Ordering::Greater => Sign::Positive,
            };
            assert_eq!(orient2d(a, b, c), Ok(r), "{i} {j}");
            assert_eq!(orient2d_exact(a, b, c), r);
            let naive = Sign::of_f64((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]));
            naive_wrong += usize::from(naive != r);
            total += 1;
            for e in [-1000, -332, 332, 1000] {
                let k = |p: [f64; 2]| p.map(|x| x * pow2(e / 2) * pow2(e - e / 2));
                assert_eq!(orient2d_unchecked(k(a), k(b), k(c)), r, "scale 2^{e}");
            }
        }
    }
    println!("orient2d: {naive_wrong} of {total} naive signs wrong");
    assert!(naive_wrong > 0);
}

#[test]
fn projected_orientation_is_the_normal_component() {
    let mut rng = Rng::new(3);
    for _ in 0..2_000 {
        let [a, b, c] = [0; 3].map(|_| grid_point(&mut rng, 1 << 30));
        let n = crate::geometry::cross(crate::geometry::sub(b, a), crate::geometry::sub(c, a));
        for (k, nk) in n.iter().enumerate() {
            // Small grid: the float normal is exact here.
            assert_eq!(orient2d_projected(a, b, c, k), Sign::of_f64(*nk));
        }
    }
}

#[test]
fn extreme_and_mixed_magnitudes() {
    let tiny = f64::from_bits(1); // 2^-1074
    let max = f64::MAX;
    // d just above the plane z = 0 by the smallest subnormal, the triangle spanning huge values.
    let (a, b, c) = ([0.0, 0.0, 0.0], [max, 0.0, 0.0], [0.0, max, 0.0]);
    assert_eq!(orient3d(a, b, c, [1.0, 1.0, tiny]), Ok(Sign::Positive));
    assert_eq!(orient3d(a, b, c, [1.0, 1.0, -tiny]), Ok(Sign::Negative));
    assert_eq!(orient3d(a, b, c, [1e300, -1e300, 0.0]), Ok(Sign::Zero));
    // Mixed 1e100 and 1e-100 coordinates in one call.
    let d = [1e-100, 1e100, 1e-100];
    assert_eq!(
        orient3d([0.0; 3], [1e100, 0.0, 0.0], [0.0, 1e100, 0.0], d),
        Ok(Sign::Positive)
    );
    assert_eq!(
        orient2d([-max, -max], [max, max], [0.0, tiny]),
        Ok(Sign::Positive)
    );
    assert_eq!(
        orient2d([-max, -max], [max, max], [0.0, 0.0]),
        Ok(Sign::Zero)
    );
}

#[test]
fn non_finite_input_is_refused() {
    let p = [0.0; 3];
    let e = orient3d(p, p, p, [f64::NAN, 0.0, 0.0]).expect_err("refused");
    assert!(e.value.is_nan());
    assert!(e.to_string().contains("non-finite"));
    assert_eq!(
        orient2d([0.0, 0.0], [f64::INFINITY, 0.0], [1.0, 1.0]),
        Err(NonFiniteInput {
            value: f64::INFINITY
        })
    );
}

#[test]
fn bigint_matches_i128() {
    let mut rng = Rng::new(4);
    for _ in 0..5_000 {
        let x = rng.int(1 << 60) as i128;
        let y = rng.int(1 << 60) as i128;
        let (bx, by) = (BigInt::from_i128(x), BigInt::from_i128(y));
        assert_eq!(bx.add(&by), BigInt::from_i128(x + y));
        assert_eq!(bx.sub(&by), BigInt::from_i128(x - y));
        assert_eq!(bx.mul(&by), BigInt::from_i128(x * y));
        assert_eq!(
            BigInt::from_f64_scaled(x as f64, 0).sign(),
            BigInt::from_i128(x).sign()
        );
    }
}

#[test]
fn expansion_stages_agree_with_the_exact_reference() {
    // Near-coplanar points (where the filter fails), random grid points, and both scaled to
    // 2^±200 (inside the stage's range) and 2^±600 (outside: the stage must step aside).
    let mut rng = Rng::new(21);
    let (mut decided, mut zero) = (0, 0);
    for round in 0..20_000 {
        let ([a, b, c, d], r) = if round % 2 == 0 {
            near_coplanar(&mut rng)
        } else {
            let bound = (1i64 << 39) - 1;
            let p = [0; 4].map(|_| grid_point(&mut rng, bound));
            (p, reference3(p[0], p[1], p[2], p[3]))
        };
        if let Some(s) = orient3d_expansion(a, b, c, d) {
            assert_eq!(s, r, "{a:?} {b:?} {c:?} {d:?}");
            decided += 1;
            zero += usize::from(s == Sign::Zero);
        }
        for e in [-200, 200] {
            let [sa, sb, sc, sd] = [a, b, c, d].map(|p| scaled(p, e));
            if let Some(s) = orient3d_expansion(sa, sb, sc, sd) {
                assert_eq!(s, r, "scale 2^{e}");
            }
        }
        for e in [-600, 600] {
            let [sa, sb, sc, sd] = [a, b, c, d].map(|p| scaled(p, e));
            let nonzero = [sa, sb, sc].iter().any(|p| p != &sd);
            if nonzero {
                assert_eq!(orient3d_expansion(sa, sb, sc, sd), None, "scale 2^{e}");
            }
        }
    }
    println!("expansion stage: {decided} of 20000 decided, {zero} zero");
    // (11,572 at the time of writing: the nudged coordinates make some differences inexact.)
    assert!(decided > 10_000 && zero > 0, "{decided} {zero}");
    // An inexact difference (1 − 2⁻⁶⁰ is not an f64 difference of these): no answer.
    let tiny = pow2(-60);
    assert_eq!(
        orient3d_expansion(
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [tiny, 0.0, 0.0]
        ),
        None
    );
    // The 2×2 stage on Shewchuk's near-collinear grid (b, c = 12, 24: the differences are
    // mostly inexact, the stage steps aside) and on the same grid with b, c = 0.625, 0.875
    // (differences exact by Sterbenz: the stage decides every one).
    let u = pow2(-53);
    let s = pow2(53) as i128;
    let mut decided2 = [0, 0];
    for (k, (fb, fc)) in [(12.0, 24.0), (0.625, 0.875)].into_iter().enumerate() {
        for i in 0..64 {
            for j in 0..64 {
                let a = [0.5 + i as f64 * u, 0.5 + j as f64 * u];
                let (b, c) = ([fb, fb], [fc, fc]);
                let ia = [s / 2 + i, s / 2 + j];
                let (ib, ic) = ([(fb * pow2(53)) as i128; 2], [(fc * pow2(53)) as i128; 2]);
                let det = (ib[0] - ia[0]) * (ic[1] - ia[1]) - (ib[1] - ia[1]) * (ic[0] - ia[0]);
                let r = Sign::of_f64(det as f64);
                for (p, q, t) in [(a, b, c), (b, c, a), (c, a, b)] {
                    if let Some(sg) = orient2d_expansion(p, q, t) {
                        assert_eq!(sg, r, "{i} {j}");
                        decided2[k] += 1;
                    }
                }
            }
        }
    }
    println!("orient2d expansion stage decided {decided2:?} of 12288 each");
    assert_eq!(decided2[1], 3 * 4096);
}

/// `PlaneFilter` on `(a, b, c, d)` against the exact sign `want`: when `side` answers, it is
/// `want`, and `strict_sides` sets a bit exactly when `side` gives a non-zero sign. Returns
/// whether `side` answered.
fn plane_filter_case(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3], want: Sign) -> bool {
    let plane = PlaneFilter::new(a, b, c);
    let got = plane.side(d);
    if let Some(s) = got {
        assert_eq!(s, want, "{a:?} {b:?} {c:?} {d:?}");
    }
    let (pos, neg) = plane.strict_sides([&d, &a]);
    assert_eq!(
        pos & 1 != 0,
        got == Some(Sign::Positive),
        "{a:?} {b:?} {c:?} {d:?}"
    );
    assert_eq!(
        neg & 1 != 0,
        got == Some(Sign::Negative),
        "{a:?} {b:?} {c:?} {d:?}"
    );
    // `a` itself is on the plane: never a strict side.
    assert_eq!((pos | neg) & 2, 0);
    got.is_some()
}

/// The precomputed plane filter never contradicts the exact sign: random grid points (where it
/// must decide almost always), points within an ulp of the plane and exactly on it (zero), the
/// triangle's own corners, the same configurations scaled by `2^e` for `e` from −1000 to 600
/// (1e±100 is about 2^±332, just outside the filter's range: it must defer), and mixed 1e100 /
/// 1e-100 coordinates.
#[test]
fn plane_filter_agrees_with_the_exact_orient3d() {
    let mut rng = Rng::new(23);
    let mut decided = 0;
    for _ in 0..20_000 {
        let bound = 1i64 << 30;
        let [a, b, c, d] = [0; 4].map(|_| grid_point(&mut rng, bound));
        decided += usize::from(plane_filter_case(a, b, c, d, reference3(a, b, c, d)));
        for p in [a, b, c] {
            plane_filter_case(a, b, c, p, Sign::Zero);
        }
    }
    assert!(decided > 19_900, "{decided} of 20000 generic cases decided");
    let (mut near, mut zero) = (0, 0);
    for _ in 0..20_000 {
        let ([a, b, c, d], want) = near_coplanar(&mut rng);
        near += usize::from(plane_filter_case(a, b, c, d, want));
        zero += usize::from(want == Sign::Zero);
    }
    assert!(zero > 300, "{zero} exactly coplanar cases");
    println!("{near} of 20000 near-coplanar cases decided");
    let mut decided_scaled = 0;
    for e in [-1000, -700, -332, -300, -100, 100, 300, 332, 600] {
        for round in 0..2_000 {
            let ([a, b, c, d], _) = if round % 2 == 0 {
                let bound = 1i64 << 30;
                let p = [0; 4].map(|_| grid_point(&mut rng, bound));
                (p, Sign::Zero)
            } else {
                near_coplanar(&mut rng)
            };
            let [a, b, c, d] = [a, b, c, d].map(|p| scaled(p, e));
            let got = plane_filter_case(a, b, c, d, orient3d_exact(a, b, c, d));
            decided_scaled += usize::from(got);
            if e.abs() >= 332 {
                assert!(!got || e == -332, "2^{e}: decided outside the range");
            }
        }
    }
    // e = ±100, ±300 are inside the range: the generic half decides there.
    assert!(decided_scaled > 3_900, "{decided_scaled}");
    for _ in 0..5_000 {
        let mixed = |rng: &mut Rng| {
            [0; 3].map(|_| {
                let x = rng.unit() - 0.5;
                if rng.next_u64().is_multiple_of(2) {
                    x * 1e100
                } else {
                    x * 1e-100
                }
            })
        };
        let [a, b, c, d] = [0; 4].map(|_| mixed(&mut rng));
        plane_filter_case(a, b, c, d, orient3d_exact(a, b, c, d));
    }
}

/// `orient2d_static_bound`: wherever the `f64` determinant of two differences around `c` is
/// beyond the bound, its sign is the exact `orient2d` — on near-collinear points around `c` (the
/// Shewchuk grid: most undecided), random ones, mixed magnitudes, and out-of-range differences
/// (never decided).
#[test]
fn orient2d_static_bound_decides_only_exact_signs() {
    let mut rng = Rng::new(0x5e1f_0005);
    let (mut decided, mut total) = (0usize, 0usize);
    for round in 0..4000 {
        let c = [rng.unit() - 0.5, rng.unit() - 0.5];
        let scale = pow2(round % 9 * 40 - 160);
        let near = round % 3 == 0;
        let dir = [rng.unit() - 0.5, rng.unit() - 0.5];
        let pts: Vec<[f64; 2]> = (0..8)
            .map(|_| {
                if near {
                    // Nearly on one line through c.
                    let t = rng.unit() * 2.0 - 1.0;
                    let u = pow2(-50) * (rng.unit() - 0.5);
                    [c[0] + t * dir[0] + u, c[1] + t * dir[1] - u]
                } else {
                    [
                        c[0] + scale * (rng.unit() - 0.5),
                        c[1] + scale * (rng.unit() - 0.5),
                    ]
                }
            })
            .collect();
        let diffs: Vec<[f64; 2]> = pts.iter().map(|p| [p[0] - c[0], p[1] - c[1]]).collect();
        let bound = orient2d_static_bound(&diffs);
        for i in 0..pts.len() {
            for j in 0..pts.len() {
                let (a, b) = (diffs[i], diffs[j]);
                let det = a[0] * b[1] - a[1] * b[0];
                total += 1;
                if det > bound || det < -bound {
                    decided += 1;
                    assert_eq!(Sign::of_f64(det), orient2d_exact(pts[i], pts[j], c));
                    assert_eq!(orient2d_filter(pts[i], pts[j], c), Some(Sign::of_f64(det)));
                }
            }
        }
    }
    println!("static bound: {decided} of {total} decided");
    assert!(decided > total / 4 && decided < total);
    // A component outside the filter's range decides nothing.
    assert_eq!(orient2d_static_bound(&[[1.0, pow2(-600)]]), f64::INFINITY);
    assert_eq!(orient2d_static_bound(&[[pow2(600), 1.0]]), f64::INFINITY);
    assert!(orient2d_static_bound(&[[0.0, 0.0]]) == 0.0);
}
