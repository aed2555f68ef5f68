use super::*;

/// A small deterministic generator (xorshift64*), so the tests need no dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    fn point(&mut self, s: f64) -> [f64; 3] {
        [self.range(-s, s), self.range(-s, s), self.range(-s, s)]
    }
}

/// A random triangle soup with shared vertices: `nv` points, `nf` faces of small triangles
/// around random centres, some of them degenerate (a repeated vertex or three collinear points).
fn random_mesh(seed: u64, nf: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut rng = Rng(seed | 1);
    let mut positions = Vec::new();
    let mut faces = Vec::new();
    for i in 0..nf {
        let c = rng.point(1.0);
        let base = positions.len() as u32;
        let a = [
            c[0] + rng.range(-0.2, 0.2),
            c[1] + rng.range(-0.2, 0.2),
            c[2] + rng.range(-0.2, 0.2),
        ];
        let b = [
            c[0] + rng.range(-0.2, 0.2),
            c[1] + rng.range(-0.2, 0.2),
            c[2] + rng.range(-0.2, 0.2),
        ];
        match i % 17 {
            0 => {
                // Repeated vertex.
                positions.push(a);
                positions.push(b);
                faces.push([base, base + 1, base + 1]);
            }
            1 => {
                // Collinear.
                positions.push(a);
                positions.push(b);
                positions.push([
                    (a[0] + b[0]) / 2.0,
                    (a[1] + b[1]) / 2.0,
                    (a[2] + b[2]) / 2.0,
                ]);
                faces.push([base, base + 1, base + 2]);
            }
            2 if base > 3 => {
                // Shares two vertices with an earlier face.
                positions.push(a);
                faces.push([base - 2, base - 1, base]);
            }
            _ => {
                positions.push(a);
                positions.push(b);
                positions.push([
                    c[0] + rng.range(-0.2, 0.2),
                    c[1] + rng.range(-0.2, 0.2),
                    c[2] + rng.range(-0.2, 0.2),
                ]);
                faces.push([base, base + 1, base + 2]);
            }
        }
    }
    (positions, faces)
}

fn brute_closest(positions: &[[f64; 3]], faces: &[[u32; 3]], p: [f64; 3]) -> (u32, f64) {
    let mut best = (u32::MAX, f64::INFINITY);
    for (i, f) in faces.iter().enumerate() {
        let t = [
            positions[f[0] as usize],
            positions[f[1] as usize],
            positions[f[2] as usize],
        ];
        let (q, _) = closest_on_triangle(p, &t);
        let d = sub(q, p);
        let d2 = dot(d, d);
        if d2 < best.1 {
            best = (i as u32, d2);
        }
    }
    best
}

fn brute_pairs(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let boxes: Vec<Aabb> = faces
        .iter()
        .map(|f| {
            Aabb::of_points(&[
                positions[f[0] as usize],
                positions[f[1] as usize],
                positions[f[2] as usize],
            ])
        })
        .collect();
    let mut out = Vec::new();
    for i in 0..boxes.len() {
        for j in i + 1..boxes.len() {
            if boxes[i].overlaps(&boxes[j]) {
                out.push([i as u32, j as u32]);
            }
        }
    }
    out
}

fn brute_rays(positions: &[[f64; 3]], faces: &[[u32; 3]], o: [f64; 3], d: [f64; 3]) -> Vec<RayHit> {
    let mut hits = Vec::new();
    for (i, f) in faces.iter().enumerate() {
        let t = [
            positions[f[0] as usize],
            positions[f[1] as usize],
            positions[f[2] as usize],
        ];
        if let Some((t, w)) = ray_triangle(o, d, &t) {
            hits.push(RayHit {
                face: i as u32,
                t,
                barycentric: w,
            });
        }
    }
    hits.sort_by(|a, b| a.t.total_cmp(&b.t).then(a.face.cmp(&b.face)));
    hits
}

#[test]
fn closest_point_equals_brute_force() {
    for seed in [1u64, 7, 99] {
        let (pos, faces) = random_mesh(seed, 300);
        let bvh = Bvh::new(&pos, &faces).expect("ok");
        let mut rng = Rng(seed * 31 + 5);
        for _ in 0..400 {
            let p = rng.point(1.6);
            let got = bvh.closest_point(p).expect("ok");
            let (face, d2) = brute_closest(&pos, &faces, p);
            // A hint, good or bad, changes nothing.
            for hint in [0, face, (face + 7) % faces.len() as u32, u32::MAX] {
                assert_eq!(bvh.closest_point_hinted(p, hint), Some(got));
            }
            assert_eq!(got.distance_squared, d2, "seed {seed} at {p:?}");
            assert_eq!(got.face, face);
            // The point and its barycentrics agree.
            let t = bvh.triangle(got.face);
            for k in 0..3 {
                let q = got.barycentric[0] * t[0][k]
                    + got.barycentric[1] * t[1][k]
                    + got.barycentric[2] * t[2][k];
                assert!((q - got.point[k]).abs() < 1e-12);
            }
        }
    }
}

