//! `.npz` files (a zip of `.npy` arrays, as NumPy's `np.savez` / `np.savez_compressed` write them).
//!
//! The entries are parsed and written by [`crate::parse_npy`] / [`crate::write_npy`]. Zip entries
//! may be stored or deflated; we write stored entries (like `np.savez`). Reading is bounded: only
//! the directory is read on open, an entry is inflated to at most its declared size, and all the
//! entries read from one file together to at most a total ([`NpzReader::total_limit`]): a small
//! file of many entries, each under the per-entry cap, cannot make a reader allocate gigabytes.

use std::cell::{Cell, OnceCell, RefCell};
use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use crate::{NpyArray, NpyData, NpyError, ensure_regular_file, parse_npy, write_npy};

/// The most bytes one entry may declare (uncompressed) before it is refused unread.
pub const MAX_ENTRY_BYTES: u64 = 1 << 32;

/// By default, the entries read from one file may inflate to at most this many times the file's
/// size in total ([`NpzReader::total_limit`]). Arrays of mesh data deflate by a factor of about
/// 1–8 (`np.savez` stores them uncompressed, factor 1); deflate itself reaches ~1000 on zeros.
pub const MAX_INFLATION: u64 = 64;

/// The default total is never below this (small files of legitimately compressible arrays).
pub const MIN_TOTAL_BYTES: u64 = 64 << 20;

/// One `*.npy` entry of the zip's central directory.
#[derive(Debug)]
struct Entry {
    key: String,
    index: usize,
    /// Declared uncompressed size.
    size: u64,
}

/// The arrays of an `.npz` file, read lazily: [`NpzReader::open`] reads only the zip's directory,
/// and an entry is inflated (at most its declared size, which must not exceed
/// [`MAX_ENTRY_BYTES`]) and parsed the first time it is asked for, then kept. Entries nobody asks
/// for are never inflated, so a large unused entry costs nothing. The declared sizes of the
/// entries read are charged against a total ([`NpzReader::total_limit`]); an entry that would
/// exceed it is refused unread.
pub struct NpzReader {
    path: PathBuf,
    zip: RefCell<zip::ZipArchive<std::io::BufReader<File>>>,
    entries: Vec<Entry>,
    loaded: Vec<OnceCell<NpyArray>>,
    /// The total the entries read may inflate to.
    total_limit: u64,
    /// Bytes charged so far (declared sizes of the entries read).
    inflated: Cell<u64>,
}

impl std::fmt::Debug for NpzReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NpzReader")
            .field("path", &self.path)
            .field("entries", &self.entries)
            .finish()
    }
}

