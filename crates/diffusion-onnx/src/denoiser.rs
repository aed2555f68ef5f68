//! IF's stage-I / stage-II UNets as ONNX sessions, behind [`csd::Denoiser`].

use std::borrow::Cow;

use ort::session::{Session, SessionInputValue};

use crate::OnnxError;
use crate::manifest::{Dtype, ModelDir, Stage, StageManifest};
use crate::runtime::{SessionOptions, open_session};
use crate::session::{Kind, check_signature, float_input, float_output, int_input};

/// One IF UNet. Inputs: `sample` `(N, C_in, H, W)` f32 NCHW, one timestep, one embedding (and for
/// stage II one noise-level class label) per sample; output `(N, C_out, H, W)` f32 (ε in channels
/// 0..3, learned variance after). An fp16 model gets its float inputs rounded to f16 and its output
/// widened back to f32; everything outside the session is f32.
///
/// The whole batch (csd's conditional and unconditional halves, 2B samples) runs in one session call,
/// or in calls of at most [`SessionOptions::max_batch`] samples each.
pub struct OnnxDenoiser {
    session: Session,
    max_batch: Option<usize>,
    stage: Stage,
    spec: StageManifest,
    embedding_shape: [usize; 2],
    label: String,
    file: std::path::PathBuf,
}

impl std::fmt::Debug for OnnxDenoiser {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnnxDenoiser")
            .field("stage", &self.stage)
            .field("dtype", &self.spec.dtype)
            .field("embedding_shape", &self.embedding_shape)
            .finish_non_exhaustive()
    }
}

impl OnnxDenoiser {
    /// Opens one stage of a model directory and checks the graph against the manifest.
    pub fn open(
        model: &ModelDir,
        stage: Stage,
        options: &SessionOptions,
    ) -> Result<Self, OnnxError> {
        let label = format!("{} UNet", stage.key());
        let spec = model
            .stage(stage)
            .ok_or_else(|| OnnxError::Manifest {
                dir: model.root().to_path_buf(),
                message: format!(
                    "no [{}] in manifest.toml; export stage II too, or run with stage-II weight 0",
                    stage.key()
                ),
            })?
            .clone();
        let file = model.path_of(&spec.file);
        if options.max_batch == Some(0) {
            return Err(OnnxError::Shape {
                model: label,
                message: "max_batch = 0: at least one sample per session call".into(),
            });
        }
        let session = open_session(&file, options, &label)?;
        let mut inputs = vec![
            (spec.sample.as_str(), Kind::Float, 4),
            (spec.timestep.as_str(), Kind::Int64, 1),
            (spec.encoder_hidden_states.as_str(), Kind::Float, 3),
        ];
        if let Some(c) = &spec.class_labels {
            inputs.push((c.as_str(), Kind::Int64, 1));
        }
        check_signature(
            &session,
            &label,
            spec.dtype,
            &inputs,
            (&spec.output, Kind::Float, 4),
        )?;
        let e = &model.manifest().embeddings;
        Ok(Self {
            session,
            max_batch: options.max_batch,
            stage,
            spec,
            embedding_shape: [e.tokens, e.dim],
            label,
            file,
        })
    }

    /// Which stage.
    pub fn stage(&self) -> Stage {
        self.stage
    }

    /// The model's float type.
    pub fn dtype(&self) -> Dtype {
        self.spec.dtype
    }

    /// The stage's manifest entry.
    pub fn spec(&self) -> &StageManifest {
        &self.spec
    }

    fn shape_error(&self, message: String) -> OnnxError {
        OnnxError::Shape {
            model: self.label.clone(),
            message,
        }
    }

