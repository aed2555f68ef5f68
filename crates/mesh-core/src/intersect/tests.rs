use super::*;
use crate::predicates::tests::Rng;

type P = [f64; 3];

/// Two separate triangles (no shared index): do they intersect?
fn pair(t1: [P; 3], t2: [P; 3]) -> bool {
    let positions: Vec<P> = t1.iter().chain(t2.iter()).copied().collect();
    let r = self_intersections(&positions, &[[0, 1, 2], [3, 4, 5]]).expect("ok");
    r.pairs == vec![(0, 1)]
}

fn scale_all(ts: &[P], s: f64) -> Vec<P> {
    ts.iter().map(|p| p.map(|x| x * s)).collect()
}

/// The brute-force oracle: every pair `i < j` in index order, no BVH, no boxes.
fn oracle(positions: &[P], faces: &[[u32; 3]]) -> Vec<(u32, u32)> {
    let tris: Vec<Tri> = faces
        .iter()
        .map(|f| Tri::new(f.map(|v| positions[v as usize])))
        .collect();
    let mut out = Vec::new();
    for i in 0..faces.len() {
        for j in i + 1..faces.len() {
            if faces_intersect(faces[i], &tris[i], faces[j], &tris[j]) {
                out.push((i as u32, j as u32));
            }
        }
    }
    out
}

const BASE: [P; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

/// Every hand-made case `(name, t1, t2, expected)`, non-adjacent.
fn hand_cases() -> Vec<(&'static str, [P; 3], [P; 3], bool)> {
    let e = 1.0 / (1u64 << 40) as f64;
    vec![
        (
            "touching at a point (vertex on the interior)",
            BASE,
            [[0.25, 0.25, 0.0], [0.25, 1.25, 1.0], [1.25, 0.25, 1.0]],
            true,
        ),
        (
            "a hair above the point",
            BASE,
            [[0.25, 0.25, e], [0.25, 1.25, 1.0], [1.25, 0.25, 1.0]],
            false,
        ),
        (
            "crossing (one pierces the other)",
            BASE,
            [[0.2, 0.2, -1.0], [0.2, 0.2, 1.0], [0.3, 0.25, 0.0]],
            true,
        ),
        (
            "crossing edges (edge on edge, perpendicular)",
            BASE,
            [[0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [0.5, 0.0, 1.0]],
            true,
        ),
        (
            "edge crossing an edge in space",
            BASE,
            [[0.5, 0.0, -1.0], [0.5, 0.0, 1.0], [0.5, -1.0, 0.0]],
            true,
        ),
        (
            "edges passing by a hair",
            BASE,
            [[0.5, -e, -1.0], [0.5, -e, 1.0], [0.5, -1.0, 0.0]],
            false,
        ),
        (
            "coplanar overlap",
            BASE,
            [[0.2, 0.2, 0.0], [1.2, 0.2, 0.0], [0.2, 1.2, 0.0]],
            true,
        ),
        (
            "coplanar, one inside the other",
            BASE,
            [[0.1, 0.1, 0.0], [0.2, 0.1, 0.0], [0.1, 0.2, 0.0]],
            true,
        ),
        (
            "coplanar touching along an edge (separate vertices)",
            BASE,
            [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
            true,
        ),
        (
            "coplanar touching at a corner",
            BASE,
            [[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]],
            true,
        ),
        (
            "coplanar, a hair apart",
            BASE,
            [[1.0 + e, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]],
            false,
        ),
        (
            "parallel planes",
            BASE,
            [[0.0, 0.0, e], [1.0, 0.0, e], [0.0, 1.0, e]],
            false,
        ),
        (
            "needles crossing",
            [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 1.0 + e, 0.0]],
            [[0.0, 1.0, -e], [1.0, 0.0, -e], [0.5, 0.5, e]],
            true,
        ),
        (
            "needles passing",
            [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 1.0 + e, 0.0]],
            [[0.0, 1.0, e], [1.0, 0.0, e], [0.5, 0.5, 2.0 * e]],
            false,
        ),
    ]
}

#[test]
fn hand_made_cases_at_every_scale() {
    for (name, t1, t2, want) in hand_cases() {
        assert_eq!(pair(t1, t2), want, "{name}");
        assert_eq!(pair(t2, t1), want, "{name} (swapped)");
        // 2^±332 ≈ 1e±100 (exact scalings: the same answer), and the ends of the range.
        for e in [-332i32, 332, -1000, 1000] {
            let s = 2f64.powi(e);
            let a = scale_all(&t1, s);
            let b = scale_all(&t2, s);
            assert_eq!(
                pair([a[0], a[1], a[2]], [b[0], b[1], b[2]]),
                want,
                "{name} at 2^{e}"
            );
        }
    }
}

#[test]
fn edge_adjacent_faces_count_only_when_folded() {
    // Faces (0, 1, 2) and (1, 0, 3) share edge 0–1.
    let e = 1.0 / (1u64 << 40) as f64;
    let check = |d: P| {
        let positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.3, 1.0, 0.0], d];
        self_intersections(&positions, &[[0, 1, 2], [1, 0, 3]])
            .expect("ok")
            .pairs
            .len()
    };
    assert_eq!(check([0.6, 0.5, 0.0]), 1, "folded flat onto the other face");
    assert_eq!(
        check([5.0, 0.1, 0.0]),
        1,
        "folded, no vertex inside the other"
    );
    assert_eq!(check([0.6, -0.5, 0.0]), 0, "flat neighbour");
    assert_eq!(check([0.6, 0.5, e]), 0, "almost folded");
    assert_eq!(check([0.6, -0.5, 1.0]), 0, "a dihedral angle");
    // The same at 1e-100 and 1e100.
    for s in [2f64.powi(-332), 2f64.powi(332)] {
        let positions = scale_all(
            &[
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.3, 1.0, 0.0],
                [0.6, 0.5, 0.0],
            ],
            s,
        );
        assert_eq!(
            self_intersections(&positions, &[[0, 1, 2], [1, 0, 3]])
                .expect("ok")
                .pairs
                .len(),
            1
        );
    }
}