impl NpzReader {
    /// Opens the zip and lists its `*.npy` entries (entries with other names are ignored);
    /// nothing is inflated yet. The key of `verts.npy` is `verts`.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, NpyError> {
        let path = path.as_ref().to_path_buf();
        ensure_regular_file(&path).map_err(|e| NpyError::io(&path, e))?;
        let file = File::open(&path).map_err(|e| NpyError::io(&path, e))?;
        let file_len = file.metadata().map_err(|e| NpyError::io(&path, e))?.len();
        let mut zip =
            zip::ZipArchive::new(std::io::BufReader::new(file)).map_err(|e| NpyError::Archive {
                path: path.clone(),
                message: format!("not a readable .npz (zip) archive: {e}"),
            })?;
        let mut entries: Vec<Entry> = Vec::new();
        for i in 0..zip.len() {
            let entry = zip.by_index_raw(i).map_err(|e| NpyError::Archive {
                path: path.clone(),
                message: format!("zip entry {i} is unreadable: {e}"),
            })?;
            let Some(key) = entry.name().strip_suffix(".npy") else {
                continue;
            };
            if entries.iter().any(|e| e.key == key) {
                return Err(NpyError::Array {
                    path: path.clone(),
                    key: key.to_string(),
                    message: "stored twice in the archive".into(),
                });
            }
            entries.push(Entry {
                key: key.to_string(),
                index: i,
                size: entry.size(),
            });
        }
        let loaded = entries.iter().map(|_| OnceCell::new()).collect();
        Ok(Self {
            path,
            zip: RefCell::new(zip),
            entries,
            loaded,
            total_limit: file_len.saturating_mul(MAX_INFLATION).max(MIN_TOTAL_BYTES),
            inflated: Cell::new(0),
        })
    }

    /// The most bytes the entries read from this file may inflate to in total (declared sizes).
    /// By default [`MAX_INFLATION`] × the file's size, at least [`MIN_TOTAL_BYTES`].
    pub fn total_limit(&self) -> u64 {
        self.total_limit
    }

    /// Lowers (never raises) the total: a caller that knows what the file can hold for its task
    /// (e.g. the arrays of a mesh of known size) bounds it by that.
    #[must_use]
    pub fn with_total_limit(mut self, bytes: u64) -> Self {
        self.total_limit = self.total_limit.min(bytes);
        self
    }

    /// The file this was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Keys in file order.
    pub fn keys(&self) -> impl Iterator<Item = &str> {
        self.entries.iter().map(|e| e.key.as_str())
    }

    /// Declared (uncompressed) size in bytes of the entry under `key`, without inflating it.
    pub fn declared_size(&self, key: &str) -> Option<u64> {
        self.entries.iter().find(|e| e.key == key).map(|e| e.size)
    }

    /// The array stored under `key`, if any and readable (use [`NpzReader::require`] to learn why
    /// one is not).
    pub fn get(&self, key: &str) -> Option<&NpyArray> {
        self.load(key).ok().flatten()
    }

    /// The array under `key`, or an error naming the missing or malformed key.
    pub fn require(&self, key: &str) -> Result<&NpyArray, NpyError> {
        self.load(key)?
            .ok_or_else(|| self.err(key, "missing from the file".into()))
    }

    /// Inflates and parses `key` on first use (`Ok(None)` when there is no such entry).
    fn load(&self, key: &str) -> Result<Option<&NpyArray>, NpyError> {
        let Some(k) = self.entries.iter().position(|e| e.key == key) else {
            return Ok(None);
        };
        if let Some(a) = self.loaded[k].get() {
            return Ok(Some(a));
        }
        let Entry { index, size, .. } = self.entries[k];
        if size > MAX_ENTRY_BYTES {
            return Err(self.err(
                key,
                format!(
                    "the zip entry declares {size} bytes uncompressed, more than the {MAX_ENTRY_BYTES} allowed"
                ),
            ));
        }
        let charged = self.inflated.get().saturating_add(size);
        if charged > self.total_limit {
            return Err(self.err(
                key,
                format!(
                    "the zip entry declares {size} bytes uncompressed; with the {} bytes of the \
                     entries read before, that is more than the {} bytes this file may inflate to \
                     ({MAX_INFLATION} × its size, at least {MIN_TOTAL_BYTES}, or what the task \
                     needs): a decompression bomb or a corrupt file",
                    self.inflated.get(),
                    self.total_limit
                ),
            ));
        }
        self.inflated.set(charged);
        let mut zip = self.zip.borrow_mut();
        let entry = zip
            .by_index(index)
            .map_err(|e| self.err(key, format!("the zip entry is unreadable: {e}")))?;
        // Never more than the declared size, whatever the compressed stream expands to.
        let mut bytes = Vec::with_capacity(size.min(1 << 26) as usize);
        entry
            .take(size)
            .read_to_end(&mut bytes)
            .map_err(|e| self.err(key, format!("cannot decompress the zip entry: {e}")))?;
        drop(zip);
        let array = parse_npy(&bytes).map_err(|message| self.err(key, message))?;
        let _ = self.loaded[k].set(array);
        Ok(self.loaded[k].get())
    }

    /// Reads every array and returns `(key, array)` pairs in file order.
    pub fn into_arrays(self) -> Result<Vec<(String, NpyArray)>, NpyError> {
        for e in &self.entries {
            self.load(&e.key)?;
        }
        Ok(self
            .entries
            .into_iter()
            .zip(self.loaded)
            .filter_map(|(e, a)| a.into_inner().map(|a| (e.key, a)))
            .collect())
    }

    /// An `(n, 3)` float array (`<f2`, `<f4` or `<f8`, converted) as `f32` rows.
    pub fn rows3_f32(&self, key: &str) -> Result<Vec<[f32; 3]>, NpyError> {
        let a = self.require(key)?;
        let Some(flat) = a.to_f32() else {
            return Err(self.err(
                key,
                format!("expected float data, found {}", a.data.descr()),
            ));
        };
        self.check_rows3(key, a)?;
        Ok(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
    }

    /// An `(n, 3)` float array as `f64` rows.
    pub fn rows3_f64(&self, key: &str) -> Result<Vec<[f64; 3]>, NpyError> {
        let a = self.require(key)?;
        let flat = match &a.data {
            NpyData::F16(_) | NpyData::F32(_) | NpyData::F64(_) => {
                a.to_f64_vec().unwrap_or_default()
            }
            _ => {
                return Err(self.err(
                    key,
                    format!("expected float data, found {}", a.data.descr()),
                ));
            }
        };
        self.check_rows3(key, a)?;
        Ok(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
    }

    /// An `(n, 3)` integer array (any integer dtype) as `u32` index rows; negative or too large
    /// values are an error naming the first bad row.
    pub fn rows3_u32(&self, key: &str) -> Result<Vec<[u32; 3]>, NpyError> {
        let a = self.require(key)?;
        let flat = a.to_i64_vec().ok_or_else(|| {
            self.err(
                key,
                format!("expected integer indices, found {}", a.data.descr()),
            )
        })?;
        self.check_rows3(key, a)?;
        let mut out = Vec::with_capacity(flat.len() / 3);
        for (row, c) in flat.chunks_exact(3).enumerate() {
            let mut t = [0u32; 3];
            for k in 0..3 {
                t[k] = u32::try_from(c[k]).map_err(|_| {
                    self.err(
                        key,
                        format!("row {row} holds index {} (must be 0 ≤ i < 2³²)", c[k]),
                    )
                })?;
            }
            out.push(t);
        }
        Ok(out)
    }

    /// The string of a 0-d unicode array.
    pub fn string(&self, key: &str) -> Result<String, NpyError> {
        let a = self.require(key)?;
        a.as_str().map(str::to_owned).ok_or_else(|| {
            self.err(
                key,
                format!(
                    "expected a 0-d unicode string, found {} of shape {:?}",
                    a.data.descr(),
                    a.shape
                ),
            )
        })
    }

    fn check_rows3(&self, key: &str, a: &NpyArray) -> Result<(), NpyError> {
        if a.shape.len() == 2 && a.shape[1] == 3 {
            Ok(())
        } else {
            Err(self.err(key, format!("expected shape (N, 3), found {:?}", a.shape)))
        }
    }

    fn err(&self, key: &str, message: String) -> NpyError {
        NpyError::Array {
            path: self.path.clone(),
            key: key.to_string(),
            message,
        }
    }
}

/// Writes an `.npz` (stored, uncompressed entries named `<key>.npy`, like `np.savez`).
///
/// Missing parent folders are created. Call [`NpzWriter::finish`] to complete the file; a writer
/// dropped without it leaves an incomplete zip.
pub struct NpzWriter {
    path: PathBuf,
    zip: zip::ZipWriter<BufWriter<File>>,
    keys: Vec<String>,
}

impl std::fmt::Debug for NpzWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NpzWriter")
            .field("path", &self.path)
            .field("keys", &self.keys)
            .finish()
    }
}

