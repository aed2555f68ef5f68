//! Reading the small files a user names (configs, manifests, masks, model manifests): only regular
//! files are opened, so a named pipe cannot block a run and a device cannot be read without end
//! (see [`mesh_core::io::ensure_regular_file`]; meshes go through `mesh_core::io`, which does the same).

use std::path::Path;

/// [`std::fs::read_to_string`] of a regular file, without a leading UTF-8 byte-order mark (which
/// Windows editors write; left in place it would hide the first key, row or index). Text in UTF-16
/// (a byte-order mark `FF FE` or `FE FF`) is refused with what to do, not as invalid UTF-8.
pub fn read_to_string(path: &Path) -> std::io::Result<String> {
    mesh_core::io::ensure_regular_file(path)?;
    text(std::fs::read(path)?)
}

/// `bytes` as UTF-8 text without a leading byte-order mark (see [`read_to_string`]).
pub fn text(bytes: Vec<u8>) -> std::io::Result<String> {
    if bytes.starts_with(b"\xFF\xFE") || bytes.starts_with(b"\xFE\xFF") {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            "the file is UTF-16 text; save it as UTF-8",
        ));
    }
    let text = String::from_utf8(bytes)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// [`std::fs::read`] of a regular file.
pub fn read(path: &Path) -> std::io::Result<Vec<u8>> {
    mesh_core::io::ensure_regular_file(path)?;
    std::fs::read(path)
}

#[cfg(test)]
mod tests {
    use std::path::Path;
    use std::time::Duration;

    #[test]
    fn byte_order_marks_are_dropped_and_utf16_is_named() {
        assert_eq!(
            super::text(b"\xEF\xBB\xBFa = 1".to_vec()).expect("utf-8"),
            "a = 1"
        );
        assert_eq!(super::text(b"a = 1".to_vec()).expect("utf-8"), "a = 1");
        let e = super::text(b"\xFF\xFEa\0".to_vec()).expect_err("utf-16");
        assert!(e.to_string().contains("UTF-16"), "{e}");
    }

    #[test]
    fn configs_manifests_and_masks_that_are_not_regular_files_are_refused_without_blocking() {
        let dir = tempfile::tempdir().expect("tempdir");
        let fifo = dir.path().join("config.toml");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .is_ok_and(|s| s.success());
        let folder = dir.path().join("manifest.toml");
        std::fs::create_dir(&folder).expect("mkdir");
        let (tx, rx) = std::sync::mpsc::channel();
        let (f2, d2) = (fifo.clone(), folder.clone());
        std::thread::spawn(move || {
            let config = made.then(|| {
                format!(
                    "{:#}",
                    crate::config::load(&f2).expect_err("a FIFO is not a config")
                )
            });
            let manifest = format!(
                "{:#}",
                crate::batch::read_manifest(&d2).expect_err("a folder is not a manifest")
            );
            let mask = format!(
                "{:#}",
                crate::cmd::apply::read_mask(Path::new("/dev/zero"), 3)
                    .expect_err("a device is not a mask")
            );
            let _ = tx.send((config, manifest, mask));
        });
        let (config, manifest, mask) = rx
            .recv_timeout(Duration::from_secs(20))
            .expect("a reader blocked on a path that is not a regular file");
        if let Some(config) = config {
            assert!(
                config.contains("a named pipe (FIFO), not a regular file"),
                "{config}"
            );
        }
        assert!(
            manifest.contains("a directory, not a regular file"),
            "{manifest}"
        );
        assert!(mask.contains("a device, not a regular file"), "{mask}");
    }
}
