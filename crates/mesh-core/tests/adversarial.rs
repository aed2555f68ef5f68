//! Hostile inputs (issue 9 §3): every reader gives a clear error or a correct mesh, in time and
//! memory bounded by the input; validation's degeneracy tests are scale-free.
#![cfg(feature = "io")]

mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use mesh_core::io::{read_mesh, write_glb};
use mesh_core::validate::{IssueKind, RepairOptions, repair, validate};
use mesh_core::{MeshError, TriMesh};

fn put(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write");
    p
}

fn err_of(r: Result<TriMesh, MeshError>) -> String {
    r.expect_err("must be refused").to_string()
}

fn bunny() -> TriMesh {
    read_mesh(common::fixture("bunny.obj")).expect("bunny reads")
}

/// Generous wall-clock bound that only a hang (not a slow machine) exceeds.
const HANG: Duration = Duration::from_secs(20);

// ---------------------------------------------------------------- OFF, PLY, OBJ

#[test]
fn off_corner_counts_of_a_trillion_and_u64_max_are_line_errors_not_allocations() {
    let dir = tempfile::tempdir().expect("tempdir");
    for n in ["1000000000000", "18446744073709551615"] {
        let text = format!("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n{n} 0 1 2\n");
        let e = err_of(read_mesh(put(dir.path(), "big.off", text.as_bytes())));
        assert!(
            e.contains(&format!("announces {n} corners but lists 3")),
            "{e}"
        );
    }
    // Also a count above u64: not a number of corners at all.
    let text = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n99999999999999999999999 0 1 2\n";
    let e = err_of(read_mesh(put(dir.path(), "huge.off", text.as_bytes())));
    assert!(e.contains("corner count"), "{e}");
}

#[test]
fn ply_elements_without_properties_cost_nothing_whatever_their_count() {
    let dir = tempfile::tempdir().expect("tempdir");
    for format in ["ascii", "binary_little_endian"] {
        let mut bytes = format!(
            "ply\nformat {format} 1.0\nelement junk 18446744073709551615\n\
             element vertex 3\nproperty uchar x\nproperty uchar y\nproperty uchar z\n\
             element face 1\nproperty list uchar uchar vertex_indices\nend_header\n"
        )
        .into_bytes();
        if format == "ascii" {
            bytes.extend_from_slice(b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
        } else {
            bytes.extend_from_slice(&[0, 0, 0, 1, 0, 0, 0, 1, 0, 3, 0, 1, 2]);
        }
        let t = Instant::now();
        let m = read_mesh(put(dir.path(), "junk.ply", &bytes)).expect("reads");
        assert!(t.elapsed() < HANG, "{format}: took {:?}", t.elapsed());
        assert_eq!(m.faces, vec![[0, 1, 2]], "{format}");
        assert_eq!(m.positions[1], [1.0, 0.0, 0.0], "{format}");
    }
}

#[test]
fn a_utf8_bom_does_not_hide_the_first_record_of_text_formats() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bom = "\u{FEFF}";
    let obj = format!("{bom}v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\n");
    let m = read_mesh(put(dir.path(), "bom.obj", obj.as_bytes())).expect("reads");
    assert_eq!(m.positions.len(), 4);
    assert_eq!(m.positions[0], [0.0, 0.0, 0.0]);
    assert_eq!(m.faces, vec![[0, 2, 1], [0, 1, 3]]);
    let off = format!("{bom}OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    let m = read_mesh(put(dir.path(), "bom.off", off.as_bytes())).expect("reads");
    assert_eq!(m.faces, vec![[0, 1, 2]]);
    let ply = format!(
        "{bom}ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
         0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    );
    let m = read_mesh(put(dir.path(), "bom.ply", ply.as_bytes())).expect("reads");
    assert_eq!(m.faces, vec![[0, 1, 2]]);
}

#[test]
fn obj_index_errors_name_the_kind_of_index() {
    let dir = tempfile::tempdir().expect("tempdir");
    let base = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\n";
    let e = err_of(read_mesh(put(
        dir.path(),
        "n0.obj",
        format!("{base}f 1//0 2//1 3//1\n").as_bytes(),
    )));
    assert!(e.contains("normal index 0 is invalid"), "{e}");
    let e = err_of(read_mesh(put(
        dir.path(),
        "nneg.obj",
        format!("{base}f 1//-5 2//1 3//1\n").as_bytes(),
    )));
    assert!(e.contains("relative normal index -5"), "{e}");
    let e = err_of(read_mesh(put(
        dir.path(),
        "v0.obj",
        format!("{base}f 0 2 3\n").as_bytes(),
    )));
    assert!(e.contains("vertex index 0 is invalid"), "{e}");
}

// ---------------------------------------------------------------- glTF

fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            s.push(if k <= c.len() {
                A[((n >> (18 - 6 * k)) & 63) as usize] as char
            } else {
                '='
            });
        }
    }
    s
}

