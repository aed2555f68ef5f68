use super::*;
use crate::shapes;
use crate::topology::{boundary_edges, connected_components};

/// A torus (major radius 1, minor 0.4), `n × m` quads split in two: genus 1, closed.
pub(crate) fn torus(n: usize, m: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (u, v) = (
                i as f64 / n as f64 * std::f64::consts::TAU,
                j as f64 / m as f64 * std::f64::consts::TAU,
            );
            let r = 1.0 + 0.4 * v.cos();
            p.push([r * u.cos(), r * u.sin(), 0.4 * v.sin()]);
        }
    }
    let id = |i: usize, j: usize| ((i % n) * m + (j % m)) as u32;
    let mut f = Vec::new();
    for i in 0..n {
        for j in 0..m {
            f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    (p, f)
}

/// A flat `k × k` grid over `[0, 1]²`.
fn grid(k: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    for j in 0..=k {
        for i in 0..=k {
            p.push([i as f64 / k as f64, j as f64 / k as f64, 0.0]);
        }
    }
    let id = |i: usize, j: usize| (j * (k + 1) + i) as u32;
    let mut f = Vec::new();
    for j in 0..k {
        for i in 0..k {
            f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    (p, f)
}

/// `(V − E + F, components, boundary loops)`.
pub(crate) fn topology_of(p: &[[f64; 3]], f: &[[u32; 3]]) -> (i64, usize, usize) {
    let edges = crate::topology::edges(f).len() as i64;
    let mut used = vec![false; p.len()];
    for t in f {
        for &v in t {
            used[v as usize] = true;
        }
    }
    let nv = used.iter().filter(|&&u| u).count() as i64;
    let (_, comps) = connected_components(p.len(), f);
    let comps = comps - (p.len() - nv as usize);
    let b = boundary_edges(f);
    let (_, loops) = crate::topology::graph_components(p.len(), b.iter().copied());
    let mut on_boundary = vec![false; p.len()];
    for e in &b {
        on_boundary[e[0] as usize] = true;
        on_boundary[e[1] as usize] = true;
    }
    let loops = loops - on_boundary.iter().filter(|&&x| !x).count();
    (nv - edges + f.len() as i64, comps, loops)
}

/// Share of distinct edges with length in `[4/5·L, 4/3·L]`.
pub(crate) fn share_in_range(p: &[[f64; 3]], f: &[[u32; 3]], l: f64) -> f64 {
    let edges = crate::topology::edges(f);
    let inside = edges
        .iter()
        .filter(|e| {
            let d = dist(p[e[0] as usize], p[e[1] as usize]);
            (0.8 * l - 1e-12..=4.0 / 3.0 * l + 1e-12).contains(&d)
        })
        .count();
    inside as f64 / edges.len() as f64
}

fn run(p: &[[f64; 3]], f: &[[u32; 3]], l: f64) -> Remeshed {
    let out = remesh(p, f, &RemeshOptions::new(l)).expect("remeshes");
    // The output is a valid manifold mesh.
    HalfEdgeMesh::new(&out.positions, &out.faces)
        .expect("manifold output")
        .check()
        .expect("consistent");
    assert_eq!(out.source_faces.len(), out.faces.len());
    assert!(out.source_faces.iter().all(|&s| (s as usize) < f.len()));
    out
}

#[test]
fn operators_keep_the_structure_consistent() {
    for (p, f) in [grid(6), torus(12, 8), {
        let m = shapes::icosphere(2);
        (m.positions, m.faces)
    }] {
        let mut mesh = HalfEdgeMesh::new(&p, &f).expect("builds");
        mesh.check().expect("consistent after build");
        let o = RemeshOptions::new(0.2);
        let surface = Bvh::new(&p, &f).expect("bvh");
        let mut r = Remesher::new(&mut mesh, &p, &f, &o, &surface).expect("remesher");
        for round in 0..3 {
            r.split_long_edges().expect("splits");
            r.mesh
                .check()
                .unwrap_or_else(|e| panic!("after split {round}: {e}"));
            r.collapse_short_edges();
            r.mesh
                .check()
                .unwrap_or_else(|e| panic!("after collapse {round}: {e}"));
            r.flip_edges();
            r.mesh
                .check()
                .unwrap_or_else(|e| panic!("after flip {round}: {e}"));
            r.relax_and_project(&surface);
        }
        // Coarsen hard: collapses dominate.
        r.lo = 0.8 * 0.6;
        r.hi = 4.0 / 3.0 * 0.6;
        for round in 0..3 {
            r.collapse_short_edges();
            r.mesh
                .check()
                .unwrap_or_else(|e| panic!("after coarse collapse {round}: {e}"));
            r.flip_edges();
            r.mesh
                .check()
                .unwrap_or_else(|e| panic!("after coarse flip {round}: {e}"));
        }
        let before = topology_of(&p, &f);
        let (q, g) = r.mesh.compact();
        assert_eq!(topology_of(&q, &g), before);
    }
}

#[test]
fn sphere_edges_land_in_range_close_to_the_input() {
    let s = shapes::icosphere(4);
    let l = 0.08;
    let out = run(&s.positions, &s.faces, l);
    let share = share_in_range(&out.positions, &out.faces, l);
    assert!(share >= 0.9, "share in range {share}");
    let h = hausdorff(&out.positions, &out.faces, &s.positions, &s.faces).expect("hausdorff");
    assert!(h.max() < 0.05 * l, "hausdorff {h:?}");
    assert_eq!(topology_of(&out.positions, &out.faces), (2, 1, 0));
    let q = quality(&out.positions, &out.faces).expect("quality");
    assert!(q.min_angle_deg > 20.0, "{q:?}");
    assert!(q.share_valence_6 > 0.6, "{q:?}");
}

#[test]
fn topology_is_preserved() {
    // A torus, two disjoint spheres, an open grid.
    let (tp, tf) = torus(40, 16);
    let s = shapes::icosphere(3);
    let mut two_p = s.positions.clone();
    let mut two_f = s.faces.clone();
    let n = two_p.len() as u32;
    two_p.extend(s.positions.iter().map(|p| [p[0] + 3.0, p[1], p[2]]));
    two_f.extend(s.faces.iter().map(|f| f.map(|v| v + n)));
    let (gp, gf) = grid(10);
    for (name, p, f, l) in [
        ("torus", tp, tf, 0.1),
        ("two spheres", two_p, two_f, 0.15),
        ("grid", gp, gf, 0.05),
        (
            "wavy grid",
            shapes::obtuse_wavy_grid(12).positions,
            shapes::obtuse_wavy_grid(12).faces,
            0.1,
        ),
    ] {
        let before = topology_of(&p, &f);
        let out = run(&p, &f, l);
        assert_eq!(topology_of(&out.positions, &out.faces), before, "{name}");
        let share = share_in_range(&out.positions, &out.faces, l);
        assert!(share >= 0.85, "{name}: share in range {share}");
    }
}

#[test]
fn grid_boundary_and_corners_stay() {
    let (p, f) = grid(8);
    let out = run(&p, &f, 0.04);
    // Flat stays flat; the four corners are still there exactly; boundary vertices on the square.
    assert!(out.positions.iter().all(|q| q[2].abs() < 1e-12));
    for c in [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
    ] {
        assert!(out.positions.contains(&c), "corner {c:?}");
    }
    for e in boundary_edges(&out.faces) {
        for v in e {
            let q = out.positions[v as usize];
            let on_side = [q[0], q[1], 1.0 - q[0], 1.0 - q[1]]
                .iter()
                .any(|d| d.abs() < 1e-12);
            assert!(on_side, "boundary vertex {q:?} left the square's sides");
        }
    }
}

#[test]
fn deterministic() {
    let (p, f) = torus(30, 12);
    let a = remesh(&p, &f, &RemeshOptions::new(0.12)).expect("a");
    let b = remesh(&p, &f, &RemeshOptions::new(0.12)).expect("b");
    assert_eq!(a, b);
}

#[test]
fn bad_input_is_refused_clearly() {
    let s = shapes::icosphere(1);
    let (p, f) = (s.positions, s.faces);
    let o = |l: f64| RemeshOptions::new(l);
    for l in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(
            matches!(remesh(&p, &f, &o(l)), Err(RemeshError::EdgeLength(_))),
            "{l}"
        );
    }
    let e = remesh(&p, &f, &o(10.0)).expect_err("too long");
    assert!(matches!(e, RemeshError::MeshSmallerThanEdge { .. }));
    assert!(e.to_string().contains("smaller than one target edge"));
    let e = remesh(&p, &f, &o(1e-6)).expect_err("too many");
    match &e {
        RemeshError::TooManyFaces { predicted, max, .. } => {
            assert!(*predicted > 10_000_000_000 && *max == 2_000_000, "{e}")
        }
        other => panic!("{other}"),
    }
    assert!(e.to_string().contains("faces, over the limit of 2000000"));
    let mut bad = p.clone();
    bad[3][1] = f64::NAN;
    let e = remesh(&bad, &f, &o(0.3)).expect_err("nan");
    assert!(
        matches!(e, RemeshError::Input(BvhError::NonFinite { vertex: 3, .. })),
        "{e}"
    );
    let mut bad_f = f.clone();
    bad_f[0][1] = 999;
    assert!(matches!(
        remesh(&p, &bad_f, &o(0.3)),
        Err(RemeshError::Input(BvhError::FaceIndex {
            face: 0,
            index: 999,
            ..
        }))
    ));
    assert_eq!(remesh(&p, &[], &o(0.3)), Err(RemeshError::Empty));
    assert_eq!(remesh(&p, &[[0, 0, 1]], &o(0.3)), Err(RemeshError::Empty));
    let mut opts = o(0.3);
    opts.feature_angle_deg = 200.0;
    assert!(matches!(
        remesh(&p, &f, &opts),
        Err(RemeshError::FeatureAngle(_))
    ));
    opts.feature_angle_deg = f64::NAN;
    assert!(matches!(
        remesh(&p, &f, &opts),
        Err(RemeshError::FeatureAngle(_))
    ));
    let mut opts = o(0.3);
    opts.iterations = MAX_ITERATIONS + 1;
    assert!(matches!(
        remesh(&p, &f, &opts),
        Err(RemeshError::Iterations { .. })
    ));

    // Huge and tiny scales.
    for scale in [1e80, 1e-80] {
        let q: Vec<[f64; 3]> = p.iter().map(|v| v.map(|c| c * scale)).collect();
        let e = remesh(&q, &f, &o(0.3 * scale)).expect_err("scale");
        assert!(matches!(e, RemeshError::Scale { .. }), "{e}");
        assert!(e.to_string().contains("normalize it first"));
    }
    // Large and small but fine scales give the same mesh, scaled (powers of two scale exactly).
    for scale in [2f64.powi(200), 2f64.powi(-200)] {
        let q: Vec<[f64; 3]> = p.iter().map(|v| v.map(|c| c * scale)).collect();
        let out = remesh(&q, &f, &o(0.3 * scale)).expect("scaled");
        let plain = remesh(&p, &f, &o(0.3)).expect("plain");
        assert_eq!(out.faces, plain.faces, "scale {scale}");
    }
    // A mesh of one point (all vertices equal) is smaller than any edge.
    let point = vec![[1.0; 3]; 4];
    let e = remesh(&point, &shapes::tetrahedron().faces, &o(0.1)).expect_err("point");
    assert!(matches!(e, RemeshError::MeshSmallerThanEdge { .. }), "{e}");
    // A long needle strip: its area predicts nothing, its edge lengths do.
    let needle = vec![
        [0.0, 0.0, 0.0],
        [1000.0, 0.0, 0.0],
        [1000.0, 1e-9, 0.0],
        [0.0, 1e-9, 0.0],
    ];
    let mut opts = o(0.001);
    opts.max_faces = 100_000;
    let e = remesh(&needle, &[[0, 1, 2], [0, 2, 3]], &opts).expect_err("needle");
    assert!(matches!(e, RemeshError::TooManyFaces { .. }), "{e}");

    // Non-manifold edge: three faces on edge (0, 1).
    let q = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let e = remesh(&q, &[[0, 1, 2], [1, 0, 3], [0, 1, 4]], &o(0.3)).expect_err("non-manifold");
    assert_eq!(e, RemeshError::NonManifoldEdge { a: 0, b: 1 });
    assert!(e.to_string().contains("non-manifold edge (0, 1)"));
    // Inconsistent orientation.
    let e = remesh(&q, &[[0, 1, 2], [0, 1, 3]], &o(0.3)).expect_err("orientation");
    assert_eq!(e, RemeshError::NonManifoldEdge { a: 0, b: 1 });
    // Non-manifold vertex: two triangles touching at vertex 0 (a bow tie), and two closed
    // tetrahedra sharing a vertex.
    let q = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 0.0, 0.0],
        [-1.0, -1.0, 0.0],
    ];
    let e = remesh(&q, &[[0, 1, 2], [0, 3, 4]], &o(0.3)).expect_err("bow tie");
    assert_eq!(e, RemeshError::NonManifoldVertex { vertex: 0 });
    let t = shapes::tetrahedron();
    let mut tp = t.positions.clone();
    tp.extend(t.positions.iter().skip(1).map(|p| [p[0] + 5.0, p[1], p[2]]));
    tp[4] = [tp[4][0] - 5.0 + 0.0, tp[4][1], tp[4][2]];
    let mut tf = t.faces.clone();
    let remap = |v: u32| if v == 0 { 0 } else { v + 3 };
    tf.extend(t.faces.iter().map(|f| f.map(remap)));
    assert!(matches!(
        remesh(&tp, &tf, &o(0.3)),
        Err(RemeshError::NonManifoldVertex { vertex: 0 })
    ));
}

