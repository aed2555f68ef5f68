//! Replay of an optimization: a run's `snapshots.npz`.
//!
//! The file holds `iterations` (int, shape `[K]`, strictly increasing, the first usually 0) and `x`
//! (float, shape `[K, V, 3]`): the deformed positions at each of those iterations, in the vertex
//! order and side-2 cube frame of the run's result mesh. Optionally `faces` (int, `[F, 3]`), so
//! that a run still being written — which has no `deformation.npz` yet — can be drawn as a mesh;
//! without it the faces come from `deformation.npz`, and a run with neither is drawn as points.
//!
//! The run rewrites the file atomically every `snapshot_every` iterations, so the viewer reads it
//! again whenever its (modification time, length) changes. A file that is missing, unreadable,
//! half-written or inconsistent is not an error of the server: it is reported as "no replay" with
//! the reason ([`ReplayState::Unavailable`]), and the page keeps polling.

use std::path::Path;
use std::sync::Arc;
use std::time::SystemTime;

use anyhow::{Context, bail, ensure};

/// The snapshot file's name inside a run directory.
pub const SNAPSHOTS_FILE: &str = "snapshots.npz";

/// A parsed, validated `snapshots.npz`.
#[derive(Debug)]
pub struct Snapshots {
    /// (modification time, length) of the file when it was read.
    pub stamp: (SystemTime, u64),
    /// The iteration of each snapshot, strictly increasing.
    pub iterations: Vec<i64>,
    /// Vertices per snapshot (`V`).
    pub vertices: usize,
    /// All positions, snapshot-major: snapshot `k` is `x[3·V·k .. 3·V·(k+1)]`.
    pub x: Vec<f32>,
    /// The faces stored in the file, if any.
    pub faces: Option<Vec<[u32; 3]>>,
}

impl Snapshots {
    /// Reads and validates `path` (see the module documentation for what is checked).
    pub fn read(path: &Path, stamp: (SystemTime, u64)) -> anyhow::Result<Self> {
        let npz = npy::npz::NpzReader::open(path)?;
        let it = npz.require("iterations")?;
        ensure!(
            it.shape.len() == 1,
            "`iterations` has shape {:?}, expected [K]",
            it.shape
        );
        let iterations = it.to_i64_vec().with_context(|| {
            format!("`iterations` holds {}, expected integers", it.data.descr())
        })?;
        let xa = npz.require("x")?;
        let k = iterations.len();
        ensure!(
            xa.shape.len() == 3 && xa.shape[0] == k && xa.shape[2] == 3,
            "`x` has shape {:?}, expected [{k}, V, 3] (one row of positions per iteration)",
            xa.shape
        );
        let vertices = xa.shape[1];
        ensure!(k > 0 && vertices > 0, "the file holds no snapshot");
        let x = xa
            .to_f32()
            .with_context(|| format!("`x` holds {}, expected floats", xa.data.descr()))?;
        if let Some(w) = iterations.windows(2).find(|w| w[1] <= w[0]) {
            bail!(
                "`iterations` is not strictly increasing ({} then {})",
                w[0],
                w[1]
            );
        }
        if let Some(&i) = iterations.iter().find(|&&i| i < 0) {
            bail!("`iterations` holds the negative iteration {i}");
        }
        if let Some(bad) = x.iter().position(|c| !c.is_finite()) {
            bail!(
                "`x` at iteration {} holds a non-finite coordinate",
                iterations[bad / (3 * vertices)]
            );
        }
        let faces = if npz.keys().any(|key| key == "faces") {
            let faces = npz.rows3_u32("faces")?;
            if let Some(f) = faces
                .iter()
                .find(|f| f.iter().any(|&v| v as usize >= vertices))
            {
                bail!("`faces` holds {f:?}, out of range for {vertices} vertices");
            }
            Some(faces)
        } else {
            None
        };
        Ok(Self {
            stamp,
            iterations,
            vertices,
            x,
            faces,
        })
    }

    /// The positions of the snapshot at `iteration` (None when there is none).
    pub fn at(&self, iteration: i64) -> Option<&[f32]> {
        let k = self.iterations.binary_search(&iteration).ok()?;
        let n = 3 * self.vertices;
        self.x.get(k * n..(k + 1) * n)
    }
}

/// What a run's replay looks like right now.
#[derive(Clone, Debug)]
pub enum ReplayState {
    /// A valid snapshot file.
    Available(Arc<Snapshots>),
    /// No usable file, and why (missing, half-written, inconsistent).
    Unavailable(String),
}
