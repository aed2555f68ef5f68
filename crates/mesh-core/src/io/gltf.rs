//! glTF 2.0 (`.gltf` with external or data-URI buffers, and binary `.glb`).
//!
//! Read: every triangle primitive (`TRIANGLES`, `TRIANGLE_STRIP`, `TRIANGLE_FAN`) of every mesh
//! instance in the default scene (else the first scene; without scenes, every root node), with node transforms applied (world = parent · local, column
//! vectors; faces are flipped where a transform mirrors, so they stay CCW). Meshes no node uses
//! are read with the identity transform. Primitives are appended one after another, without
//! welding (repair welds exact duplicates). Normals, when every primitive has them, are
//! transformed by the inverse transpose and renormalized. [`read_gltf_with_parts`] also returns
//! the triangles of each named node (its own mesh instance, not its children) and each named mesh
//! (all its instances) as region parts.
//! Write (`.glb`): one mesh, one node, positions (and normals) as `f32` VEC3 with `min`/`max`,
//! `u32` indices.

use std::path::Path;

use gltf::mesh::Mode;

use super::{MeshWithNormals, io_err, parse_err};
use crate::region::{NamedPart, PartKind, Parts};
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

/// Elements (vertices and indices) a file may expand to, beyond its own size: see
/// [`read_gltf`]'s docs. Legitimate files read each accessor about once, so a file whose
/// instancing multiplies its data by more than this is refused rather than allowed to fill memory.
const EXPANSION_PER_BYTE: usize = 16;
/// Elements always allowed, whatever the input's size.
const EXPANSION_FLOOR: usize = 1 << 22;

/// A buffer's bytes: the GLB blob, a decoded data URI, or a file next to the `.gltf`.
struct Buffers {
    data: Vec<Vec<u8>>,
}

/// Decodes standard base64 (with or without `=` padding; whitespace is not allowed).
fn decode_base64(s: &str) -> Option<Vec<u8>> {
    let val = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => u32::from(c - b'A'),
            b'a'..=b'z' => u32::from(c - b'a') + 26,
            b'0'..=b'9' => u32::from(c - b'0') + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            _ => return None,
        })
    };
    let b = s.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(b.len() / 4 * 3 + 3);
    for chunk in b.chunks(4) {
        if chunk.len() == 1 {
            return None;
        }
        let mut acc = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            acc |= val(c)? << (18 - 6 * i);
        }
        let bytes = acc.to_be_bytes();
        out.extend_from_slice(&bytes[1..chunk.len()]);
    }
    Some(out)
}

/// Decodes `%XX` escapes of a URI path (invalid escapes are kept as written).
fn percent_decode(s: &str) -> Vec<u8> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%'
            && i + 2 < b.len()
            && let Ok(v) =
                u8::from_str_radix(std::str::from_utf8(&b[i + 1..i + 3]).unwrap_or("x"), 16)
        {
            out.push(v);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    out
}