#[test]
fn vertex_adjacent_faces_count_when_they_meet_elsewhere() {
    let check = |a: P, b: P, c: P, d: P| {
        let positions = vec![[0.0, 0.0, 0.0], a, b, c, d];
        self_intersections(&positions, &[[0, 1, 2], [0, 3, 4]])
            .expect("ok")
            .pairs
            .len()
    };
    // A crossing through the shared vertex: both contain the direction +x.
    assert_eq!(
        check(
            [1.0, 1.0, 0.0],
            [1.0, -1.0, 0.0],
            [0.1, 0.0, 0.1],
            [0.1, 0.0, -0.1]
        ),
        1
    );
    // Meeting at the shared vertex only (a fan around it).
    assert_eq!(
        check(
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0]
        ),
        0
    );
    assert_eq!(
        check(
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [-1.0, -1.0, 1.0]
        ),
        0
    );
    // Coplanar overlapping corners.
    assert_eq!(
        check(
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 2.0, 0.0]
        ),
        1
    );
    // Coplanar, touching along an edge ray from the vertex (separate end vertices).
    assert_eq!(
        check(
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 2.0, 0.0],
            [-1.0, 1.0, 0.0]
        ),
        1
    );
    // An opposite edge meeting the other face away from the vertex.
    assert_eq!(
        check(
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.4, 0.4, -1.0],
            [0.4, 0.4, 1.0]
        ),
        1
    );
    // Coplanar, opposite cones.
    assert_eq!(
        check(
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0]
        ),
        0
    );
}

#[test]
fn duplicate_and_degenerate_faces() {
    let positions = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.5, 0.0, 0.0],
    ];
    // A duplicated face (reversed) and a zero-area face lying inside face 0.
    let r =
        self_intersections(&positions, &[[0, 1, 2], [0, 2, 1], [0, 3, 1], [2, 2, 1]]).expect("ok");
    assert_eq!(r.pairs, vec![(0, 1)]);
    assert_eq!(r.faces, vec![0, 1]);
    assert_eq!(r.degenerate, vec![2, 3]);
}

#[test]
fn a_triangle_through_a_tetrahedron() {
    // The case of CGAL's `tetra_intersected_by_triangle.off`, built by hand.
    let tet = crate::shapes::tetrahedron();
    let mut positions = tet.positions.clone();
    let mut faces = tet.faces.clone();
    let clean = self_intersections(&positions, &faces).expect("ok");
    assert!(clean.pairs.is_empty());
    let n = positions.len() as u32;
    positions.extend([[-3.0, -3.0, 0.25], [3.0, -3.0, 0.25], [0.0, 3.0, 0.25]]);
    faces.push([n, n + 1, n + 2]);
    let r = self_intersections(&positions, &faces).expect("ok");
    let f = faces.len() as u32 - 1;
    // The three side faces, not the base.
    assert_eq!(r.pairs, vec![(1, f), (2, f), (3, f)]);
    assert_eq!(r.per_component.len(), 2);
    assert_eq!(r.per_component[1].pairs_across, r.pairs.len());
    println!("triangle through a tetrahedron: pairs {:?}", r.pairs);
    assert!(new_pairs(&r, &r).expect("ok").is_empty());
}

#[test]
fn clean_closed_meshes_have_no_pairs() {
    for level in 0..4 {
        let m = crate::shapes::icosphere(level);
        let r = self_intersections(&m.positions, &m.faces).expect("ok");
        assert!(r.pairs.is_empty(), "icosphere({level}): {:?}", r.pairs);
        assert!(r.degenerate.is_empty());
        assert_eq!(r.per_component.len(), 1);
    }
    let m = crate::shapes::octahedron();
    assert!(
        self_intersections(&m.positions, &m.faces)
            .expect("ok")
            .pairs
            .is_empty()
    );
}

#[test]
fn new_pairs_are_pairs_not_counts() {
    let m = crate::shapes::icosphere(2);
    let mut checker = SelfIntersectionChecker::new(&m.positions, &m.faces).expect("ok");
    let source = checker.check();
    // Push one vertex through the opposite side of the sphere.
    let mut moved = m.positions.clone();
    moved[0] = moved[0].map(|x| -1.5 * x);
    let deformed = checker.check_moved(&moved).expect("ok");
    let new = new_pairs(&source, &deformed).expect("ok");
    assert!(!new.is_empty());
    assert_eq!(new, deformed.pairs);
    // The checker after a refit answers as a fresh check.
    assert_eq!(deformed, self_intersections(&moved, &m.faces).expect("ok"));
    // Back to the source: nothing new.
    let back = checker.check_moved(&m.positions).expect("ok");
    assert!(new_pairs(&source, &back).expect("ok").is_empty());
    assert!(new_pairs(&back, &deformed).expect("ok") == deformed.pairs);
}