/// One triangle: 3 f32 VEC3 positions then 3 u16 indices (padded), as a base64 data URI.
fn triangle_buffer() -> (String, usize) {
    let mut bin = Vec::new();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
        for c in p {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    (
        format!("data:application/octet-stream;base64,{}", base64(&bin)),
        bin.len(),
    )
}

/// A `.gltf` around the triangle buffer with the given scenes/nodes JSON and position accessor
/// fields (`type`, `componentType`) and position view stride.
fn triangle_gltf(
    scenes_and_nodes: &str,
    pos_type: &str,
    pos_component: u32,
    stride: u32,
) -> String {
    let (uri, len) = triangle_buffer();
    let stride = if stride == 0 {
        String::new()
    } else {
        format!(", \"byteStride\": {stride}")
    };
    format!(
        r#"{{"asset": {{"version": "2.0"}}, {scenes_and_nodes}
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
  "buffers": [{{"byteLength": {len}, "uri": "{uri}"}}],
  "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 36{stride}}},
                  {{"buffer": 0, "byteOffset": 36, "byteLength": 6}}],
  "accessors": [{{"bufferView": 0, "componentType": {pos_component}, "count": 3, "type": "{pos_type}", "min": [0, 0, 0], "max": [1, 1, 0]}},
                {{"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}}]}}"#
    )
}

const ONE_NODE: &str = r#""scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],"#;

#[test]
fn gltf_triangle_reads_and_byte_stride_smaller_than_an_element_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let ok = triangle_gltf(ONE_NODE, "VEC3", 5126, 0);
    let m = read_mesh(put(dir.path(), "ok.gltf", ok.as_bytes())).expect("reads");
    assert_eq!(m.faces, vec![[0, 1, 2]]);
    assert_eq!(m.positions[2], [0.0, 1.0, 0.0]);
    let bad = triangle_gltf(ONE_NODE, "VEC3", 5126, 4);
    let e = err_of(read_mesh(put(dir.path(), "stride.gltf", bad.as_bytes())));
    assert!(
        e.contains("byteStride 4, smaller than one VEC3 element (12 bytes)"),
        "{e}"
    );
    // A stride that makes the last element run past the view.
    let bad = triangle_gltf(ONE_NODE, "VEC3", 5126, 16);
    let e = err_of(read_mesh(put(dir.path(), "long.gltf", bad.as_bytes())));
    assert!(e.contains("do not fit in bufferView 0"), "{e}");
}

/// A non-unit rotation quaternion used to scale the mesh by its squared length: one off by f32
/// rounding is normalized, one clearly off (or zero, or not finite) is refused naming the node.
#[test]
fn gltf_non_unit_quaternions_are_normalized_when_rounding_and_refused_otherwise() {
    let dir = tempfile::tempdir().expect("tempdir");
    let with_rotation = |q: &str| {
        triangle_gltf(
            &format!(
                r#""scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0, "rotation": {q}}}],"#
            ),
            "VEC3",
            5126,
            0,
        )
    };
    let m = read_mesh(put(
        dir.path(),
        "near.gltf",
        with_rotation("[0, 0, 0, 1.0004]").as_bytes(),
    ))
    .expect("a quaternion within rounding of unit length");
    assert_eq!(m.positions[1], [1.0, 0.0, 0.0], "not scaled");
    for q in ["[0, 0, 0, 2]", "[0, 0, 0, 0]", "[0, 0, 0.5, 0.5]"] {
        let e = err_of(read_mesh(put(
            dir.path(),
            "far.gltf",
            with_rotation(q).as_bytes(),
        )));
        assert!(
            e.contains("node 0: rotation") && e.contains("unit quaternions"),
            "{q}: {e}"
        );
    }
    // A byte-order mark before the JSON (Windows editors) is not part of it.
    let bom = [
        b"\xEF\xBB\xBF".as_slice(),
        triangle_gltf(ONE_NODE, "VEC3", 5126, 0).as_bytes(),
    ]
    .concat();
    let m = read_mesh(put(dir.path(), "bom.gltf", &bom)).expect("a BOM");
    assert_eq!(m.faces, vec![[0, 1, 2]]);
}

#[test]
fn gltf_attribute_naming_a_missing_accessor_is_an_error() {
    // Found by `cargo xtask fuzz` (gltf, seed 7): the `gltf` crate's validation indexed it.
    let dir = tempfile::tempdir().expect("tempdir");
    for index in ["7", "4294967295"] {
        let bad = triangle_gltf(ONE_NODE, "VEC3", 5126, 0)
            .replace("\"POSITION\": 0", &format!("\"POSITION\": {index}"));
        let e = err_of(read_mesh(put(dir.path(), "acc.gltf", bad.as_bytes())));
        assert!(
            e.contains(&format!("attribute accessor {index} does not exist")),
            "{e}"
        );
    }
}

#[test]
fn gltf_wrongly_typed_position_accessor_is_named_as_such() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bad = triangle_gltf(ONE_NODE, "SCALAR", 5126, 0);
    let e = err_of(read_mesh(put(dir.path(), "t.gltf", bad.as_bytes())));
    assert!(
        e.contains("POSITION (accessor 0) is SCALAR of FLOAT; expected VEC3"),
        "{e}"
    );
    assert!(!e.contains("without"), "{e}");
}

#[test]
fn gltf_with_two_scenes_reads_the_default_scene_or_else_the_first() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Scene 0 instances the triangle at the origin, scene 1 moved by x + 5.
    let nodes = r#""scenes": [{"nodes": [0]}, {"nodes": [1]}],
        "nodes": [{"mesh": 0}, {"mesh": 0, "translation": [5, 0, 0]}],"#;
    let first = triangle_gltf(nodes, "VEC3", 5126, 0);
    let m = read_mesh(put(dir.path(), "first.gltf", first.as_bytes())).expect("reads");
    assert_eq!(m.faces.len(), 1, "one scene only");
    assert_eq!(m.positions[1], [1.0, 0.0, 0.0]);
    let default1 = triangle_gltf(&format!(r#""scene": 1, {nodes}"#), "VEC3", 5126, 0);
    let m = read_mesh(put(dir.path(), "second.gltf", default1.as_bytes())).expect("reads");
    assert_eq!(m.faces.len(), 1, "one scene only");
    assert_eq!(m.positions[1], [6.0, 0.0, 0.0]);
}

#[test]
fn gltf_nodes_sharing_children_are_refused_at_once_instead_of_walked_exponentially() {
    let dir = tempfile::tempdir().expect("tempdir");
    // 40 levels of two nodes, each the parent of both nodes of the next level: 2⁴⁰ paths.
    let levels = 40;
    let mut nodes = Vec::new();
    for l in 0..levels {
        for _ in 0..2 {
            if l + 1 < levels {
                nodes.push(format!(
                    r#"{{"mesh": 0, "children": [{}, {}]}}"#,
                    2 * (l + 1),
                    2 * (l + 1) + 1
                ));
            } else {
                nodes.push(r#"{"mesh": 0}"#.to_string());
            }
        }
    }
    let sn = format!(
        r#""scene": 0, "scenes": [{{"nodes": [0, 1]}}], "nodes": [{}],"#,
        nodes.join(",")
    );
    let t = Instant::now();
    let e = err_of(read_mesh(put(
        dir.path(),
        "dag.gltf",
        triangle_gltf(&sn, "VEC3", 5126, 0).as_bytes(),
    )));
    assert!(t.elapsed() < HANG);
    assert!(e.contains("node 78 is reached twice"), "{e}");
    // A cycle is refused the same way.
    let sn = r#""scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0, "children": [1]}, {"children": [0]}],"#;
    let r = read_mesh(put(
        dir.path(),
        "cycle.gltf",
        triangle_gltf(sn, "VEC3", 5126, 0).as_bytes(),
    ));
    assert!(r.is_err());
}

#[test]
fn gltf_instancing_is_bounded_by_the_input_size() {
    // 300 root nodes instancing one mesh of 60 000 vertices: 18 M vertices from a 0.7 MB buffer.
    let n = 60_000usize;
    let mut bin = Vec::with_capacity(n * 12);
    for i in 0..n {
        for c in [i as f32, (i % 7) as f32, (i % 3) as f32] {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(dir.path().join("big.bin"), &bin).expect("write");
    let nodes: Vec<String> = (0..300).map(|_| r#"{"mesh": 0}"#.to_string()).collect();
    let roots: Vec<String> = (0..300).map(|i| i.to_string()).collect();
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [{}]}}],
  "nodes": [{}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
  "buffers": [{{"byteLength": {}, "uri": "big.bin"}}],
  "bufferViews": [{{"buffer": 0, "byteLength": {}}}],
  "accessors": [{{"bufferView": 0, "componentType": 5126, "count": {n}, "type": "VEC3", "min": [0, 0, 0], "max": [{n}, 6, 2]}}]}}"#,
        roots.join(","),
        nodes.join(","),
        bin.len(),
        bin.len()
    );
    let e = err_of(read_mesh(put(dir.path(), "many.gltf", json.as_bytes())));
    assert!(e.contains("exceeds the limit"), "{e}");
}

#[test]
fn gltf_buffer_uris_must_name_regular_files_inside_the_folder_and_hold_byte_length() {
    let dir = tempfile::tempdir().expect("tempdir");
    let with_uri = |uri: &str, len: usize| {
        triangle_gltf(ONE_NODE, "VEC3", 5126, 0)
            .replace(&triangle_buffer().0, uri)
            .replace(
                &format!("\"byteLength\": {}", triangle_buffer().1),
                &format!("\"byteLength\": {len}"),
            )
    };
    for uri in [
        "/dev/zero",
        "../outside.bin",
        "file:///dev/zero",
        "http://x/y.bin",
    ] {
        let e = err_of(read_mesh(put(
            dir.path(),
            "abs.gltf",
            with_uri(uri, 44).as_bytes(),
        )));
        assert!(e.contains("not a relative path inside"), "{uri}: {e}");
    }
    // A link inside the folder to a device file: not a regular file.
    std::os::unix::fs::symlink("/dev/zero", dir.path().join("zero.bin")).expect("symlink");
    let e = err_of(read_mesh(put(
        dir.path(),
        "dev.gltf",
        with_uri("zero.bin", 44).as_bytes(),
    )));
    assert!(e.contains("is not a regular file"), "{e}");
    // A folder is not a regular file either.
    std::fs::create_dir(dir.path().join("sub.bin")).expect("mkdir");
    let e = err_of(read_mesh(put(
        dir.path(),
        "dir.gltf",
        with_uri("sub.bin", 44).as_bytes(),
    )));
    assert!(e.contains("is not a regular file"), "{e}");
    // A file shorter than its declared byteLength.
    std::fs::write(dir.path().join("short.bin"), [0u8; 10]).expect("write");
    let e = err_of(read_mesh(put(
        dir.path(),
        "short.gltf",
        with_uri("short.bin", 44).as_bytes(),
    )));
    assert!(
        e.contains("holds 10 bytes but the buffer declares 44"),
        "{e}"
    );
    // The same bytes as a file next to the .gltf (percent-encoded name) read correctly.
    let (uri, len) = triangle_buffer();
    let bytes = {
        let b64 = uri.split_once(',').map(|(_, b)| b).unwrap_or("");
        decode(b64)
    };
    std::fs::write(dir.path().join("tri angle.bin"), &bytes).expect("write");
    let m = read_mesh(put(
        dir.path(),
        "file.gltf",
        with_uri("tri%20angle.bin", len).as_bytes(),
    ))
    .expect("reads");
    assert_eq!(m.faces, vec![[0, 1, 2]]);
}

fn decode(s: &str) -> Vec<u8> {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let v: Vec<u32> = s
        .bytes()
        .filter(|&c| c != b'=')
        .map(|c| A.iter().position(|&a| a == c).unwrap_or(0) as u32)
        .collect();
    let mut out = Vec::new();
    for c in v.chunks(4) {
        let mut n = 0u32;
        for (i, x) in c.iter().enumerate() {
            n |= x << (18 - 6 * i);
        }
        out.extend_from_slice(&n.to_be_bytes()[1..c.len()]);
    }
    out
}

#[test]
fn glb_with_a_lying_byte_length_or_missing_chunk_is_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("t.glb");
    write_glb(&p, &bunny(), None).expect("writes");
    let bytes = std::fs::read(&p).expect("read");
    let text = String::from_utf8_lossy(&bytes).into_owned();
    let at = text.find("\"buffers\":[{\"byteLength\":").expect("buffers");
    // Same-width replacement of the declared length by a larger number.
    let digits_at = at + "\"buffers\":[{\"byteLength\":".len();
    let mut b = bytes.clone();
    let end = b[digits_at..]
        .iter()
        .position(|c| !c.is_ascii_digit())
        .expect("digits");
    for c in &mut b[digits_at..digits_at + end] {
        *c = b'9';
    }
    let e = err_of(read_mesh(put(dir.path(), "lie.glb", &b)));
    assert!(
        e.contains("declares") || e.contains("not a valid glTF"),
        "{e}"
    );
}

