//! glTF 2.0 (`.gltf` with external or data-URI buffers, and binary `.glb`).
//!
//! Read: every triangle primitive (`TRIANGLES`, `TRIANGLE_STRIP`, `TRIANGLE_FAN`) of every mesh
//! instance in the scene graph, with node transforms applied (world = parent · local, column
//! vectors; faces are flipped where a transform mirrors, so they stay CCW). Meshes no node uses
//! are read with the identity transform. Primitives are appended one after another, without
//! welding (repair welds exact duplicates). Normals, when every primitive has them, are
//! transformed by the inverse transpose and renormalized.
//! Write (`.glb`): one mesh, one node, positions (and normals) as `f32` VEC3 with `min`/`max`,
//! `u32` indices.

use std::path::Path;

use gltf::mesh::Mode;

use super::{MeshWithNormals, io_err, parse_err};
use crate::{MeshError, TriMesh};

type Mat4 = [[f64; 4]; 4]; // column-major: m[col][row]

fn mat_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut c = [[0.0; 4]; 4];
    for col in 0..4 {
        for row in 0..4 {
            c[col][row] = (0..4).map(|k| a[k][row] * b[col][k]).sum();
        }
    }
    c
}

fn to_f64(m: [[f32; 4]; 4]) -> Mat4 {
    m.map(|c| c.map(f64::from))
}

const IDENTITY: Mat4 = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// Upper-left 3×3 determinant.
fn det3(m: &Mat4) -> f64 {
    let a = |r: usize, c: usize| m[c][r];
    a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1))
        - a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0))
        + a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0))
}

/// Cofactor matrix of the upper-left 3×3 (= det · inverse transpose): maps normals.
fn cofactor3(m: &Mat4) -> [[f64; 3]; 3] {
    let a = |r: usize, c: usize| m[c][r];
    let mut out = [[0.0; 3]; 3]; // out[row][col]
    for r in 0..3 {
        for c in 0..3 {
            let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
            let (c1, c2) = ((c + 1) % 3, (c + 2) % 3);
            out[r][c] = a(r1, c1) * a(r2, c2) - a(r1, c2) * a(r2, c1);
        }
    }
    out
}

struct Collector<'a> {
    buffers: &'a [gltf::buffer::Data],
    positions: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    normals: Vec<[f64; 3]>,
    all_normals: bool,
}

impl Collector<'_> {
    fn add_mesh(
        &mut self,
        mesh: gltf::Mesh<'_>,
        world: &Mat4,
        path: &Path,
    ) -> Result<(), MeshError> {
        let flip = det3(world) < 0.0;
        let cof = cofactor3(world);
        let sign = if flip { -1.0 } else { 1.0 };
        for prim in mesh.primitives() {
            let mode = prim.mode();
            if !matches!(
                mode,
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                continue;
            }
            let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d.0[..]));
            let Some(pos) = reader.read_positions() else {
                return Err(parse_err(
                    path,
                    format!(
                        "mesh {} has a triangle primitive without POSITION",
                        mesh.index()
                    ),
                ));
            };
            let base = self.positions.len();
            let local: Vec<[f32; 3]> = pos.collect();
            for p in &local {
                let p = p.map(f64::from);
                let mut q = [0.0; 3];
                for r in 0..3 {
                    q[r] =
                        world[0][r] * p[0] + world[1][r] * p[1] + world[2][r] * p[2] + world[3][r];
                }
                self.positions.push(q);
            }
            match reader.read_normals() {
                Some(ns) => {
                    for n in ns {
                        let n = n.map(f64::from);
                        let mut q = [0.0; 3];
                        for r in 0..3 {
                            q[r] = sign * (cof[r][0] * n[0] + cof[r][1] * n[1] + cof[r][2] * n[2]);
                        }
                        let l = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt().max(1e-30);
                        self.normals.push(q.map(|c| c / l));
                    }
                }
                None => self.all_normals = false,
            }
            let idx: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..local.len() as u32).collect(),
            };
            let nlocal = local.len();
            let mesh_index = mesh.index();
            let off = |i: u32| -> Result<u32, MeshError> {
                if i as usize >= nlocal {
                    return Err(parse_err(
                        path,
                        format!(
                            "mesh {mesh_index}: index {i} is beyond the primitive's {nlocal} vertices"
                        ),
                    ));
                }
                u32::try_from(base + i as usize)
                    .map_err(|_| parse_err(path, "more than 2³² vertices in total"))
            };
            let mut tri = |a: u32, b: u32, c: u32| -> Result<(), MeshError> {
                let t = [off(a)?, off(b)?, off(c)?];
                self.faces.push(if flip { [t[0], t[2], t[1]] } else { t });
                Ok(())
            };
            match mode {
                Mode::Triangles => {
                    for c in idx.chunks_exact(3) {
                        tri(c[0], c[1], c[2])?;
                    }
                }
                Mode::TriangleStrip => {
                    for k in 2..idx.len() {
                        if k.is_multiple_of(2) {
                            tri(idx[k - 2], idx[k - 1], idx[k])?;
                        } else {
                            tri(idx[k - 1], idx[k - 2], idx[k])?;
                        }
                    }
                }
                _ => {
                    for k in 2..idx.len() {
                        tri(idx[0], idx[k - 1], idx[k])?;
                    }
                }
            }
        }
        Ok(())
    }

    fn add_node(
        &mut self,
        node: gltf::Node<'_>,
        parent: &Mat4,
        depth: usize,
        path: &Path,
    ) -> Result<(), MeshError> {
        if depth > 256 {
            return Err(parse_err(
                path,
                "node hierarchy is deeper than 256 levels (a cycle?)",
            ));
        }
        let world = mat_mul(parent, &to_f64(node.transform().matrix()));
        if let Some(m) = node.mesh() {
            self.add_mesh(m, &world, path)?;
        }
        for child in node.children() {
            self.add_node(child, &world, depth + 1, path)?;
        }
        Ok(())
    }
}

