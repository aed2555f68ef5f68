//! Stanford PLY: `ascii 1.0`, `binary_little_endian 1.0` and `binary_big_endian 1.0`.
//!
//! Read: element `vertex` with scalar properties `x y z` (any numeric type; `nx ny nz` read as
//! normals when present), element `face` with a list property `vertex_indices` or `vertex_index`
//! (any integer count and index types), polygons fan-triangulated. Other scalar properties of
//! `vertex` and `face` are returned as region properties by [`read_ply_with_parts`] (a face's
//! value repeated on each of its triangles). Every other element and property is skipped, with
//! its size, in all three encodings.
//! Write: `x y z` (and `nx ny nz`) as `double`, faces as `list uchar int vertex_indices`.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::{MeshWithNormals, io_err, parse_err, read_bytes};
use crate::region::{Parts, ScalarProperty};
use crate::{MeshError, TriMesh};

/// The body encoding of a PLY file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyEncoding {
    /// Whitespace-separated text.
    Ascii,
    /// Binary, little-endian.
    BinaryLittleEndian,
    /// Binary, big-endian (read only).
    BinaryBigEndian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Clone, Debug)]
enum Property {
    Scalar {
        name: String,
        ty: Scalar,
    },
    List {
        name: String,
        count: Scalar,
        item: Scalar,
    },
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// A cursor over the body that yields numbers as `f64` in any encoding.
struct Body<'a> {
    bytes: &'a [u8],
    pos: usize,
    encoding: PlyEncoding,
    path: &'a Path,
}

impl Body<'_> {
    fn read(&mut self, ty: Scalar, what: &dyn Fn() -> String) -> Result<f64, MeshError> {
        match self.encoding {
            PlyEncoding::Ascii => {
                while self.pos < self.bytes.len() && self.bytes[self.pos].is_ascii_whitespace() {
                    self.pos += 1;
                }
                let start = self.pos;
                while self.pos < self.bytes.len() && !self.bytes[self.pos].is_ascii_whitespace() {
                    self.pos += 1;
                }
                if start == self.pos {
                    return Err(parse_err(
                        self.path,
                        format!("file is truncated: it ends before {}", what()),
                    ));
                }
                let tok = String::from_utf8_lossy(&self.bytes[start..self.pos]);
                tok.parse::<f64>().map_err(|_| {
                    parse_err(self.path, format!("`{tok}` is not a number ({})", what()))
                })
            }
            enc => {
                let n = ty.size();
                let end = self.pos + n;
                if end > self.bytes.len() {
                    return Err(parse_err(
                        self.path,
                        format!("file is truncated: it ends before {}", what()),
                    ));
                }
                let mut b = [0u8; 8];
                b[..n].copy_from_slice(&self.bytes[self.pos..end]);
                if enc == PlyEncoding::BinaryBigEndian {
                    b[..n].reverse();
                }
                self.pos = end;
                Ok(match ty {
                    Scalar::I8 => f64::from(b[0] as i8),
                    Scalar::U8 => f64::from(b[0]),
                    Scalar::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
                    Scalar::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
                    Scalar::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    Scalar::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    Scalar::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    Scalar::F64 => f64::from_le_bytes(b),
                })
            }
        }
    }
}

/// Reads a PLY file (vertices in file order). See the module docs.
pub fn read_ply(path: &Path) -> Result<MeshWithNormals, MeshError> {
    read_ply_with_parts(path).map(|(m, _)| m)
}

/// Like [`read_ply`], also returning the scalar properties of `vertex` (other than `x y z nx ny
/// nz`) and `face` as region properties (per triangle).
///
/// Stages: [`split_header`] (header text and where the body starts), [`parse_header`] (encoding
/// and elements), then [`read_element`] for each element in file order.
pub fn read_ply_with_parts(path: &Path) -> Result<(MeshWithNormals, Parts), MeshError> {
    let all = read_bytes(path)?;
    let bytes = super::strip_bom(&all);
    let (header, body_start) = split_header(bytes, path)?;
    let (encoding, elements) = parse_header(&header, path)?;
    let mut body = Body {
        bytes: &bytes[body_start..],
        pos: 0,
        encoding,
        path,
    };
    let mut out = PlyContents::default();
    for el in &elements {
        read_element(el, &mut body, bytes.len(), &mut out)?;
    }
    if !out.saw_vertex {
        return Err(parse_err(path, "the header declares no `vertex` element"));
    }
    let PlyContents {
        positions,
        normals,
        faces,
        parts,
        ..
    } = out;
    let normals = (!normals.is_empty() && normals.len() == positions.len()).then_some(normals);
    Ok(((TriMesh { positions, faces }, normals), parts))
}