#[test]
fn ray_hits_equal_brute_force() {
    let (pos, faces) = random_mesh(3, 400);
    let bvh = Bvh::new(&pos, &faces).expect("ok");
    let mut rng = Rng(12345);
    let mut total = 0;
    for i in 0..300 {
        let o = rng.point(2.0);
        let mut d = rng.point(1.0);
        if i % 10 == 0 {
            d = [0.0, 0.0, 1.0]; // axis-parallel rays exercise the zero-direction slabs
        }
        let want = brute_rays(&pos, &faces, o, d);
        let got = bvh.ray_hits(o, d, f64::INFINITY);
        assert_eq!(got, want);
        assert_eq!(
            bvh.ray_first_hit(o, d, f64::INFINITY),
            want.first().copied()
        );
        // A limit keeps only hits up to it.
        if let Some(h) = want.first() {
            let limited = bvh.ray_hits(o, d, h.t);
            assert!(limited.iter().all(|x| x.t <= h.t) && !limited.is_empty());
        }
        total += want.len();
    }
    assert!(total > 50, "the rays should hit something ({total})");
}

#[test]
fn overlap_pairs_equal_brute_force_and_box_query() {
    for seed in [2u64, 5] {
        let (pos, faces) = random_mesh(seed, 500);
        let bvh = Bvh::new(&pos, &faces).expect("ok");
        let got = bvh.overlapping_pairs();
        let want = brute_pairs(&pos, &faces);
        assert_eq!(got, want);
        assert!(!want.is_empty());
        let mut rng = Rng(seed + 100);
        for _ in 0..50 {
            let c = rng.point(1.0);
            let q = Aabb::of_points(&[c, [c[0] + 0.3, c[1] + 0.2, c[2] + 0.1]]);
            let got = bvh.faces_overlapping(&q);
            let want: Vec<u32> = (0..faces.len() as u32)
                .filter(|&f| bvh.face_bounds(f).overlaps(&q))
                .collect();
            assert_eq!(got, want);
        }
    }
}

#[test]
fn refit_answers_as_a_rebuild() {
    let (mut pos, faces) = random_mesh(11, 300);
    let mut bvh = Bvh::new(&pos, &faces).expect("ok");
    let mut rng = Rng(77);
    for p in pos.iter_mut() {
        let d = rng.point(0.3);
        for k in 0..3 {
            p[k] += d[k];
        }
    }
    bvh.refit(&pos).expect("ok");
    let fresh = Bvh::new(&pos, &faces).expect("ok");
    assert_eq!(bvh.overlapping_pairs(), fresh.overlapping_pairs());
    assert_eq!(bvh.overlapping_pairs(), brute_pairs(&pos, &faces));
    for _ in 0..200 {
        let p = rng.point(1.5);
        assert_eq!(bvh.closest_point(p), fresh.closest_point(p));
        let d = rng.point(1.0);
        assert_eq!(
            bvh.ray_hits(p, d, f64::INFINITY),
            fresh.ray_hits(p, d, f64::INFINITY)
        );
    }
    // Wrong vertex count and NaN are refused and leave the tree as it was.
    assert!(matches!(
        bvh.refit(&pos[1..]),
        Err(BvhError::VertexCount { .. })
    ));
    let mut bad = pos.clone();
    bad[faces[3][1] as usize][2] = f64::NAN;
    assert!(matches!(bvh.refit(&bad), Err(BvhError::NonFinite { .. })));
    assert_eq!(bvh.overlapping_pairs(), fresh.overlapping_pairs());
}

