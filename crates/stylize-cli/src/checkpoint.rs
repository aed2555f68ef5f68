//! Checkpoints: everything needed to continue a run exactly where it stopped — the raw targets x,
//! Adam's moments and step count, the RNG state and the last finished iteration — written
//! atomically (temporary file in the same directory, then rename).

use std::path::Path;

use anyhow::Context;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Version of the checkpoint layout.
pub const CHECKPOINT_VERSION: u32 = 1;

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
}

impl Checkpoint {
    /// Writes `path` atomically: `path.tmp` first, then a rename over `path`.
    pub fn save_atomic(&self, path: &Path) -> anyhow::Result<()> {
        let tmp = path.with_extension("json.tmp");
        let text = serde_json::to_string(self).context("cannot serialize checkpoint")?;
        std::fs::write(&tmp, text).with_context(|| format!("cannot write {}", tmp.display()))?;
        std::fs::rename(&tmp, path)
            .with_context(|| format!("cannot move {} to {}", tmp.display(), path.display()))
    }

    /// Reads a checkpoint.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let c: Self = serde_json::from_str(&text)
            .with_context(|| format!("checkpoint {} is corrupt", path.display()))?;
        anyhow::ensure!(
            c.version == CHECKPOINT_VERSION,
            "checkpoint {} has version {}, this build reads {CHECKPOINT_VERSION}",
            path.display(),
            c.version
        );
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
        };
        let path = dir.path().join("checkpoint.json");
        c.save_atomic(&path).unwrap_or_else(|e| panic!("{e:#}"));
        let mut back = Checkpoint::load(&path).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(back.x, c.x);
        assert_eq!(back.adam, c.adam);
        let (a, b): (u64, u64) = (rng.random(), back.rng.random());
        assert_eq!(a, b);
        assert!(!path.with_extension("json.tmp").exists());
    }
}
