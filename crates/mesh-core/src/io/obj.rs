//! Wavefront OBJ: `v` and `f` records (plus `vn` for normals, and `o`/`g`/`usemtl` as named parts
//! for regions); everything else is ignored.
//!
//! We parse OBJ ourselves rather than with `tobj`: `tobj` renumbers vertices in order of first use
//! and drops unreferenced ones, which would break "vertex 0 is pinned" compatibility with the
//! reference (and saved `.npz` files) and any mapping of results back to the file's numbering.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use std::collections::HashMap;

use super::{io_err, parse_err, read_bytes, truncation_hint};
use crate::region::{NamedPart, PartKind, Parts};
use crate::{MeshError, TriMesh};

/// Reads an OBJ file: vertices in file order (all of them), faces fan-triangulated
/// (`[v0, v_i, v_{i+1}]`), 1-based and negative (relative) indices resolved. Texture coordinates,
/// groups, materials, lines and points are ignored. Returns per-vertex normals when every vertex
/// referenced by a face uses a single `vn` and all vertices have one.
pub fn read_obj(path: &Path) -> Result<super::MeshWithNormals, MeshError> {
    read_obj_with_parts(path).map(|(m, _)| m)
}

/// Like [`read_obj`], also returning the named parts: each `o` object, `g` group (a `g` line
/// with several names puts the following faces in each) and `usemtl` material, with the
/// triangles (file order, after fan triangulation) that follow it.
pub fn read_obj_with_parts(path: &Path) -> Result<(super::MeshWithNormals, Parts), MeshError> {
    let bytes = read_bytes(path)?;
    read_obj_bytes(path, &bytes).map_err(|e| truncation_hint(e, &bytes))
}

fn read_obj_bytes(path: &Path, bytes: &[u8]) -> Result<(super::MeshWithNormals, Parts), MeshError> {
    let text = String::from_utf8_lossy(super::strip_bom(bytes));
    let mut positions: Vec<[f64; 3]> = Vec::new();
    let mut vn: Vec<[f64; 3]> = Vec::new();
    // Per polygon: (line number, corners as 0-based (position, normal) indices).
    type Corner = (i64, Option<i64>);
    let mut polys: Vec<(usize, Vec<Corner>)> = Vec::new();
    // Named parts: `(kind, name)` → index into `named`; the parts the current faces belong to,
    // and per polygon an index into `tag_sets`.
    let mut named: Vec<NamedPart> = Vec::new();
    let mut part_index: HashMap<(PartKind, String), usize> = HashMap::new();
    let mut current: [Vec<usize>; 3] = Default::default(); // object, groups, material
    let mut tag_sets: Vec<Vec<usize>> = vec![Vec::new()];
    let mut poly_tags: Vec<usize> = Vec::new();
    let mut part = |kind: PartKind, name: &str| -> usize {
        *part_index
            .entry((kind, name.to_string()))
            .or_insert_with(|| {
                named.push(NamedPart {
                    kind,
                    name: name.to_string(),
                    faces: Vec::new(),
                });
                named.len() - 1
            })
    };
    for (lineno, line) in text.lines().enumerate() {
        let lineno = lineno + 1;
        let line = line.split('#').next().unwrap_or("");
        let mut tok = line.split_whitespace();
        let Some(kind) = tok.next() else { continue };
        match kind {
            "v" | "vn" => {
                let mut p = [0.0f64; 3];
                for (k, slot) in p.iter_mut().enumerate() {
                    let t = tok.next().ok_or_else(|| {
                        parse_err(
                            path,
                            format!("line {lineno}: `{kind}` needs 3 coordinates, found {k}"),
                        )
                    })?;
                    *slot = t.parse::<f64>().map_err(|_| {
                        parse_err(path, format!("line {lineno}: `{t}` is not a number"))
                    })?;
                }
                if kind == "v" {
                    positions.push(p);
                } else {
                    vn.push(p);
                }
            }
            "f" => {
                let mut corners = Vec::new();
                for t in tok {
                    let mut parts = t.split('/');
                    let v = parse_index(
                        parts.next().unwrap_or(""),
                        positions.len(),
                        "vertex",
                        path,
                        lineno,
                    )?;
                    let _vt = parts.next();
                    let n = match parts.next() {
                        Some(s) if !s.is_empty() => {
                            Some(parse_index(s, vn.len(), "normal", path, lineno)?)
                        }
                        _ => None,
                    };
                    corners.push((v, n));
                }
                if corners.len() < 3 {
                    return Err(parse_err(
                        path,
                        format!(
                            "line {lineno}: a face needs at least 3 corners, found {}",
                            corners.len()
                        ),
                    ));
                }
                polys.push((lineno, corners));
                let tags: Vec<usize> = current.iter().flatten().copied().collect();
                if tag_sets.last() != Some(&tags) {
                    tag_sets.push(tags);
                }
                poly_tags.push(tag_sets.len() - 1);
            }
            "o" | "g" | "usemtl" => {
                let (kind, slot) = match kind {
                    "o" => (PartKind::Object, 0),
                    "g" => (PartKind::Group, 1),
                    _ => (PartKind::Material, 2),
                };
                // `g` alone (or `g default`) leaves every group; `o`/`usemtl` take one name.
                current[slot] = tok
                    .filter(|name| !(kind == PartKind::Group && *name == "default"))
                    .take(if kind == PartKind::Group {
                        usize::MAX
                    } else {
                        1
                    })
                    .map(|name| part(kind, name))
                    .collect();
            }
            _ => {}
        }
    }
    let mut faces = Vec::with_capacity(polys.len());
    let mut normal_of: Vec<Option<i64>> = vec![None; positions.len()];
    let mut normals_consistent = !vn.is_empty();
    for ((lineno, corners), &tags) in polys.iter().zip(&poly_tags) {
        let mut idx = Vec::with_capacity(corners.len());
        for &(v, n) in corners {
            let v0 = u32::try_from(v).map_err(|_| {
                parse_err(
                    path,
                    format!("line {lineno}: vertex index {} is out of range", v + 1),
                )
            })?;
            idx.push(v0);
            if normals_consistent {
                match (n, normal_of.get_mut(v as usize)) {
                    (Some(n), Some(slot)) if n >= 0 && (n as usize) < vn.len() => match slot {
                        None => *slot = Some(n),
                        Some(m) if *m == n => {}
                        Some(_) => normals_consistent = false,
                    },
                    _ => normals_consistent = false,
                }
            }
        }
        for i in 1..idx.len() - 1 {
            for &t in &tag_sets[tags] {
                named[t].faces.push(faces.len() as u32);
            }
            faces.push([idx[0], idx[i], idx[i + 1]]);
        }
    }
    let normals = if normals_consistent && normal_of.iter().all(Option::is_some) {
        Some(
            normal_of
                .iter()
                .map(|n| vn[n.unwrap_or(0) as usize])
                .collect(),
        )
    } else {
        None
    };
    let parts = Parts {
        named,
        ..Parts::default()
    };
    Ok(((TriMesh { positions, faces }, normals), parts))
}