#[test]
fn glb_header_lengths_below_the_header_or_beyond_the_file_are_refused() {
    // Found by `cargo xtask fuzz` (glb, seed 1): a total length under 12 overflowed inside the
    // `gltf` crate.
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("t.glb");
    write_glb(&p, &bunny(), None).expect("writes");
    let bytes = std::fs::read(&p).expect("read");
    for declared in [0u32, 4, 11, bytes.len() as u32 + 1] {
        let mut b = bytes.clone();
        b[8..12].copy_from_slice(&declared.to_le_bytes());
        let e = err_of(read_mesh(put(dir.path(), "len.glb", &b)));
        assert!(
            e.contains(&format!("declares a length of {declared} bytes")),
            "{e}"
        );
    }
    let e = err_of(read_mesh(put(dir.path(), "short.glb", b"glTF\x02\0\0\0")));
    assert!(e.contains("truncated"), "{e}");
}

// ---------------------------------------------------------------- validation

fn opts() -> RepairOptions {
    RepairOptions::default()
}

#[test]
fn a_debris_triangle_far_away_does_not_delete_the_mesh_as_zero_area() {
    let b = bunny();
    let clean = repair(&b, &opts()).expect("bunny repairs");
    let mut m = b.clone();
    let n = m.positions.len() as u32;
    m.positions.extend([
        [1e6, 1e6, 1e6],
        [1e6 + 0.1, 1e6, 1e6],
        [1e6, 1e6 + 0.1, 1e6],
    ]);
    m.faces.push([n, n + 1, n + 2]);
    let r = repair(&m, &opts()).expect("repairs");
    assert!(
        r.report.issue(IssueKind::ZeroAreaFaces).is_none(),
        "{:?}",
        r.report
    );
    assert_eq!(r.mesh.faces.len(), clean.mesh.faces.len() + 1);
    assert_eq!(r.report.components, clean.report.components + 1);
}

