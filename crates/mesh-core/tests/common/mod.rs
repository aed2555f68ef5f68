//! Shared helpers for mesh-core's integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

/// `fixtures/meshes/<name>` in the repository.
pub fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/meshes")
        .join(name)
}
