//! `snapshots.npz` of a run directory: the deformed mesh along the optimization, for replay (the
//! viewer scrubs through it and polls it while the run goes).
//!
//! Contents (NumPy `.npz`, stored entries, written with the `npy` crate):
//! - `iterations`: int64, shape `[K]`, strictly increasing, starting at 0;
//! - `faces`: int64, shape `[F, 3]`: the mesh's faces (those of `mesh.obj`), so a reader can draw
//!   a running run before `deformation.npz` exists (absent from files written by
//!   [`Snapshots::write`]);
//! - `x`: float32, shape `[K, V, 3]`: entry `k` holds the dARAP positions of the targets `x` after
//!   iteration `iterations[k]`, i.e. `Darap::forward(x_k)` with `x_k` rounded to f32 as
//!   `deformation.npz` saves it — the frame, vertex order and values of the run's `mesh.obj` /
//!   `mesh.ply` (the repaired, side-2-cube-normalized mesh, after dARAP's post-process). Entry 0 is
//!   the initial targets (the rest normals): the undeformed mesh in that same frame.
//!
//! Entries are taken at iteration 0, every `run.snapshot_every` iterations and at the last
//! iteration. The whole file is rewritten at each entry, atomically ([`rundir::durable`]: a
//! temporary file in the same folder, synced, renamed), so a reader never sees a torn file. On a
//! resume from a checkpoint at iteration c, entries after c (written before a kill) are dropped
//! first, so the file never holds duplicate or future iterations. The file is not part of the task
//! identity: `run.snapshot_every` may change between a run and its resume.

use std::path::{Path, PathBuf};

use crate::error::{Context, Error, Result, invalid};
use darap::Darap;
use npy::npz::{NpzReader, NpzWriter};
use npy::{NpyArray, NpyData};

/// The file name inside a run directory.
pub const FILE_NAME: &str = "snapshots.npz";

/// The snapshots read back from a file.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshots {
    /// `iterations`, one per entry.
    pub iterations: Vec<i64>,
    /// Vertices per entry (V).
    pub vertices: usize,
    /// `x`, row-major `[K, V, 3]`.
    pub x: Vec<f32>,
}

impl Snapshots {
    /// Reads `path`, checking the keys, dtypes, shapes and that the iterations increase strictly.
    pub fn read(path: &Path) -> Result<Self> {
        let npz = NpzReader::open(path)?;
        let iterations = npz.require("iterations")?;
        let x = npz.require("x")?;
        let (NpyData::I64(its), [k]) = (&iterations.data, iterations.shape.as_slice()) else {
            invalid!(
                "{}: `iterations` must be int64 of shape [K], got {} {:?}",
                path.display(),
                iterations.data.descr(),
                iterations.shape
            );
        };
        let (NpyData::F32(xs), [kx, v, 3]) = (&x.data, x.shape.as_slice()) else {
            invalid!(
                "{}: `x` must be float32 of shape [K, V, 3], got {} {:?}",
                path.display(),
                x.data.descr(),
                x.shape
            );
        };
        if k != kx {
            invalid!("{}: {k} iterations but {kx} position sets", path.display());
        }
        if its.windows(2).any(|w| w[0] >= w[1]) {
            invalid!("{}: iterations do not increase strictly", path.display());
        }
        Ok(Self {
            iterations: its.clone(),
            vertices: *v,
            x: xs.clone(),
        })
    }

    /// Number of entries (K).
    pub fn len(&self) -> usize {
        self.iterations.len()
    }

    /// Whether there is no entry.
    pub fn is_empty(&self) -> bool {
        self.iterations.is_empty()
    }

