//! Object File Format (OFF), ASCII: `OFF` (also `COFF`, `NOFF`, `CNOFF`, … headers), counts
//! `V F E`, `V` vertex lines (first three numbers are x y z, extras such as colours ignored), `F`
//! face lines `n i_1 … i_n [colour]` (0-based, fan-triangulated). `#` starts a comment.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::{MeshWithNormals, io_err, parse_err, read_bytes, truncation_hint};
use crate::{MeshError, TriMesh};

/// Reads an ASCII OFF file (vertices in file order). Binary OFF and other dimensions than 3 are
/// rejected with a clear error; a file with fewer vertex or face lines than its header announces is
/// reported as truncated.
pub fn read_off(path: &Path) -> Result<MeshWithNormals, MeshError> {
    let bytes = read_bytes(path)?;
    read_off_bytes(path, &bytes).map_err(|e| truncation_hint(e, &bytes))
}

fn read_off_bytes(path: &Path, bytes: &[u8]) -> Result<MeshWithNormals, MeshError> {
    let text = String::from_utf8_lossy(super::strip_bom(bytes));
    // Non-empty lines with comments removed, with their 1-based line numbers.
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.split('#').next().unwrap_or("").trim()))
        .filter(|(_, l)| !l.is_empty());
    let Some((_, first)) = lines.next() else {
        return Err(parse_err(
            path,
            "the file is empty (expected an `OFF` header)",
        ));
    };
    let mut tokens: Vec<&str> = first.split_whitespace().collect();
    let head = tokens.first().copied().unwrap_or("");
    let counts_line: Vec<&str> = if let Some(prefix) = head.strip_suffix("OFF") {
        if prefix.contains('4') || prefix.contains('n') {
            return Err(parse_err(
                path,
                format!("`{head}` files (not 3-dimensional) are not supported"),
            ));
        }
        if tokens.get(1) == Some(&"BINARY") {
            return Err(parse_err(
                path,
                "binary OFF is not supported; save as ASCII OFF",
            ));
        }
        tokens.remove(0);
        if tokens.is_empty() {
            match lines.next() {
                Some((_, l)) => l.split_whitespace().collect(),
                None => {
                    return Err(parse_err(
                        path,
                        "file ends after the header: expected `V F E` counts",
                    ));
                }
            }
        } else {
            tokens
        }
    } else if head.parse::<usize>().is_ok() {
        tokens // header-less OFF: counts first
    } else {
        return Err(parse_err(
            path,
            format!("expected an `OFF` header, found `{head}`"),
        ));
    };
    let count = |i: usize, what: &str| -> Result<usize, MeshError> {
        counts_line
            .get(i)
            .and_then(|t| t.parse::<usize>().ok())
            .ok_or_else(|| {
                parse_err(
                    path,
                    format!("expected the number of {what} in the `V F E` line"),
                )
            })
    };
    let nv = count(0, "vertices")?;
    let nf = count(1, "faces")?;
    // Capacity bounded by the file size, so a lying header cannot reserve gigabytes.
    let mut positions = Vec::with_capacity(nv.min(text.len() / 6));
    for i in 0..nv {
        let (lineno, l) = lines.next().ok_or_else(|| {
            parse_err(
                path,
                format!("file is truncated: expected {nv} vertices, it ends after {i}"),
            )
        })?;
        let mut p = [0.0; 3];
        let mut it = l.split_whitespace();
        for (k, slot) in p.iter_mut().enumerate() {
            let t = it.next().ok_or_else(|| {
                parse_err(
                    path,
                    format!("line {lineno}: vertex {i} needs 3 coordinates, found {k}"),
                )
            })?;
            *slot = t
                .parse()
                .map_err(|_| parse_err(path, format!("line {lineno}: `{t}` is not a number")))?;
        }
        positions.push(p);
    }
    let mut faces = Vec::with_capacity(nf.min(text.len() / 8));
    for i in 0..nf {
        let (lineno, l) = lines.next().ok_or_else(|| {
            parse_err(
                path,
                format!("file is truncated: expected {nf} faces, it ends after {i}"),
            )
        })?;
        let mut it = l.split_whitespace();
        let n: usize = it.next().and_then(|t| t.parse().ok()).ok_or_else(|| {
            parse_err(
                path,
                format!("line {lineno}: face {i} must start with its corner count"),
            )
        })?;
        if n < 3 {
            return Err(parse_err(
                path,
                format!("line {lineno}: face {i} has {n} corners, at least 3 are needed"),
            ));
        }
        // The corners are read from the line before anything is sized by `n`, so a count of
        // 10¹² or 2⁶⁴−1 is an error about the line, not an allocation.
        let mut idx = Vec::new();
        for t in it.by_ref().take(n) {
            idx.push(t.parse::<u32>().map_err(|_| {
                parse_err(path, format!("line {lineno}: `{t}` is not a vertex index"))
            })?);
        }
        if idx.len() < n {
            return Err(parse_err(
                path,
                format!(
                    "line {lineno}: face {i} announces {n} corners but lists {}",
                    idx.len()
                ),
            ));
        }
        for k in 1..n - 1 {
            faces.push([idx[0], idx[k], idx[k + 1]]);
        }
    }
    Ok((TriMesh { positions, faces }, None))
}

/// Writes an ASCII OFF file (`OFF`, counts, vertices, `3 a b c` faces). OFF has no normals.
pub fn write_off(path: &Path, mesh: &TriMesh) -> Result<(), MeshError> {
    let file = File::create(path).map_err(|e| io_err(path, e))?;
    let mut w = BufWriter::new(file);
    let go = |w: &mut BufWriter<File>| -> std::io::Result<()> {
        writeln!(w, "OFF")?;
        writeln!(w, "{} {} 0", mesh.positions.len(), mesh.faces.len())?;
        for p in &mesh.positions {
            writeln!(w, "{} {} {}", p[0], p[1], p[2])?;
        }
        for f in &mesh.faces {
            writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
        }
        w.flush()
    };
    go(&mut w).map_err(|e| io_err(path, e))
}
