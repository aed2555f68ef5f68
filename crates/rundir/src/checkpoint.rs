//! The checkpoint container: the layout version, the last finished iteration and the task's
//! identity ([`TaskIdentity`], so that a resume can refuse a different task) around the caller's
//! own state `S` (for stylize: the raw targets, Adam's state, the RNG and the config). Written
//! atomically and durably ([`crate::durable`]).
//!
//! The file is one JSON object: `version`, `iteration`, then the fields of `S` in their order,
//! then `identity` — for stylize `{"version":…,"iteration":…,"x":…,"adam":…,"rng":…,
//! "config_toml":…,"identity":…}`. Writing flattens `S` into that object without buffering
//! (numbers reach the JSON writer as they are, so `f64` and `u128` stay exact); reading parses
//! the header and `S` each from the whole text, so `S` must not deny unknown fields.
//!
//! Versions: 2 adds `identity`. Version-1 checkpoints (written before identities existed) still
//! load, with `identity: None`; a resume refuses them (their task cannot be verified).

use std::path::Path;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::error::{Error, IoContext, Result};
use crate::identity::TaskIdentity;

/// Version of the checkpoint layout.
pub const CHECKPOINT_VERSION: u32 = 2;

/// The oldest layout [`Checkpoint::load`] reads.
pub const OLDEST_CHECKPOINT_VERSION: u32 = 1;

/// The state `state` after `iteration` finished iterations (1-indexed; 0 = before the first).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Checkpoint<S> {
    /// Layout version ([`CHECKPOINT_VERSION`]).
    pub version: u32,
    /// Last finished iteration.
    pub iteration: u64,
    /// The caller's state, its fields written between `iteration` and `identity`.
    #[serde(flatten)]
    pub state: S,
    /// The task this checkpoint belongs to (`None`: a version-1 checkpoint).
    pub identity: Option<TaskIdentity>,
}

/// What this crate reads of a checkpoint (the rest is `S`'s).
#[derive(Deserialize)]
struct Header {
    version: u32,
    iteration: u64,
    #[serde(default)]
    identity: Option<TaskIdentity>,
}

impl<S: Serialize> Checkpoint<S> {
    /// Writes `path` atomically and durably (see [`crate::durable::replace_with`]).
    pub fn save_atomic(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self)?;
        crate::durable::replace_bytes(path, text.as_bytes())
    }
}

impl<S: DeserializeOwned> Checkpoint<S> {
    /// Reads a checkpoint: a file that does not parse, has a version outside
    /// [`OLDEST_CHECKPOINT_VERSION`]..=[`CHECKPOINT_VERSION`], or (version 2 on) lacks its
    /// identity is [`Error::Corrupt`].
    pub fn load(path: &Path) -> Result<Self> {
        let corrupt = |message: String| Error::Corrupt {
            path: path.to_path_buf(),
            message,
        };
        let text = std::fs::read_to_string(path).io_context("cannot read", path)?;
        let parse_error = |e: serde_json::Error| {
            corrupt(format!("checkpoint {} is corrupt: {e}", path.display()))
        };
        // The header first: its fields come first in the layout, so a missing field is named in
        // the layout's order.
        let header: Header = serde_json::from_str(&text).map_err(parse_error)?;
        let state: S = serde_json::from_str(&text).map_err(parse_error)?;
        let c = Self {
            version: header.version,
            iteration: header.iteration,
            state,
            identity: header.identity,
        };
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

    /// A caller's state with the kinds of values stylize's has: f64 rows, a u128, a string.
    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    struct State {
        x: Vec<[f64; 3]>,
        counter: u128,
        note: String,
    }

    fn ok<T, E: std::fmt::Display>(r: std::result::Result<T, E>) -> T {
        r.unwrap_or_else(|e| panic!("{e}"))
    }

    fn identity() -> TaskIdentity {
        TaskIdentity {
            fields: [("mesh.sha256".to_string(), "ab".to_string())].into(),
        }
    }

    #[test]
    fn the_state_is_written_between_the_header_and_the_identity_exactly() {
        let dir = ok(tempfile::tempdir());
        let c = Checkpoint {
            version: CHECKPOINT_VERSION,
            iteration: 3,
            // Values whose shortest decimal form needs all 17 digits, and a u128 past u64.
            state: State {
                x: vec![
                    [0.1 + 0.2, -1e-300, 2.0f64.sqrt()],
                    [f64::MAX, 5e-324, -0.0],
                ],
                counter: u128::MAX - 7,
                note: "[run]\nseed = 9\n".into(),
            },
            identity: Some(identity()),
        };
        let path = dir.path().join("checkpoint.json");
        ok(c.save_atomic(&path));
        let text = ok(std::fs::read_to_string(&path));
        assert_eq!(
            text,
            format!(
                "{{\"version\":2,\"iteration\":3,\"x\":[[0.30000000000000004,-1e-300,\
                 1.4142135623730951],[1.7976931348623157e+308,5e-324,-0.0]],\"counter\":{},\
                 \"note\":\"[run]\\nseed = 9\\n\",\"identity\":{{\"fields\":{{\"mesh.sha256\":\
                 \"ab\"}}}}}}",
                u128::MAX - 7
            )
        );
        let back: Checkpoint<State> = ok(Checkpoint::load(&path));
        assert_eq!(back, c);
        let entries = std::fs::read_dir(dir.path())
            .map(|d| d.count())
            .unwrap_or_default();
        assert_eq!(entries, 1, "no temporary file is left");
    }

    #[test]
    fn version_one_checkpoints_load_without_identity_and_version_two_needs_it() {
        let dir = ok(tempfile::tempdir());
        let path = dir.path().join("checkpoint.json");
        let v1 = r#"{"version":1,"iteration":1,"x":[[0.0,0.0,0.0]],"counter":1,"note":""}"#;
        ok(std::fs::write(&path, v1));
        let back: Checkpoint<State> = ok(Checkpoint::load(&path));
        assert_eq!((back.version, back.identity), (1, None));
        ok(std::fs::write(
            &path,
            v1.replace("\"version\":1", "\"version\":2"),
        ));
        let e = Checkpoint::<State>::load(&path).map(|_| ()).err();
        let e = e.map(|e| e.to_string()).unwrap_or_default();
        assert!(
            e.ends_with("(version 2) has no task identity: it is corrupt"),
            "{e}"
        );
        ok(std::fs::write(
            &path,
            v1.replace("\"version\":1", "\"version\":3"),
        ));
        let e = Checkpoint::<State>::load(&path).map(|_| ()).err();
        let e = e.map(|e| e.to_string()).unwrap_or_default();
        assert!(
            e.ends_with("has version 3, this build reads versions 1 to 2"),
            "{e}"
        );
    }

    #[test]
    fn a_damaged_checkpoint_is_corrupt_naming_the_missing_field() {
        let dir = ok(tempfile::tempdir());
        let path = dir.path().join("checkpoint.json");
        for (text, field) in [
            (r#"{"iteration":1,"x":[],"counter":1,"note":""}"#, "version"),
            (r#"{"version":1,"iteration":1,"counter":1,"note":""}"#, "x"),
            (r#"{"version":1,"x":[],"note":""}"#, "iteration"),
        ] {
            ok(std::fs::write(&path, text));
            let e = Checkpoint::<State>::load(&path).map(|_| ()).err();
            assert!(matches!(&e, Some(Error::Corrupt { .. })), "{text}: {e:?}");
            let e = e.map(|e| e.to_string()).unwrap_or_default();
            assert!(
                e.contains("is corrupt: missing field") && e.contains(&format!("`{field}`")),
                "{e}"
            );
        }
    }
}