    /// The positions of entry `k` (V rows).
    pub fn positions(&self, k: usize) -> Option<Vec<[f32; 3]>> {
        let n = self.vertices * 3;
        self.x
            .get(k * n..(k + 1) * n)
            .map(|s| s.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
    }

    /// Keeps the entries with iteration ≤ `last`.
    fn truncate_after(&mut self, last: u64) {
        let keep = self
            .iterations
            .iter()
            .take_while(|&&i| u64::try_from(i).is_ok_and(|i| i <= last))
            .count();
        self.iterations.truncate(keep);
        self.x.truncate(keep * self.vertices * 3);
    }

    /// Writes the file atomically and durably (without `faces`).
    pub fn write(&self, path: &Path) -> Result<()> {
        self.write_with_faces(path, &[])
    }

    /// Writes the file atomically and durably, with the mesh's `faces` (int64 `[F, 3]`) unless
    /// `faces` is empty, so a reader can draw a running run before `deformation.npz` exists.
    pub fn write_with_faces(&self, path: &Path, faces: &[[u32; 3]]) -> Result<()> {
        let k = self.iterations.len();
        let faces = (!faces.is_empty())
            .then(|| {
                let flat = faces.iter().flatten().map(|&i| i64::from(i)).collect();
                NpyArray::new(vec![faces.len(), 3], NpyData::I64(flat)).map_err(Error::Invalid)
            })
            .transpose()?;
        let iterations = NpyArray::new(vec![k], NpyData::I64(self.iterations.clone()))
            .map_err(Error::Invalid)?;
        let x = NpyArray::new(vec![k, self.vertices, 3], NpyData::F32(self.x.clone()))
            .map_err(Error::Invalid)?;
        rundir::durable::replace_with(path, |tmp| -> Result<()> {
            let mut w = NpzWriter::create(tmp)?;
            w.add("iterations", &iterations)?;
            w.add("x", &x)?;
            if let Some(f) = &faces {
                w.add("faces", f)?;
            }
            w.finish()?;
            Ok(())
        })
        .with_context(|| format!("cannot write {}", path.display()))
    }
}

/// Takes the snapshots of a running loop (see the module documentation).
pub struct SnapshotRecorder<'a> {
    path: PathBuf,
    darap: &'a Darap,
    /// The mesh's faces, written beside the positions.
    faces: Vec<[u32; 3]>,
    every: u64,
    last_iteration: u64,
    snapshots: Snapshots,
}

impl std::fmt::Debug for SnapshotRecorder<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SnapshotRecorder")
            .field("path", &self.path)
            .field("every", &self.every)
            .field("entries", &self.snapshots.len())
            .finish_non_exhaustive()
    }
}

/// dARAP positions of `x` rounded to f32 (what `deformation.npz` saves), as f32.
fn deformed_f32(darap: &Darap, x: &[[f64; 3]]) -> Result<Vec<f32>> {
    let x_saved: Vec<[f64; 3]> = x.iter().map(|p| p.map(|c| f64::from(c as f32))).collect();
    let d = darap
        .forward(&x_saved)
        .context("dARAP forward (snapshot)")?;
    Ok(d.positions
        .iter()
        .flat_map(|p| p.map(|c| c as f32))
        .collect())
}

impl<'a> SnapshotRecorder<'a> {
    /// Starts recording into `path` for a loop at `iteration` with targets `x` that ends at
    /// `last_iteration`, one entry every `every` iterations (0: none, but a resume still drops the
    /// entries after `iteration` from an existing file).
    ///
    /// Fresh start (`iteration == 0`): the file is (re)written with entry 0. Resume: the existing
    /// file's entries after `iteration` are dropped; a file that is missing, unreadable or of
    /// another mesh is started again from entry 0 (the rest normals) and the checkpoint's
    /// `iteration`, and the returned warning says so. Returns `None` with `every == 0` on a fresh
    /// start.
    pub fn start(
        path: PathBuf,
        darap: &'a Darap,
        faces: &[[u32; 3]],
        every: u64,
        iteration: u64,
        x: &[[f64; 3]],
        last_iteration: u64,
    ) -> Result<(Option<Self>, Option<String>)> {
        let vertices = darap.num_vertices();
        let fresh = |its: &[u64], xs: &[&[[f64; 3]]]| -> Result<Snapshots> {
            let mut s = Snapshots {
                iterations: Vec::new(),
                vertices,
                x: Vec::new(),
            };
            for (&i, x) in its.iter().zip(xs) {
                s.iterations.push(
                    i64::try_from(i)
                        .map_err(|_| Error::Invalid(format!("iteration {i} out of range")))?,
                );
                s.x.extend(deformed_f32(darap, x)?);
            }
            Ok(s)
        };
        let mut warning = None;
        let snapshots = if iteration == 0 {
            if every == 0 {
                return Ok((None, None));
            }
            fresh(&[0], &[x])?
        } else {
            let existing = if path.exists() || every > 0 {
                Some(Snapshots::read(&path).and_then(|s| {
                    if s.vertices == vertices {
                        Ok(s)
                    } else {
                        invalid!("{} vertices, the mesh has {vertices}", s.vertices)
                    }
                }))
            } else {
                None
            };
            match existing {
                None => return Ok((None, None)),
                Some(Ok(mut s)) => {
                    let before = s.len();
                    s.truncate_after(iteration);
                    if s.len() != before {
                        s.write(&path)?;
                    }
                    s
                }
                Some(Err(e)) => {
                    warning = Some(format!(
                        "{} could not be continued ({e:#}); the replay restarts with iterations 0 and {iteration}",
                        path.display()
                    ));
                    let s = fresh(&[0, iteration], &[darap.rest_normals(), x])?;
                    if every > 0 {
                        s.write(&path)?;
                    }
                    s
                }
            }
        };
        if every == 0 {
            return Ok((None, warning));
        }
        if iteration == 0 {
            snapshots.write_with_faces(&path, faces)?;
        }
        Ok((
            Some(Self {
                path,
                darap,
                faces: faces.to_vec(),
                every,
                last_iteration,
                snapshots,
            }),
            warning,
        ))
    }