#[test]
fn bad_input_and_empty_mesh() {
    let pos = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, f64::NAN, 0.0],
        [0.0, 0.0, f64::INFINITY],
    ];
    let e = Bvh::new(&pos, &[[0, 1, 2]]).expect_err("refused");
    assert!(matches!(e, BvhError::NonFinite { vertex: 2, .. }));
    assert!(e.to_string().contains("vertex 2"));
    assert!(matches!(
        Bvh::new(&pos, &[[0, 1, 3]]),
        Err(BvhError::NonFinite { vertex: 3, .. })
    ));
    assert!(matches!(
        Bvh::new(&pos, &[[0, 1, 9]]),
        Err(BvhError::FaceIndex {
            face: 0,
            index: 9,
            num_vertices: 4
        })
    ));
    // A NaN vertex that no face uses is fine.
    assert!(Bvh::new(&pos, &[[0, 1, 0]]).is_ok());

    let empty = Bvh::new(&[], &[]).expect("ok");
    assert!(empty.is_empty());
    assert_eq!(empty.shape(), (0, 0));
    assert_eq!(empty.closest_point([0.0; 3]), None);
    assert_eq!(
        empty.ray_first_hit([0.0; 3], [1.0, 0.0, 0.0], f64::INFINITY),
        None
    );
    assert!(empty.overlapping_pairs().is_empty());
    assert!(
        empty
            .faces_overlapping(&Aabb::of_points(&[[0.0; 3]]))
            .is_empty()
    );

    // Non-finite queries answer nothing instead of panicking.
    let tri = Bvh::new(
        &pos[..2]
            .iter()
            .copied()
            .chain([[0.0, 1.0, 0.0]])
            .collect::<Vec<_>>(),
        &[[0, 1, 2]],
    )
    .expect("ok");
    assert_eq!(tri.closest_point([f64::NAN, 0.0, 0.0]), None);
    assert_eq!(
        tri.ray_first_hit([0.2, 0.2, 1.0], [0.0, 0.0, f64::NAN], 1e9),
        None
    );
    assert_eq!(
        tri.ray_first_hit([0.2, 0.2, 1.0], [0.0, 0.0, 0.0], 1e9),
        None
    );
    let hit = tri
        .ray_first_hit([0.2, 0.2, 1.0], [0.0, 0.0, -1.0], f64::INFINITY)
        .expect("ok");
    assert_eq!(hit.t, 1.0);
    assert_eq!(hit.barycentric, [0.6000000000000001, 0.2, 0.2]);
}

#[test]
fn degenerate_faces_closest_points() {
    // A repeated-vertex face is its segment; a point face is its point.
    let pos = vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [5.0, 5.0, 5.0]];
    let bvh = Bvh::new(&pos, &[[0, 1, 1], [2, 2, 2]]).expect("ok");
    let c = bvh.closest_point([1.0, 1.0, 0.0]).expect("ok");
    assert_eq!(
        (c.face, c.point, c.distance_squared),
        (0, [1.0, 0.0, 0.0], 1.0)
    );
    let c = bvh.closest_point([5.0, 5.0, 6.0]).expect("ok");
    assert_eq!(
        (c.face, c.point, c.distance_squared),
        (1, [5.0, 5.0, 5.0], 1.0)
    );
    // Rays never hit degenerate faces.
    assert!(
        bvh.ray_hits([1.0, 0.0, 1.0], [0.0, 0.0, -1.0], f64::INFINITY)
            .is_empty()
    );
}

#[test]
fn tree_is_deterministic_and_shallow() {
    let (pos, faces) = random_mesh(9, 5000);
    let a = Bvh::new(&pos, &faces).expect("ok");
    let b = Bvh::new(&pos, &faces).expect("ok");
    assert_eq!(a.order, b.order);
    let (nodes, depth) = a.shape();
    assert!(nodes < 2 * faces.len());
    // ⌈log₂(5000 / 4)⌉ + 1 = 12.
    assert!(depth <= 12, "depth {depth}");
    // A mesh with every centroid equal still splits (ties by index) and stays shallow.
    let pos = vec![[0.0; 3]; 3];
    let faces = vec![[0u32, 1, 2]; 1000];
    let t = Bvh::new(&pos, &faces).expect("ok");
    assert!(t.shape().1 <= 9);
    assert_eq!(t.overlapping_pairs().len(), 1000 * 999 / 2);
}

