//! OFF, PLY and glTF/GLB: readers on hand-made files, writer round trips, bad files.
#![cfg(feature = "io")]

mod common;

use std::path::{Path, PathBuf};

use mesh_core::io::{
    PlyEncoding, read_mesh, read_mesh_with_normals, write_glb, write_mesh, write_off, write_ply,
};
use mesh_core::normals::vertex_normals_area_weighted;
use mesh_core::{MeshError, TriMesh};

fn put(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write");
    p
}

fn bunny() -> TriMesh {
    read_mesh(common::fixture("bunny.obj")).expect("bunny reads")
}

#[test]
fn ply_ascii_and_binary_round_trip_exactly_with_normals() {
    let m = bunny();
    let n = vertex_normals_area_weighted(&m.positions, &m.faces);
    let dir = tempfile::tempdir().expect("tempdir");
    for enc in [PlyEncoding::Ascii, PlyEncoding::BinaryLittleEndian] {
        let p = dir.path().join(format!("b_{enc:?}.ply"));
        write_ply(&p, &m, Some(&n), enc).expect("writes");
        let (back, bn) = read_mesh_with_normals(&p).expect("reads back");
        assert_eq!(back, m, "{enc:?}");
        assert_eq!(bn.as_deref(), Some(n.as_slice()), "{enc:?}");
    }
    // write_mesh picks binary little endian for .ply.
    let p = dir.path().join("x/y.ply");
    write_mesh(&p, &m, None).expect("writes");
    let head = std::fs::read(&p).expect("read");
    assert!(head.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
    assert_eq!(read_mesh_with_normals(&p).expect("reads").1, None);
    assert!(matches!(
        write_ply(&p, &m, None, PlyEncoding::BinaryBigEndian),
        Err(MeshError::UnsupportedFormat { .. })
    ));
}

/// A binary PLY with float positions, extra scalar properties between and after x y z, an
/// `int`-counted `vertex_index` list with a quad, and an extra element with a list after faces.
fn odd_binary_ply(big_endian: bool) -> Vec<u8> {
    let fmt = if big_endian {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let mut b = format!(
        "ply\r\nformat {fmt} 1.0\r\ncomment odd layout\r\nelement vertex 4\r\nproperty float x\r\n\
         property int flags\r\nproperty float y\r\nproperty float z\r\nproperty uchar red\r\n\
         property double quality\r\nelement face 1\r\nproperty uchar tag\r\n\
         property list int uint vertex_index\r\nproperty short extra\r\n\
         element edge 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n"
    )
    .into_bytes();
    let mut put = |bytes: &[u8]| {
        let mut v = bytes.to_vec();
        if big_endian {
            v.reverse();
        }
        b.extend_from_slice(&v);
    };
    let verts = [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.5],
    ];
    for (i, p) in verts.iter().enumerate() {
        put(&p[0].to_le_bytes());
        put(&(i as i32 * 100).to_le_bytes());
        put(&p[1].to_le_bytes());
        put(&p[2].to_le_bytes());
        put(&[200u8]);
        put(&(-1.5f64).to_le_bytes());
    }
    put(&[7u8]);
    put(&4i32.to_le_bytes());
    for v in [0u32, 1, 2, 3] {
        put(&v.to_le_bytes());
    }
    put(&(-3i16).to_le_bytes());
    put(&[2u8]);
    put(&0i32.to_le_bytes());
    put(&2i32.to_le_bytes());
    b
}

#[test]
fn ply_binary_skips_extra_properties_and_elements_in_both_byte_orders() {
    let dir = tempfile::tempdir().expect("tempdir");
    for be in [false, true] {
        let p = put(dir.path(), &format!("odd_{be}.ply"), &odd_binary_ply(be));
        let m = read_mesh(&p).expect("reads");
        assert_eq!(
            m.positions,
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.5]
            ]
        );
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3]], "quad fan-triangulated");
    }
}

#[test]
fn ply_ascii_with_double_positions_and_polygons_reads() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = "ply\nformat ascii 1.0\nelement vertex 5\nproperty double x\nproperty double y\n\
                property double z\nproperty uchar alpha\nelement face 2\n\
                property list uchar int vertex_indices\nend_header\n\
                0 0 0 1\n1 0 0 1\n1 1 0 1\n0 1 0 1\n0.5 0.5 0.1234567890123 1\n\
                5 0 1 2 3 4\n3 4 3 2\n";
    let m = read_mesh(put(dir.path(), "a.ply", text.as_bytes())).expect("reads");
    assert_eq!(m.positions[4], [0.5, 0.5, 0.1234567890123]);
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [4, 3, 2]]);
}

