//! Self-intersections of the fixture meshes: no false positives on the clean closed ones, and the
//! counts of the others as they are (run with `--nocapture` to see them; `docs/self_intersections.md`
//! quotes them).
#![cfg(feature = "io")]

mod common;

use mesh_core::bvh::ray_triangle;
use mesh_core::intersect::self_intersections;
use mesh_core::io::read_mesh;

type P = [f64; 3];

/// Möller–Trumbore in plain f64 on each edge as a segment (right for generic crossings).
fn float_tri_tri(a: &[P; 3], b: &[P; 3]) -> bool {
    let edge_hits = |t: &[P; 3], u: &[P; 3]| {
        (0..3).any(|i| {
            let (p, q) = (t[i], t[(i + 1) % 3]);
            let d = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
            matches!(ray_triangle(p, d, u), Some((s, _)) if s <= 1.0)
        })
    };
    edge_hits(a, b) || edge_hits(b, a)
}

fn counts(name: &str) -> (usize, usize, usize, usize) {
    let m = read_mesh(common::fixture(name)).expect("reads");
    let r = self_intersections(&m.positions, &m.faces).expect("checks");
    println!(
        "{name}: {} faces, {} components, {} intersecting pairs, {} faces involved, {} degenerate, {} candidates",
        m.faces.len(),
        r.per_component.len(),
        r.pairs.len(),
        r.faces.len(),
        r.degenerate.len(),
        r.candidates
    );
    // Pairs by how many vertex indices the two faces share (0: apart, 1: a corner, 2: an edge),
    // and how many of the non-adjacent ones a plain-f64 edge-through-triangle test confirms.
    let mut by_shared = [0usize; 4];
    let mut float_confirms = 0;
    for &(a, b) in &r.pairs {
        let (fa, fb) = (m.faces[a as usize], m.faces[b as usize]);
        let shared = fa.iter().filter(|v| fb.contains(v)).count();
        by_shared[shared] += 1;
        if shared == 0 {
            let ta = fa.map(|v| m.positions[v as usize]);
            let tb = fb.map(|v| m.positions[v as usize]);
            float_confirms += usize::from(float_tri_tri(&ta, &tb));
        }
    }
    println!(
        "{name}: pairs sharing 0/1/2/3 vertices: {by_shared:?}; f64 test confirms {float_confirms} of the {} non-adjacent",
        by_shared[0]
    );
    assert_eq!(
        float_confirms, by_shared[0],
        "{name}: every crossing is a generic one"
    );
    (
        m.faces.len(),
        r.pairs.len(),
        r.faces.len(),
        r.degenerate.len(),
    )
}

#[test]
fn clean_closed_fixtures_have_no_self_intersections() {
    for name in ["bunny.obj", "eight.off", "fandisk.off"] {
        let (_, pairs, faces, _) = counts(name);
        assert_eq!((pairs, faces), (0, 0), "{name}");
    }
}

#[test]
fn other_fixtures_as_they_are() {
    for name in ["triceratops.off", "cow.off"] {
        let (f, _, involved, _) = counts(name);
        assert!(involved <= f);
    }
}