#[test]
fn degenerate_faces_are_handled() {
    // An icosphere with one face replaced by a zero-area fan around a duplicate of its centre
    // (three faces, one of them with a repeated vertex), plus an unused NaN vertex.
    let s = shapes::icosphere(3);
    let (mut p, mut f) = (s.positions, s.faces);
    let t = f.remove(0);
    let (a, b, c) = (p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]);
    let m = p.len() as u32;
    // A point on edge (a, b): faces (a, m, c), (m, b, c) and the zero-area (a, b, m) sliver
    // cannot all coexist manifoldly, so use a needle: m very close to the edge's midpoint.
    p.push([
        (a[0] + b[0]) / 2.0,
        (a[1] + b[1]) / 2.0,
        (a[2] + b[2]) / 2.0,
    ]);
    let _ = c;
    f.push([t[0], m, t[2]]);
    f.push([m, t[1], t[2]]);
    // The edge (a, b) now has the neighbour face only on one side: fill it with a zero-area
    // triangle (a, b, m) — collinear, area 0.
    f.push([t[1], m, t[0]]);
    f.push([t[0], t[0], t[1]]); // repeated vertex: dropped
    p.push([f64::NAN; 3]); // unused: ignored
    let out = run(&p, &f, 0.1);
    let q = quality(&out.positions, &out.faces).expect("quality");
    assert!(q.min_angle_deg > 10.0, "{q:?}");
    assert_eq!(topology_of(&out.positions, &out.faces), (2, 1, 0));
}