    /// Runs the UNet once; see the type's docs for layouts.
    pub fn run(
        &mut self,
        sample: &csd::Tensor,
        timesteps: &[i64],
        embeddings: &[&csd::Embedding],
        class_labels: Option<&[i64]>,
    ) -> Result<csd::Tensor, OnnxError> {
        let &[n, c, h, w] = sample.shape.as_slice() else {
            return Err(self.shape_error(format!(
                "sample must be (N, C, H, W), got shape {:?}",
                sample.shape
            )));
        };
        if n == 0 || h == 0 || w == 0 {
            return Err(self.shape_error(format!("empty sample of shape {:?}", sample.shape)));
        }
        if c != self.spec.in_channels {
            return Err(self.shape_error(format!(
                "sample has {c} channels, this UNet takes {} (shape {:?})",
                self.spec.in_channels, sample.shape
            )));
        }
        if sample.data.len() != n * c * h * w {
            return Err(self.shape_error(format!(
                "sample of shape {:?} has {} values",
                sample.shape,
                sample.data.len()
            )));
        }
        if timesteps.len() != n || embeddings.len() != n {
            return Err(self.shape_error(format!(
                "{n} samples need {n} timesteps and {n} embeddings, got {} and {}",
                timesteps.len(),
                embeddings.len()
            )));
        }
        let [tokens, dim] = self.embedding_shape;
        let mut text = Vec::with_capacity(n * tokens * dim);
        for (i, e) in embeddings.iter().enumerate() {
            if e.shape != [tokens, dim] || e.data.len() != tokens * dim {
                return Err(self.shape_error(format!(
                    "embedding {i} has shape {:?} ({} values), this model takes ({tokens}, {dim}); embeddings from a \
                     different text encoder or cache?",
                    e.shape,
                    e.data.len()
                )));
            }
            text.extend_from_slice(&e.data);
        }
        let labels = match (&self.spec.class_labels, class_labels) {
            (Some(_), Some(l)) if l.len() == n => Some(l.to_vec()),
            (Some(_), Some(l)) => {
                return Err(self.shape_error(format!(
                    "{n} samples need {n} class labels, got {}",
                    l.len()
                )));
            }
            (Some(_), None) => {
                return Err(self.shape_error("stage II needs noise-level class labels".into()));
            }
            (None, Some(_)) => return Err(self.shape_error("stage I takes no class labels".into())),
            (None, None) => None,
        };
        let chunk = self.max_batch.unwrap_or(n).clamp(1, n);
        let per_sample = c * h * w;
        let mut data = Vec::new();
        for start in (0..n).step_by(chunk) {
            let end = (start + chunk).min(n);
            let out = self.run_session(
                [end - start, c, h, w],
                sample.data[start * per_sample..end * per_sample].to_vec(),
                &timesteps[start..end],
                text[start * tokens * dim..end * tokens * dim].to_vec(),
                labels.as_ref().map(|l| &l[start..end]),
            )?;
            if data.is_empty() {
                data = out;
                data.reserve((n - end) * self.spec.out_channels * h * w);
            } else {
                data.extend_from_slice(&out);
            }
        }
        Ok(csd::Tensor {
            shape: vec![n, self.spec.out_channels, h, w],
            data,
        })
    }

    /// One session call on `m = shape[0]` samples whose inputs are already checked; returns the
    /// output values `(m, C_out, H, W)` after checking their shape.
    fn run_session(
        &mut self,
        shape: [usize; 4],
        sample: Vec<f32>,
        timesteps: &[i64],
        text: Vec<f32>,
        labels: Option<&[i64]>,
    ) -> Result<Vec<f32>, OnnxError> {
        let [m, c, h, w] = shape;
        let [tokens, dim] = self.embedding_shape;
        let dtype = self.spec.dtype;
        let mut inputs: Vec<(Cow<'_, str>, SessionInputValue<'_>)> = vec![
            (
                Cow::from(self.spec.sample.as_str()),
                float_input(dtype, vec![m, c, h, w], sample)?.into(),
            ),
            (
                Cow::from(self.spec.timestep.as_str()),
                int_input(vec![m], timesteps.to_vec())?.into(),
            ),
            (
                Cow::from(self.spec.encoder_hidden_states.as_str()),
                float_input(dtype, vec![m, tokens, dim], text)?.into(),
            ),
        ];
        if let (Some(name), Some(l)) = (&self.spec.class_labels, labels) {
            inputs.push((
                Cow::from(name.as_str()),
                int_input(vec![m], l.to_vec())?.into(),
            ));
        }
        let label = self.label.clone();
        let outputs = self
            .session
            .run(inputs)
            .map_err(|e| OnnxError::ort(format!("running the {label}"), e))?;
        let value = outputs
            .get(&self.spec.output)
            .ok_or_else(|| OnnxError::Signature {
                model: label.clone(),
                message: format!("output `{}` missing from the results", self.spec.output),
            })?;
        let (out_shape, data) = float_output(value, dtype, &format!("the {label} output"))?;
        if out_shape != [m, self.spec.out_channels, h, w] {
            return Err(OnnxError::Shape {
                model: label,
                message: format!(
                    "output shape {out_shape:?}, expected [{m}, {}, {h}, {w}]",
                    self.spec.out_channels
                ),
            });
        }
        Ok(data)
    }
}

impl csd::Denoiser for OnnxDenoiser {
    /// E.g. "stage1 UNet, models/if/unet_stage1.onnx (fp16)".
    fn describe(&self) -> String {
        format!(
            "{}, {} ({})",
            self.label,
            self.file.display(),
            self.spec.dtype.as_str()
        )
    }

    fn predict(
        &mut self,
        sample: &csd::Tensor,
        timesteps: &[i64],
        embeddings: &[&csd::Embedding],
        class_labels: Option<&[i64]>,
    ) -> Result<csd::Tensor, csd::GuidanceError> {
        Ok(self.run(sample, timesteps, embeddings, class_labels)?)
    }
}