#[test]
fn candidate_pairs_hold_every_overlapping_pair_once_and_only_rounding_extras() {
    // Random soups of 500 and 2,000 faces (leaves of the pair traversal up to 32 faces, so both
    // leaf and interior splits are exercised).
    for (seed, nf) in [(3u64, 500usize), (8, 2000)] {
        let (pos, faces) = random_mesh(seed, nf);
        let bvh = Bvh::new(&pos, &faces).expect("ok");
        let mut got = Vec::new();
        bvh.for_each_candidate_pair(|a, b| got.push([a, b]));
        let n = got.len();
        got.sort_unstable();
        got.dedup();
        assert_eq!(got.len(), n, "a pair was reported twice");
        assert!(got.iter().all(|p| p[0] < p[1]));
        let want = brute_pairs(&pos, &faces);
        let mut extra = got.clone();
        extra.retain(|p| want.binary_search(p).is_err());
        assert_eq!(
            got.len() - extra.len(),
            want.len(),
            "an overlapping pair is missing"
        );
        // Extras: boxes apart by less than the f32 rounding.
        for p in &extra {
            let (a, b) = (bvh.face_bounds(p[0]), bvh.face_bounds(p[1]));
            let gap = (0..3)
                .map(|k| (a.lo[k] - b.hi[k]).max(b.lo[k] - a.hi[k]))
                .fold(f64::NEG_INFINITY, f64::max);
            assert!(gap > 0.0 && gap < 1e-6, "{p:?}: gap {gap}");
        }
    }
    // Two faces whose boxes are one f64 ulp apart at x = 1: a candidate (the f32 boxes touch),
    // never an overlapping pair.
    let x = 1.0f64;
    let y = f64::from_bits(x.to_bits() + 1);
    let pos = vec![
        [0.0, 0.0, 0.0],
        [x, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [y, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [2.0, 1.0, 0.0],
    ];
    let faces = vec![[0, 1, 2], [3, 4, 5]];
    let bvh = Bvh::new(&pos, &faces).expect("ok");
    let mut cands = Vec::new();
    bvh.for_each_candidate_pair(|a, b| cands.push([a, b]));
    assert_eq!(cands, vec![[0, 1]]);
    assert!(bvh.overlapping_pairs().is_empty());
}

#[test]
fn pair_build_gives_the_same_candidates_as_the_median_build() {
    let candidates = |bvh: &Bvh| {
        let mut c = Vec::new();
        bvh.for_each_candidate_pair(|a, b| c.push([a, b]));
        let n = c.len();
        c.sort_unstable();
        c.dedup();
        assert_eq!(c.len(), n, "a pair was reported twice");
        c
    };
    let mut cases = vec![
        random_mesh(3, 500),
        random_mesh(8, 2000),
        // Every centroid equal: every Morton code equal, split in halves by count.
        (vec![[0.0; 3]; 3], vec![[0, 1, 2]; 300]),
        // One face.
        (
            vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            vec![[0, 1, 2]],
        ),
    ];
    // Two clusters of very different sizes far apart (most Morton bits separate the clusters).
    let (mut pos, mut faces) = random_mesh(5, 700);
    let (far, far_faces) = random_mesh(6, 300);
    let base = pos.len() as u32;
    pos.extend(far.iter().map(|p| p.map(|c| 1e6 + 1e-3 * c)));
    faces.extend(far_faces.iter().map(|f| f.map(|v| v + base)));
    cases.push((pos, faces));
    // The Morton tree's candidates, as face pairs `(min, max)`, sorted; and its leaf order.
    let morton = |tree: &PairTree, order: &[u32]| {
        let mut c = Vec::new();
        tree.traverse(&[(0, 0)], |x, y| {
            let (f, g) = (order[x], order[y]);
            c.push([f.min(g), f.max(g)]);
        });
        let n = c.len();
        c.sort_unstable();
        c.dedup();
        assert_eq!(c.len(), n, "a pair was reported twice");
        c
    };
    for (pos, faces) in cases {
        let median = Bvh::new(&pos, &faces).expect("ok");
        let (tree, order, leaf_faces) = PairTree::for_mesh(&pos, &faces).expect("ok");
        let (_, again, _) = PairTree::for_mesh(&pos, &faces).expect("ok");
        assert!((0..faces.len()).all(|x| leaf_faces[x] == faces[order[x] as usize]));
        assert_eq!(order, again, "not deterministic");
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert!(sorted.iter().copied().eq(0..faces.len() as u32));
        assert_eq!(morton(&tree, &order), candidates(&median));
        // Moved vertices: the refitted tree gives the candidates of a tree built there.
        let moved: Vec<[f64; 3]> = pos
            .iter()
            .enumerate()
            .map(|(i, p)| [p[0] * 1.5 + (i % 7) as f64 * 0.01, p[2], -p[1]])
            .collect();
        let mut refitted = tree.clone();
        refitted.refit(|x| faces[order[x] as usize].map(|v| moved[v as usize]));
        let moved_median = Bvh::new(&moved, &faces).expect("ok");
        assert_eq!(morton(&refitted, &order), candidates(&moved_median));
        assert!(!candidates(&moved_median).is_empty() || faces.len() < 2);
    }
}

#[test]
fn filtered_closest_point_with_a_hint_equals_brute_force() {
    let (pos, faces) = random_mesh(13, 300);
    let bvh = Bvh::new(&pos, &faces).expect("ok");
    let mut rng = Rng(17);
    // Only the odd faces.
    let odd: Vec<[u32; 3]> = faces.iter().skip(1).step_by(2).copied().collect();
    for _ in 0..300 {
        let p = rng.point(1.6);
        let got = bvh.closest_point_filtered(p, |f| f % 2 == 1).expect("ok");
        let (k, d2) = brute_closest(&pos, &odd, p);
        assert_eq!(got.distance_squared, d2);
        assert_eq!(got.face, 2 * k + 1);
        // A hint, accepted or not, good or bad, changes nothing.
        for hint in [0, got.face, (got.face + 7) % faces.len() as u32, u32::MAX] {
            assert_eq!(
                bvh.closest_point_filtered_hinted(p, hint, |f| f % 2 == 1),
                Some(got)
            );
        }
    }
}

#[test]
fn pair_build_refuses_bad_input_as_the_median_build() {
    let pos = vec![
        [0.0; 3],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [f64::NAN, 0.0, 0.0],
    ];
    for faces in [vec![[0, 1, 2], [0, 1, 3]], vec![[0, 1, 2], [0, 1, 9]]] {
        // (Compared as text: the NaN of the error is not equal to itself.)
        let err = PairTree::for_mesh(&pos, &faces)
            .map(|_| ())
            .expect_err("refused");
        let want = Bvh::new(&pos, &faces).map(|_| ()).expect_err("refused");
        assert_eq!(err.to_string(), want.to_string());
    }
    let (tree, order, _) = PairTree::for_mesh(&pos, &[]).expect("empty is fine");
    assert!(order.is_empty());
    tree.traverse(&[(0, 0)], |_, _| panic!("no faces, no pairs"));
    assert!(tree.tasks(4).is_empty());
}

#[test]
fn outward_rounding_is_the_nearest_f32_on_the_far_side() {
    // The reference: round to nearest, then one step with the standard library's neighbours.
    let down = |x: f64| {
        let y = x as f32;
        if f64::from(y) > x { y.next_down() } else { y }
    };
    let up = |x: f64| {
        let y = x as f32;
        if f64::from(y) < x { y.next_up() } else { y }
    };
    let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
    let tiny = f64::from(f32::from_bits(1));
    let max = f64::from(f32::MAX);
    let mut xs = vec![
        0.0,
        -0.0,
        tiny,
        -tiny,
        tiny / 2.0,
        -tiny / 2.0,
        tiny / 3.0,
        -tiny / 3.0,
        1e-300,
        -1e-300,
        f64::from(f32::MIN_POSITIVE),
        f64::from(f32::MIN_POSITIVE) * (1.0 - 1e-12),
        1.0,
        -1.0,
        1.0 + f64::EPSILON,
        -1.0 - f64::EPSILON,
        1.0 - f64::EPSILON,
        0.1,
        -0.1,
        max,
        -max,
        max * (1.0 + 1e-12),
        -max * (1.0 + 1e-12),
        1e300,
        -1e300,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
        f64::MAX,
        f64::MIN,
    ];
    // Random bit patterns (every exponent, both signs) and random values near f32 grid points.
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for _ in 0..20_000 {
        xs.push(f64::from_bits(rng.next()));
        let g = f64::from(f32::from_bits(rng.next() as u32));
        let nudge = [-1i64, 0, 1][(rng.next() % 3) as usize];
        xs.push(f64::from_bits(g.to_bits().wrapping_add(nudge as u64)));
    }
    for &x in &xs {
        let (lo, hi) = (f32_outward(x, true), f32_outward(x, false));
        assert!(same(lo, down(x)), "down({x:e}): {lo:e} vs {:e}", down(x));
        assert!(same(hi, up(x)), "up({x:e}): {hi:e} vs {:e}", up(x));
        if !x.is_nan() {
            // On the far side of x, and the nearest f32 there.
            assert!(f64::from(lo) <= x && x <= f64::from(hi), "{x:e}");
            assert!(lo == f32::INFINITY || f64::from(lo.next_up()) > x, "{x:e}");
            assert!(
                hi == f32::NEG_INFINITY || f64::from(hi.next_down()) < x,
                "{x:e}"
            );
        }
    }
}