#[test]
fn a_coarse_target_stops_at_a_valid_mesh() {
    // Target ≈ the diagonal: collapses run until the link condition stops them.
    let s = shapes::icosphere(3);
    let out = run(&s.positions, &s.faces, 3.0);
    assert!(out.faces.len() >= 4);
    assert_eq!(topology_of(&out.positions, &out.faces), (2, 1, 0));
}

#[test]
fn quality_figures() {
    let (p, f) = grid(2);
    let q = quality(&p, &f).expect("quality");
    assert_eq!((q.vertices, q.faces), (9, 8));
    assert!((q.min_angle_deg - 45.0).abs() < 1e-9);
    assert_eq!(q.share_below_30_deg, 0.0);
    // One interior vertex with valence 6 (the centre: 4 axis neighbours + 2 diagonal).
    assert_eq!(q.share_valence_6, 1.0);
    let h = hausdorff(&p, &f, &p, &f).expect("self");
    assert!(h.max() < 1e-15);
    let lifted: Vec<[f64; 3]> = p.iter().map(|q| [q[0], q[1], 0.25]).collect();
    let h = hausdorff(&p, &f, &lifted, &f).expect("lifted");
    assert_eq!((h.a_to_b, h.b_to_a), (0.25, 0.25));
    assert!(quality(&p, &[[0, 1, 99]]).is_err());
}

