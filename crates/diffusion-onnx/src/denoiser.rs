//! IF's stage-I / stage-II UNets as ONNX sessions, behind [`csd::Denoiser`].

use std::borrow::Cow;

use ort::memory::Allocator;
use ort::session::{IoBinding, Session, SessionInputValue};
use ort::value::{DynTensor, Tensor};

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
///
/// With [`SessionOptions::io_binding`] (the default) the calls go through an ONNX Runtime IO binding
/// whose tensors persist between calls ([`Bound`]): each input is written once per call straight
/// into its session tensor (no intermediate `Vec`), the text embeddings only when they changed
/// (compared bit for bit), and the output tensor is preallocated and reused. On the CPU execution
/// provider the bound tensors are the ones the kernels read, so the results are bit-identical to
/// the unbound path (tested); on the CUDA provider ONNX Runtime copies each bound input to the
/// device once when it is bound and the output back once per call.
pub struct OnnxDenoiser {
    session: Session,
    max_batch: Option<usize>,
    io_binding: bool,
    bound: Option<Bound>,
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
            io_binding: options.io_binding,
            bound: None,
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
        for (i, e) in embeddings.iter().enumerate() {
            if e.shape != [tokens, dim] || e.data.len() != tokens * dim {
                return Err(self.shape_error(format!(
                    "embedding {i} has shape {:?} ({} values), this model takes ({tokens}, {dim}); embeddings from a \
                     different text encoder or cache?",
                    e.shape,
                    e.data.len()
                )));
            }
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
            let shape = [end - start, c, h, w];
            let samples = &sample.data[start * per_sample..end * per_sample];
            let labels = labels.as_ref().map(|l| &l[start..end]);
            let out = if self.io_binding {
                self.run_bound(
                    shape,
                    samples,
                    &timesteps[start..end],
                    &embeddings[start..end],
                    labels,
                )?
            } else {
                let mut text = Vec::with_capacity((end - start) * tokens * dim);
                for e in &embeddings[start..end] {
                    text.extend_from_slice(&e.data);
                }
                self.run_session(
                    shape,
                    samples.to_vec(),
                    &timesteps[start..end],
                    text,
                    labels,
                )?
            };
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

    /// One session call through the persistent IO binding ([`Bound`]) on `m = shape[0]` samples
    /// whose inputs are already checked; returns the output values `(m, C_out, H, W)`.
    fn run_bound(
        &mut self,
        shape: [usize; 4],
        sample: &[f32],
        timesteps: &[i64],
        embeddings: &[&csd::Embedding],
        labels: Option<&[i64]>,
    ) -> Result<Vec<f32>, OnnxError> {
        let label = self.label.clone();
        let ort_err =
            |step: &str, e: ort::Error| OnnxError::ort(format!("{step} for the {label}"), e);
        // Reuse the bound tensors while the shape stays; a new shape (first call, a ragged last
        // chunk, another view count) frees the old ones first, then allocates. On an error the
        // binding is dropped and rebuilt by the next call.
        let mut b = match self.bound.take() {
            Some(b) if b.shape == shape => b,
            old => {
                drop(old);
                Bound::new(
                    &self.session,
                    shape,
                    self.spec.out_channels,
                    self.embedding_shape,
                    self.spec.dtype,
                    labels.is_some(),
                )
                .map_err(|e| ort_err("preparing the IO binding", e))?
            }
        };
        let dtype = self.spec.dtype;
        write_floats(&mut b.sample, dtype, sample).map_err(|e| ort_err("writing the sample", e))?;
        b.io.bind_input(self.spec.sample.as_str(), &b.sample)
            .map_err(|e| ort_err("binding the sample", e))?;
        b.timesteps
            .extract_tensor_mut()
            .1
            .copy_from_slice(timesteps);
        b.io.bind_input(self.spec.timestep.as_str(), &b.timesteps)
            .map_err(|e| ort_err("binding the timesteps", e))?;
        let changed = write_embeddings(&mut b.text, dtype, embeddings, !b.text_bound)
            .map_err(|e| ort_err("writing the text embeddings", e))?;
        if changed || !b.text_bound {
            b.io.bind_input(self.spec.encoder_hidden_states.as_str(), &b.text)
                .map_err(|e| ort_err("binding the text embeddings", e))?;
            b.text_bound = true;
        }
        if let (Some(name), Some(t), Some(l)) = (&self.spec.class_labels, b.labels.as_mut(), labels)
        {
            t.extract_tensor_mut().1.copy_from_slice(l);
            b.io.bind_input(name.as_str(), &*t)
                .map_err(|e| ort_err("binding the class labels", e))?;
        }
        if !b.output_bound {
            b.io.bind_output(self.spec.output.as_str(), &mut b.output)
                .map_err(|e| ort_err("binding the output", e))?;
            b.output_bound = true;
        }
        let (out_shape, data) = {
            let outputs = self
                .session
                .run_binding(&b.io)
                .map_err(|e| OnnxError::ort(format!("running the {label}"), e))?;
            let value = outputs
                .get(&self.spec.output)
                .ok_or_else(|| OnnxError::Signature {
                    model: label.clone(),
                    message: format!("output `{}` missing from the results", self.spec.output),
                })?;
            float_output(value, dtype, &format!("the {label} output"))?
        };
        self.bound = Some(b);
        check_output_shape(label, &out_shape, shape, self.spec.out_channels)?;
        Ok(data)
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
        check_output_shape(label, &out_shape, shape, self.spec.out_channels)?;
        Ok(data)
    }
}

/// The persistent IO binding of one input shape: the session's input and output tensors, allocated
/// once by ONNX Runtime's CPU allocator and rewritten in place on every call.
struct Bound {
    io: IoBinding,
    /// `(m, C_in, H, W)` of the sample these tensors hold.
    shape: [usize; 4],
    sample: DynTensor,
    timesteps: Tensor<i64>,
    text: DynTensor,
    /// Whether `text` has been bound since it was allocated (before that its contents are garbage).
    text_bound: bool,
    labels: Option<Tensor<i64>>,
    output: DynTensor,
    output_bound: bool,
}

impl Bound {
    fn new(
        session: &Session,
        [m, c, h, w]: [usize; 4],
        out_channels: usize,
        [tokens, dim]: [usize; 2],
        dtype: Dtype,
        labels: bool,
    ) -> ort::Result<Self> {
        let cpu = Allocator::default();
        let float = |shape: Vec<usize>| -> ort::Result<DynTensor> {
            Ok(match dtype {
                Dtype::Fp32 => Tensor::<f32>::new(&cpu, shape)?.upcast(),
                Dtype::Fp16 => Tensor::<half::f16>::new(&cpu, shape)?.upcast(),
            })
        };
        Ok(Self {
            io: session.create_binding()?,
            shape: [m, c, h, w],
            sample: float(vec![m, c, h, w])?,
            timesteps: Tensor::<i64>::new(&cpu, [m])?,
            text: float(vec![m, tokens, dim])?,
            text_bound: false,
            labels: if labels {
                Some(Tensor::<i64>::new(&cpu, [m])?)
            } else {
                None
            },
            output: float(vec![m, out_channels, h, w])?,
            output_bound: false,
        })
    }
}

/// Writes f32 `values` into a float tensor of `dtype` (rounding to nearest for fp16).
fn write_floats(tensor: &mut DynTensor, dtype: Dtype, values: &[f32]) -> ort::Result<()> {
    match dtype {
        Dtype::Fp32 => tensor
            .try_extract_tensor_mut::<f32>()?
            .1
            .copy_from_slice(values),
        Dtype::Fp16 => {
            for (d, &v) in tensor
                .try_extract_tensor_mut::<half::f16>()?
                .1
                .iter_mut()
                .zip(values)
            {
                *d = half::f16::from_f32(v);
            }
        }
    }
    Ok(())
}

/// Writes the embeddings, one `(tokens, dim)` block per sample, into the text tensor, skipping
/// blocks whose bits are already there unless `all`; returns whether anything was written.
fn write_embeddings(
    tensor: &mut DynTensor,
    dtype: Dtype,
    embeddings: &[&csd::Embedding],
    all: bool,
) -> ort::Result<bool> {
    let mut changed = false;
    match dtype {
        Dtype::Fp32 => {
            let data = tensor.try_extract_tensor_mut::<f32>()?.1;
            let per = data.len() / embeddings.len().max(1);
            for (d, e) in data.chunks_exact_mut(per).zip(embeddings) {
                let same = !all
                    && d.iter()
                        .zip(&e.data)
                        .all(|(a, b)| a.to_bits() == b.to_bits());
                if !same {
                    d.copy_from_slice(&e.data);
                    changed = true;
                }
            }
        }
        Dtype::Fp16 => {
            let data = tensor.try_extract_tensor_mut::<half::f16>()?.1;
            let per = data.len() / embeddings.len().max(1);
            for (d, e) in data.chunks_exact_mut(per).zip(embeddings) {
                for (a, &b) in d.iter_mut().zip(&e.data) {
                    let h = half::f16::from_f32(b);
                    if all || a.to_bits() != h.to_bits() {
                        *a = h;
                        changed = true;
                    }
                }
            }
        }
    }
    Ok(changed)
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

/// The output of a UNet call on input `shape = [m, C_in, H, W]` must be `[m, out_channels, H, W]`.
fn check_output_shape(
    label: String,
    out_shape: &[usize],
    shape: [usize; 4],
    out_channels: usize,
) -> Result<(), OnnxError> {
    let [m, _, h, w] = shape;
    if out_shape != [m, out_channels, h, w] {
        return Err(OnnxError::Shape {
            model: label,
            message: format!(
                "output shape {out_shape:?}, expected [{m}, {out_channels}, {h}, {w}]"
            ),
        });
    }
    Ok(())
}
