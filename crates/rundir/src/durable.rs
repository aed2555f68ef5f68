//! Durable, atomic file replacement: every checkpoint and output is written to a uniquely named
//! temporary file in the target's folder, flushed to stable storage (`fsync` of the file), renamed
//! over the target, and the folder is `fsync`ed so the rename itself survives a crash.
//!
//! Temporary names are `.<stem>.tmp-<pid>-<16 hex random>.<ext>`: unique per process and call (two
//! processes never share a temporary file even when they write the same target), hidden, and they
//! keep the target's extension because some writers choose the format from it (`mesh.obj`).
//! [`is_temp_name`] recognizes them, so a run directory's leftovers from a killed process are
//! known to be ours.
//!
//! [`replace_with`] is generic over the writer's error type, so a caller's own writers (a mesh,
//! an image, an archive) return their own errors through it.

use std::collections::hash_map::RandomState;
use std::fs::File;
use std::hash::{BuildHasher, Hasher};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, IoContext, Result};

/// Marker between the stem and the process id in temporary names.
const TEMP_MARK: &str = ".tmp-";

/// 64 random bits: SipHash under a fresh key of the standard library's `RandomState` (seeded
/// from the operating system's random source once per thread, then stepped per key) over a
/// process-wide counter and the time. Never repeats within a process; across processes and
/// hosts it is as unpredictable as the key.
pub(crate) fn random_u64() -> u64 {
    static CALLS: AtomicU64 = AtomicU64::new(0);
    let mut h = RandomState::new().build_hasher();
    h.write_u64(CALLS.fetch_add(1, Ordering::Relaxed));
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    h.write_u128(now);
    h.finish()
}

/// A fresh temporary path next to `target` (same folder, same extension).
pub fn temp_path(target: &Path) -> PathBuf {
    let stem = target
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let suffix = random_u64();
    let mut name = format!(".{stem}{TEMP_MARK}{}-{suffix:016x}", std::process::id());
    if let Some(ext) = target.extension() {
        name.push('.');
        name.push_str(&ext.to_string_lossy());
    }
    target.with_file_name(name)
}

/// Whether `name` is a temporary name made by [`temp_path`] (or the legacy `checkpoint.json.tmp`).
pub fn is_temp_name(name: &str) -> bool {
    (name.starts_with('.') && name.contains(TEMP_MARK)) || name == "checkpoint.json.tmp"
}

/// `fsync` of a folder, so that renames and creations inside it are durable. Folders that cannot
/// be opened for syncing (some network file systems refuse) are skipped silently: the data itself
/// was synced, only the rename's durability is then up to the file system.
pub fn sync_dir(dir: &Path) -> Result<()> {
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    match File::open(dir) {
        Ok(f) => match f.sync_all() {
            Ok(()) => Ok(()),
            // EINVAL/ENOTSUP: the file system does not sync folders; nothing more can be done.
            Err(e) if matches!(e.raw_os_error(), Some(22) | Some(95)) => Ok(()),
            Err(e) => Err(Error::io("cannot sync folder", dir, e)),
        },
        Err(_) => Ok(()),
    }
}

/// Writes `target` atomically: `write` fills a temporary path next to it, which is then synced,
/// renamed over `target`, and the folder synced. On any error the temporary file is removed and
/// `target` is left as it was. `write`'s error type is the caller's (this crate's [`Error`]s
/// convert into it).
pub fn replace_with<E: From<Error>>(
    target: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), E> {
    let tmp = temp_path(target);
    let result = write(&tmp).and_then(|()| {
        File::open(&tmp)
            .and_then(|f| f.sync_all())
            .io_context("cannot sync", &tmp)?;
        std::fs::rename(&tmp, target).map_err(|e| Error::Io {
            message: format!("cannot move {} to {}", tmp.display(), target.display()),
            path: target.to_path_buf(),
            source: e,
        })?;
        Ok(sync_dir(target.parent().unwrap_or(Path::new(".")))?)
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// [`replace_with`] for bytes already in memory.
pub fn replace_bytes(target: &Path, bytes: &[u8]) -> Result<()> {
    replace_with(target, |tmp| {
        std::fs::write(tmp, bytes).io_context("cannot write", tmp)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temp_names_are_unique_keep_the_extension_and_are_recognized() {
        let a = temp_path(Path::new("/r/mesh.obj"));
        let b = temp_path(Path::new("/r/mesh.obj"));
        assert_ne!(a, b);
        assert_eq!(a.extension().and_then(|e| e.to_str()), Some("obj"));
        let name = a.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        assert!(is_temp_name(name), "{name}");
        assert!(name.contains(&std::process::id().to_string()));
        assert!(!is_temp_name("mesh.obj") && !is_temp_name("notes.tmp-1"));
    }

    #[test]
    fn failed_write_leaves_target_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let target = dir.path().join("run.json");
        replace_bytes(&target, b"old").unwrap_or_else(|e| panic!("{e}"));
        let r = replace_with(&target, |tmp| {
            std::fs::write(tmp, b"partial").io_context("cannot write", tmp)?;
            Err(Error::refused(tmp, "disk full"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&target).unwrap_or_default(), b"old");
        let entries = std::fs::read_dir(dir.path())
            .map(|d| d.count())
            .unwrap_or_default();
        assert_eq!(entries, 1, "the temporary file is removed");
    }
}