/// The header's text (from `ply` to `end_header`) and the offset where the body starts (after the
/// newline, `\n` or `\r\n`, that ends `end_header`).
fn split_header<'b>(
    bytes: &'b [u8],
    path: &Path,
) -> Result<(std::borrow::Cow<'b, str>, usize), MeshError> {
    if !bytes.starts_with(b"ply") {
        return Err(parse_err(path, "not a PLY file (it must start with `ply`)"));
    }
    let marker = b"end_header";
    let hend = bytes
        .windows(marker.len())
        .position(|w| w == marker)
        .ok_or_else(|| parse_err(path, "the header never ends (no `end_header` line)"))?;
    let header = String::from_utf8_lossy(&bytes[..hend]);
    let mut body_start = hend + marker.len();
    while body_start < bytes.len() && bytes[body_start] != b'\n' {
        body_start += 1;
    }
    Ok((header, (body_start + 1).min(bytes.len())))
}

/// The `format` line's encoding and the declared elements with their properties.
fn parse_header(header: &str, path: &Path) -> Result<(PlyEncoding, Vec<Element>), MeshError> {
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    for (i, line) in header.lines().enumerate().skip(1) {
        let lineno = i + 1;
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.first().copied() {
            Some("format") => {
                encoding = Some(match t.get(1).copied() {
                    Some("ascii") => PlyEncoding::Ascii,
                    Some("binary_little_endian") => PlyEncoding::BinaryLittleEndian,
                    Some("binary_big_endian") => PlyEncoding::BinaryBigEndian,
                    other => {
                        return Err(parse_err(
                            path,
                            format!(
                                "line {lineno}: unknown PLY format {:?}",
                                other.unwrap_or("")
                            ),
                        ));
                    }
                })
            }
            Some("element") => {
                let (Some(name), Some(count)) = (t.get(1), t.get(2).and_then(|c| c.parse().ok()))
                else {
                    return Err(parse_err(
                        path,
                        format!("line {lineno}: expected `element NAME COUNT`"),
                    ));
                };
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    properties: Vec::new(),
                });
            }
            Some("property") => {
                let el = elements.last_mut().ok_or_else(|| {
                    parse_err(
                        path,
                        format!("line {lineno}: `property` before any `element`"),
                    )
                })?;
                el.properties.push(parse_property(&t, line, lineno, path)?);
            }
            _ => {} // comment, obj_info, blank
        }
    }
    let encoding = encoding.ok_or_else(|| parse_err(path, "the header has no `format` line"))?;
    Ok((encoding, elements))
}

/// One `property TYPE NAME` or `property list COUNT ITEM NAME` line, split into words `t`.
fn parse_property(
    t: &[&str],
    line: &str,
    lineno: usize,
    path: &Path,
) -> Result<Property, MeshError> {
    let bad = || {
        parse_err(
            path,
            format!("line {lineno}: malformed property `{}`", line.trim()),
        )
    };
    Ok(if t.get(1) == Some(&"list") {
        Property::List {
            count: t.get(2).and_then(|s| Scalar::parse(s)).ok_or_else(bad)?,
            item: t.get(3).and_then(|s| Scalar::parse(s)).ok_or_else(bad)?,
            name: t.get(4).ok_or_else(bad)?.to_string(),
        }
    } else {
        Property::Scalar {
            ty: t.get(1).and_then(|s| Scalar::parse(s)).ok_or_else(bad)?,
            name: t.get(2).ok_or_else(bad)?.to_string(),
        }
    })
}

/// What the body's elements fill in.
#[derive(Default)]
struct PlyContents {
    positions: Vec<[f64; 3]>,
    normals: Vec<[f64; 3]>,
    faces: Vec<[u32; 3]>,
    parts: Parts,
    saw_vertex: bool,
}

