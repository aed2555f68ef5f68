//! `.npy` files for embeddings and reference tensors, on top of the [`npy`](::npy) crate (the project's one
//! NumPy reader and writer: little-endian, C order, `<f2 <f4 <f8 <i8 …`). This module adds the file
//! path to errors ([`OnnxError::Npy`]) and writes atomically.

use std::io::Write;
use std::path::Path;

pub use ::npy::{NpyArray, NpyData};

use crate::OnnxError;

fn bad(path: &Path, message: impl Into<String>) -> OnnxError {
    OnnxError::Npy {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Parses a `.npy` file from bytes. `path` only names it in errors.
pub fn parse_npy(bytes: &[u8], path: &Path) -> Result<NpyArray, OnnxError> {
    ::npy::parse_npy(bytes).map_err(|m| bad(path, m))
}

/// Reads a `.npy` file.
pub fn read_npy(path: impl AsRef<Path>) -> Result<NpyArray, OnnxError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| OnnxError::io(path, e))?;
    parse_npy(&bytes, path)
}

/// Serializes an array as `.npy` version 1.0 bytes.
pub fn npy_bytes(array: &NpyArray) -> Vec<u8> {
    ::npy::write_npy(array)
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
    fn errors_name_the_file_and_half_floats_widen_exactly() {
        let err =
            parse_npy(b"PK\x03\x04 not npy at all", Path::new("cache/x.npy")).expect_err("not npy");
        assert!(err.to_string().contains("cache/x.npy"), "{err}");
        let a = NpyArray {
            shape: vec![2],
            data: NpyData::F16(vec![half::f16::from_f32(0.25), half::f16::MAX]),
        };
        let back = parse_npy(&npy_bytes(&a), Path::new("x")).expect("round trip");
        assert_eq!(back.to_f32(), Some(vec![0.25, 65504.0]));
    }
}
