//! Self-intersections of the fixture meshes: no false positives on the clean closed ones, and the
//! counts of the others as they are (run with `--nocapture` to see them; `docs/self_intersections.md`
//! quotes them).
#![cfg(feature = "io")]

mod common;

use mesh_core::intersect::self_intersections;
use mesh_core::io::read_mesh;

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