/// Resolves an OBJ index (1-based, or negative = relative to the count so far) to 0-based.
/// Indices beyond the vertices read so far are kept (forward references are legal in some files;
/// validation reports any that stay out of range).
/// `what` names the kind of index in messages (`vertex`, `normal`).
fn parse_index(
    s: &str,
    count: usize,
    what: &str,
    path: &Path,
    lineno: usize,
) -> Result<i64, MeshError> {
    let i: i64 = s
        .parse()
        .map_err(|_| parse_err(path, format!("line {lineno}: `{s}` is not a {what} index")))?;
    match i {
        0 => Err(parse_err(
            path,
            format!("line {lineno}: {what} index 0 is invalid (OBJ indices start at 1)"),
        )),
        i if i > 0 => Ok(i - 1),
        i => {
            let r = count as i64 + i;
            if r < 0 {
                Err(parse_err(
                    path,
                    format!(
                        "line {lineno}: relative {what} index {i} points before the first {what}"
                    ),
                ))
            } else {
                Ok(r)
            }
        }
    }
}

/// Writes `v` lines (shortest round-trip decimal), optional `vn` lines (one per vertex) and
/// 1-based `f` lines (`f a//a b//b c//c` with normals).
pub fn write_obj(
    path: &Path,
    mesh: &TriMesh,
    normals: Option<&[[f64; 3]]>,
) -> Result<(), MeshError> {
    let file = File::create(path).map_err(|e| io_err(path, e))?;
    let mut w = BufWriter::new(file);
    let go = |w: &mut BufWriter<File>| -> std::io::Result<()> {
        writeln!(
            w,
            "# {} vertices, {} faces (written by mesh-core)",
            mesh.positions.len(),
            mesh.faces.len()
        )?;
        for p in &mesh.positions {
            writeln!(w, "v {} {} {}", p[0], p[1], p[2])?;
        }
        if let Some(ns) = normals {
            for n in ns {
                writeln!(w, "vn {} {} {}", n[0], n[1], n[2])?;
            }
        }
        for f in &mesh.faces {
            let (a, b, c) = (f[0] as u64 + 1, f[1] as u64 + 1, f[2] as u64 + 1);
            if normals.is_some() {
                writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?;
            } else {
                writeln!(w, "f {a} {b} {c}")?;
            }
        }
        w.flush()
    };
    go(&mut w).map_err(|e| io_err(path, e))
}