#[test]
fn an_unreferenced_vertex_at_f32_max_does_not_make_a_mesh_unusable() {
    let b = bunny();
    let clean = repair(&b, &opts()).expect("bunny repairs");
    let mut m = b.clone();
    m.positions.push([3.4e38, -3.4e38, 3.4e38]);
    let r = repair(&m, &opts()).expect("repairs");
    assert_eq!(r.mesh, clean.mesh);
    assert!(r.report.issue(IssueKind::ZeroAreaFaces).is_none());
    assert_eq!(
        r.report
            .issue(IssueKind::UnreferencedVertices)
            .map(|i| i.count),
        Some(1)
    );
}

#[test]
fn spheres_scaled_by_1e200_and_1e_minus_200_keep_every_face_and_their_orientation() {
    let s = mesh_core::shapes::icosphere(2);
    for scale in [1e200, 1e-200, 1e300] {
        let mut m = s.clone();
        for p in &mut m.positions {
            *p = p.map(|c| c * scale);
        }
        let rep = validate(&m, &opts());
        assert!(rep.is_clean(), "scale {scale}: {:?}", rep.issues);
        assert_eq!(rep.output_faces, s.faces.len(), "scale {scale}");
        // Turned inside out, it is detected and flipped back (the volume's sign survives).
        let mut inv = m.clone();
        for f in &mut inv.faces {
            *f = [f[0], f[2], f[1]];
        }
        let r = repair(&inv, &opts()).expect("repairs");
        assert!(
            r.report.issue(IssueKind::InwardFacing).is_some(),
            "scale {scale}: {:?}",
            r.report.issues
        );
        assert_eq!(r.mesh.faces, m.faces, "scale {scale}");
    }
}