#[test]
fn off_reads_headers_comments_colours_and_polygons_and_round_trips() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = "COFF # coloured\n# comment line\n\n4 2 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n\
                1 1 0 0 0 255 255\n0 1 0 9 9 9 255\n4 0 1 2 3 1 2 3\n3 2 1 0\n";
    let m = read_mesh(put(dir.path(), "c.off", text.as_bytes())).expect("reads");
    assert_eq!(m.positions.len(), 4);
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [2, 1, 0]]);
    let inline = "OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    let m2 = read_mesh(put(dir.path(), "i.off", inline.as_bytes())).expect("reads");
    assert_eq!(m2.faces, vec![[0, 1, 2]]);
    let b = bunny();
    let p = dir.path().join("b.off");
    write_off(&p, &b).expect("writes");
    assert_eq!(read_mesh(&p).expect("reads back"), b);
}

#[test]
fn glb_round_trip_keeps_f32_positions_normals_and_valid_bounds() {
    let m = bunny();
    let n = vertex_normals_area_weighted(&m.positions, &m.faces);
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("out/bunny.glb");
    write_mesh(&p, &m, Some(&n)).expect("writes");
    let (back, bn) = read_mesh_with_normals(&p).expect("reads back");
    assert_eq!(back.faces, m.faces);
    for (a, b) in back.positions.iter().zip(&m.positions) {
        for k in 0..3 {
            assert_eq!(a[k], f64::from(b[k] as f32));
        }
    }
    let bn = bn.expect("normals present");
    for (a, b) in bn.iter().zip(&n) {
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-6);
        }
    }
    // Independent check of the container with the gltf crate: min/max equal the true bounds.
    let g = gltf::Gltf::open(&p).expect("valid glTF");
    let acc = g.document.accessors().next().expect("position accessor");
    let min = acc.min().expect("min present");
    let max = acc.max().expect("max present");
    for k in 0..3 {
        let lo = m
            .positions
            .iter()
            .map(|q| q[k] as f32)
            .fold(f32::INFINITY, f32::min);
        let hi = m
            .positions
            .iter()
            .map(|q| q[k] as f32)
            .fold(f32::NEG_INFINITY, f32::max);
        assert_eq!(min[k].as_f64().map(|x| x as f32), Some(lo));
        assert_eq!(max[k].as_f64().map(|x| x as f32), Some(hi));
    }
    let mut nan = m.clone();
    nan.positions[0][0] = f64::NAN;
    assert!(write_glb(&dir.path().join("nan.glb"), &nan, None).is_err());
}

#[test]
fn gltf_node_transforms_are_applied_and_mirrors_keep_faces_ccw() {
    // One triangle in the z = 0 plane (normal +z), instanced twice:
    // node 0: translation (10, 0, 0) with child node 1: scale (2, 2, 2);
    // node 2: scale (−1, 1, 1) (a mirror).
    let dir = tempfile::tempdir().expect("tempdir");
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for i in [0u16, 1, 2, 0] {
        bin.extend_from_slice(&i.to_le_bytes()); // 3 indices + 2 bytes padding
    }
    put(dir.path(), "tri.bin", &bin);
    let json = r#"{
      "asset": {"version": "2.0"},
      "scene": 0,
      "scenes": [{"nodes": [0, 2]}],
      "nodes": [
        {"translation": [10, 0, 0], "children": [1]},
        {"scale": [2, 2, 2], "mesh": 0},
        {"scale": [-1, 1, 1], "mesh": 0}
      ],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
      "buffers": [{"uri": "tri.bin", "byteLength": 44}],
      "bufferViews": [
        {"buffer": 0, "byteOffset": 0, "byteLength": 36},
        {"buffer": 0, "byteOffset": 36, "byteLength": 6}
      ],
      "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
         "min": [0, 0, 0], "max": [1, 1, 0]},
        {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
      ]
    }"#;
    let p = put(dir.path(), "scene.gltf", json.as_bytes());
    let m = read_mesh(&p).expect("reads");
    assert_eq!(
        m.positions,
        vec![
            [10.0, 0.0, 0.0],
            [12.0, 0.0, 0.0],
            [10.0, 2.0, 0.0],
            [0.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0]
        ]
    );
    assert_eq!(m.faces, vec![[0, 1, 2], [3, 5, 4]]);
    // Both copies face +z after the transform.
    let n = mesh_core::normals::face_normals(&m.positions, &m.faces);
    assert_eq!(n, vec![[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]);
}

#[test]
fn garbage_and_empty_files_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let junk: Vec<u8> = (0..2000u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    for name in ["j.ply", "j.off", "j.glb", "j.gltf", "j.obj"] {
        let p = put(dir.path(), name, &junk);
        let e = read_mesh(&p).expect_err("garbage is rejected");
        assert!(e.to_string().contains(name), "{e}");
        let e = read_mesh(put(dir.path(), &format!("empty_{name}"), b""))
            .expect_err("empty is rejected");
        assert!(e.to_string().contains("empty_"), "{e}");
    }
    let e = read_mesh(put(
        dir.path(),
        "h.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\n",
    ))
    .expect_err("no end");
    assert!(e.to_string().contains("end_header"), "{e}");
    let e = read_mesh(put(
        dir.path(),
        "nof.ply",
        b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n",
    ))
    .expect_err("no y");
    assert!(e.to_string().contains("x, y or z"), "{e}");
}

