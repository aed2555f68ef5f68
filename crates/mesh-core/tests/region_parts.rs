//! Named parts and properties read beside the mesh, and regions that follow repair.
#![cfg(feature = "io")]

use std::path::{Path, PathBuf};

use mesh_core::io::read_mesh_with_parts;
use mesh_core::region::{PartKind, RegionInput, RegionSpec, select};
use mesh_core::validate::{RepairOptions, repair};

fn put(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).expect("write");
    p
}

/// Selected vertices of a region on the repaired mesh, as positions (independent of numbering).
fn selected_positions(path: &Path, spec: &str) -> Vec<[f64; 3]> {
    let (mesh, parts) = read_mesh_with_parts(path).expect("reads");
    let r = repair(&mesh, &RepairOptions::default()).expect("repairs");
    let input = RegionInput {
        positions: &r.mesh.positions,
        faces: &r.mesh.faces,
        vertex_map: &r.vertex_map,
        face_map: &r.face_map,
        parts: &parts,
    };
    let region = select(&[RegionSpec::parse(spec).expect("parses")], &input).expect("selects");
    let mut out: Vec<[f64; 3]> = (0..r.mesh.positions.len())
        .filter(|&v| region.free[v])
        .map(|v| r.mesh.positions[v])
        .collect();
    out.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
    out
}

/// Two unit quads side by side along x, as OBJ with objects, groups and materials. The right
/// quad's corner at x = 1 is written twice (vertices 2 and 7, an exact duplicate on an open
/// border, which repair welds), and a degenerate triangle (dropped by repair) sits in group `junk`.
const TWO_QUADS: &str = "\
v 0 0 0
v 0 1 0
v 1 0 0
v 1 1 0
v 2 0 0
v 2 1 0
v 5 5 5
v 1 0 0
o left
g seat back
usemtl wood
f 1 3 4 2
o right
g
usemtl metal
f 8 5 6 4
g junk
f 1 1 3
";

#[test]
fn obj_groups_objects_and_materials_are_parts_and_follow_repair() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = put(dir.path(), "quads.obj", TWO_QUADS.as_bytes());
    let (mesh, parts) = read_mesh_with_parts(&p).expect("reads");
    assert_eq!(mesh.faces.len(), 5);
    let names: Vec<(PartKind, &str, Vec<u32>)> = parts
        .named
        .iter()
        .map(|p| (p.kind, p.name.as_str(), p.faces.clone()))
        .collect();
    assert_eq!(
        names,
        vec![
            (PartKind::Object, "left", vec![0, 1]),
            (PartKind::Group, "seat", vec![0, 1]),
            (PartKind::Group, "back", vec![0, 1]),
            (PartKind::Material, "wood", vec![0, 1]),
            (PartKind::Object, "right", vec![2, 3, 4]),
            (PartKind::Material, "metal", vec![2, 3, 4]),
            (PartKind::Group, "junk", vec![4]),
        ]
    );
    // Any-face rule, on the repaired mesh (the duplicate welded, vertex 7 "5 5 5" dropped).
    let square = |x0: f64| {
        vec![
            [x0, 0.0, 0.0],
            [x0, 1.0, 0.0],
            [x0 + 1.0, 0.0, 0.0],
            [x0 + 1.0, 1.0, 0.0],
        ]
    };
    assert_eq!(selected_positions(&p, "part:seat"), square(0.0));
    assert_eq!(selected_positions(&p, "part:wood"), square(0.0));
    // The right quad used the duplicate (file vertex 8): it maps onto the welded corner.
    assert_eq!(selected_positions(&p, "part:metal"), square(1.0));
    assert_eq!(selected_positions(&p, "not:part:junk").len(), 6);
    // `junk` holds only the dropped degenerate face: selecting it is an empty-region error.
    let (mesh, parts) = read_mesh_with_parts(&p).expect("reads");
    let r = repair(&mesh, &RepairOptions::default()).expect("repairs");
    let input = RegionInput {
        positions: &r.mesh.positions,
        faces: &r.mesh.faces,
        vertex_map: &r.vertex_map,
        face_map: &r.face_map,
        parts: &parts,
    };
    let e = select(&[RegionSpec::Part("junk".into())], &input).expect_err("an error");
    assert!(e.to_string().contains("selects no vertex"), "{e}");
}

#[test]
fn ply_vertex_and_face_properties_are_compared() {
    let ply = "\
ply
format ascii 1.0
element vertex 6
property float x
property float y
property float z
property uchar label
property float quality
element face 2
property list uchar int vertex_indices
property int part_id
end_header
0 0 0 1 0.1
0 1 0 1 0.2
1 0 0 3 0.9
1 1 0 3 0.8
2 0 0 3 0.7
2 1 0 1 0.6
4 0 2 3 1 7
4 2 4 5 3 9
";
    let dir = tempfile::tempdir().expect("tempdir");
    let p = put(dir.path(), "labels.ply", ply.as_bytes());
    let (mesh, parts) = read_mesh_with_parts(&p).expect("reads");
    assert_eq!(mesh.faces.len(), 4);
    let names: Vec<&str> = parts
        .vertex_properties
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    assert_eq!(names, ["label", "quality"]);
    assert_eq!(parts.face_properties.len(), 1);
    assert_eq!(parts.face_properties[0].values, [7.0, 7.0, 9.0, 9.0]);
    assert_eq!(
        selected_positions(&p, "property:label == 3"),
        vec![[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 0.0, 0.0]]
    );
    assert_eq!(selected_positions(&p, "property:quality>0.65").len(), 3);
    assert_eq!(selected_positions(&p, "property:part_id==9").len(), 4);
    let e = RegionSpec::parse("property:colour>1").expect("parses");
    let (mesh, parts) = read_mesh_with_parts(&p).expect("reads");
    let r = repair(&mesh, &RepairOptions::default()).expect("repairs");
    let input = RegionInput {
        positions: &r.mesh.positions,
        faces: &r.mesh.faces,
        vertex_map: &r.vertex_map,
        face_map: &r.face_map,
        parts: &parts,
    };
    let e = select(&[e], &input).expect_err("an error").to_string();
    assert!(
        e.contains("no property named `colour`") && e.contains("face property `part_id`"),
        "{e}"
    );
}

#[test]
fn gltf_named_nodes_and_meshes_are_parts() {
    // One triangle mesh "leaf", instanced by node "left" and by node "right" (translated).
    let dir = tempfile::tempdir().expect("tempdir");
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for i in [0u16, 1, 2, 0] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    put(dir.path(), "tri.bin", &bin);
    let json = r#"{
      "asset": {"version": "2.0"},
      "scene": 0,
      "scenes": [{"nodes": [0, 1]}],
      "nodes": [
        {"name": "left", "mesh": 0},
        {"name": "right", "translation": [3, 0, 0], "mesh": 0}
      ],
      "meshes": [{"name": "leaf", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
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
    let (_, parts) = read_mesh_with_parts(&p).expect("reads");
    let names: Vec<(PartKind, &str, Vec<u32>)> = parts
        .named
        .iter()
        .map(|p| (p.kind, p.name.as_str(), p.faces.clone()))
        .collect();
    assert_eq!(
        names,
        vec![
            (PartKind::Node, "left", vec![0]),
            (PartKind::Mesh, "leaf", vec![0, 1]),
            (PartKind::Node, "right", vec![1]),
        ]
    );
}
