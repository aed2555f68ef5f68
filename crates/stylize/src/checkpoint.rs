//! Checkpoints: everything needed to continue a run exactly where it stopped — the raw targets x,
//! Adam's moments and step count, the RNG state and the last finished iteration — plus the
//! identity of the task ([`crate::identity`]) so that a resume can refuse a different task. Written
//! atomically and durably ([`crate::durable`]: unique temporary file, `fsync`, rename, `fsync` of
//! the folder).
//!
//! Versions: 2 adds `identity`. Version-1 checkpoints (written before identities existed) still
//! load, with `identity: None`; a resume refuses them (their task cannot be verified).

use std::path::Path;

use crate::error::{Error, IoContext, Result};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::identity::TaskIdentity;

/// Version of the checkpoint layout.
pub const CHECKPOINT_VERSION: u32 = 2;

/// The oldest layout [`Checkpoint::load`] reads.
pub const OLDEST_CHECKPOINT_VERSION: u32 = 1;

/// The state after `iteration` finished iterations (1-indexed; 0 = before the first).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// Layout version ([`CHECKPOINT_VERSION`]).
    pub version: u32,
    /// Last finished iteration.
    pub iteration: u64,
    /// Raw targets x, one row per vertex (JSON keeps f64 exactly).
    pub x: Vec<[f64; 3]>,
    /// Adam's state.
    pub adam: optim::AdamState,
    /// The run's generator, as it stands after `iteration`.
    pub rng: ChaCha8Rng,
    /// The resolved config the run was started with (TOML); a resume must use the same.
    pub config_toml: String,
    /// The task this checkpoint belongs to (`None`: a version-1 checkpoint).
    #[serde(default)]
    pub identity: Option<TaskIdentity>,
}

impl Checkpoint {
    /// Writes `path` atomically and durably (see [`crate::durable::replace_with`]).
    pub fn save_atomic(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self)?;
        crate::durable::replace_bytes(path, text.as_bytes())
    }

    /// Reads a checkpoint.
    pub fn load(path: &Path) -> Result<Self> {
        let corrupt = |message: String| Error::Corrupt {
            path: path.to_path_buf(),
            message,
        };
        let text = std::fs::read_to_string(path).io_context("cannot read", path)?;
        let c: Self = serde_json::from_str(&text)
            .map_err(|e| corrupt(format!("checkpoint {} is corrupt: {e}", path.display())))?;
        if !(OLDEST_CHECKPOINT_VERSION..=CHECKPOINT_VERSION).contains(&c.version) {
            return Err(corrupt(format!(
                "checkpoint {} has version {}, this build reads versions \
                 {OLDEST_CHECKPOINT_VERSION} to {CHECKPOINT_VERSION}",
                path.display(),
                c.version
            )));
        }
        if c.version >= 2 && c.identity.is_none() {
            return Err(corrupt(format!(
                "checkpoint {} (version {}) has no task identity: it is corrupt",
                path.display(),
                c.version
            )));
        }
        Ok(c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn checkpoint_round_trip_restores_rng_stream_and_exact_floats() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let _: f64 = rng.random();
        let c = Checkpoint {
            version: CHECKPOINT_VERSION,
            iteration: 3,
            // Values whose shortest decimal form needs all 17 digits (exact parsing is required).
            x: (0..200)
                .map(|_| {
                    [
                        rng.random::<f64>(),
                        -rng.random::<f64>() * 1e-7,
                        rng.random::<f64>() * 3e5,
                    ]
                })
                .collect(),
            adam: optim::AdamState {
                step: 6,
                m: vec![1e-9, 0.5, 0.25],
                v: vec![1e-300, 2.0, 3.0],
            },
            rng: rng.clone(),
            config_toml: "[run]\nseed = 9\n".into(),
            identity: Some(TaskIdentity {
                fields: [("mesh.sha256".to_string(), "ab".to_string())].into(),
            }),
        };
        let path = dir.path().join("checkpoint.json");
        c.save_atomic(&path).unwrap_or_else(|e| panic!("{e:#}"));
        let mut back = Checkpoint::load(&path).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(back.x, c.x);
        assert_eq!(back.adam, c.adam);
        let (a, b): (u64, u64) = (rng.random(), back.rng.random());
        assert_eq!(a, b);
        assert_eq!(back.identity, c.identity);
        let entries = std::fs::read_dir(dir.path())
            .map(|d| d.count())
            .unwrap_or_default();
        assert_eq!(entries, 1, "no temporary file is left");
    }

    #[test]
    fn version_one_checkpoints_load_without_identity() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let c = Checkpoint {
            version: 1,
            iteration: 1,
            x: vec![[0.0; 3]],
            adam: optim::AdamState {
                step: 1,
                m: vec![0.0; 3],
                v: vec![0.0; 3],
            },
            rng: ChaCha8Rng::seed_from_u64(1),
            config_toml: String::new(),
            identity: None,
        };
        let mut v = serde_json::to_value(&c).unwrap_or_default();
        if let Some(o) = v.as_object_mut() {
            o.remove("identity");
        }
        let path = dir.path().join("checkpoint.json");
        std::fs::write(&path, v.to_string()).unwrap_or_else(|e| panic!("{e}"));
        let back = Checkpoint::load(&path).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(back.identity, None);
        // A version-2 checkpoint must carry its identity.
        v["version"] = 2.into();
        std::fs::write(&path, v.to_string()).unwrap_or_else(|e| panic!("{e}"));
        assert!(Checkpoint::load(&path).is_err());
    }
}