/// Loads every buffer, checking each against its declared `byteLength` and reading no more than
/// that. URIs: `data:` (base64) or a relative path inside the glTF's folder naming a regular file;
/// absolute paths, other schemes, `..` and non-regular files (devices, fifos) are refused.
fn load_buffers(
    doc: &gltf::Document,
    blob: Option<Vec<u8>>,
    path: &Path,
) -> Result<Buffers, MeshError> {
    let mut blob = blob;
    let mut data = Vec::new();
    for buffer in doc.buffers() {
        let i = buffer.index();
        let declared = buffer.length();
        let bytes = match buffer.source() {
            gltf::buffer::Source::Bin => blob.take().ok_or_else(|| {
                parse_err(
                    path,
                    format!(
                        "buffer {i} refers to the GLB binary chunk, which is missing (or used twice)"
                    ),
                )
            })?,
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                let (_, payload) = uri.split_once(";base64,").ok_or_else(|| {
                    parse_err(
                        path,
                        format!("buffer {i}: only base64 `data:` URIs are supported"),
                    )
                })?;
                decode_base64(payload).ok_or_else(|| {
                    parse_err(path, format!("buffer {i}: the data URI is not valid base64"))
                })?
            }
            gltf::buffer::Source::Uri(uri) => {
                let rel = percent_decode(uri);
                let rel = String::from_utf8(rel).map_err(|_| {
                    parse_err(path, format!("buffer {i}: URI {uri:?} is not UTF-8"))
                })?;
                let rel_path = Path::new(&rel);
                let escapes = rel_path.components().any(|c| {
                    !matches!(
                        c,
                        std::path::Component::Normal(_) | std::path::Component::CurDir
                    )
                });
                if rel.contains(':') || rel.is_empty() || escapes {
                    return Err(parse_err(
                        path,
                        format!(
                            "buffer {i}: URI {uri:?} is not a relative path inside the glTF's folder \
                             (absolute paths, `..` and URL schemes are refused; put the buffer next to the .gltf)"
                        ),
                    ));
                }
                let file_path = path.parent().unwrap_or(Path::new("")).join(rel_path);
                let meta = std::fs::metadata(&file_path).map_err(|e| io_err(&file_path, e))?;
                if !meta.is_file() {
                    return Err(parse_err(
                        path,
                        format!(
                            "buffer {i}: {} is not a regular file",
                            file_path.display()
                        ),
                    ));
                }
                if meta.len() < declared as u64 {
                    return Err(parse_err(
                        path,
                        format!(
                            "buffer {i}: {} holds {} bytes but the buffer declares {declared}",
                            file_path.display(),
                            meta.len()
                        ),
                    ));
                }
                let file = std::fs::File::open(&file_path).map_err(|e| io_err(&file_path, e))?;
                let mut b = Vec::with_capacity(declared);
                std::io::Read::read_to_end(
                    &mut std::io::Read::take(file, declared as u64),
                    &mut b,
                )
                .map_err(|e| io_err(&file_path, e))?;
                b
            }
        };
        if bytes.len() < declared {
            return Err(parse_err(
                path,
                format!(
                    "buffer {i} declares {declared} bytes but only {} are present (truncated file?)",
                    bytes.len()
                ),
            ));
        }
        data.push(bytes);
    }
    Ok(Buffers { data })
}

fn type_name(d: gltf::accessor::Dimensions) -> &'static str {
    use gltf::accessor::Dimensions as D;
    match d {
        D::Scalar => "SCALAR",
        D::Vec2 => "VEC2",
        D::Vec3 => "VEC3",
        D::Vec4 => "VEC4",
        D::Mat2 => "MAT2",
        D::Mat3 => "MAT3",
        D::Mat4 => "MAT4",
    }
}

fn component_name(t: gltf::accessor::DataType) -> &'static str {
    use gltf::accessor::DataType as T;
    match t {
        T::I8 => "BYTE",
        T::U8 => "UNSIGNED_BYTE",
        T::I16 => "SHORT",
        T::U16 => "UNSIGNED_SHORT",
        T::U32 => "UNSIGNED_INT",
        T::F32 => "FLOAT",
    }
}

struct Collector<'a> {
    buffers: &'a Buffers,
    positions: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    normals: Vec<[f64; 3]>,
    all_normals: bool,
    /// Named nodes and meshes with their triangles.
    parts: Parts,
    /// Elements (accessor components) still allowed to be read.
    budget: usize,
}

impl<'a> Collector<'a> {
    /// The bytes of accessor `acc`, each element's `size` bytes checked to lie inside its buffer
    /// view and the view inside its buffer, before anything is allocated. Returns the view's
    /// bytes, the accessor's offset in them and the stride.
    fn accessor_bytes(
        &mut self,
        acc: &gltf::Accessor<'_>,
        what: &str,
        path: &Path,
    ) -> Result<(&'a [u8], usize, usize), MeshError> {
        let ai = acc.index();
        let bad = |m: String| parse_err(path, format!("{what} (accessor {ai}): {m}"));
        if acc.sparse().is_some() {
            return Err(bad("sparse accessors are not supported".into()));
        }
        let Some(view) = acc.view() else {
            return Err(bad("it has no bufferView".into()));
        };
        let elem = acc.size();
        let count = acc.count();
        let components = count
            .checked_mul(acc.dimensions().multiplicity())
            .ok_or_else(|| bad(format!("count {count} is too large")))?;
        if components > self.budget {
            return Err(bad(format!(
                "reading {count} more elements exceeds the limit for a file of this size \
                 ({EXPANSION_PER_BYTE} elements per input byte; nodes instancing large meshes many times?)"
            )));
        }
        self.budget -= components;
        let buffers: &'a Buffers = self.buffers;
        let buf = buffers
            .data
            .get(view.buffer().index())
            .ok_or_else(|| bad(format!("buffer {} is missing", view.buffer().index())))?;
        let vi = view.index();
        let vend = view
            .offset()
            .checked_add(view.length())
            .filter(|&e| e <= buf.len())
            .ok_or_else(|| {
                bad(format!(
                    "bufferView {vi} (offset {}, length {}) runs past the end of its {}-byte buffer",
                    view.offset(),
                    view.length(),
                    buf.len()
                ))
            })?;
        let bytes = &buf[view.offset()..vend];
        let stride = view.stride().unwrap_or(elem);
        if stride < elem {
            return Err(bad(format!(
                "bufferView {vi} has byteStride {stride}, smaller than one {} element ({elem} bytes)",
                type_name(acc.dimensions())
            )));
        }
        if count > 0 {
            let need = (count - 1)
                .checked_mul(stride)
                .and_then(|x| x.checked_add(elem))
                .and_then(|x| x.checked_add(acc.offset()));
            if need.is_none_or(|n| n > bytes.len()) {
                return Err(bad(format!(
                    "{count} elements of {elem} bytes (stride {stride}) from offset {} do not fit in \
                     bufferView {vi} of {} bytes",
                    acc.offset(),
                    bytes.len()
                )));
            }
        }
        Ok((bytes, acc.offset(), stride))
    }

