//! The reference's saved-deformation `.npz` (spec §8), read and written with the `npy` crate, and
//! made ready to re-apply ([`SavedDeformation::ready_layer`], [`ReadyLayer`]): what `apply`, the
//! viewer and the examples share.

use std::path::{Path, PathBuf};

use serde_json::Value;

use darap::{Darap, DarapError, DarapOptions, PostProcess, RotationRule};
use mesh_core::TriMesh;
use npy::npz::{NpzReader, NpzWriter};
use npy::{NpyArray, NpyData, NpyError};

/// Why a saved deformation cannot be read or written.
#[derive(Debug, thiserror::Error)]
pub enum SavedError {
    /// The file, the archive or one of its arrays (the message names the file and the key).
    #[error(transparent)]
    Npy(#[from] NpyError),
    /// Two arrays that must agree in length do not.
    #[error("{what}: expected {expected} entries, got {got}")]
    LengthMismatch {
        /// Which array.
        what: &'static str,
        /// The expected length.
        expected: usize,
        /// The actual length.
        got: usize,
    },
    /// [`SavedDeformation::set_extra`] was asked to set one of the five standard keys.
    #[error("`{0}` is a standard key of the saved-deformation format, not an extra")]
    StandardKey(String),
    /// The file's `normalize_target_normals` is false (re-applying supports normalized target
    /// normals only).
    #[error(
        "{}: `normalize_target_normals` is false; only normalized target normals are supported",
        path.display()
    )]
    NotNormalized {
        /// The file.
        path: PathBuf,
    },
    /// The extra key `rotation_rule` is not a string, is empty, or names no rule.
    #[error("{message}")]
    RotationRule {
        /// What is wrong, naming the key.
        message: &'static str,
        /// The unknown name, when there is one.
        #[source]
        source: Option<darap::UnknownName>,
    },
    /// The extra key `region_weights` is not one f64 per vertex.
    #[error("{}: `region_weights` must hold one f64 per vertex ({vertices})", path.display())]
    RegionWeights {
        /// The file.
        path: PathBuf,
        /// The number of vertices.
        vertices: usize,
    },
    /// The dARAP layer cannot be built on the saved rest mesh.
    #[error("cannot build the dARAP layer for {}", path.display())]
    Layer {
        /// The file.
        path: PathBuf,
        /// Why.
        source: DarapError,
    },
    /// The saved region weights are refused by the layer.
    #[error("{}: invalid region_weights", path.display())]
    InvalidRegion {
        /// The file.
        path: PathBuf,
        /// Why.
        source: DarapError,
    },
    /// The extra key `to_input_frame` is not a finite, invertible 4×4 affine matrix, or
    /// `output_frame` / `up` names no frame or axis.
    #[error("{key} of the saved file: {message}")]
    Frame {
        /// The key.
        key: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The layer refused a region (see [`ReadyLayer::set_region`]).
    #[error(transparent)]
    Darap(#[from] DarapError),
}

/// Which vertices may rotate when a saved deformation is re-applied ([`ReadyLayer::set_region`]).
#[derive(Clone, Debug, PartialEq)]
pub enum Region {
    /// Every vertex (the saved region ignored).
    Whole,
    /// The region the run saved (`region_weights`), else every vertex.
    Saved,
    /// The caller's selection: `free[v]` for each vertex of the saved file that may rotate,
    /// feathered by `feather` rings (None: the saved run's `region_feather`, else 0) into weights
    /// ([`mesh_core::region::feather_weights`]).
    Free {
        /// One flag per vertex, in the saved file's order.
        free: Vec<bool>,
        /// Feather rings.
        feather: Option<u32>,
    },
}

/// A saved deformation ready to re-apply (spec §8 "apply"): the rest mesh (the saved f32 `verts`
/// as f64, normalized to the side-2 cube: the frame of every result), the saved target normals,
/// and the prefactored dARAP layer (`spokes_and_rims_mine`, first vertex of each component
/// pinned, [`PostProcess::RecenterRescale`]). λ changes without refactoring ([`Self::at_lambda`]).
#[derive(Debug)]
pub struct ReadyLayer {
    /// The rest mesh, side-2 cube frame.
    pub rest: TriMesh,
    /// The saved target normals (raw, as f64; the layer normalizes them).
    pub targets: Vec<[f64; 3]>,
    /// The layer.
    pub layer: Darap,
}

impl ReadyLayer {
    /// Sets the region of the layer (see [`Region`]); `saved` is the deformation the layer was
    /// built from and `path` names it in errors.
    pub fn set_region(
        &mut self,
        saved: &SavedDeformation,
        path: &Path,
        region: Region,
    ) -> Result<(), SavedError> {
        let weights = match region {
            Region::Whole => None,
            Region::Saved => saved.region_weights(path)?,
            Region::Free { free, feather } => {
                let rings = feather.or(saved.region_feather()).unwrap_or(0) as usize;
                Some(mesh_core::region::feather_weights(
                    &free,
                    &saved.faces,
                    rings,
                ))
            }
        };
        if let Some(weights) = weights {
            self.layer.set_region_weights(Some(weights))?;
        }
        Ok(())
    }

    /// The saved targets deformed at strength `lambda` (the layer keeps `lambda`).
    pub fn at_lambda(&mut self, lambda: f64) -> Result<darap::Deformation, DarapError> {
        self.layer.set_lambda(lambda);
        self.layer.forward(&self.targets)
    }

    /// The saved targets at λ = `lambda`, pushed `strength` times as far by the strength control
    /// ([`Darap::forward_at_strength`]: the `procrustes` rule's increment from λ to
    /// `strength·λ` on top of the result at λ; `docs/strength.md`). At `strength = 1` it is
    /// [`Self::at_lambda`]`(lambda)` exactly. The layer keeps `lambda`.
    pub fn at_strength(
        &mut self,
        lambda: f64,
        strength: f64,
    ) -> Result<darap::Deformation, DarapError> {
        self.layer.set_lambda(lambda);
        self.layer.forward_at_strength(&self.targets, strength)
    }
}

/// Value of the extra key `format_version` that we add to files we write.
pub const FORMAT_VERSION: i64 = 1;

/// A saved deformation in the reference's format (spec §8):
///
/// | key | dtype, shape | meaning |
/// |---|---|---|
/// | `verts` | `<f4` (V, 3) | rest mesh after side-2 cube normalization |
/// | `faces` | `<i8` (F, 3) | CCW triangles |
/// | `verts_normals` | `<f4` (V, 3) | the raw optimized target normals x (not unit length) |
/// | `deform_by_csd_cfg` | `<U…` 0-d | JSON: `local_step_procrustes.{lamb, normalize_target_normals}`, `arap_energy_type`, `solve_method`, `pin_first_vertex` |
/// | `dataset_cfg` | `<U…` 0-d | JSON describing the input |
///
/// Any other keys (ours: `format_version`, `seed`, `rotation_rule`, …) up to [`MAX_EXTRA_BYTES`]
/// in total are kept in [`extra`] in file order (the ones beyond are skipped unread) and written back after the five standard keys; readers that ignore unknown keys
/// (the reference) are unaffected.
///
/// [`extra`]: SavedDeformation::extra
#[derive(Clone, Debug, PartialEq)]
pub struct SavedDeformation {
    /// Rest vertices (side-2 cube normalized), f32.
    pub verts: Vec<[f32; 3]>,
    /// Faces (stored as i64 on disk).
    pub faces: Vec<[u32; 3]>,
    /// Raw optimized target normals, one per vertex.
    pub verts_normals: Vec<[f32; 3]>,
    /// JSON text of the optimization config.
    pub deform_by_csd_cfg: String,
    /// JSON text of the dataset config.
    pub dataset_cfg: String,
    /// Every other array in the file, in file order.
    pub extra: Vec<(String, NpyArray)>,
}

/// Extra (non-standard) entries are read, in file order, while their declared (uncompressed)
/// sizes add up to at most this; the others are skipped unread.
pub const MAX_EXTRA_BYTES: u64 = 1 << 24;

const STANDARD_KEYS: [&str; 5] = [
    "verts",
    "faces",
    "verts_normals",
    "deform_by_csd_cfg",
    "dataset_cfg",
];

impl SavedDeformation {
    /// Reads a saved deformation. `verts`/`verts_normals` may be f32 or f64 (converted to f32),
    /// `faces` any integer dtype; shapes must be (V, 3), (F, 3), (V, 3), and face indices must be
    /// below V.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, SavedError> {
        let r = NpzReader::open(path)?;
        let verts = r.rows3_f32("verts")?;
        let faces = r.rows3_u32("faces")?;
        let verts_normals = r.rows3_f32("verts_normals")?;
        let deform_by_csd_cfg = r.string("deform_by_csd_cfg")?;
        let dataset_cfg = r.string("dataset_cfg")?;
        let npy_err = |key: &str, message: String| NpyError::Array {
            path: r.path().to_path_buf(),
            key: key.into(),
            message,
        };
        if verts_normals.len() != verts.len() {
            return Err(SavedError::from(npy_err(
                "verts_normals",
                format!(
                    "has {} rows but `verts` has {}",
                    verts_normals.len(),
                    verts.len()
                ),
            )));
        }
        if let Some((fi, f)) = faces
            .iter()
            .enumerate()
            .find(|(_, f)| f.iter().any(|&v| v as usize >= verts.len()))
        {
            return Err(SavedError::from(npy_err(
                "faces",
                format!(
                    "face {fi} = {f:?} refers to a vertex beyond the {} in `verts`",
                    verts.len()
                ),
            )));
        }
        // Extra keys are metadata (ours are a few bytes); large ones are not loaded at all, so an
        // unrelated big entry cannot make reading cost memory.
        // The bound is on their total: many entries each under it would add up without one.
        let mut extra = Vec::new();
        let mut extra_bytes = 0u64;
        for key in r.keys() {
            if STANDARD_KEYS.contains(&key) {
                continue;
            }
            let Some(size) = r
                .declared_size(key)
                .filter(|&s| s <= MAX_EXTRA_BYTES - extra_bytes)
            else {
                continue;
            };
            extra_bytes += size;
            extra.push((key.to_string(), r.require(key)?.clone()));
        }
        Ok(Self {
            verts,
            faces,
            verts_normals,
            deform_by_csd_cfg,
            dataset_cfg,
            extra,
        })
    }

    /// Writes the five standard keys (in the order above), then [`Self::extra`].
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), SavedError> {
        if self.verts_normals.len() != self.verts.len() {
            return Err(SavedError::LengthMismatch {
                what: "verts_normals (one per vertex)",
                expected: self.verts.len(),
                got: self.verts_normals.len(),
            });
        }
        let mut w = NpzWriter::create(path)?;
        w.add("verts", &NpyArray::f32_rows3(&self.verts))?;
        w.add("faces", &NpyArray::i64_rows3(&self.faces))?;
        w.add("verts_normals", &NpyArray::f32_rows3(&self.verts_normals))?;
        w.add(
            "deform_by_csd_cfg",
            &NpyArray::scalar_str(&self.deform_by_csd_cfg),
        )?;
        w.add("dataset_cfg", &NpyArray::scalar_str(&self.dataset_cfg))?;
        for (k, a) in &self.extra {
            w.add(k, a)?;
        }
        Ok(w.finish()?)
    }

    /// The extra array under `key`.
    pub fn extra(&self, key: &str) -> Option<&NpyArray> {
        self.extra.iter().find(|(k, _)| k == key).map(|(_, a)| a)
    }

    /// Sets (replacing) the extra array under `key`. Standard keys cannot be set this way.
    pub fn set_extra(&mut self, key: &str, array: NpyArray) -> Result<(), SavedError> {
        if STANDARD_KEYS.contains(&key) {
            return Err(SavedError::StandardKey(key.to_string()));
        }
        match self.extra.iter_mut().find(|(k, _)| k == key) {
            Some(slot) => slot.1 = array,
            None => self.extra.push((key.to_string(), array)),
        }
        Ok(())
    }

    /// The parsed `deform_by_csd_cfg` JSON (`Value::Null` if it is not valid JSON).
    pub fn csd_cfg(&self) -> Value {
        serde_json::from_str(&self.deform_by_csd_cfg).unwrap_or(Value::Null)
    }

    /// `local_step_procrustes.lamb`: the λ used in training, if recorded as a finite number ≥ 0
    /// ([`Self::recorded_lambda`] says what is wrong otherwise).
    pub fn lambda(&self) -> Option<f64> {
        self.recorded_lambda().ok()
    }

    /// The recorded λ, or why there is none to use: `deform_by_csd_cfg` is not valid JSON, it has
    /// no `local_step_procrustes.lamb`, or that is not a finite number ≥ 0 (the message names
    /// the value; the caller names the file).
    pub fn recorded_lambda(&self) -> std::result::Result<f64, String> {
        let cfg = self.csd_cfg();
        if cfg.is_null() {
            return Err(format!(
                "`deform_by_csd_cfg` is not valid JSON ({:?}…), so the λ it should record cannot \
                 be read",
                self.deform_by_csd_cfg.chars().take(60).collect::<String>()
            ));
        }
        let Some(lamb) = cfg.get("local_step_procrustes").and_then(|l| l.get("lamb")) else {
            return Err("it records no λ (local_step_procrustes.lamb)".into());
        };
        match lamb.as_f64() {
            Some(l) if l.is_finite() && l >= 0.0 => Ok(l),
            _ => Err(format!(
                "the recorded λ (local_step_procrustes.lamb = {lamb}) is not a finite number ≥ 0"
            )),
        }
    }

    /// `pin_first_vertex` (default `true`).
    pub fn pin_first_vertex(&self) -> bool {
        self.csd_cfg()
            .get("pin_first_vertex")
            .and_then(Value::as_bool)
            .unwrap_or(true)
    }

    /// `local_step_procrustes.normalize_target_normals` (default `true`, as the reference).
    pub fn normalize_target_normals(&self) -> bool {
        self.csd_cfg()
            .get("local_step_procrustes")
            .and_then(|v| v.get("normalize_target_normals"))
            .and_then(Value::as_bool)
            .unwrap_or(true)
    }

    /// `arap_energy_type` (e.g. `"spokes_and_rims_mine"`), if recorded.
    pub fn arap_energy_type(&self) -> Option<String> {
        self.csd_cfg()
            .get("arap_energy_type")
            .and_then(Value::as_str)
            .map(str::to_owned)
    }

    /// `solve_method` (e.g. `"arap"`), if recorded.
    pub fn solve_method(&self) -> Option<String> {
        self.csd_cfg()
            .get("solve_method")
            .and_then(Value::as_str)
            .map(str::to_owned)
    }

    /// The extra key `rotation_rule` (the rule the run used), if recorded.
    pub fn rotation_rule(&self) -> Result<Option<RotationRule>, SavedError> {
        let Some(array) = self.extra("rotation_rule") else {
            return Ok(None);
        };
        let bad = |message, source| SavedError::RotationRule { message, source };
        let NpyData::Unicode(v) = &array.data else {
            return Err(bad("key `rotation_rule` is not a string", None));
        };
        match v.first().map(|s| s.trim().to_ascii_lowercase()) {
            Some(name) => name
                .parse()
                .map(Some)
                .map_err(|e| bad("key `rotation_rule` of the saved file", Some(e))),
            None => Err(bad("key `rotation_rule` of the saved file is empty", None)),
        }
    }

    /// The region a localized run saved (`region_weights`: one f64 per vertex, 1 free … 0 held at
    /// the identity), if any; `path` names the file in errors.
    pub fn region_weights(&self, path: &Path) -> Result<Option<Vec<f64>>, SavedError> {
        let n = self.verts.len();
        match self.extra("region_weights").map(|a| &a.data) {
            None => Ok(None),
            Some(NpyData::F64(w)) if w.len() == n => Ok(Some(w.clone())),
            Some(_) => Err(SavedError::RegionWeights {
                path: path.to_path_buf(),
                vertices: n,
            }),
        }
    }

    /// The feather rings a localized run saved (`region_feather`), if any (a negative or
    /// oversized value reads as 0).
    pub fn region_feather(&self) -> Option<u32> {
        match self.extra("region_feather").map(|a| &a.data) {
            Some(NpyData::I64(v)) => v.first().map(|&k| u32::try_from(k).unwrap_or(0)),
            _ => None,
        }
    }

    /// Records the frames of a run ([`crate::frame`]): `to_input_frame` (`<f8` (4, 4), the map
    /// from the frame of `verts` to the input file's coordinates), `output_frame` (the frame the
    /// run wrote its `mesh.*` in: `input` or `normalized`) and `up` (the input's up axis).
    pub fn set_input_frame(
        &mut self,
        frame: &crate::frame::InputFrame,
        output: crate::frame::OutputFrame,
        up: crate::frame::UpAxis,
    ) -> Result<(), SavedError> {
        let matrix = NpyArray::new(vec![4, 4], NpyData::F64(frame.to_matrix().to_vec())).map_err(
            |message| SavedError::Frame {
                key: "to_input_frame",
                message,
            },
        )?;
        self.set_extra("to_input_frame", matrix)?;
        self.set_extra("output_frame", NpyArray::scalar_str(output.name()))?;
        self.set_extra("up", NpyArray::scalar_str(up.name()))
    }

    /// The extra key `to_input_frame` (None: a file without it, e.g. the reference's, whose
    /// input frame is unknown).
    pub fn input_frame(&self) -> Result<Option<crate::frame::InputFrame>, SavedError> {
        let Some(array) = self.extra("to_input_frame") else {
            return Ok(None);
        };
        let bad = |message: String| SavedError::Frame {
            key: "to_input_frame",
            message,
        };
        let NpyData::F64(m) = &array.data else {
            return Err(bad("not an array of f64".into()));
        };
        if array.shape != [4, 4] {
            return Err(bad(format!("shape {:?}, expected (4, 4)", array.shape)));
        }
        crate::frame::InputFrame::from_matrix(m)
            .map(Some)
            .map_err(|e| bad(e.to_string()))
    }

    /// A string extra key parsed with `parse` (None when absent).
    fn frame_name<T>(
        &self,
        key: &'static str,
        parse: impl Fn(&str) -> crate::Result<T>,
    ) -> Result<Option<T>, SavedError> {
        let Some(array) = self.extra(key) else {
            return Ok(None);
        };
        let NpyData::Unicode(v) = &array.data else {
            return Err(SavedError::Frame {
                key,
                message: "not a string".into(),
            });
        };
        let name = v.first().map(String::as_str).unwrap_or("");
        parse(name).map(Some).map_err(|e| SavedError::Frame {
            key,
            message: e.to_string(),
        })
    }

    /// The extra key `output_frame`: the frame of the run's `mesh.*` files. A file without it
    /// (written before output frames existed, or by the reference) had them in the normalized
    /// frame.
    pub fn output_frame(&self) -> Result<crate::frame::OutputFrame, SavedError> {
        Ok(self
            .frame_name("output_frame", str::parse)?
            .unwrap_or(crate::frame::OutputFrame::Normalized))
    }

    /// The extra key `up`: the input's up axis (+y when absent).
    pub fn up(&self) -> Result<crate::frame::UpAxis, SavedError> {
        Ok(self.frame_name("up", str::parse)?.unwrap_or_default())
    }

    /// The rest mesh's positions in the frame of every result: the saved f32 `verts` as f64,
    /// normalized to the side-2 cube.
    pub fn rest_positions(&self) -> Vec<[f64; 3]> {
        let mut rest = self.verts_f64();
        mesh_core::normalize::side2_cube(&mut rest);
        rest
    }

    /// The dARAP layer that re-applies this deformation, over the whole mesh (set a region with
    /// [`ReadyLayer::set_region`]): built at strength `lambda` with `rotation_rule` (None: the
    /// file's `rotation_rule` key, else `gis`). `path` names the file in errors. Refused when the
    /// file's `normalize_target_normals` is false.
    pub fn ready_layer(
        &self,
        path: &Path,
        lambda: f64,
        rotation_rule: Option<RotationRule>,
    ) -> Result<ReadyLayer, SavedError> {
        if !self.normalize_target_normals() {
            return Err(SavedError::NotNormalized {
                path: path.to_path_buf(),
            });
        }
        let rule = match rotation_rule {
            Some(r) => r,
            None => self.rotation_rule()?.unwrap_or_default(),
        };
        let rest = self.rest_positions();
        let options = DarapOptions {
            lambda,
            rotation_rule: rule,
            post_process: PostProcess::RecenterRescale,
        };
        let layer =
            Darap::new(&rest, &self.faces, options).map_err(|source| SavedError::Layer {
                path: path.to_path_buf(),
                source,
            })?;
        Ok(ReadyLayer {
            rest: TriMesh::new(rest, self.faces.clone()),
            targets: self.verts_normals_f64(),
            layer,
        })
    }

    /// [`Self::ready_layer`] as the run saved it: at the recorded λ (0 when none is recorded),
    /// with the file's rotation rule and its region ([`Region::Saved`]).
    pub fn ready_layer_as_saved(&self, path: &Path) -> Result<ReadyLayer, SavedError> {
        let mut ready = self.ready_layer(path, self.lambda().unwrap_or(0.0), None)?;
        ready
            .set_region(self, path, Region::Saved)
            .map_err(|e| match e {
                SavedError::Darap(source) => SavedError::InvalidRegion {
                    path: path.to_path_buf(),
                    source,
                },
                e => e,
            })?;
        Ok(ready)
    }

    /// Rest vertices as f64.
    pub fn verts_f64(&self) -> Vec<[f64; 3]> {
        self.verts
            .iter()
            .map(|v| [f64::from(v[0]), f64::from(v[1]), f64::from(v[2])])
            .collect()
    }

    /// Target normals as f64.
    pub fn verts_normals_f64(&self) -> Vec<[f64; 3]> {
        self.verts_normals
            .iter()
            .map(|v| [f64::from(v[0]), f64::from(v[1]), f64::from(v[2])])
            .collect()
    }
}