impl NpzWriter {
    /// Creates (or truncates) the file.
    pub fn create(path: impl AsRef<Path>) -> Result<Self, NpyError> {
        let path = path.as_ref().to_path_buf();
        if let Some(parent) = path.parent()
            && !parent.as_os_str().is_empty()
        {
            std::fs::create_dir_all(parent).map_err(|e| NpyError::io(parent, e))?;
        }
        let file = File::create(&path).map_err(|error| NpyError::Io {
            path: path.clone(),
            error,
        })?;
        Ok(Self {
            path,
            zip: zip::ZipWriter::new(BufWriter::new(file)),
            keys: Vec::new(),
        })
    }

    /// Adds one array under `key` (written as `<key>.npy`). Keys must be unique.
    pub fn add(&mut self, key: &str, array: &NpyArray) -> Result<(), NpyError> {
        if self.keys.iter().any(|k| k == key) {
            return Err(NpyError::Array {
                path: self.path.clone(),
                key: key.into(),
                message: "written twice".into(),
            });
        }
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored)
            .large_file(true);
        let bytes = write_npy(array);
        self.zip
            .start_file(format!("{key}.npy"), options)
            .map_err(|e| self.io_err(e.to_string()))?;
        self.zip
            .write_all(&bytes)
            .map_err(|e| self.io_err(e.to_string()))?;
        self.keys.push(key.to_string());
        Ok(())
    }

    /// Completes the zip and flushes the file.
    pub fn finish(self) -> Result<(), NpyError> {
        let path = self.path.clone();
        let w = self.zip.finish().map_err(|e| NpyError::Io {
            path: path.clone(),
            error: std::io::Error::other(e.to_string()),
        })?;
        w.into_inner()
            .map_err(|e| NpyError::Io {
                path: path.clone(),
                error: e.into_error(),
            })?
            .sync_all()
            .map_err(|error| NpyError::Io { path, error })
    }

    fn io_err(&self, msg: String) -> NpyError {
        NpyError::Io {
            path: self.path.clone(),
            error: std::io::Error::other(msg),
        }
    }
}

