//! Validation and repair on small hand-built meshes with known problems.

use mesh_core::TriMesh;
use mesh_core::geometry::signed_volume;
use mesh_core::validate::{Action, IssueKind, Locations, RepairOptions, repair, validate};

fn tet() -> TriMesh {
    mesh_core::shapes::tetrahedron()
}

fn opts() -> RepairOptions {
    RepairOptions::default()
}

#[test]
fn clean_closed_mesh_reports_nothing_and_repair_is_identity() {
    let r = repair(&tet(), &opts()).expect("clean mesh repairs");
    assert!(r.report.is_clean(), "{:?}", r.report.issues);
    assert_eq!(r.mesh, tet());
    assert!(r.report.closed);
    assert_eq!(r.report.components, 1);
    assert_eq!(r.vertex_map, vec![Some(0), Some(1), Some(2), Some(3)]);
}

#[test]
fn nan_coordinates_are_refused_naming_the_vertices() {
    let mut m = tet();
    m.positions[2][1] = f64::NAN;
    m.positions[3][0] = f64::INFINITY;
    let report = validate(&m, &opts());
    let i = report
        .issue(IssueKind::NonFiniteCoordinates)
        .expect("reported");
    assert_eq!(i.action, Action::Refused);
    assert_eq!(i.examples, Locations::Vertices(vec![2, 3]));
    let e = repair(&m, &opts()).expect_err("refused");
    let msg = e.to_string();
    assert!(msg.contains("NaN") && msg.contains("vertex 2, 3"), "{msg}");

    // With the drop option, the vertex and every face touching it go.
    let o = RepairOptions {
        drop_nonfinite_vertices: true,
        ..opts()
    };
    let mut one = tet();
    one.positions[3][0] = f64::INFINITY;
    let r = repair(&one, &o).expect("dropping repairs");
    assert_eq!(r.mesh.faces, vec![[0, 2, 1]]);
    assert_eq!(r.vertex_map, vec![Some(0), Some(1), Some(2), None]);
    assert_eq!(r.face_map, vec![Some(0), None, None, None]);
    // Dropping both leaves nothing usable: refused.
    assert!(repair(&m, &o).is_err());
    for p in &r.mesh.positions {
        assert!(p.iter().all(|c| c.is_finite()));
    }
}

#[test]
fn out_of_range_index_is_refused_naming_the_face() {
    let mut m = tet();
    m.faces[3] = [1, 2, 9];
    let e = repair(&m, &opts()).expect_err("refused");
    let msg = e.to_string();
    assert!(
        msg.contains("face 3") && msg.contains("only 4 vertices"),
        "{msg}"
    );
    let o = RepairOptions {
        drop_out_of_range_faces: true,
        ..opts()
    };
    let r = repair(&m, &o).expect("dropping repairs");
    assert_eq!(r.face_map, vec![Some(0), Some(1), Some(2), None]);
    assert!(!r.report.closed);
}

#[test]
fn exact_duplicate_vertices_are_welded_onto_the_first_and_close_the_surface() {
    // Vertex 4 is a copy of vertex 1 (as after a UV seam split); face 3 uses the copy.
    let mut m = tet();
    m.positions.push([1.0, 0.0, 0.0]);
    m.faces[3] = [4, 2, 3];
    let before = validate(
        &m,
        &RepairOptions {
            weld_exact_duplicates: false,
            ..opts()
        },
    );
    assert!(
        before.issue(IssueKind::BoundaryEdges).is_some(),
        "crack before welding"
    );
    let r = repair(&m, &opts()).expect("repairs");
    let i = r
        .report
        .issue(IssueKind::DuplicateVertices)
        .expect("reported");
    assert_eq!(i.examples, Locations::VertexPairs(vec![[4, 1]]));
    assert_eq!(
        r.vertex_map,
        vec![Some(0), Some(1), Some(2), Some(3), Some(1)]
    );
    assert_eq!(r.mesh, tet());
    assert!(r.report.closed);
    // −0.0 and +0.0 are the same position.
    let mut z = tet();
    z.positions.push([-0.0, 0.0, 0.0]);
    z.faces[0] = [4, 2, 1];
    assert_eq!(repair(&z, &opts()).expect("repairs").mesh, tet());
}