#[test]
fn collinear_faces_are_zero_area_at_any_scale_and_tiny_well_shaped_faces_are_not() {
    for scale in [1e-150, 1e-3, 1.0, 1e150] {
        let p = |x: f64, y: f64, z: f64| [x * scale, y * scale, z * scale];
        let m = TriMesh::new(
            vec![
                p(0., 0., 0.),
                p(1., 0., 0.),
                p(0., 1., 0.),
                p(0., 0., 1.),
                p(0.5, 0., 0.),
                // A well-shaped triangle a million times smaller than the rest.
                p(2., 2., 2.),
                p(2. + 1e-6, 2., 2.),
                p(2., 2. + 1e-6, 2.),
            ],
            vec![
                [0, 2, 1],
                [0, 1, 3],
                [0, 3, 2],
                [1, 2, 3],
                [0, 4, 1],
                [5, 6, 7],
            ],
        );
        let rep = validate(&m, &opts());
        assert_eq!(
            rep.issue(IssueKind::ZeroAreaFaces)
                .map(|i| i.examples.clone()),
            Some(mesh_core::validate::Locations::Faces(vec![4])),
            "scale {scale}"
        );
    }
}

/// Runs `f` in a thread; fails the test (instead of hanging it) when `f` blocks past [`HANG`].
fn within_hang_bound<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(HANG).expect(
        "the reader blocked: it must refuse a path that is not a regular file without opening it",
    )
}