    /// After iteration `iteration` with targets `x`: adds an entry and rewrites the file when one
    /// is due (a multiple of `every`, or the last iteration) and newer than the last entry.
    pub fn after_iteration(&mut self, iteration: u64, x: &[[f64; 3]]) -> Result<()> {
        let due = iteration.is_multiple_of(self.every) || iteration == self.last_iteration;
        let newer = self
            .snapshots
            .iterations
            .last()
            .is_none_or(|&l| u64::try_from(l).is_ok_and(|l| iteration > l));
        if !(due && newer) {
            return Ok(());
        }
        self.snapshots.iterations.push(
            i64::try_from(iteration)
                .map_err(|_| Error::Invalid(format!("iteration {iteration} out of range")))?,
        );
        self.snapshots.x.extend(deformed_f32(self.darap, x)?);
        self.snapshots.write_with_faces(&self.path, &self.faces)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Snapshots {
        Snapshots {
            iterations: vec![0, 50, 100, 120],
            vertices: 2,
            x: (0..24).map(|i| i as f32 * 0.5).collect(),
        }
    }

    #[test]
    fn round_trips_and_truncates_after_an_iteration() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join(FILE_NAME);
        let s = sample();
        s.write(&path).unwrap_or_else(|e| panic!("{e:#}"));
        let back = Snapshots::read(&path).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(back, s);
        assert_eq!(
            back.positions(1),
            Some(vec![[3.0, 3.5, 4.0], [4.5, 5.0, 5.5]])
        );
        assert_eq!(back.positions(4), None);
        // No temporary file is left next to it.
        let names: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap_or_else(|e| panic!("{e}"))
            .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
            .collect();
        assert_eq!(names, vec![FILE_NAME.to_string()]);
        let mut t = back;
        t.truncate_after(100);
        assert_eq!(t.iterations, vec![0, 50, 100]);
        assert_eq!(t.x.len(), 3 * 2 * 3);
        t.truncate_after(49);
        assert_eq!(t.iterations, vec![0]);
    }

    #[test]
    fn reading_refuses_wrong_dtypes_shapes_and_orders() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join(FILE_NAME);
        let its = |v: Vec<i64>| {
            NpyArray::new(vec![v.len()], NpyData::I64(v)).unwrap_or_else(|e| panic!("{e}"))
        };
        let x = |k: usize| {
            NpyArray::new(vec![k, 1, 3], NpyData::F32(vec![0.0; 3 * k]))
                .unwrap_or_else(|e| panic!("{e}"))
        };
        let cases = [
            (its(vec![0, 5]), x(3), "position sets"),
            (its(vec![0, 5, 5]), x(3), "increase"),
            (
                its(vec![0]),
                NpyArray::new(vec![1, 1, 3], NpyData::F64(vec![0.0; 3]))
                    .unwrap_or_else(|e| panic!("{e}")),
                "float32",
            ),
            (
                NpyArray::new(vec![1], NpyData::I32(vec![0])).unwrap_or_else(|e| panic!("{e}")),
                x(1),
                "int64",
            ),
        ];
        for (i, x, what) in cases {
            npy::npz::write_npz(&path, [("iterations", &i), ("x", &x)])
                .unwrap_or_else(|e| panic!("{e}"));
            let e = Snapshots::read(&path)
                .err()
                .map(|e| format!("{e:#}"))
                .unwrap_or_default();
            assert!(e.contains(what), "{what}: {e}");
        }
    }
}