/// Reads the `el.count` records of one element: vertices (positions, normals, extra scalar
/// properties), faces (fan-triangulated polygons, per-face scalars repeated per triangle), or any
/// other element (read and dropped). `file_len` bounds the reservation a header may ask for.
fn read_element(
    el: &Element,
    body: &mut Body<'_>,
    file_len: usize,
    out: &mut PlyContents,
) -> Result<(), MeshError> {
    let path = body.path;
    let is_vertex = el.name == "vertex";
    let is_face = el.name == "face";
    let slot = |name: &str| {
        el.properties
            .iter()
            .position(|p| matches!(p, Property::Scalar { name: n, .. } if n == name))
    };
    let xyz = [slot("x"), slot("y"), slot("z")];
    let nxyz = [slot("nx"), slot("ny"), slot("nz")];
    let has_normals = nxyz.iter().all(Option::is_some);
    if is_vertex {
        out.saw_vertex = true;
        if xyz.iter().any(Option::is_none) {
            return Err(parse_err(
                path,
                "element `vertex` lacks an x, y or z property",
            ));
        }
        // Bounded by the file size, so a lying header cannot reserve gigabytes.
        out.positions.reserve(el.count.min(file_len / 3));
    }
    let list_slot = el.properties.iter().position(
        |p| matches!(p, Property::List { name, .. } if name == "vertex_indices" || name == "vertex_index"),
    );
    if is_face && list_slot.is_none() {
        return Err(parse_err(
            path,
            "element `face` has no `vertex_indices` list",
        ));
    }
    if el.properties.is_empty() {
        // Nothing to read per element: skipping is exact and keeps the work bounded by the
        // file's size whatever count the header declares.
        return Ok(());
    }
    let (kept, first_kept) = register_region_properties(el, is_vertex, is_face, &mut out.parts);
    let mut values = vec![0.0f64; el.properties.len()];
    let mut poly: Vec<u32> = Vec::new();
    for i in 0..el.count {
        let triangles_before = out.faces.len();
        for (k, p) in el.properties.iter().enumerate() {
            let pname = match p {
                Property::Scalar { name, .. } | Property::List { name, .. } => name.as_str(),
            };
            let what = || format!("{} {i} of {} (its `{pname}`)", el.name, el.count);
            match p {
                Property::Scalar { ty, .. } => values[k] = body.read(*ty, &what)?,
                Property::List { count, item, .. } => {
                    let keep = Some(k) == list_slot && is_face;
                    read_list(body, *count, *item, keep, i, &what, &mut poly)?;
                    if keep {
                        for j in 1..poly.len() - 1 {
                            out.faces.push([poly[0], poly[j], poly[j + 1]]);
                        }
                    }
                }
            }
        }
        if is_vertex {
            let g = |s: Option<usize>| values[s.unwrap_or(0)];
            out.positions.push([g(xyz[0]), g(xyz[1]), g(xyz[2])]);
            if has_normals {
                out.normals.push([g(nxyz[0]), g(nxyz[1]), g(nxyz[2])]);
            }
            for (j, &k) in kept.iter().enumerate() {
                out.parts.vertex_properties[first_kept + j]
                    .values
                    .push(values[k]);
            }
        } else if is_face {
            for (j, &k) in kept.iter().enumerate() {
                let list = &mut out.parts.face_properties[first_kept + j].values;
                list.extend(std::iter::repeat_n(
                    values[k],
                    out.faces.len() - triangles_before,
                ));
            }
        }
    }
    Ok(())
}

/// The scalar properties of a `vertex` (other than `x y z nx ny nz`) or `face` element, added
/// (empty) to `parts`: their slots in the element and the index of the first in the parts' list.
fn register_region_properties(
    el: &Element,
    is_vertex: bool,
    is_face: bool,
    parts: &mut Parts,
) -> (Vec<usize>, usize) {
    if !(is_vertex || is_face) {
        return (Vec::new(), 0);
    }
    let list = if is_vertex {
        &mut parts.vertex_properties
    } else {
        &mut parts.face_properties
    };
    let first = list.len();
    let mut kept = Vec::new();
    for (k, p) in el.properties.iter().enumerate() {
        if let Property::Scalar { name, .. } = p
            && (!is_vertex || !["x", "y", "z", "nx", "ny", "nz"].contains(&name.as_str()))
        {
            kept.push(k);
            list.push(ScalarProperty {
                name: name.clone(),
                values: Vec::new(),
            });
        }
    }
    (kept, first)
}