    /// A `VEC3` attribute (`FLOAT`, or the integer types of KHR_mesh_quantization, normalized or
    /// not) as `f64` triples.
    fn read_vec3(
        &mut self,
        acc: &gltf::Accessor<'_>,
        what: &str,
        path: &Path,
    ) -> Result<Vec<[f64; 3]>, MeshError> {
        use gltf::accessor::{DataType as T, Dimensions as D};
        let ty = acc.data_type();
        if acc.dimensions() != D::Vec3 || ty == T::U32 {
            return Err(parse_err(
                path,
                format!(
                    "{what} (accessor {}) is {} of {}; expected VEC3 of FLOAT",
                    acc.index(),
                    type_name(acc.dimensions()),
                    component_name(ty)
                ),
            ));
        }
        let normalized = acc.normalized();
        let (bytes, offset, stride) = self.accessor_bytes(acc, what, path)?;
        let cs = ty.size();
        let comp = |b: &[u8]| -> f64 {
            match ty {
                T::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                T::I8 => {
                    let v = f64::from(b[0] as i8);
                    if normalized { (v / 127.0).max(-1.0) } else { v }
                }
                T::U8 => {
                    let v = f64::from(b[0]);
                    if normalized { v / 255.0 } else { v }
                }
                T::I16 => {
                    let v = f64::from(i16::from_le_bytes([b[0], b[1]]));
                    if normalized {
                        (v / 32767.0).max(-1.0)
                    } else {
                        v
                    }
                }
                T::U16 => {
                    let v = f64::from(u16::from_le_bytes([b[0], b[1]]));
                    if normalized { v / 65535.0 } else { v }
                }
                T::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            }
        };
        Ok((0..acc.count())
            .map(|i| {
                let s = offset + i * stride;
                [
                    comp(&bytes[s..s + cs]),
                    comp(&bytes[s + cs..s + 2 * cs]),
                    comp(&bytes[s + 2 * cs..s + 3 * cs]),
                ]
            })
            .collect())
    }

    /// Indices: `SCALAR` of `UNSIGNED_BYTE`, `UNSIGNED_SHORT` or `UNSIGNED_INT`.
    fn read_indices(
        &mut self,
        acc: &gltf::Accessor<'_>,
        what: &str,
        path: &Path,
    ) -> Result<Vec<u32>, MeshError> {
        use gltf::accessor::{DataType as T, Dimensions as D};
        let ty = acc.data_type();
        if acc.dimensions() != D::Scalar || !matches!(ty, T::U8 | T::U16 | T::U32) {
            return Err(parse_err(
                path,
                format!(
                    "{what} (accessor {}) is {} of {}; expected SCALAR of UNSIGNED_BYTE, \
                     UNSIGNED_SHORT or UNSIGNED_INT",
                    acc.index(),
                    type_name(acc.dimensions()),
                    component_name(ty)
                ),
            ));
        }
        let (bytes, offset, stride) = self.accessor_bytes(acc, what, path)?;
        Ok((0..acc.count())
            .map(|i| {
                let b = &bytes[offset + i * stride..];
                match ty {
                    T::U8 => u32::from(b[0]),
                    T::U16 => u32::from(u16::from_le_bytes([b[0], b[1]])),
                    _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
                }
            })
            .collect())
    }