#[test]
fn bad_input_is_refused_clearly() {
    let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    assert_eq!(self_intersections(&p, &[]), Err(IntersectError::Empty));
    let e = self_intersections(&p, &[[0, 1, 3]]).expect_err("refused");
    assert!(e.to_string().contains("face 0 uses vertex 3"), "{e}");
    let mut bad = p.clone();
    bad[1][2] = f64::NAN;
    let e = self_intersections(&bad, &[[0, 1, 2]]).expect_err("refused");
    assert!(e.to_string().contains("non-finite"), "{e}");
    bad[1][2] = f64::INFINITY;
    assert!(self_intersections(&bad, &[[0, 1, 2]]).is_err());
    let mut c = SelfIntersectionChecker::new(&p, &[[0, 1, 2]]).expect("ok");
    assert!(c.update(&p[..2]).is_err());
    assert!(c.update(&bad).is_err());
    assert!(
        c.check().pairs.is_empty(),
        "unchanged after a refused update"
    );
    let a = c.check();
    let m = crate::shapes::tetrahedron();
    let b = self_intersections(&m.positions, &m.faces).expect("ok");
    assert!(matches!(
        new_pairs(&a, &b),
        Err(IntersectError::DifferentMeshes { .. })
    ));
    // Huge but finite coordinates are fine.
    let huge = vec![[0.0, 0.0, 0.0], [f64::MAX, 0.0, 0.0], [0.0, f64::MAX, 0.0]];
    assert!(
        self_intersections(&huge, &[[0, 1, 2]])
            .expect("ok")
            .pairs
            .is_empty()
    );
}

/// A random soup on a coarse integer grid: many coplanar, collinear and touching configurations.
fn random_soup(rng: &mut Rng, n: usize, grid: i64, shared: bool) -> (Vec<P>, Vec<[u32; 3]>) {
    let nv = if shared { n } else { 3 * n };
    let positions: Vec<P> = (0..nv)
        .map(|_| [0; 3].map(|_| rng.int(grid) as f64 * 0.125))
        .collect();
    let faces = (0..n)
        .map(|i| {
            if shared {
                [0; 3].map(|_| (rng.next_u64() % nv as u64) as u32)
            } else {
                [3 * i as u32, 3 * i as u32 + 1, 3 * i as u32 + 2]
            }
        })
        .collect();
    (positions, faces)
}

#[test]
fn random_soups_match_the_brute_force_oracle() {
    let mut rng = Rng::new(11);
    let mut total = 0;
    for round in 0..300 {
        let grid = [2, 3, 8, 1000][round % 4];
        let (p, f) = random_soup(&mut rng, 12 + round % 20, grid, round % 2 == 0);
        let r = self_intersections(&p, &f).expect("ok");
        assert_eq!(r.pairs, oracle(&p, &f), "round {round}");
        total += r.pairs.len();
        // At 1e±100 (exact power-of-two scaling) the answer is the same.
        if round % 10 == 0 {
            for e in [-332, 332] {
                let q = scale_all(&p, 2f64.powi(e));
                assert_eq!(self_intersections(&q, &f).expect("ok").pairs, r.pairs);
            }
        }
    }
    assert!(total > 100);
}

/// A jittered `k×k` grid in the plane z = 0, folded over along x = fold (the part beyond is
/// mirrored back onto the rest, lifted by `lift`).
fn folded_grid(rng: &mut Rng, k: usize, fold: f64, lift: f64) -> (Vec<P>, Vec<[u32; 3]>) {
    let mut positions = Vec::new();
    for j in 0..=k {
        for i in 0..=k {
            let jit = |r: &mut Rng| r.int(1) as f64 / 64.0;
            let x = i as f64 / k as f64 + jit(rng);
            let y = j as f64 / k as f64 + jit(rng);
            let (x, z) = if x > fold {
                (2.0 * fold - x, lift)
            } else {
                (x, 0.0)
            };
            positions.push([x, y, z]);
        }
    }
    let mut faces = Vec::new();
    let w = (k + 1) as u32;
    for j in 0..k as u32 {
        for i in 0..k as u32 {
            let (a, b, c, d) = (
                j * w + i,
                j * w + i + 1,
                (j + 1) * w + i,
                (j + 1) * w + i + 1,
            );
            faces.push([a, b, d]);
            faces.push([a, d, c]);
        }
    }
    (positions, faces)
}

#[test]
fn folded_grids_match_the_brute_force_oracle() {
    let mut rng = Rng::new(12);
    for round in 0..40 {
        let lift = [0.0, 0.0, 1.0 / 128.0, -1.0 / 64.0][round % 4];
        let fold = [0.5, 0.375, 0.625][round % 3];
        let (p, f) = folded_grid(&mut rng, 6 + round % 4, fold, lift);
        let r = self_intersections(&p, &f).expect("ok");
        assert_eq!(r.pairs, oracle(&p, &f), "round {round}");
        if lift == 0.0 {
            assert!(!r.pairs.is_empty(), "a flat fold overlaps itself");
        }
    }
}

/// Möller–Trumbore in plain f64 (the BVH's ray test) on each edge as a segment: an independent
/// test that is right for generic (non-degenerate, non-coplanar) random triangles.
fn float_tri_tri(a: &[P; 3], b: &[P; 3]) -> bool {
    let edge_hits = |t: &[P; 3], u: &[P; 3]| {
        (0..3).any(|i| {
            let (p, q) = (t[i], t[(i + 1) % 3]);
            let d = crate::geometry::sub(q, p);
            matches!(crate::bvh::ray_triangle(p, d, u), Some((s, _)) if s <= 1.0)
        })
    };
    edge_hits(a, b) || edge_hits(b, a)
}

