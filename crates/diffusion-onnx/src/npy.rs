//! Minimal `.npy` (NumPy format 1.0/2.0) reading and writing for embeddings and reference tensors:
//! little-endian `<f2`, `<f4`, `<i8`, C order only.

use std::io::Write;
use std::path::Path;

use crate::OnnxError;

/// Element values of an [`NpyArray`].
#[derive(Clone, Debug, PartialEq)]
pub enum NpyData {
    /// `<f2` (IEEE half).
    F16(Vec<half::f16>),
    /// `<f4`.
    F32(Vec<f32>),
    /// `<i8`.
    I64(Vec<i64>),
}

/// An n-dimensional array read from or written to `.npy`, row-major (C order).
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// Shape, outermost first (empty for a scalar).
    pub shape: Vec<usize>,
    /// Values.
    pub data: NpyData,
}

impl NpyArray {
    /// The values as `f32` (half widened exactly); `None` for integer data.
    pub fn to_f32(&self) -> Option<Vec<f32>> {
        match &self.data {
            NpyData::F16(v) => Some(v.iter().map(|x| x.to_f32()).collect()),
            NpyData::F32(v) => Some(v.clone()),
            NpyData::I64(_) => None,
        }
    }

    /// The values as `i64`; `None` for float data.
    pub fn as_i64(&self) -> Option<&[i64]> {
        match &self.data {
            NpyData::I64(v) => Some(v),
            _ => None,
        }
    }
}

fn bad(path: &Path, message: impl Into<String>) -> OnnxError {
    OnnxError::Npy {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Parses a `.npy` file from bytes. `path` only names it in errors.
pub fn parse_npy(bytes: &[u8], path: &Path) -> Result<NpyArray, OnnxError> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad(path, "not a .npy file (bad magic)"));
    }
    let major = bytes[6];
    let (header_len, start) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10usize),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err(bad(path, "truncated header"));
            }
            (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            )
        }
        v => return Err(bad(path, format!("unsupported .npy version {v}"))),
    };
    let end = start
        .checked_add(header_len)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| bad(path, "truncated header"))?;
    let header =
        std::str::from_utf8(&bytes[start..end]).map_err(|_| bad(path, "header is not UTF-8"))?;
    let field = |key: &str| -> Option<&str> {
        let k = header.find(&format!("'{key}'"))?;
        let rest = &header[k + key.len() + 2..];
        let colon = rest.find(':')?;
        Some(rest[colon + 1..].trim_start())
    };
    let descr = field("descr")
        .and_then(|s| s.strip_prefix('\''))
        .and_then(|s| s.split('\'').next())
        .ok_or_else(|| bad(path, "header has no descr"))?;
    let fortran = field("fortran_order").ok_or_else(|| bad(path, "header has no fortran_order"))?;
    if fortran.starts_with("True") {
        return Err(bad(
            path,
            "Fortran-ordered arrays are not supported (save with np.ascontiguousarray)",
        ));
    }
    let shape_str = field("shape")
        .and_then(|s| s.strip_prefix('('))
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| bad(path, "header has no shape"))?;
    let mut shape = Vec::new();
    for part in shape_str
        .split(',')
        .map(str::trim)
        .filter(|p| !p.is_empty())
    {
        shape.push(
            part.parse::<usize>()
                .map_err(|_| bad(path, format!("bad shape entry `{part}`")))?,
        );
    }
    let count = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or_else(|| bad(path, "shape overflows"))?;
    let body = &bytes[end..];
    let need = |size: usize| -> Result<&[u8], OnnxError> {
        let n = count
            .checked_mul(size)
            .ok_or_else(|| bad(path, "shape overflows"))?;
        if body.len() != n {
            return Err(bad(
                path,
                format!(
                    "expected {n} data bytes for shape {shape:?}, found {}",
                    body.len()
                ),
            ));
        }
        Ok(body)
    };
    let data = match descr {
        "<f2" => NpyData::F16(
            need(2)?
                .chunks_exact(2)
                .map(|c| half::f16::from_le_bytes([c[0], c[1]]))
                .collect(),
        ),
        "<f4" => NpyData::F32(
            need(4)?
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
        ),
        "<i8" => NpyData::I64(
            need(8)?
                .chunks_exact(8)
                .map(|c| i64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
                .collect(),
        ),
        other => {
            return Err(bad(
                path,
                format!("unsupported dtype `{other}` (expected <f2, <f4 or <i8)"),
            ));
        }
    };
    Ok(NpyArray { shape, data })
}

/// Reads a `.npy` file.
pub fn read_npy(path: impl AsRef<Path>) -> Result<NpyArray, OnnxError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| OnnxError::io(path, e))?;
    parse_npy(&bytes, path)
}

/// Serializes an array as `.npy` version 1.0 bytes.
pub fn npy_bytes(array: &NpyArray) -> Vec<u8> {
    let descr = match array.data {
        NpyData::F16(_) => "<f2",
        NpyData::F32(_) => "<f4",
        NpyData::I64(_) => "<i8",
    };
    let shape = match array.shape.len() {
        0 => "()".to_string(),
        1 => format!("({},)", array.shape[0]),
        _ => format!(
            "({})",
            array
                .shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}");
    // Pad so that magic (6) + version (2) + length (2) + header + '\n' is a multiple of 64.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(header.len() + 10);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    match &array.data {
        NpyData::F16(v) => v
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        NpyData::F32(v) => v
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
        NpyData::I64(v) => v
            .iter()
            .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
    }
    out
}

/// Writes a `.npy` file atomically (temporary file in the same directory, then rename).
pub fn write_npy(path: impl AsRef<Path>, array: &NpyArray) -> Result<(), OnnxError> {
    let path = path.as_ref();
    let tmp = path.with_extension(format!("npy.tmp{}", std::process::id()));
    let write = || -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(&npy_bytes(array))?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    };
    write().map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        OnnxError::io(path, e)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_and_i64_round_trip_through_bytes() {
        let a = NpyArray {
            shape: vec![2, 3],
            data: NpyData::F32(vec![1.0, -2.5, 3.0, 0.0, 1e-8, 7.0]),
        };
        let bytes = npy_bytes(&a);
        assert_eq!((bytes.len() - 6 * 4) % 64, 0, "header padded to 64 bytes");
        assert_eq!(parse_npy(&bytes, Path::new("x")).ok(), Some(a));
        let b = NpyArray {
            shape: vec![4],
            data: NpyData::I64(vec![3, 9, 1202, -1]),
        };
        assert_eq!(parse_npy(&npy_bytes(&b), Path::new("x")).ok(), Some(b));
    }

    #[test]
    fn truncated_or_foreign_files_are_errors_not_panics() {
        let a = NpyArray {
            shape: vec![8],
            data: NpyData::F32(vec![0.5; 8]),
        };
        let bytes = npy_bytes(&a);
        for cut in [0, 5, 9, 20, bytes.len() - 1] {
            assert!(
                parse_npy(&bytes[..cut], Path::new("x")).is_err(),
                "cut at {cut}"
            );
        }
        assert!(parse_npy(b"PK\x03\x04 not npy at all", Path::new("x")).is_err());
    }
}
