//! The fixture meshes of `fixtures/meshes/` (see its README for sources): real files with known
//! problems, and hand-made bad inputs.
#![cfg(feature = "io")]

mod common;

use mesh_core::MeshError;
use mesh_core::io::read_mesh;
use mesh_core::topology::{EdgeFaces, connected_components};
use mesh_core::validate::{Action, IssueKind, Locations, RepairOptions, repair, validate};

fn opts() -> RepairOptions {
    RepairOptions::default()
}

#[test]
fn bone_ply_unreferenced_vertices_are_dropped_with_a_correct_vertex_map() {
    let m = read_mesh(common::fixture("bone.ply")).expect("bone.ply reads");
    assert_eq!((m.positions.len(), m.faces.len()), (1872, 3022));
    // Independent count of the vertices no face uses.
    let mut used = vec![false; m.positions.len()];
    for f in &m.faces {
        for &v in f {
            used[v as usize] = true;
        }
    }
    let unused: Vec<u32> = (0..used.len() as u32)
        .filter(|&v| !used[v as usize])
        .collect();
    assert_eq!(unused.len(), 359);

    let r = repair(&m, &opts()).expect("repairs");
    let issue = r
        .report
        .issue(IssueKind::UnreferencedVertices)
        .expect("reported");
    assert_eq!(issue.count, 359);
    assert_eq!(issue.action, Action::Repaired);
    assert_eq!(r.mesh.positions.len(), 1872 - 359);
    // The map drops exactly the unused vertices, keeps order, and carries positions and faces.
    let mut next = 0u32;
    for (old, new) in r.vertex_map.iter().enumerate() {
        if used[old] {
            assert_eq!(*new, Some(next));
            assert_eq!(r.mesh.positions[next as usize], m.positions[old]);
            next += 1;
        } else {
            assert_eq!(*new, None);
        }
    }
    for (old, f) in m.faces.iter().enumerate() {
        let new = r.face_map[old].expect("no face dropped");
        assert_eq!(
            r.mesh.faces[new as usize],
            f.map(|v| r.vertex_map[v as usize].unwrap_or(u32::MAX))
        );
    }
    assert!(r.report.closed);
}

#[test]
fn triceratops_needle_triangles_are_reported_and_kept() {
    let m = read_mesh(common::fixture("triceratops.off")).expect("reads");
    let r = repair(&m, &opts()).expect("repairs");
    let issue = r
        .report
        .issue(IssueKind::NeedleFaces)
        .expect("needles reported");
    // Faces 828 and 842 are caps: a vertex almost on the middle of the opposite edge
    // (corner angles ≈ 0°, 0°, 180°; areas ≈ 7e-8 and 9e-8, i.e. 8.8e-7 and 1.3e-6 of their
    // longest edge squared: above the default zero-area tolerance of 1e-12).
    assert_eq!(issue.examples, Locations::Faces(vec![828, 842]));
    assert_eq!(issue.action, Action::Kept);
    assert_eq!(
        r.mesh, m,
        "repair keeps needle faces: nothing else is wrong with this mesh"
    );
    // With a stricter zero-area tolerance they count as degenerate and are dropped instead (the
    // next flattest face of the model has an area of 0.015 × its longest edge squared).
    let strict = RepairOptions {
        zero_area_tolerance: 1e-5,
        ..opts()
    };
    let r = repair(&m, &strict).expect("repairs");
    assert_eq!(
        r.report
            .issue(IssueKind::ZeroAreaFaces)
            .map(|i| i.examples.clone()),
        Some(Locations::Faces(vec![828, 842]))
    );
    assert_eq!(r.mesh.faces.len(), 5660 - 2);
}

#[test]
fn two_components_are_detected() {
    let m = read_mesh(common::fixture("bad/two_components.obj")).expect("reads");
    let (labels, n) = connected_components(m.positions.len(), &m.faces);
    assert_eq!(n, 2);
    assert_eq!(labels, vec![0, 0, 0, 1, 1, 1]);
    let report = validate(&m, &opts());
    assert_eq!(report.components, 2);
    assert_eq!(
        report.issue(IssueKind::SeveralComponents).map(|i| i.action),
        Some(Action::Kept)
    );
}