#[test]
fn paths_that_are_not_regular_files_are_refused_without_being_opened() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A directory named like a mesh.
    let d = dir.path().join("folder.obj");
    std::fs::create_dir(&d).expect("mkdir");
    // A link to an endless device, named like a mesh and like an .npz.
    let zero_obj = dir.path().join("zero.obj");
    std::os::unix::fs::symlink("/dev/zero", &zero_obj).expect("symlink");
    let zero_npz = dir.path().join("zero.npz");
    std::os::unix::fs::symlink("/dev/zero", &zero_npz).expect("symlink");
    // A named pipe nobody writes to: opening it for reading would block forever.
    let fifo = dir.path().join("pipe.ply");
    let made_fifo = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .map(|s| s.success())
        .unwrap_or(false);

    let e = err_of(read_mesh(&d));
    assert!(e.contains("a directory, not a regular file"), "{e}");
    let e = within_hang_bound(move || err_of(read_mesh(&zero_obj)));
    assert!(e.contains("a device, not a regular file"), "{e}");
    let e = within_hang_bound(move || {
        npy::npz::NpzReader::open(&zero_npz)
            .expect_err("a device is not an .npz")
            .to_string()
    });
    assert!(e.contains("a device, not a regular file"), "{e}");
    if made_fifo {
        let e = within_hang_bound(move || err_of(read_mesh(&fifo)));
        assert!(e.contains("a named pipe (FIFO), not a regular file"), "{e}");
    } else {
        eprintln!("mkfifo unavailable: the FIFO case was not exercised");
    }
}

#[test]
fn io_errors_state_their_reason_once() {
    // The reason is in the message and not also the error's source, so a reporter that prints the
    // chain (anyhow's `{:#}`) does not repeat it.
    let dir = tempfile::tempdir().expect("tempdir");
    let e = read_mesh(dir.path().join("missing.obj")).expect_err("missing");
    let text = e.to_string();
    assert!(
        text.contains("missing.obj") && text.contains("No such file"),
        "{text}"
    );
    assert!(std::error::Error::source(&e).is_none(), "{text}");
}