    fn add_mesh(
        &mut self,
        mesh: gltf::Mesh<'_>,
        world: &Mat4,
        path: &Path,
    ) -> Result<(), MeshError> {
        let flip = det3(world) < 0.0;
        let cof = cofactor3(world);
        let sign = if flip { -1.0 } else { 1.0 };
        let mesh_index = mesh.index();
        for prim in mesh.primitives() {
            let mode = prim.mode();
            if !matches!(
                mode,
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                continue;
            }
            let pi = prim.index();
            let Some(pos_acc) = prim.get(&gltf::Semantic::Positions) else {
                return Err(parse_err(
                    path,
                    format!(
                        "mesh {mesh_index} primitive {pi} is a triangle primitive without a POSITION attribute"
                    ),
                ));
            };
            let local = self.read_vec3(
                &pos_acc,
                &format!("mesh {mesh_index} primitive {pi}: POSITION"),
                path,
            )?;
            let base = self.positions.len();
            for p in &local {
                let mut q = [0.0; 3];
                for r in 0..3 {
                    q[r] =
                        world[0][r] * p[0] + world[1][r] * p[1] + world[2][r] * p[2] + world[3][r];
                }
                self.positions.push(q);
            }
            let normals = match prim.get(&gltf::Semantic::Normals) {
                Some(acc) => Some(self.read_vec3(
                    &acc,
                    &format!("mesh {mesh_index} primitive {pi}: NORMAL"),
                    path,
                )?),
                None => None,
            };
            match normals {
                Some(ns) if ns.len() == local.len() => {
                    for n in ns {
                        let mut q = [0.0; 3];
                        for r in 0..3 {
                            q[r] = sign * (cof[r][0] * n[0] + cof[r][1] * n[1] + cof[r][2] * n[2]);
                        }
                        let l = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt().max(1e-30);
                        self.normals.push(q.map(|c| c / l));
                    }
                }
                _ => self.all_normals = false,
            }
            let nlocal = local.len();
            let idx: Vec<u32> = match prim.indices() {
                Some(acc) => self.read_indices(
                    &acc,
                    &format!("mesh {mesh_index} primitive {pi}: indices"),
                    path,
                )?,
                None => {
                    let n = u32::try_from(nlocal)
                        .map_err(|_| parse_err(path, "more than 2³² vertices in one primitive"))?;
                    (0..n).collect()
                }
            };
            let off = |i: u32| -> Result<u32, MeshError> {
                if i as usize >= nlocal {
                    return Err(parse_err(
                        path,
                        format!(
                            "mesh {mesh_index} primitive {pi}: index {i} is beyond the primitive's {nlocal} vertices"
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

    /// Appends the triangles `range` to the part `(kind, name)` (created on first use).
    fn add_part(&mut self, kind: PartKind, name: &str, range: std::ops::Range<usize>) {
        let named = &mut self.parts.named;
        let index = match named.iter().position(|p| p.kind == kind && p.name == name) {
            Some(i) => i,
            None => {
                named.push(NamedPart {
                    kind,
                    name: name.to_string(),
                    faces: Vec::new(),
                });
                named.len() - 1
            }
        };
        named[index].faces.extend(range.map(|f| f as u32));
    }

    /// Adds `node` and its subtree. `visited` makes the walk linear in the number of nodes: glTF
    /// requires the node hierarchy to be a forest (each node at most one parent, no cycles), and
    /// a node reached twice (shared child, cycle, or listed twice as a root) is refused.
    fn add_node(
        &mut self,
        node: gltf::Node<'_>,
        parent: &Mat4,
        depth: usize,
        visited: &mut [bool],
        path: &Path,
    ) -> Result<(), MeshError> {
        if depth > 256 {
            return Err(parse_err(path, "node hierarchy is deeper than 256 levels"));
        }
        let ni = node.index();
        match visited.get_mut(ni) {
            Some(v) if *v => {
                return Err(parse_err(
                    path,
                    format!(
                        "node {ni} is reached twice in the scene (a node shared by two parents, a \
                         cycle, or a root listed twice); glTF requires the nodes to form trees"
                    ),
                ));
            }
            Some(v) => *v = true,
            None => return Err(parse_err(path, format!("node {ni} does not exist"))),
        }
        let world = mat_mul(parent, &to_f64(local_matrix(&node, path)?));
        if let Some(m) = node.mesh() {
            let first = self.faces.len();
            let mesh_name = m.name().map(str::to_string);
            self.add_mesh(m, &world, path)?;
            let range = first..self.faces.len();
            if let Some(name) = node.name() {
                self.add_part(PartKind::Node, name, range.clone());
            }
            if let Some(name) = mesh_name {
                self.add_part(PartKind::Mesh, &name, range);
            }
        }
        for child in node.children() {
            self.add_node(child, &world, depth + 1, visited, path)?;
        }
        Ok(())
    }
}

/// How far a node's rotation quaternion may be from unit length and still be taken (normalized):
/// exporters write f32 components, so a unit quaternion comes back within ~1e-7 of length 1.
pub const QUATERNION_TOLERANCE: f64 = 1e-3;

/// A node's local transform. glTF requires `rotation` to be a unit quaternion; one within
/// [`QUATERNION_TOLERANCE`] of unit length is normalized (f32 rounding), anything else is refused:
/// the matrix of a quaternion of length `s` also scales by `s²`, which would silently resize the
/// mesh.
fn local_matrix(node: &gltf::Node<'_>, path: &Path) -> Result<[[f32; 4]; 4], MeshError> {
    match node.transform() {
        gltf::scene::Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => {
            let length = rotation
                .iter()
                .map(|&c| f64::from(c) * f64::from(c))
                .sum::<f64>()
                .sqrt();
            if !(length.is_finite() && (length - 1.0).abs() <= QUATERNION_TOLERANCE) {
                return Err(parse_err(
                    path,
                    format!(
                        "node {}: rotation {rotation:?} is a quaternion of length {length}; glTF \
                         requires unit quaternions (within {QUATERNION_TOLERANCE} here), and a \
                         non-unit one would scale the mesh by its squared length",
                        node.index()
                    ),
                ));
            }
            let rotation = rotation.map(|c| (f64::from(c) / length) as f32);
            Ok(gltf::scene::Transform::Decomposed {
                translation,
                rotation,
                scale,
            }
            .matrix())
        }
        matrix => Ok(matrix.matrix()),
    }
}

/// Reads a `.gltf` or `.glb` file. See the module docs.
///
/// Bounded by the input: every accessor is checked against its buffer view and buffer before it
/// is read; buffers are read up to their declared `byteLength` only; the nodes of one scene (the
/// default scene, else the first) are visited once each; and the elements read in total are
/// limited to 16 per byte of input (file plus buffers) plus 4 Mi, so instancing cannot multiply
/// a small file into gigabytes.
pub fn read_gltf(path: &Path) -> Result<MeshWithNormals, MeshError> {
    read_gltf_with_parts(path).map(|(m, _)| m)
}

/// Like [`read_gltf`], also returning named nodes and meshes as region parts.
pub fn read_gltf_with_parts(path: &Path) -> Result<(MeshWithNormals, Parts), MeshError> {
    let bytes = super::read_bytes(path)?;
    if bytes.starts_with(b"glTF") {
        // The GLB header's total length, checked here: the `gltf` crate subtracts 12 from it
        // unchecked.
        let declared = bytes
            .get(8..12)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
        match declared {
            Some(n) if (12..=bytes.len()).contains(&n) => {}
            Some(n) => {
                return Err(parse_err(
                    path,
                    format!(
                        "the GLB header declares a length of {n} bytes; the file has {} (at least 12 are needed)",
                        bytes.len()
                    ),
                ));
            }
            None => return Err(parse_err(path, "the GLB header is truncated")),
        }
    }
    let invalid = |e: gltf::Error| match e {
        gltf::Error::Io(source) => io_err(path, source),
        e => parse_err(path, format!("not a valid glTF 2.0 file: {e}")),
    };
    // A `.gltf` (JSON) written with a UTF-8 byte-order mark is read without it.
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(super::strip_bom(&bytes)).map_err(invalid)?;
    // The `gltf` crate's validation indexes the POSITION accessor unchecked: check every
    // attribute's accessor index first.
    let root = document.into_json();
    for (mi, m) in root.meshes.iter().enumerate() {
        for (pi, prim) in m.primitives.iter().enumerate() {
            for index in prim.attributes.values() {
                if index.value() >= root.accessors.len() {
                    return Err(parse_err(
                        path,
                        format!(
                            "mesh {mi} primitive {pi}: attribute accessor {} does not exist ({} accessors)",
                            index.value(),
                            root.accessors.len()
                        ),
                    ));
                }
            }
        }
    }
    let doc = gltf::Document::from_json(root).map_err(invalid)?;
    let buffers = load_buffers(&doc, blob, path)?;
    let input_bytes = bytes.len() + buffers.data.iter().map(Vec::len).sum::<usize>();
    let mut c = Collector {
        buffers: &buffers,
        positions: Vec::new(),
        faces: Vec::new(),
        normals: Vec::new(),
        all_normals: true,
        parts: Parts::default(),
        budget: input_bytes
            .saturating_mul(EXPANSION_PER_BYTE)
            .saturating_add(EXPANSION_FLOOR),
    };
    // Roots: the nodes of the default scene (else the first; a file with several scenes holds
    // alternatives, not parts), or, without scenes, the nodes that are nobody's child.
    let nodes: Vec<gltf::Node<'_>> = doc.nodes().collect();
    let roots: Vec<usize> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().map(|n| n.index()).collect(),
        None => {
            let mut is_child = vec![false; nodes.len()];
            for n in &nodes {
                for ch in n.children() {
                    if let Some(slot) = is_child.get_mut(ch.index()) {
                        *slot = true;
                    }
                }
            }
            (0..is_child.len()).filter(|&i| !is_child[i]).collect()
        }
    };
    let mut used_mesh = vec![false; doc.meshes().len()];
    for n in &nodes {
        if let Some(m) = n.mesh()
            && let Some(slot) = used_mesh.get_mut(m.index())
        {
            *slot = true;
        }
    }
    let mut visited = vec![false; nodes.len()];
    for &r in &roots {
        if let Some(node) = nodes.get(r) {
            c.add_node(node.clone(), &IDENTITY, 0, &mut visited, path)?;
        }
    }
    for m in doc.meshes() {
        if !used_mesh[m.index()] {
            let first = c.faces.len();
            let name = m.name().map(str::to_string);
            c.add_mesh(m, &IDENTITY, path)?;
            if let Some(name) = name {
                c.add_part(PartKind::Mesh, &name, first..c.faces.len());
            }
        }
    }
    let normals =
        (c.all_normals && c.normals.len() == c.positions.len() && !c.positions.is_empty())
            .then_some(c.normals);
    Ok((
        (
            TriMesh {
                positions: c.positions,
                faces: c.faces,
            },
            normals,
        ),
        c.parts,
    ))
}

/// Writes a binary glTF (`.glb`): positions and optional normals as `f32` VEC3 (positions with
/// `min`/`max`), `u32` indices, one mesh instanced by one node of the default scene.
pub fn write_glb(
    path: &Path,
    mesh: &TriMesh,
    normals: Option<&[[f64; 3]]>,
) -> Result<(), MeshError> {
    write_glb_with_colors(path, mesh, normals, None)
}

/// [`write_glb`] with optional per-vertex colours: `COLOR_0`, `f32` VEC3, **linear** RGB in
/// [0, 1] as glTF defines it (convert sRGB colours first), one per vertex.
pub fn write_glb_with_colors(
    path: &Path,
    mesh: &TriMesh,
    normals: Option<&[[f64; 3]]>,
    colors: Option<&[[f32; 3]]>,
) -> Result<(), MeshError> {
    let nv = mesh.positions.len();
    for (what, len) in [
        ("normals", normals.map(<[_]>::len)),
        ("colors", colors.map(<[_]>::len)),
    ] {
        if let Some(len) = len
            && len != nv
        {
            return Err(MeshError::Invalid(format!(
                "{}: {len} {what} for {nv} vertices",
                path.display()
            )));
        }
    }
    if let Some(c) = colors
        && let Some(v) = c
            .iter()
            .position(|c| c.iter().any(|x| !(0.0..=1.0).contains(x)))
    {
        return Err(MeshError::Invalid(format!(
            "{}: colour of vertex {v} is outside [0, 1]",
            path.display()
        )));
    }
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
    let col_off = bin.len();
    if let Some(cs) = colors {
        for c in cs {
            for &x in c {
                bin.extend_from_slice(&x.to_le_bytes());
            }
        }
    }
    let col_len = bin.len() - col_off;
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
    if colors.is_some() {
        let view = buffer_views.len();
        buffer_views.push(serde_json::json!({"buffer": 0, "byteOffset": col_off, "byteLength": col_len, "target": 34962}));
        attributes["COLOR_0"] = serde_json::json!(accessors.len());
        accessors.push(serde_json::json!({"bufferView": view, "componentType": 5126, "count": nv, "type": "VEC3"}));
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