#[test]
fn empty_and_truncated_files_give_clear_errors() {
    let e = read_mesh(common::fixture("bad/empty.obj")).expect_err("empty");
    assert!(matches!(e, MeshError::Empty { .. }));
    assert!(
        e.to_string().contains("empty.obj") && e.to_string().contains("no triangles"),
        "{e}"
    );

    let e = read_mesh(common::fixture("bad/truncated.off")).expect_err("truncated");
    let s = e.to_string();
    assert!(
        s.contains("truncated.off") && s.contains("truncated"),
        "{s}"
    );

    let e = read_mesh(common::fixture("bad/truncated.ply")).expect_err("truncated");
    let s = e.to_string();
    assert!(
        s.contains("truncated.ply") && s.contains("file is truncated") && s.contains("of 3022"),
        "{s}"
    );
}

#[test]
fn nan_and_out_of_range_fixtures_are_refused_with_locations() {
    let m = read_mesh(common::fixture("bad/nan_coordinates.obj")).expect("loads");
    let e = repair(&m, &opts()).expect_err("refused");
    assert!(
        e.to_string().contains("NaN") && e.to_string().contains("vertex 3"),
        "{e}"
    );
    let m = read_mesh(common::fixture("bad/out_of_range_index.obj")).expect("loads");
    let e = repair(&m, &opts()).expect_err("refused");
    assert!(e.to_string().contains("face 2"), "{e}");
}

#[test]
fn clean_fixtures_are_closed_and_have_the_expected_genus() {
    // Euler characteristic V − E + F = 2 − 2g: bunny, fandisk and cow are spheres, eight has
    // two handles.
    for (name, genus) in [
        ("bunny.obj", 0),
        ("fandisk.off", 0),
        ("eight.off", 2),
        ("cow.off", 0),
    ] {
        let m = read_mesh(common::fixture(name)).expect("reads");
        let r = repair(&m, &opts()).expect("repairs");
        assert!(r.report.closed, "{name}");
        assert_eq!(r.report.components, 1, "{name}");
        let e = EdgeFaces::new(&r.mesh.faces).len() as i64;
        let chi = r.mesh.positions.len() as i64 - e + r.mesh.faces.len() as i64;
        assert_eq!(chi, 2 - 2 * genus, "{name}");
    }
}

#[test]
fn cow_touching_vertex_is_kept_apart_unless_asked() {
    // cow.off is a closed sphere (V − E + F = 2) in which vertex 2903 sits exactly on vertex 44:
    // two points of the surface touch. Welding them would pinch the sphere.
    let m = read_mesh(common::fixture("cow.off")).expect("reads");
    assert_eq!(m.positions[2903], m.positions[44]);
    let r = repair(&m, &opts()).expect("repairs");
    let i = r
        .report
        .issue(IssueKind::TouchingVertices)
        .expect("reported");
    assert_eq!(i.examples, Locations::VertexPairs(vec![[2903, 44]]));
    assert_eq!(i.action, Action::Kept);
    assert!(r.report.issue(IssueKind::DuplicateVertices).is_none());
    assert_eq!(r.mesh, m);
    let forced = RepairOptions {
        weld_touching_vertices: true,
        ..opts()
    };
    let r = repair(&m, &forced).expect("repairs");
    assert_eq!(r.vertex_map[2903], r.vertex_map[44]);
    let e = EdgeFaces::new(&r.mesh.faces).len() as i64;
    let chi = r.mesh.positions.len() as i64 - e + r.mesh.faces.len() as i64;
    assert_eq!(
        chi, 1,
        "welding pinches: one vertex fewer, same edges and faces"
    );
}

#[test]
fn repair_is_idempotent_on_every_fixture() {
    // Repairing a repaired mesh changes nothing and only informational issues remain.
    for name in [
        "bunny.obj",
        "bone.ply",
        "cow.off",
        "eight.off",
        "fandisk.off",
        "triceratops.off",
        "bad/two_components.obj",
    ] {
        let m = read_mesh(common::fixture(name)).expect("reads");
        let once = repair(&m, &opts()).expect("repairs");
        let twice = repair(&once.mesh, &opts()).expect("repairs again");
        assert_eq!(twice.mesh, once.mesh, "{name}");
        let identity: Vec<Option<u32>> = (0..once.mesh.positions.len() as u32).map(Some).collect();
        assert_eq!(twice.vertex_map, identity, "{name}");
        for i in &twice.report.issues {
            assert_eq!(i.action, Action::Kept, "{name}: {}", i.message);
        }
    }
}