/// Reads a `.gltf` or `.glb` file. See the module docs.
pub fn read_gltf(path: &Path) -> Result<MeshWithNormals, MeshError> {
    let gltf = gltf::Gltf::open(path).map_err(|e| match e {
        gltf::Error::Io(source) => io_err(path, source),
        e => parse_err(path, format!("not a valid glTF 2.0 file: {e}")),
    })?;
    let base = path.parent();
    let buffers = gltf::import_buffers(&gltf.document, base, gltf.blob.clone())
        .map_err(|e| parse_err(path, format!("cannot load the glTF buffers: {e}")))?;
    let doc = &gltf.document;
    let mut c = Collector {
        buffers: &buffers,
        positions: Vec::new(),
        faces: Vec::new(),
        normals: Vec::new(),
        all_normals: true,
    };
    // Roots: the nodes of every scene (or, without scenes, nodes that are nobody's child).
    let mut roots: Vec<usize> = doc
        .scenes()
        .flat_map(|s| s.nodes().map(|n| n.index()).collect::<Vec<_>>())
        .collect();
    if doc.scenes().len() == 0 {
        let mut is_child = vec![false; doc.nodes().len()];
        for n in doc.nodes() {
            for ch in n.children() {
                is_child[ch.index()] = true;
            }
        }
        roots = (0..is_child.len()).filter(|&i| !is_child[i]).collect();
    }
    roots.dedup();
    let nodes: Vec<gltf::Node<'_>> = doc.nodes().collect();
    let mut used_mesh = vec![false; doc.meshes().len()];
    for n in doc.nodes() {
        if let Some(m) = n.mesh() {
            used_mesh[m.index()] = true;
        }
    }
    for &r in &roots {
        if let Some(node) = nodes.get(r) {
            c.add_node(node.clone(), &IDENTITY, 0, path)?;
        }
    }
    for m in doc.meshes() {
        if !used_mesh[m.index()] {
            c.add_mesh(m, &IDENTITY, path)?;
        }
    }
    let normals =
        (c.all_normals && c.normals.len() == c.positions.len() && !c.positions.is_empty())
            .then_some(c.normals);
    Ok((
        TriMesh {
            positions: c.positions,
            faces: c.faces,
        },
        normals,
    ))
}

/// Writes a binary glTF (`.glb`): positions and optional normals as `f32` VEC3 (positions with
/// `min`/`max`), `u32` indices, one mesh instanced by one node of the default scene.
pub fn write_glb(
    path: &Path,
    mesh: &TriMesh,
    normals: Option<&[[f64; 3]]>,
) -> Result<(), MeshError> {
    let nv = mesh.positions.len();
    let mut bin: Vec<u8> = Vec::with_capacity(nv * 24 + mesh.faces.len() * 12);
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &mesh.positions {
        for k in 0..3 {
            let x = p[k] as f32;
            if !x.is_finite() {
                return Err(MeshError::Invalid(format!(
                    "{}: cannot write non-finite coordinates to glTF",
                    path.display()
                )));
            }
            lo[k] = lo[k].min(x);
            hi[k] = hi[k].max(x);
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    if nv == 0 {
        lo = [0.0; 3];
        hi = [0.0; 3];
    }
    let pos_len = bin.len();
    if let Some(ns) = normals {
        for n in ns {
            for &c in n {
                bin.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
    }
    let nrm_len = bin.len() - pos_len;
    let idx_off = bin.len();
    for f in &mesh.faces {
        for &v in f {
            bin.extend_from_slice(&v.to_le_bytes());
        }
    }
    let idx_len = bin.len() - idx_off;
    let max_index = mesh.faces.iter().flatten().copied().max().unwrap_or(0);
    let min_index = mesh.faces.iter().flatten().copied().min().unwrap_or(0);
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let mut buffer_views = vec![
        serde_json::json!({"buffer": 0, "byteOffset": 0, "byteLength": pos_len, "target": 34962}),
    ];
    let mut accessors = vec![serde_json::json!({
        "bufferView": 0, "componentType": 5126, "count": nv, "type": "VEC3",
        "min": lo, "max": hi
    })];
    let mut attributes = serde_json::json!({"POSITION": 0});
    if normals.is_some() {
        buffer_views.push(serde_json::json!({"buffer": 0, "byteOffset": pos_len, "byteLength": nrm_len, "target": 34962}));
        accessors.push(serde_json::json!({"bufferView": 1, "componentType": 5126, "count": nv, "type": "VEC3"}));
        attributes["NORMAL"] = serde_json::json!(1);
    }
    let iv = buffer_views.len();
    buffer_views.push(serde_json::json!({"buffer": 0, "byteOffset": idx_off, "byteLength": idx_len, "target": 34963}));
    accessors.push(serde_json::json!({
        "bufferView": iv, "componentType": 5125, "count": mesh.faces.len() * 3, "type": "SCALAR",
        "min": [min_index], "max": [max_index]
    }));
    let json = serde_json::json!({
        "asset": {"version": "2.0", "generator": "mesh-core"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": attributes, "indices": iv, "mode": 4}]}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": buffer_views,
        "accessors": accessors,
    });
    let mut json = serde_json::to_vec(&json).map_err(|e| MeshError::Invalid(e.to_string()))?;
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let total = u32::try_from(total).map_err(|_| {
        MeshError::Invalid(format!(
            "{}: mesh too large for a GLB file (over 4 GiB)",
            path.display()
        ))
    })?;
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total.to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    std::fs::write(path, out).map_err(|e| io_err(path, e))
}