#[test]
fn generic_triangles_agree_with_a_float_test() {
    let mut rng = Rng::new(13);
    let mut hits = 0;
    for _ in 0..20_000 {
        let t: Vec<P> = (0..6)
            .map(|_| [rng.unit(), rng.unit(), rng.unit()])
            .collect();
        let (a, b) = ([t[0], t[1], t[2]], [t[3], t[4], t[5]]);
        let want = float_tri_tri(&a, &b);
        assert_eq!(
            triangles_intersect(&Tri::new(a), &Tri::new(b)),
            want,
            "{a:?} {b:?}"
        );
        hits += usize::from(want);
    }
    assert!(hits > 1000);
}

/// A torus with `n × m` quads (`2nm` faces).
fn torus(n: usize, m: usize) -> (Vec<P>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (u, v) = (
                i as f64 / n as f64 * std::f64::consts::TAU,
                j as f64 / m as f64 * std::f64::consts::TAU,
            );
            let r = 1.0 + 0.35 * v.cos();
            p.push([r * u.cos(), r * u.sin(), 0.35 * v.sin()]);
        }
    }
    let mut f = Vec::new();
    let id = |i: usize, j: usize| ((i % n) * m + j % m) as u32;
    for i in 0..n {
        for j in 0..m {
            f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    (p, f)
}

#[test]
fn tori_are_clean() {
    let (p, f) = torus(24, 12);
    assert!(self_intersections(&p, &f).expect("ok").pairs.is_empty());
}

/// Print-only timings of the checker's refit + query (the viewer's per-slider-move cost);
/// `cargo test -p mesh-core --lib intersect::tests::timing -- --ignored --nocapture`.
#[test]
#[ignore = "print-only timing"]
fn timing_refit_and_check() {
    for (n, m) in [(200, 100), (295, 200)] {
        let (p, f) = torus(n, m);
        let t0 = std::time::Instant::now();
        let mut checker = SelfIntersectionChecker::new(&p, &f).expect("ok");
        let build = t0.elapsed();
        let reps = 5;
        let (mut refit, mut check) = (0.0, 0.0);
        let mut last = None;
        for k in 0..reps {
            let s = 1.0 + 0.01 * k as f64;
            let moved: Vec<P> = p
                .iter()
                .map(|q| [q[0] * s, q[1], q[2] * (1.0 + 0.1 * (3.0 * q[0]).sin())])
                .collect();
            let t = std::time::Instant::now();
            checker.update(&moved).expect("ok");
            refit += t.elapsed().as_secs_f64();
            let t = std::time::Instant::now();
            last = Some(checker.check());
            check += t.elapsed().as_secs_f64();
        }
        let r = last.expect("ok");
        println!(
            "{} faces: build {:.1} ms, refit {:.2} ms, check {:.1} ms (mean of {reps}; {} candidates, {} pairs)",
            f.len(),
            build.as_secs_f64() * 1e3,
            refit / reps as f64 * 1e3,
            check / reps as f64 * 1e3,
            r.candidates,
            r.pairs.len()
        );
    }
}

/// The shared-edge filter never claims "opposite sides" for a configuration on one side: exact
/// folds (both opposite corners in the plane, same side — the filter must defer, and the fold is
/// found) and near-folds, at scales 2^-60..2^60; and it does decide flat neighbours (opposite
/// sides) in most cases, which is its point.
#[test]
fn shared_edge_filter_only_decides_opposite_sides() {
    let mut rng = Rng::new(41);
    let mut decided = 0usize;
    let n = 20_000;
    for k in 0..n {
        let s = 2f64.powi((k % 121) as i32 - 60);
        let t = [rng.unit(), rng.unit(), rng.unit()].map(|x| (x - 0.5) * s);
        let at = |x: f64, y: f64, z: f64| [t[0] + x * s, t[1] + y * s, t[2] + z * s];
        let (u, v) = (at(0.0, 0.0, 0.0), at(1.0, 0.0, 0.0));
        let (x1, x2) = (rng.unit() * 2.0 - 0.5, rng.unit() * 2.0 - 0.5);
        let (y1, y2) = (rng.unit() + 1e-3, rng.unit() + 1e-3);
        let dz = if k % 2 == 0 {
            0.0
        } else {
            (rng.unit() - 0.5) * 1e-9
        };
        // Same side (a fold when dz = 0): never "clearly opposite".
        let (a, b) = (at(x1, y1, 0.0), at(x2, y2, dz));
        assert!(!clearly_opposite_sides(u, v, a, b), "{k}: {a:?} {b:?}");
        // Opposite sides (a flat or nearly flat neighbour).
        let b = at(x2, -y2, dz);
        if clearly_opposite_sides(u, v, a, b) {
            decided += 1;
            assert!(!edge_fold(u, v, a, b, &Tri::new([u, v, a])));
        }
    }
    assert!(decided > n * 9 / 10, "{decided} of {n}");
}

/// A fan of `k` faces around vertex 0 at the origin: link vertex `i` at angle `turns·2π·i/k`
/// (exactly: cos/sin rounded, then scaled), radius `r[i]`, height `z[i]`; closed or open.
fn fan(angles: &[f64], r: &[f64], z: &[f64], closed: bool) -> (Vec<P>, Vec<[u32; 3]>) {
    let mut positions = vec![[0.0; 3]];
    for i in 0..angles.len() {
        positions.push([r[i] * angles[i].cos(), r[i] * angles[i].sin(), z[i]]);
    }
    let k = angles.len() as u32;
    let faces = (0..if closed { k } else { k - 1 })
        .map(|i| [0, 1 + i, 1 + (i + 1) % k])
        .collect();
    (positions, faces)
}

#[test]
fn fans_are_built_only_for_simple_consistent_chains() {
    // A closed fan of 6 (octahedron-like vertex), an open one, and the refused kinds.
    let closed: Vec<[u32; 3]> = (0..6).map(|i| [0, 1 + i, 1 + (i + 1) % 6]).collect();
    let f = Fans::new(7, &closed);
    assert_eq!(f.kind[0], 1);
    assert_eq!(
        &f.link[f.offsets[0] as usize..f.offsets[1] as usize],
        &[1, 2, 3, 4, 5, 6]
    );
    // Each link vertex has an open fan of two faces.
    assert_eq!(f.kind[1], 2);
    let open: Vec<[u32; 3]> = (0..5).map(|i| [0, 1 + i, 2 + i]).collect();
    let f = Fans::new(7, &open);
    assert_eq!(f.kind[0], 2);
    assert_eq!(
        &f.link[f.offsets[0] as usize..f.offsets[1] as usize],
        &[1, 2, 3, 4, 5, 6]
    );
    // One face flipped: inconsistent orientation.
    let mut flipped = closed.clone();
    flipped[2] = [0, 4, 3];
    assert_eq!(Fans::new(7, &flipped).kind[0], 0);
    // A duplicated face, either orientation.
    let mut dup = closed.clone();
    dup.push(closed[0]);
    assert_eq!(Fans::new(7, &dup).kind[0], 0);
    let two = vec![[0, 1, 2], [0, 2, 1]];
    assert_eq!(Fans::new(3, &two).kind[0], 0);
    // Two fans through one vertex (a bow tie), and a face using the vertex twice.
    let bowtie = vec![
        [0, 1, 2],
        [0, 2, 3],
        [0, 3, 1],
        [0, 4, 5],
        [0, 5, 6],
        [0, 6, 4],
    ];
    assert_eq!(Fans::new(7, &bowtie).kind[0], 0);
    assert_eq!(Fans::new(3, &[[0, 0, 1], [0, 1, 2]]).kind[0], 0);
}

#[test]
fn fans_up_to_the_size_limit_are_built_and_larger_ones_are_left_to_the_pairs() {
    // A flat closed fan of MAX_FAN faces has a fan (certified); one more face and it has none,
    // and its pairs are still the oracle's: none when flat, the crossings when it winds twice.
    for (k, turns) in [
        (Fans::MAX_FAN, 1.0),
        (Fans::MAX_FAN + 1, 1.0),
        (Fans::MAX_FAN + 1, 2.0),
    ] {
        let angles: Vec<f64> = (0..k)
            .map(|i| turns * std::f64::consts::TAU * i as f64 / k as f64)
            .collect();
        let z: Vec<f64> = (0..k).map(|i| (turns - 1.0) * 0.01 * i as f64).collect();
        let (p, f) = fan(&angles, &vec![1.0; k], &z, true);
        let checker = SelfIntersectionChecker::new(&p, &f).expect("ok");
        assert_eq!(checker.fans.kind[0] != 0, k <= Fans::MAX_FAN, "k = {k}");
        if k <= Fans::MAX_FAN {
            assert_eq!(
                &checker.fans.link[..k],
                &(1..=k as u32).collect::<Vec<_>>()[..]
            );
            assert!(checker.fans.certify(&p)[0]);
        }
        let r = checker.check();
        assert_eq!(r.pairs, oracle(&p, &f), "k = {k}, turns = {turns}");
        assert_eq!(r.pairs.is_empty(), turns == 1.0, "k = {k}, turns = {turns}");
    }
}

#[test]
fn fans_winding_twice_are_not_certified_and_their_pairs_are_found() {
    // A spiral staircase around the vertex: 7 link vertices, each face turning 2·(2π/7), so the
    // closed fan winds twice around it and must cross itself to close. And an open fan turning
    // 1.3 times (a helicoid step: certified or not, the pairs are the oracle's). Neither may be certified; the pairs must equal the brute-force oracle's.
    for (k, turns, closed) in [(7usize, 2.0, true), (9, 1.3, false), (5, 2.0, true)] {
        let angles: Vec<f64> = (0..k)
            .map(|i| turns * std::f64::consts::TAU * i as f64 / k as f64)
            .collect();
        let z: Vec<f64> = (0..k).map(|i| 0.25 * (i as f64 - k as f64 / 2.0)).collect();
        let (p, f) = fan(&angles, &vec![1.0; k], &z, closed);
        let checker = SelfIntersectionChecker::new(&p, &f).expect("ok");
        assert_ne!(checker.fans.kind[0], 0, "a simple chain");
        assert!(!checker.fans.certify(&p)[0], "k = {k}, turns = {turns}");
        let r = checker.check();
        assert_eq!(r.pairs, oracle(&p, &f));
        // Closed, the staircase must come back down through itself; open, it need not.
        assert!(
            !closed || !r.pairs.is_empty(),
            "k = {k}: the staircase crosses itself"
        );
        // Flattened (all heights 0) the faces overlap in the plane: still found.
        let (p, f) = fan(&angles, &vec![1.0; k], &vec![0.0; k], closed);
        let r = self_intersections(&p, &f).expect("ok");
        assert_eq!(r.pairs, oracle(&p, &f));
        assert!(!r.pairs.is_empty());
    }
}

/// A random fan around vertex 0 for round `round`: `3 + round % 8` links at angles on a grid of
/// `[4, 16, 1000][round % 3]` steps over `[0, arc)` (sorted unless `round % 4 == 0`, so some fans
/// fold over themselves), radii 1 or 1.25, heights on the same grid times `zscale`; closed on
/// even rounds.
fn random_fan(rng: &mut Rng, round: usize, arc: f64, zscale: f64) -> (Vec<P>, Vec<[u32; 3]>) {
    let k = 3 + round % 8;
    let grid = [4, 16, 1000][round % 3];
    let mut angles: Vec<f64> = (0..k)
        .map(|_| rng.int(grid) as f64 / grid as f64 * arc)
        .collect();
    if !round.is_multiple_of(4) {
        angles.sort_by(f64::total_cmp);
    }
    let r: Vec<f64> = (0..k).map(|_| 1.0 + rng.int(2) as f64 * 0.25).collect();
    let z: Vec<f64> = (0..k)
        .map(|_| rng.int(grid) as f64 / grid as f64 * zscale)
        .collect();
    fan(&angles, &r, &z, round.is_multiple_of(2))
}

/// Checks the fan `(p, f)` against the brute-force oracle (the same pairs; a certified fan has
/// none) and returns whether its vertex 0 was certified, with the oracle's pairs.
fn fan_against_the_oracle(p: &[P], f: &[[u32; 3]], round: usize) -> (bool, Vec<(u32, u32)>) {
    let checker = SelfIntersectionChecker::new(p, f).expect("ok");
    let cert = checker.fans.kind[0] != 0 && checker.fans.certify(p)[0];
    let expected = oracle(p, f);
    assert_eq!(checker.check().pairs, expected, "round {round}");
    assert!(
        !cert || expected.is_empty(),
        "round {round}: certified fan with pairs"
    );
    (cert, expected)
}

#[test]
fn random_fans_match_the_brute_force_oracle() {
    // Fans around one vertex with random (sorted or not) angles, radii and heights on coarse
    // grids (coplanar, collinear and folded configurations), closed and open, each also at
    // 2^±332: whenever a fan is certified, the oracle must find no pair sharing its vertex.
    let mut rng = Rng::new(13);
    let (mut certified, mut not, mut with_pairs) = (0, 0, 0);
    for round in 0..600 {
        let zscale = [0.0, 0.125, 1.0][round % 3];
        let (p, f) = random_fan(&mut rng, round, std::f64::consts::PI, zscale);
        let (cert, expected) = fan_against_the_oracle(&p, &f, round);
        if cert {
            certified += 1;
        } else {
            not += 1;
        }
        with_pairs += usize::from(!expected.is_empty());
        for e in [-332, 332] {
            let q = scale_all(&p, 2f64.powi(e));
            assert_eq!(self_intersections(&q, &f).expect("ok").pairs, expected);
        }
    }
    assert!(
        certified > 100 && not > 100 && with_pairs > 50,
        "{certified} {not} {with_pairs}"
    );
}

#[test]
fn fans_folded_at_a_crease_are_certified_along_their_normal() {
    // A vertex in the middle of a cube's edge: three faces on the top (normal −z here), three on
    // the side (−y). Along any coordinate axis one half projects to zero area, so only the
    // projection along the fan's summed normal certifies it; no pair.
    let links = [
        [1.0, 0.0, 0.0],
        [0.5, -1.0, 0.0],
        [-0.5, -1.0, 0.0],
        [-1.0, 0.0, 0.0],
        [-0.5, 0.0, -1.0],
        [0.5, 0.0, -1.0],
    ];
    let mut p = vec![[0.0; 3]];
    p.extend_from_slice(&links);
    let f: Vec<[u32; 3]> = (0..6).map(|i| [0, 1 + i, 1 + (i + 1) % 6]).collect();
    let checker = SelfIntersectionChecker::new(&p, &f).expect("ok");
    assert_eq!(checker.fans.kind[0], 1);
    assert!(checker.fans.certify(&p)[0]);
    assert!(checker.check().pairs.is_empty());
    assert!(oracle(&p, &f).is_empty());
    // Folded further (the side pushed under the top, a dihedral angle of 45°) still certified;
    // folded onto itself (the side's links moved into the top's half-space, crossing it) not,
    // and the pairs are the oracle's.
    for (dy, want_cert) in [(0.5, true), (-1.5, false)] {
        let mut q = p.clone();
        for v in q.iter_mut().skip(5) {
            v[1] = dy;
        }
        let checker = SelfIntersectionChecker::new(&q, &f).expect("ok");
        let expected = oracle(&q, &f);
        assert_eq!(checker.check().pairs, expected, "dy = {dy}");
        assert_eq!(checker.fans.certify(&q)[0], want_cert, "dy = {dy}");
        if want_cert {
            assert!(expected.is_empty());
        }
    }
}

#[test]
fn rotated_random_fans_match_the_brute_force_oracle() {
    // The random fans of `random_fans_match_the_brute_force_oracle`, folded about a random line
    // through the vertex and turned by a random rotation (so neither the coordinate axes nor
    // the fan's plane line up): certified only without pairs, pairs always the oracle's.
    let mut rng = Rng::new(0x5e1f_0006);
    let (mut certified, mut not) = (0, 0);
    for round in 0..600 {
        let (mut p, f) = random_fan(&mut rng, round, std::f64::consts::TAU, 0.125);
        // Fold: links with y < 0 rotated about the x axis by up to ±120°.
        let fold = (rng.unit() - 0.5) * 4.2;
        let (fc, fs) = (fold.cos(), fold.sin());
        for v in p.iter_mut().skip(1) {
            if v[1] < 0.0 {
                *v = [v[0], fc * v[1] - fs * v[2], fs * v[1] + fc * v[2]];
            }
        }
        // Rotate: about z, then x, then z again, by random angles.
        let rot = |v: [f64; 3], a: f64, axis: usize| {
            let (c, s) = (a.cos(), a.sin());
            let (i, j) = [(1, 2), (2, 0), (0, 1)][axis];
            let mut w = v;
            w[i] = c * v[i] - s * v[j];
            w[j] = s * v[i] + c * v[j];
            w
        };
        let (a1, a2, a3) = (rng.unit() * 6.3, rng.unit() * 6.3, rng.unit() * 6.3);
        for v in p.iter_mut() {
            *v = rot(rot(rot(*v, a1, 2), a2, 0), a3, 2);
        }
        if fan_against_the_oracle(&p, &f, round).0 {
            certified += 1;
        } else {
            not += 1;
        }
    }
    assert!(certified > 50 && not > 50, "{certified} {not}");
}

#[test]
fn threads_give_the_same_answer() {
    // A torus with a band pushed through the opposite side (pairs), checked on 1, 2 and 3
    // threads: same pairs, same candidates.
    let (mut p, f) = torus(60, 24);
    for q in p.iter_mut().take(24 * 6) {
        q[0] = -q[0] * 1.2;
    }
    let mut checker = SelfIntersectionChecker::new(&p, &f).expect("ok");
    let one = checker.check();
    assert!(!one.pairs.is_empty());
    for t in [2, 3] {
        checker.set_threads(t);
        assert_eq!(checker.check(), one, "{t} threads");
    }
}

/// The edge-crossing test that `straddling_overlap` replaced for the generic straddling case:
/// every edge of each triangle against the other (the plane sides first).
fn triangles_intersect_by_edges(ta: &Tri, tb: &Tri) -> bool {
    let sb = plane_sides(ta, tb);
    let sa = plane_sides(tb, ta);
    if strictly_one_side(&sb) || strictly_one_side(&sa) {
        return false;
    }
    if sb.iter().all(|&s| s == Sign::Zero) {
        let Some(k) = ta.drop else { return false };
        return (0..3).any(|i| segment_triangle_2d(tb.p[i], tb.p[(i + 1) % 3], ta, k))
            || point_in_triangle_2d(ta.p[0], tb, k);
    }
    (0..3).any(|i| {
        let j = (i + 1) % 3;
        segment_meets(tb.p[i], tb.p[j], sb[i], sb[j], ta)
    }) || (0..3).any(|i| {
        let j = (i + 1) % 3;
        segment_meets(ta.p[i], ta.p[j], sa[i], sa[j], tb)
    })
}

/// A random corner for round `round` of the straddling tests: in the unit cube, on a 3 × 3 × 3
/// grid (touching at edges and corners, corners on the other plane), or nearly flat (z < 1e-9).
fn straddle_test_point(rng: &mut Rng, round: usize) -> P {
    match round % 3 {
        0 => [rng.unit(), rng.unit(), rng.unit()],
        1 => [0; 3].map(|_| rng.int(3) as f64),
        _ => [rng.unit(), rng.unit(), 1e-9 * rng.unit()],
    }
}

/// The two-`orient3d` test of straddling triangles against the edge crossings, on random pairs
/// of both orientations: generic (unit cube), on coarse grids (touching at edges and corners,
/// corners on the other plane: the other path) and crossing near-parallel; both answers occur.
#[test]
fn straddling_test_agrees_with_the_edge_crossings() {
    let mut rng = Rng::new(17);
    let (mut straddling, mut hits) = (0, 0);
    for round in 0..60_000 {
        let point = |rng: &mut Rng| straddle_test_point(rng, round);
        let a = [point(&mut rng), point(&mut rng), point(&mut rng)];
        let mut b = [point(&mut rng), point(&mut rng), point(&mut rng)];
        if round % 2 == 1 {
            b.swap(1, 2);
        }
        let (ta, tb) = (Tri::new(a), Tri::new(b));
        if ta.drop.is_none() || tb.drop.is_none() {
            continue;
        }
        let want = triangles_intersect_by_edges(&ta, &tb);
        assert_eq!(triangles_intersect(&ta, &tb), want, "{a:?} {b:?}");
        assert_eq!(triangles_intersect(&tb, &ta), want, "{b:?} {a:?}");
        let (sb, sa) = (plane_sides(&ta, &tb), plane_sides(&tb, &ta));
        if !sa.contains(&Sign::Zero)
            && !sb.contains(&Sign::Zero)
            && !strictly_one_side(&sa)
            && !strictly_one_side(&sb)
        {
            straddling += 1;
            hits += usize::from(want);
        }
    }
    println!("{straddling} straddling, {hits} meeting");
    assert!(
        straddling > 5_000 && hits > 1_000 && straddling - hits > 1_000,
        "{straddling} {hits}"
    );
}

/// The shared-corner test before `straddling_at_corner`: the edges opposite the corner against
/// the other face, and the corner's edges entering the other's corner.
fn vertex_adjacent_by_edges(ta: &Tri, tb: &Tri) -> bool {
    let [v, a1, b1] = ta.p;
    let [_, a2, b2] = tb.p;
    let sb = [Sign::Zero, o3(v, a1, b1, a2), o3(v, a1, b1, b2)];
    let sa = [Sign::Zero, o3(v, a2, b2, a1), o3(v, a2, b2, b1)];
    if (sb[1] == sb[2] && sb[1] != Sign::Zero) || (sa[1] == sa[2] && sa[1] != Sign::Zero) {
        return false;
    }
    segment_meets(a1, b1, sa[1], sa[2], tb)
        || segment_meets(a2, b2, sb[1], sb[2], ta)
        || enters_corner(a1, sa[1], tb)
        || enters_corner(b1, sa[2], tb)
        || enters_corner(a2, sb[1], ta)
        || enters_corner(b2, sb[2], ta)
}

/// The one-`orient3d` test of faces sharing a corner and straddling each other's planes against
/// the edge tests, on random pairs around a shared corner (generic, on coarse grids, nearly
/// flat), both orientations; both answers occur among the straddling ones.
#[test]
fn straddling_at_a_corner_agrees_with_the_edge_tests() {
    let mut rng = Rng::new(19);
    let (mut straddling, mut hits) = (0, 0);
    for round in 0..60_000 {
        let point = |rng: &mut Rng| straddle_test_point(rng, round);
        let v = point(&mut rng);
        let a = [v, point(&mut rng), point(&mut rng)];
        let mut b = [v, point(&mut rng), point(&mut rng)];
        if round % 2 == 1 {
            b.swap(1, 2);
        }
        if round % 4 < 2 {
            // Mirrored through the corner: crossing planes, pointing away from each other.
            b = b.map(|p| [0, 1, 2].map(|k| 2.0 * v[k] - p[k]));
        }
        let (ta, tb) = (Tri::new(a), Tri::new(b));
        if ta.drop.is_none() || tb.drop.is_none() {
            continue;
        }
        let want = vertex_adjacent_by_edges(&ta, &tb);
        assert_eq!(
            vertex_adjacent_intersect::<true>(&ta, &tb),
            want,
            "{a:?} {b:?}"
        );
        assert_eq!(
            vertex_adjacent_intersect::<false>(&tb, &ta),
            want,
            "{b:?} {a:?}"
        );
        let [p, a1, b1] = a;
        let [_, a2, b2] = b;
        let sides = [
            o3(p, a1, b1, a2),
            o3(p, a1, b1, b2),
            o3(p, a2, b2, a1),
            o3(p, a2, b2, b1),
        ];
        if !sides.contains(&Sign::Zero) && sides[0] != sides[1] && sides[2] != sides[3] {
            straddling += 1;
            hits += usize::from(want);
        }
    }
    println!("{straddling} straddling, {hits} meeting");
    assert!(
        straddling > 5_000 && hits > 1_000 && straddling - hits > 1_000,
        "{straddling} {hits}"
    );
}

/// The planes' fast decisions (`decide_by_planes`) against the full exact test
/// (`faces_intersect`) on random pairs of every adjacency — none, one shared corner (both
/// orientations), a shared edge (both orientations: neighbours and folds), a repeated index, the
/// same face — with corners generic (unit cube), on a coarse grid (touching, coplanar,
/// degenerate, corners on the other plane), nearly flat, and scaled by 1e100 and 1e-100; both
/// orders of each pair. Every decision is checked, and both answers must be decided often.
#[test]
fn plane_decisions_agree_with_the_full_test() {
    let mut rng = Rng::new(29);
    let patterns: [([u32; 3], [u32; 3]); 7] = [
        ([0, 1, 2], [3, 4, 5]),
        ([0, 1, 2], [0, 3, 4]),
        ([0, 1, 2], [0, 4, 3]),
        ([0, 1, 2], [1, 0, 3]),
        ([0, 1, 2], [0, 1, 3]),
        ([0, 0, 1], [2, 3, 4]),
        ([0, 1, 2], [2, 1, 0]),
    ];
    let (mut decided, mut decided_true) = ([0usize; 7], [0usize; 7]);
    for round in 0..120_000 {
        let kind = round % 5;
        let scale = match (round / 5) % 3 {
            0 => 1.0,
            1 => 1e100,
            _ => 1e-100,
        };
        let mut point = |_| -> P {
            let p = match kind {
                0 | 1 => [rng.unit(), rng.unit(), rng.unit()],
                2 | 3 => [0; 3].map(|_| rng.int(2) as f64),
                _ => [rng.unit(), rng.unit(), 1e-9 * rng.unit()],
            };
            p.map(|x| x * scale)
        };
        let pts: [P; 6] = [0; 6].map(&mut point);
        let which = (round / 15) % patterns.len();
        let (fa, fb) = patterns[which];
        let corners = |f: [u32; 3]| f.map(|v| pts[v as usize]);
        let (pa, pb) = (corners(fa), corners(fb));
        let want = faces_intersect(fa, &Tri::new(pa), fb, &Tri::new(pb));
        let refs = |f: [u32; 3]| f.map(|v| &pts[v as usize]);
        for (f1, f2) in [(fa, fb), (fb, fa)] {
            let (p1, p2) = (refs(f1), refs(f2));
            let plane = PlaneFilter::new(*p1[0], *p1[1], *p1[2]);
            if let Some(got) = decide_by_planes(f1, p1, &plane, f2, p2) {
                assert_eq!(got, want, "{f1:?} {f2:?} {pts:?}");
                decided[which] += 1;
                decided_true[which] += usize::from(got);
            }
        }
    }
    println!("decided {decided:?}, of which true {decided_true:?}");
    // No pattern with a repeated index or the same face is decided here.
    assert_eq!(decided[5] + decided[6], 0);
    for w in 0..5 {
        assert!(decided[w] > 5_000, "{w}: {decided:?}");
    }
    // Crossing pairs (no shared corner, one shared corner) are decided `true` too.
    for w in 0..3 {
        assert!(decided_true[w] > 1_000, "{w}: {decided_true:?}");
    }
}
