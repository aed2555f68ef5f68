//! OBJ reading and writing.
#![cfg(feature = "io")]

mod common;

use mesh_core::io::{read_mesh, read_mesh_with_normals, write_mesh};
use mesh_core::normals::vertex_normals_area_weighted;
use mesh_core::{MeshError, TriMesh};

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, text).expect("write");
    p
}

#[test]
fn polygons_are_fan_triangulated_and_indices_resolved() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "quad.obj",
        "# a quad and a triangle with relative indices\n\
         o thing\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\n\
         f 1/1 2/1 3/1 4/1\nv 2 2 2\nf -1 -3 -2\nl 1 2\n",
    );
    let m = read_mesh(&p).expect("reads");
    assert_eq!(m.positions.len(), 5);
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [4, 2, 3]]);
}

#[test]
fn vertices_keep_file_order_including_unreferenced_ones() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = write(
        &dir,
        "order.obj",
        "v 0 0 0\nv 1 0 0\nv 9 9 9\nv 0 1 0\nf 4 2 1\n",
    );
    let m = read_mesh(&p).expect("reads");
    assert_eq!(m.positions[2], [9.0, 9.0, 9.0]);
    assert_eq!(m.faces, vec![[3, 1, 0]]);
}

#[test]
fn obj_round_trip_is_exact_with_normals() {
    let m = read_mesh(common::fixture("bunny.obj")).expect("bunny reads");
    let n = vertex_normals_area_weighted(&m.positions, &m.faces);
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("sub/dir/bunny_out.obj");
    write_mesh(&p, &m, Some(&n)).expect("writes");
    let (back, bn) = read_mesh_with_normals(&p).expect("reads back");
    assert_eq!(
        back, m,
        "shortest round-trip decimals reproduce f64 exactly"
    );
    assert_eq!(bn.as_deref(), Some(n.as_slice()));
    let p2 = dir.path().join("plain.obj");
    write_mesh(&p2, &m, None).expect("writes");
    assert_eq!(read_mesh_with_normals(&p2).expect("reads").1, None);
    assert!(matches!(
        write_mesh(&p2, &m, Some(&n[..3])),
        Err(MeshError::LengthMismatch { .. })
    ));
}

#[test]
fn bad_obj_inputs_give_errors_naming_file_and_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let e = read_mesh(write(&dir, "empty.obj", "")).expect_err("bad input must be rejected");
    assert!(matches!(e, MeshError::Empty { .. }), "{e}");
    assert!(e.to_string().contains("empty.obj"));
    let e = read_mesh(write(&dir, "short.obj", "v 0 0 0\nv 1 0\n"))
        .expect_err("bad input must be rejected");
    assert!(e.to_string().contains("line 2"), "{e}");
    let e =
        read_mesh(write(&dir, "word.obj", "v 0 0 zero\n")).expect_err("bad input must be rejected");
    assert!(e.to_string().contains("zero"), "{e}");
    let e = read_mesh(write(&dir, "zero.obj", "v 0 0 0\nf 0 1 2\n"))
        .expect_err("bad input must be rejected");
    assert!(e.to_string().contains("start at 1"), "{e}");
    let e = read_mesh(write(&dir, "two.obj", "v 0 0 0\nv 1 1 1\nf 1 2\n"))
        .expect_err("bad input must be rejected");
    assert!(e.to_string().contains("at least 3"), "{e}");
    let e = read_mesh(write(&dir, "rel.obj", "v 0 0 0\nf -1 -2 -3\n"))
        .expect_err("bad input must be rejected");
    assert!(e.to_string().contains("before the first vertex"), "{e}");
    let e = read_mesh(dir.path().join("missing.obj")).expect_err("bad input must be rejected");
    assert!(matches!(e, MeshError::Io { .. }));
    let e = read_mesh(write(&dir, "mesh.stl", "solid")).expect_err("bad input must be rejected");
    assert!(matches!(e, MeshError::UnsupportedFormat { .. }));
    // Out-of-range index and NaN load as written; validation reports them.
    let m = read_mesh(write(
        &dir,
        "oor.obj",
        "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 7\n",
    ))
    .expect("loads");
    assert_eq!(m.faces, vec![[0, 1, 6]]);
    assert!(m.positions[2][0].is_nan());
    let _ = TriMesh::default();
}