/// Writes `arrays` to a new `.npz` in the given order.
pub fn write_npz<'a>(
    path: impl AsRef<Path>,
    arrays: impl IntoIterator<Item = (&'a str, &'a NpyArray)>,
) -> Result<(), NpyError> {
    let mut w = NpzWriter::create(path)?;
    for (k, a) in arrays {
        w.add(k, a)?;
    }
    w.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn archives_round_trip_in_order_and_errors_name_file_and_key() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("sub/a.npz");
        let x = NpyArray::f64_rows3(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        let s = NpyArray::scalar_str("hello");
        write_npz(&path, [("x", &x), ("s", &s)]).expect("write");
        let r = NpzReader::open(&path).expect("open");
        assert_eq!(r.keys().collect::<Vec<_>>(), ["x", "s"]);
        assert_eq!(
            r.rows3_f64("x").expect("x"),
            [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
        );
        assert_eq!(r.string("s").expect("s"), "hello");
        let e = r.rows3_u32("s").expect_err("a string is no index array");
        assert!(
            matches!(&e, NpyError::Array { key, .. } if key == "s"),
            "{e}"
        );
        let e = r.require("nope").expect_err("missing");
        assert!(
            e.to_string().contains("a.npz: array `nope`: missing"),
            "{e}"
        );

        let mut w = NpzWriter::create(dir.path().join("b.npz")).expect("create");
        w.add("x", &x).expect("first");
        assert!(matches!(w.add("x", &x), Err(NpyError::Array { .. })));

        let junk = dir.path().join("junk.npz");
        std::fs::write(&junk, b"not a zip").expect("write junk");
        assert!(matches!(
            NpzReader::open(&junk),
            Err(NpyError::Archive { .. })
        ));
        assert!(matches!(
            NpzReader::open(dir.path()),
            Err(NpyError::Io { .. })
        ));
    }

    /// A small file of many deflated entries, each far under [`MAX_ENTRY_BYTES`]: the entries
    /// read may not inflate to more than the file's total, whichever entries are asked for.
    #[test]
    fn many_small_bombs_are_refused_by_the_total_not_only_per_entry() {
        use zip::write::SimpleFileOptions;
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("bomb.npz");
        // 20 MiB of zeros per entry, deflated to ~20 KiB each.
        let n = 5 << 20;
        let zeros = write_npy(&NpyArray::new(vec![n], NpyData::F32(vec![0.0; n])).expect("array"));
        let mut zip = zip::ZipWriter::new(File::create(&path).expect("create"));
        let options =
            SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
        for k in 0..5 {
            zip.start_file(format!("a{k}.npy"), options).expect("entry");
            zip.write_all(&zeros).expect("write");
        }
        zip.finish().expect("finish");
        let file_len = std::fs::metadata(&path).expect("len").len();
        assert!(file_len < 1 << 20, "the bomb is small: {file_len} bytes");

        let r = NpzReader::open(&path).expect("open");
        assert_eq!(r.total_limit(), MIN_TOTAL_BYTES);
        // Three entries (60 MiB + headers) fit under 64 MiB, the fourth does not.
        for k in 0..3 {
            assert_eq!(r.require(&format!("a{k}")).expect("fits").data.len(), n);
        }
        let e = r.require("a3").expect_err("over the total");
        assert!(e.to_string().contains("decompression bomb"), "{e}");
        // A caller's own bound is lower still.
        let r = NpzReader::open(&path)
            .expect("open")
            .with_total_limit(1 << 20);
        let e = r.require("a0").expect_err("over the caller's bound");
        assert!(
            e.to_string()
                .contains("1048576 bytes this file may inflate to"),
            "{e}"
        );
        assert!(
            NpzReader::open(&path).expect("open").into_arrays().is_err(),
            "reading every entry is refused as a whole"
        );
    }
}