#[test]
fn degenerate_and_duplicate_faces_are_dropped_with_face_map() {
    let mut m = tet();
    m.positions.push([0.5, 0.0, 0.0]); // 4: midpoint of edge 0–1, collinear with 0 and 1
    m.faces.push([0, 0, 3]); // 4: repeated vertex
    m.faces.push([0, 1, 4]); // 5: zero area
    m.faces.push([1, 3, 0]); // 6: same vertex set as face 1 (rotated)
    m.faces.push([0, 3, 1]); // 7: same vertex set as face 1 (reversed)
    let r = repair(&m, &opts()).expect("repairs");
    let rep = &r.report;
    assert_eq!(
        rep.issue(IssueKind::RepeatedVertexInFace)
            .map(|i| i.examples.clone()),
        Some(Locations::Faces(vec![4]))
    );
    assert_eq!(
        rep.issue(IssueKind::ZeroAreaFaces)
            .map(|i| i.examples.clone()),
        Some(Locations::Faces(vec![5]))
    );
    assert_eq!(
        rep.issue(IssueKind::DuplicateFaces)
            .map(|i| i.examples.clone()),
        Some(Locations::Faces(vec![6, 7]))
    );
    assert_eq!(
        r.face_map,
        vec![Some(0), Some(1), Some(2), Some(3), None, None, None, None]
    );
    // Vertex 4 only served the dropped face: now unreferenced and dropped.
    assert_eq!(r.vertex_map[4], None);
    assert_eq!(r.mesh, tet());
    // The repaired mesh is clean: repair is idempotent.
    assert!(validate(&r.mesh, &opts()).is_clean());
}

#[test]
fn unreferenced_vertices_are_dropped_and_values_map_back_to_input_numbering() {
    let mut m = tet();
    m.positions.insert(1, [7.0, 7.0, 7.0]);
    m.positions.push([8.0, 8.0, 8.0]);
    for f in m.faces.iter_mut() {
        for v in f.iter_mut() {
            if *v >= 1 {
                *v += 1;
            }
        }
    }
    let r = repair(&m, &opts()).expect("repairs");
    assert_eq!(
        r.vertex_map,
        vec![Some(0), None, Some(1), Some(2), Some(3), None]
    );
    assert_eq!(r.mesh, tet());
    let i = r
        .report
        .issue(IssueKind::UnreferencedVertices)
        .expect("reported");
    assert_eq!(i.examples, Locations::Vertices(vec![1, 5]));
    // Per-vertex outputs of the repaired mesh come back in the input's numbering.
    let back = r.to_input_vertices(&r.mesh.positions);
    for (old, v) in back.iter().enumerate() {
        if let Some(p) = v {
            assert_eq!(*p, m.positions[old]);
        }
    }
}

#[test]
fn flipped_face_is_reoriented_and_inside_out_part_is_turned_outward() {
    let mut m = tet();
    m.faces[2] = [0, 2, 3];
    let r = repair(&m, &opts()).expect("repairs");
    assert_eq!(r.mesh, tet());
    assert!(r.report.issue(IssueKind::InconsistentOrientation).is_some());

    let mut inv = tet();
    for f in inv.faces.iter_mut() {
        f.swap(1, 2);
    }
    assert!(signed_volume(&inv.positions, &inv.faces) < 0.0);
    let r = repair(&inv, &opts()).expect("repairs");
    assert_eq!(
        r.report.issue(IssueKind::InwardFacing).map(|i| i.action),
        Some(Action::Repaired)
    );
    assert!((signed_volume(&r.mesh.positions, &r.mesh.faces) - 1.0 / 6.0).abs() < 1e-15);
    let o = RepairOptions {
        fix_orientation: false,
        ..opts()
    };
    assert_eq!(
        repair(&inv, &o).expect("repairs").mesh,
        inv,
        "left alone when switched off"
    );
}