/// Reads one list property (its length, then its items). With `keep` (the face's vertex list)
/// the items must be vertex indices, at least 3, and land in `poly`; otherwise they are skipped.
fn read_list(
    body: &mut Body<'_>,
    count: Scalar,
    item: Scalar,
    keep: bool,
    face: usize,
    what: &dyn Fn() -> String,
    poly: &mut Vec<u32>,
) -> Result<(), MeshError> {
    let path = body.path;
    let n = body.read(count, what)?;
    if !(n >= 0.0 && n.fract() == 0.0) {
        return Err(parse_err(
            path,
            format!("bad list length {n} in {}", what()),
        ));
    }
    poly.clear();
    for _ in 0..n as usize {
        let v = body.read(item, what)?;
        if keep {
            if !(v >= 0.0 && v <= f64::from(u32::MAX) && v.fract() == 0.0) {
                return Err(parse_err(
                    path,
                    format!("face {face}: `{v}` is not a vertex index"),
                ));
            }
            poly.push(v as u32);
        }
    }
    if keep && poly.len() < 3 {
        return Err(parse_err(
            path,
            format!(
                "face {face} has {} corners, at least 3 are needed",
                poly.len()
            ),
        ));
    }
    Ok(())
}

/// Writes a PLY file: vertices `double x y z` (plus `double nx ny nz` with normals), faces
/// `list uchar int vertex_indices`. Indices above `i32::MAX` are refused (PLY `int`).
pub fn write_ply(
    path: &Path,
    mesh: &TriMesh,
    normals: Option<&[[f64; 3]]>,
    encoding: PlyEncoding,
) -> Result<(), MeshError> {
    if encoding == PlyEncoding::BinaryBigEndian {
        return Err(MeshError::UnsupportedFormat {
            path: path.to_path_buf(),
            extension: "ply (binary_big_endian)".into(),
            supported: "ply ascii, ply binary_little_endian",
        });
    }
    if mesh.faces.iter().flatten().any(|&v| v > i32::MAX as u32) {
        return Err(MeshError::Invalid(format!(
            "{}: a face index exceeds the PLY `int` range",
            path.display()
        )));
    }
    let file = File::create(path).map_err(|e| io_err(path, e))?;
    let mut w = BufWriter::new(file);
    let go = |w: &mut BufWriter<File>| -> std::io::Result<()> {
        let fmt = match encoding {
            PlyEncoding::Ascii => "ascii",
            _ => "binary_little_endian",
        };
        write!(
            w,
            "ply\nformat {fmt} 1.0\ncomment written by mesh-core\nelement vertex {}\n\
             property double x\nproperty double y\nproperty double z\n",
            mesh.positions.len()
        )?;
        if normals.is_some() {
            write!(
                w,
                "property double nx\nproperty double ny\nproperty double nz\n"
            )?;
        }
        write!(
            w,
            "element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            mesh.faces.len()
        )?;
        for (i, p) in mesh.positions.iter().enumerate() {
            let n = normals.map(|n| n[i]);
            if encoding == PlyEncoding::Ascii {
                write!(w, "{} {} {}", p[0], p[1], p[2])?;
                if let Some(n) = n {
                    write!(w, " {} {} {}", n[0], n[1], n[2])?;
                }
                writeln!(w)?;
            } else {
                for c in p.iter().chain(n.iter().flatten()) {
                    w.write_all(&c.to_le_bytes())?;
                }
            }
        }
        for f in &mesh.faces {
            if encoding == PlyEncoding::Ascii {
                writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
            } else {
                w.write_all(&[3u8])?;
                for &v in f {
                    w.write_all(&(v as i32).to_le_bytes())?;
                }
            }
        }
        w.flush()
    };
    go(&mut w).map_err(|e| io_err(path, e))
}