#[test]
fn every_truncation_of_every_written_format_is_an_error_not_a_panic() {
    let m = mesh_core::shapes::tetrahedron();
    let n = vertex_normals_area_weighted(&m.positions, &m.faces);
    let dir = tempfile::tempdir().expect("tempdir");
    let mut written = Vec::new();
    for (name, enc) in [
        ("a.ply", Some(PlyEncoding::Ascii)),
        ("b.ply", Some(PlyEncoding::BinaryLittleEndian)),
    ] {
        let p = dir.path().join(name);
        write_ply(&p, &m, Some(&n), enc.unwrap_or(PlyEncoding::Ascii)).expect("writes");
        written.push(p);
    }
    for name in ["c.off", "d.glb", "e.obj"] {
        let p = dir.path().join(name);
        write_mesh(&p, &m, Some(&n)).expect("writes");
        written.push(p);
    }
    for p in written {
        let full = std::fs::read(&p).expect("read");
        let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
        for cut in 0..full.len() {
            let q = dir.path().join(format!("cut.{ext}"));
            std::fs::write(&q, &full[..cut]).expect("write");
            // Text formats may legitimately parse a prefix that ends at a line break (e.g. an
            // OBJ missing its last faces); the reader must never panic and never invent data.
            if let Ok(got) = read_mesh(&q) {
                if full[cut..].iter().all(u8::is_ascii_whitespace) {
                    assert_eq!(got, m, "{ext}: only trailing whitespace was cut");
                } else {
                    // An OBJ cut inside its last `f` record can still be a valid file.
                    assert!(got.faces.len() <= m.faces.len(), "{ext} cut at {cut}");
                    assert!(
                        ext == "obj",
                        "{ext} cut at {cut} of {} was accepted",
                        full.len()
                    );
                }
            }
        }
    }
}

#[test]
fn headers_announcing_billions_of_elements_fail_fast_as_truncated() {
    let dir = tempfile::tempdir().expect("tempdir");
    let e = read_mesh(put(
        dir.path(),
        "big.off",
        b"OFF\n4000000000 4000000000 0\n0 0 0\n",
    ))
    .expect_err("lying header");
    assert!(e.to_string().contains("truncated"), "{e}");
    let ply =
        b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\n\
                property float y\nproperty float z\nend_header\n\0\0\0\0";
    let e = read_mesh(put(dir.path(), "big.ply", ply)).expect_err("lying header");
    assert!(e.to_string().contains("truncated"), "{e}");
}

#[test]
fn glb_with_vertex_colors_reads_back_and_refuses_bad_colors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mesh = mesh_core::shapes::icosphere(1);
    let n = mesh.positions.len();
    let colors: Vec<[f32; 3]> = (0..n).map(|v| [v as f32 / n as f32, 0.5, 1.0]).collect();
    let path = dir.path().join("heat.glb");
    mesh_core::io::write_glb_with_colors(&path, &mesh, None, Some(&colors)).expect("writes");
    // The reader (and the gltf crate's validation under it) accepts the file; geometry kept.
    let back = read_mesh(&path).expect("reads");
    assert_eq!(back.faces, mesh.faces);
    for (a, b) in back.positions.iter().zip(&mesh.positions) {
        for k in 0..3 {
            assert_eq!(a[k], f64::from(b[k] as f32));
        }
    }
    let gltf = gltf::Gltf::open(&path).expect("gltf parses");
    let prim = gltf
        .meshes()
        .next()
        .and_then(|m| m.primitives().next())
        .expect("a primitive");
    let color = prim
        .attributes()
        .find(|(s, _)| *s == gltf::Semantic::Colors(0))
        .map(|(_, a)| a)
        .expect("COLOR_0");
    assert_eq!(
        (color.count(), color.dimensions()),
        (n, gltf::accessor::Dimensions::Vec3)
    );
    let short = &colors[..n - 1];
    let e = mesh_core::io::write_glb_with_colors(&path, &mesh, None, Some(short))
        .expect_err("one colour missing");
    assert!(
        e.to_string()
            .contains(&format!("{} colors for {n} vertices", n - 1)),
        "{e}"
    );
    let mut bad = colors.clone();
    bad[3] = [1.5, 0.0, 0.0];
    let e = mesh_core::io::write_glb_with_colors(&path, &mesh, None, Some(&bad))
        .expect_err("out of range");
    assert!(
        e.to_string()
            .contains("colour of vertex 3 is outside [0, 1]"),
        "{e}"
    );
}