#[test]
fn two_components_are_reported_with_sizes_and_refused_on_request() {
    let mut m = tet();
    let shifted: Vec<[f64; 3]> = tet()
        .positions
        .iter()
        .map(|p| [p[0] + 5.0, p[1], p[2]])
        .collect();
    m.positions.extend(shifted);
    m.faces.extend(tet().faces.iter().map(|f| f.map(|v| v + 4)));
    let r = repair(&m, &opts()).expect("kept by default");
    let i = r
        .report
        .issue(IssueKind::SeveralComponents)
        .expect("reported");
    assert_eq!(i.count, 2);
    assert_eq!(i.examples, Locations::ComponentSizes(vec![4, 4]));
    assert_eq!(r.report.components, 2);
    let o = RepairOptions {
        refuse_several_components: true,
        ..opts()
    };
    assert!(
        repair(&m, &o)
            .expect_err("refused")
            .to_string()
            .contains("2 separate parts")
    );
}

#[test]
fn non_manifold_edge_is_reported_and_kept_or_refused() {
    // Three triangles on edge 0–1.
    let m = TriMesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 1.0, 0.0],
            [0.5, -1.0, 0.0],
            [0.5, 0.0, 1.0],
        ],
        vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]],
    );
    let r = repair(&m, &opts()).expect("kept by default");
    let i = r
        .report
        .issue(IssueKind::NonManifoldEdges)
        .expect("reported");
    assert_eq!(i.examples, Locations::Edges(vec![[0, 1]]));
    assert_eq!(r.mesh.faces.len(), 3);
    let o = RepairOptions {
        refuse_non_manifold: true,
        ..opts()
    };
    assert!(
        repair(&m, &o)
            .expect_err("refused")
            .to_string()
            .contains("edge 0–1")
    );
}

#[test]
fn needle_triangles_are_reported_and_kept() {
    let m = TriMesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 1e-3, 0.0],
            [0.0, 1.0, 0.0],
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    );
    let r = repair(&m, &opts()).expect("kept");
    let i = r.report.issue(IssueKind::NeedleFaces).expect("reported");
    assert_eq!(i.examples, Locations::Faces(vec![0]));
    assert_eq!(i.action, Action::Kept);
    assert_eq!(r.mesh.faces.len(), 2);
}

#[test]
fn empty_and_fully_degenerate_meshes_are_refused() {
    let e = repair(&TriMesh::default(), &opts()).expect_err("refused");
    assert!(e.to_string().contains("no triangles"), "{e}");
    let m = TriMesh::new(
        vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
        vec![[0, 1, 2]],
    );
    let e = repair(&m, &opts()).expect_err("refused");
    assert!(e.to_string().contains("none of the 1 faces"), "{e}");
}

#[test]
fn one_sided_surface_is_reported_and_left_unchanged() {
    // A triangulated Möbius band: 5 quads, half twist between the last and the first.
    let n = 5u32;
    let mut positions = Vec::new();
    for i in 0..n {
        let t = std::f64::consts::TAU * f64::from(i) / f64::from(n);
        let h = 0.5 * (t / 2.0).cos();
        let r = 2.0 + 0.5 * (t / 2.0).sin();
        positions.push([r * t.cos(), r * t.sin(), h]);
    }
    for i in 0..n {
        let t = std::f64::consts::TAU * f64::from(i) / f64::from(n);
        let h = -0.5 * (t / 2.0).cos();
        let r = 2.0 - 0.5 * (t / 2.0).sin();
        positions.push([r * t.cos(), r * t.sin(), h]);
    }
    let mut faces = Vec::new();
    for i in 0..n {
        let (a, b) = (i, i + n);
        let (c, d) = if i + 1 < n {
            (i + 1, i + 1 + n)
        } else {
            (n, 0)
        };
        faces.push([a, c, b]);
        faces.push([b, c, d]);
    }
    let mut m = TriMesh::new(positions, faces);
    m.faces[3].swap(1, 2); // make at least one edge inconsistent wherever the seam falls
    let r = repair(&m, &opts()).expect("kept");
    let i = r
        .report
        .issue(IssueKind::InconsistentOrientation)
        .expect("reported");
    assert_eq!(i.action, Action::Kept);
    assert!(i.message.contains("one-sided"), "{}", i.message);
    assert_eq!(r.mesh.faces, m.faces);
}