/// xorshift64*: deterministic noise without a dependency.
fn noise(state: &mut u64) -> f64 {
    *state ^= *state >> 12;
    *state ^= *state << 25;
    *state ^= *state >> 27;
    (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64 - 0.5
}

#[test]
fn stress_jittered_and_degenerate_meshes() {
    // Heavily jittered spheres and tori (folds, needles, flipped faces), collapsed copies (all of
    // a region on one point), and a range of target lengths: every call either succeeds with a
    // consistent manifold mesh of the same topology or refuses with an error — no panic, no hang.
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let sphere = shapes::icosphere(2);
    let (tp, tf) = torus(16, 8);
    for round in 0..8 {
        let (mut p, f) = if round % 2 == 0 {
            (sphere.positions.clone(), sphere.faces.clone())
        } else {
            (tp.clone(), tf.clone())
        };
        let amp = [0.0, 0.05, 0.2, 0.6][round % 4];
        for q in p.iter_mut() {
            for c in q.iter_mut() {
                *c += amp * noise(&mut seed);
            }
        }
        if round % 3 == 0 {
            // Squash a third of the vertices onto one point: zero-length edges and zero-area faces.
            let n = p.len();
            for q in p.iter_mut().take(n / 3) {
                *q = [0.1, 0.2, 0.3];
            }
        }
        let before = topology_of(&p, &f);
        for l in [0.12, 0.5] {
            match remesh(&p, &f, &RemeshOptions::new(l)) {
                Ok(out) => {
                    HalfEdgeMesh::new(&out.positions, &out.faces)
                        .expect("manifold output")
                        .check()
                        .expect("consistent");
                    assert_eq!(
                        topology_of(&out.positions, &out.faces),
                        before,
                        "round {round} L {l}"
                    );
                    assert!(
                        out.positions
                            .iter()
                            .all(|q| q.iter().all(|c| c.is_finite()))
                    );
                }
                Err(e) => panic!("round {round} L {l}: {e}"),
            }
        }
    }
}

/// The index of the edge from `a` to `b`, if they are joined.
fn edge_between(m: &HalfEdgeMesh, a: u32, b: u32) -> Option<usize> {
    let mut ring = Vec::new();
    m.outgoing(a, &mut ring);
    ring.iter()
        .find(|&&g| m.to(g) == b)
        .map(|&g| (g / 2) as usize)
}

#[test]
fn short_open_crease_chains_are_dropped_and_others_kept() {
    // A 20 × 20 grid (edge 0.05) with crease flags set by hand along rows of horizontal edges.
    let k = 20;
    let (p, f) = grid(k);
    let mut m = HalfEdgeMesh::new(&p, &f).expect("grid");
    let id = |i: usize, j: usize| (j * (k + 1) + i) as u32;
    let edge = |m: &HalfEdgeMesh, a: u32, b: u32| edge_between(m, a, b).expect("an edge");
    let row = |m: &mut HalfEdgeMesh, j: usize, from: usize, to: usize| {
        for i in from..to {
            let e = edge(m, id(i, j), id(i + 1, j));
            m.feature[e] = true;
        }
    };
    let is_feature = |m: &HalfEdgeMesh, a: u32, b: u32| m.feature[edge(m, a, b)];
    // Boundary edges are features and stay whatever happens.
    for e in 0..m.num_edges() {
        m.feature[e] = m.is_boundary_edge(e);
    }
    row(&mut m, 3, 2, 4); // isolated, 0.10 long
    row(&mut m, 6, 2, 14); // isolated, 0.60 long
    row(&mut m, 10, 0, k); // a line across, between two boundary junctions, …
    for j in 10..12 {
        // … with a tail of 0.10 going up from (5, 10) …
        let e = edge(&m, id(5, j), id(5, j + 1));
        m.feature[e] = true;
    }
    for j in 10..16 {
        // … and one of 0.30 going up from (12, 10).
        let e = edge(&m, id(12, j), id(12, j + 1));
        m.feature[e] = true;
    }
    let boundary_before = (0..m.num_edges())
        .filter(|&e| m.is_boundary_edge(e))
        .count();
    // Isolated chains and loops under 0.5, tails under 0.25 go.
    super::prune_short_feature_chains(&mut m, 0.5);
    assert!(!is_feature(&m, id(2, 3), id(3, 3)) && !is_feature(&m, id(3, 3), id(4, 3)));
    assert!((2..14).all(|i| is_feature(&m, id(i, 6), id(i + 1, 6))));
    assert!(!is_feature(&m, id(5, 10), id(5, 11)) && !is_feature(&m, id(5, 11), id(5, 12)));
    assert!((10..16).all(|j| is_feature(&m, id(12, j), id(12, j + 1))));
    // The line the short tail left stays (it is now one chain through (5, 10)).
    assert!((0..k).all(|i| is_feature(&m, id(i, 10), id(i + 1, 10))));
    let boundary_after = (0..m.num_edges())
        .filter(|&e| m.is_boundary_edge(e) && m.feature[e])
        .count();
    assert_eq!(boundary_after, boundary_before);
}

#[test]
fn hairpins_of_crease_triangles_are_unmarked_and_others_kept() {
    // A 6 × 6 grid stretched 3:1 along x: the face (i, j), (i+1, j), (i+1, j+1) has an 18.4°
    // corner at (i, j).
    let k = 6;
    let (mut p, f) = grid(k);
    for q in &mut p {
        q[0] *= 3.0;
    }
    let mut m = HalfEdgeMesh::new(&p, &f).expect("grid");
    let id = |i: usize, j: usize| (j * (k + 1) + i) as u32;
    let edge = |m: &HalfEdgeMesh, a: u32, b: u32| edge_between(m, a, b).expect("an edge");
    for e in 0..m.num_edges() {
        m.feature[e] = false;
    }
    let mark = |m: &mut HalfEdgeMesh, a: u32, b: u32| {
        let e = edge(m, a, b);
        m.feature[e] = true;
    };
    // A crease triangle: all three edges of the face at (1, 1); a hairpin at (1, 1).
    mark(&mut m, id(1, 1), id(2, 1));
    mark(&mut m, id(1, 1), id(2, 2));
    mark(&mut m, id(2, 1), id(2, 2));
    // The same 18.4° fold at (1, 4) without the third edge: a crease folding back, kept.
    mark(&mut m, id(1, 4), id(2, 4));
    mark(&mut m, id(1, 4), id(2, 5));
    // A crease triangle without a hairpin (its 18.4° corner has a third feature edge): kept.
    mark(&mut m, id(4, 1), id(5, 1));
    mark(&mut m, id(4, 1), id(5, 2));
    mark(&mut m, id(5, 1), id(5, 2));
    mark(&mut m, id(4, 1), id(3, 1));
    super::unmark_hairpins(&mut m);
    let is_feature = |m: &HalfEdgeMesh, a: u32, b: u32| m.feature[edge(m, a, b)];
    assert!(!is_feature(&m, id(1, 1), id(2, 1)) && !is_feature(&m, id(1, 1), id(2, 2)));
    assert!(is_feature(&m, id(2, 1), id(2, 2)));
    assert!(is_feature(&m, id(1, 4), id(2, 4)) && is_feature(&m, id(1, 4), id(2, 5)));
    for (a, b) in [
        (id(4, 1), id(5, 1)),
        (id(4, 1), id(5, 2)),
        (id(5, 1), id(5, 2)),
    ] {
        assert!(is_feature(&m, a, b));
    }
}

#[test]
fn a_corner_next_to_a_feature_edge_joins_the_line() {
    // A flat 4 × 4 grid (spacing 0.25); the diagonal id(1,1)–id(2,2) is a crease and the corner
    // id(1,2) is moved to 0.01 from it: the face (id(1,1), id(2,2), id(1,2)) is a cap.
    let k = 4;
    let (mut p, f) = grid(k);
    let id = |i: usize, j: usize| (j * (k + 1) + i) as u32;
    let s = 0.01 / 2f64.sqrt();
    p[id(1, 2) as usize] = [0.375 - s, 0.375 + s, 0.0];
    let mut mesh = HalfEdgeMesh::new(&p, &f).expect("grid");
    let surface = Bvh::new(&p, &f).expect("bvh");
    // L = 0.25: the corner is 0.04·L from the line.
    let mut r = Remesher::new(&mut mesh, &p, &f, &RemeshOptions::new(0.25), &surface).expect("r");
    let (a, b, v) = (id(1, 1), id(2, 2), id(1, 2));
    let e = edge_between(r.mesh, a, b).expect("the diagonal");
    r.mesh.feature[e] = true;
    r.mesh.locked[v as usize] = true;
    assert!(r.merge_corners_onto_lines());
    r.mesh.check().expect("consistent");
    let m = &*r.mesh;
    assert_eq!(
        edge_between(m, a, b),
        None,
        "the crease edge past the corner is gone"
    );
    assert!(
        m.feature[edge_between(m, a, v).expect("a–v")]
            && m.feature[edge_between(m, v, b).expect("v–b")]
    );
    let new = edge_between(m, v, id(2, 1)).expect("the flipped edge");
    assert!(!m.feature[new]);
    assert_eq!(m.pos[v as usize], p[v as usize], "the corner stays");
    // Far from the line (0.2·L), nothing happens.
    let mut p2 = p.clone();
    let s2 = 0.05 / 2f64.sqrt();
    p2[v as usize] = [0.375 - s2, 0.375 + s2, 0.0];
    let mut mesh2 = HalfEdgeMesh::new(&p2, &f).expect("grid");
    let surface2 = Bvh::new(&p2, &f).expect("bvh");
    let mut r2 =
        Remesher::new(&mut mesh2, &p2, &f, &RemeshOptions::new(0.25), &surface2).expect("r");
    let e2 = edge_between(r2.mesh, a, b).expect("the diagonal");
    r2.mesh.feature[e2] = true;
    r2.mesh.locked[v as usize] = true;
    assert!(!r2.merge_corners_onto_lines());
}

#[test]
fn a_part_thinner_than_the_target_length_does_not_self_intersect() {
    // A disc-like ellipsoid 0.06 thick remeshed at L = 0.1: the two sheets are closer than L.
    for (level, l) in [(3, 0.1), (4, 0.08)] {
        let m = shapes::icosphere(level);
        let p: Vec<[f64; 3]> = m
            .positions
            .iter()
            .map(|q| [q[0], q[1], 0.03 * q[2]])
            .collect();
        let before = crate::intersect::self_intersections(&p, &m.faces).expect("check");
        assert!(before.pairs.is_empty());
        for angle in [30.0, 180.0] {
            let o = RemeshOptions {
                feature_angle_deg: angle,
                ..RemeshOptions::new(l)
            };
            let out = remesh(&p, &m.faces, &o).expect("remeshes");
            let after =
                crate::intersect::self_intersections(&out.positions, &out.faces).expect("check");
            assert!(
                after.pairs.is_empty(),
                "level {level}, L {l}, feature angle {angle}: {} intersecting pairs",
                after.pairs.len()
            );
        }
    }
}

/// The final repair (`Remesher::repair_new_intersections`) on a hand-made fold of the kind the
/// remeshed `armadillo.off` had: a vertex pushed past its one-ring, so that its faces overlap
/// faces that share only one vertex with them. The input (the flat grid) has no pair; the folded
/// state has some; after the repair there is none, the structure is consistent and the vertex is
/// back on the input.
#[test]
fn a_fold_the_remeshing_left_is_repaired() {
    let (p, f) = grid(6);
    let l = 1.0 / 6.0;
    let surface = Bvh::new(&p, &f).expect("bvh");
    let mut mesh = HalfEdgeMesh::new(&p, &f).expect("mesh");
    let mut r =
        Remesher::new(&mut mesh, &p, &f, &RemeshOptions::new(l), &surface).expect("remesher");
    let v = 3 * 7 + 3; // (0.5, 0.5), interior
    r.mesh.pos[v] = [0.5 + 1.6 * l, 0.5 + 0.3 * l, 0.0];
    let (fp, ff) = r.mesh.compact();
    let folded = crate::intersect::self_intersections(&fp, &ff).expect("check");
    assert!(
        !folded.pairs.is_empty(),
        "the hand-made fold must intersect"
    );
    r.repair_new_intersections(&p, &f, &surface)
        .expect("remesher");
    r.mesh.check().expect("consistent after the repair");
    let (rp, rf) = r.mesh.compact();
    let after = crate::intersect::self_intersections(&rp, &rf).expect("check");
    assert!(after.pairs.is_empty(), "pairs left: {:?}", after.pairs);
    assert!(
        rp.iter().all(|q| q[2].abs() < 1e-12),
        "every vertex back on the input plane"
    );
}
