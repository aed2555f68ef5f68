//! What a checkpoint of a run holds beyond the container's header: everything needed to continue
//! the loop exactly where it stopped — the raw targets x, Adam's moments and step count, the RNG
//! state and the resolved config ([`CheckpointState`]). The container around it (layout version,
//! last finished iteration, task identity; atomic and durable writes; versions 1 and 2) is
//! [`rundir::checkpoint`]; [`Checkpoint`] is the two together.
//!
//! `checkpoint.json` is `{"version", "iteration", "x", "adam", "rng", "config_toml", "identity"}`
//! in that order, as it has always been.

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

pub use rundir::checkpoint::{CHECKPOINT_VERSION, OLDEST_CHECKPOINT_VERSION};

/// A run's checkpoint: the loop's [`CheckpointState`] in [`rundir::Checkpoint`]'s container.
pub type Checkpoint = rundir::Checkpoint<CheckpointState>;

/// The loop's state after the checkpoint's `iteration` finished iterations.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointState {
    /// Raw targets x, one row per vertex (JSON keeps f64 exactly).
    pub x: Vec<[f64; 3]>,
    /// Adam's state.
    pub adam: optim::AdamState,
    /// The run's generator, as it stands after `iteration`.
    pub rng: ChaCha8Rng,
    /// The resolved config the run was started with (TOML); a resume must use the same.
    pub config_toml: String,
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rundir::TaskIdentity;

    fn ok<T, E: std::fmt::Display>(r: std::result::Result<T, E>) -> T {
        r.unwrap_or_else(|e| panic!("{e}"))
    }

    /// The layout before the container moved to `rundir` (stylize's `Checkpoint` as it was),
    /// kept to check that new checkpoints are byte-identical to it and old ones still load.
    #[derive(Serialize, Deserialize)]
    struct LegacyCheckpoint {
        version: u32,
        iteration: u64,
        x: Vec<[f64; 3]>,
        adam: optim::AdamState,
        rng: ChaCha8Rng,
        config_toml: String,
        #[serde(default)]
        identity: Option<TaskIdentity>,
    }

    fn sample() -> Checkpoint {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let _: f64 = rng.random();
        Checkpoint {
            version: CHECKPOINT_VERSION,
            iteration: 3,
            state: CheckpointState {
                // Values whose shortest decimal form needs all 17 digits (exact parsing is
                // required).
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
            },
            identity: Some(TaskIdentity {
                fields: [("mesh.sha256".to_string(), "ab".to_string())].into(),
            }),
        }
    }

    #[test]
    fn checkpoint_round_trip_restores_rng_stream_and_exact_floats() {
        let dir = ok(tempfile::tempdir());
        let c = sample();
        let path = dir.path().join("checkpoint.json");
        ok(c.save_atomic(&path));
        let mut back = ok(Checkpoint::load(&path));
        assert_eq!(back.state.x, c.state.x);
        assert_eq!(back.state.adam, c.state.adam);
        let mut rng = c.state.rng.clone();
        let (a, b): (u64, u64) = (rng.random(), back.state.rng.random());
        assert_eq!(a, b);
        assert_eq!(back.identity, c.identity);
        let entries = std::fs::read_dir(dir.path())
            .map(|d| d.count())
            .unwrap_or_default();
        assert_eq!(entries, 1, "no temporary file is left");
    }

    /// A checkpoint written before the container moved (by hand, in that layout's key order).
    const LEGACY_TEXT: &str = concat!(
        r#"{"version":2,"iteration":7,"x":[[0.1,-2.5e-8,300000.00000000006],[0.0,-0.0,1e-300]],"#,
        r#""adam":{"step":14,"m":[1e-9,0.5],"v":[2.0,3.0000000000000004]},"#,
        r#""rng":{"seed":[4,8,15,16,23,42,4,8,15,16,23,42,4,8,15,16,23,42,4,8,15,16,23,42,4,8,"#,
        r#"15,16,23,42,4,8],"stream":27182818284,"word_pos":123456789012345678901"#,
        r#"},"config_toml":"[run]\nseed = 9\n","identity":{"fields":{"mesh.sha256":"ab","#,
        r#""style":"cube"}}}"#
    );

    #[test]
    fn the_layout_and_key_order_are_unchanged() {
        // New checkpoints: byte-identical to the old layout's serialization.
        let c = sample();
        let legacy = LegacyCheckpoint {
            version: c.version,
            iteration: c.iteration,
            x: c.state.x.clone(),
            adam: c.state.adam.clone(),
            rng: c.state.rng.clone(),
            config_toml: c.state.config_toml.clone(),
            identity: c.identity.clone(),
        };
        let text = ok(serde_json::to_string(&c));
        assert_eq!(text, ok(serde_json::to_string(&legacy)));
        let keys: Vec<usize> = [
            "\"version\":",
            "\"iteration\":",
            "\"x\":",
            "\"adam\":",
            "\"rng\":",
            "\"config_toml\":",
            "\"identity\":",
        ]
        .iter()
        .map(|k| text.find(k).unwrap_or(usize::MAX))
        .collect();
        assert!(keys.windows(2).all(|w| w[0] < w[1]), "{keys:?}: {text}");
        // Old checkpoints: load to the values the old layout reads, and write back identically.
        let dir = ok(tempfile::tempdir());
        let path = dir.path().join("checkpoint.json");
        ok(std::fs::write(&path, LEGACY_TEXT));
        let back = ok(Checkpoint::load(&path));
        let old: LegacyCheckpoint = ok(serde_json::from_str(LEGACY_TEXT));
        assert_eq!((back.version, back.iteration), (old.version, old.iteration));
        assert_eq!(back.state.x, old.x);
        assert_eq!(back.state.adam, old.adam);
        assert_eq!(back.state.rng, old.rng);
        assert_eq!(back.state.rng.get_word_pos(), old.rng.get_word_pos());
        assert_eq!(back.state.config_toml, old.config_toml);
        assert_eq!(back.identity, old.identity);
        assert_eq!(ok(serde_json::to_string(&back)), LEGACY_TEXT);
    }

    #[test]
    fn version_one_checkpoints_load_without_identity() {
        let dir = ok(tempfile::tempdir());
        let c = Checkpoint {
            version: 1,
            iteration: 1,
            state: CheckpointState {
                x: vec![[0.0; 3]],
                adam: optim::AdamState {
                    step: 1,
                    m: vec![0.0; 3],
                    v: vec![0.0; 3],
                },
                rng: ChaCha8Rng::seed_from_u64(1),
                config_toml: String::new(),
            },
            identity: None,
        };
        let mut v = serde_json::to_value(&c).unwrap_or_default();
        if let Some(o) = v.as_object_mut() {
            o.remove("identity");
        }
        let path = dir.path().join("checkpoint.json");
        ok(std::fs::write(&path, v.to_string()));
        let back = ok(Checkpoint::load(&path));
        assert_eq!(back.identity, None);
        // A version-2 checkpoint must carry its identity.
        v["version"] = 2.into();
        ok(std::fs::write(&path, v.to_string()));
        assert!(Checkpoint::load(&path).is_err());
    }
}
