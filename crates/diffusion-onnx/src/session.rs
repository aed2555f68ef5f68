//! Shared session plumbing: checking a graph's signature against the manifest, and moving f32 data
//! in and out of fp16/fp32 tensors.

use ort::session::Session;
use ort::value::{DynValue, Tensor, TensorElementType};

use crate::OnnxError;
use crate::manifest::Dtype;

/// What an input or output must be.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    /// A float tensor of the manifest's dtype.
    Float,
    /// An i64 tensor.
    Int64,
}

fn type_name(t: TensorElementType) -> String {
    match t {
        TensorElementType::Float16 => "fp16".into(),
        TensorElementType::Float32 => "fp32".into(),
        TensorElementType::Int64 => "int64".into(),
        other => format!("{other:?}"),
    }
}

/// Checks that the graph has exactly these inputs (by name, any order) and this output, with the
/// element types the manifest implies, and the given ranks where the graph states them.
pub(crate) fn check_signature(
    session: &Session,
    model: &str,
    dtype: Dtype,
    inputs: &[(&str, Kind, usize)],
    output: (&str, Kind, usize),
) -> Result<(), OnnxError> {
    let actual_in: Vec<&str> = session.inputs().iter().map(|o| o.name()).collect();
    let actual_out: Vec<&str> = session.outputs().iter().map(|o| o.name()).collect();
    let sig = |message: String| OnnxError::Signature {
        model: model.to_string(),
        message,
    };
    for (name, _, _) in inputs {
        if !actual_in.contains(name) {
            return Err(sig(format!(
                "no input named `{name}`; the graph's inputs are {actual_in:?}. Fix the names in manifest.toml"
            )));
        }
    }
    if let Some(extra) = actual_in
        .iter()
        .find(|n| !inputs.iter().any(|(m, _, _)| m == *n))
    {
        return Err(sig(format!(
            "the graph has an input `{extra}` the manifest does not declare (declared: {:?})",
            inputs.iter().map(|i| i.0).collect::<Vec<_>>()
        )));
    }
    if !actual_out.contains(&output.0) {
        return Err(sig(format!(
            "no output named `{}`; the graph's outputs are {actual_out:?}. Fix the names in manifest.toml",
            output.0
        )));
    }
    let want_float = match dtype {
        Dtype::Fp16 => TensorElementType::Float16,
        Dtype::Fp32 => TensorElementType::Float32,
    };
    let outlets = session.inputs().iter().chain(session.outputs().iter());
    for outlet in outlets {
        let Some(&(name, kind, rank)) = inputs
            .iter()
            .chain(std::iter::once(&output))
            .find(|(n, _, _)| *n == outlet.name())
        else {
            continue;
        };
        let Some(ty) = outlet.dtype().tensor_type() else {
            return Err(sig(format!("`{name}` is not a tensor")));
        };
        match kind {
            Kind::Float if ty != want_float => {
                let suggested = match ty {
                    TensorElementType::Float16 => "fp16",
                    TensorElementType::Float32 => "fp32",
                    _ => {
                        return Err(sig(format!(
                            "`{name}` is {} but must be a float tensor",
                            type_name(ty)
                        )));
                    }
                };
                return Err(OnnxError::DtypeMismatch {
                    model: model.to_string(),
                    declared: dtype.as_str().to_string(),
                    input: name.to_string(),
                    actual: type_name(ty),
                    suggested: suggested.to_string(),
                });
            }
            Kind::Int64 if ty != TensorElementType::Int64 => {
                return Err(sig(format!(
                    "`{name}` is {} but must be int64",
                    type_name(ty)
                )));
            }
            _ => {}
        }
        if let Some(shape) = outlet.dtype().tensor_shape()
            && shape.len() != rank
        {
            return Err(sig(format!(
                "`{name}` has rank {} (shape {:?}) but must have rank {rank}",
                shape.len(),
                &**shape
            )));
        }
    }
    Ok(())
}

/// A float input tensor of the model's dtype from f32 values (rounded to nearest for fp16).
pub(crate) fn float_input(
    dtype: Dtype,
    shape: Vec<usize>,
    data: Vec<f32>,
) -> Result<DynValue, OnnxError> {
    let v = match dtype {
        Dtype::Fp32 => Tensor::from_array((shape, data)).map(|t| t.into_dyn()),
        Dtype::Fp16 => {
            let h: Vec<half::f16> = data.into_iter().map(half::f16::from_f32).collect();
            Tensor::from_array((shape, h)).map(|t| t.into_dyn())
        }
    };
    v.map_err(|e| OnnxError::ort("creating an input tensor", e))
}

/// An i64 input tensor.
pub(crate) fn int_input(shape: Vec<usize>, data: Vec<i64>) -> Result<DynValue, OnnxError> {
    Tensor::from_array((shape, data))
        .map(|t| t.into_dyn())
        .map_err(|e| OnnxError::ort("creating an input tensor", e))
}

/// A float output as (shape, f32 values), widening fp16.
pub(crate) fn float_output(
    value: &DynValue,
    dtype: Dtype,
    what: &str,
) -> Result<(Vec<usize>, Vec<f32>), OnnxError> {
    let to_shape = |s: &ort::value::Shape| {
        s.iter()
            .map(|&d| usize::try_from(d).unwrap_or(0))
            .collect::<Vec<_>>()
    };
    match dtype {
        Dtype::Fp32 => {
            let (s, d) = value
                .try_extract_tensor::<f32>()
                .map_err(|e| OnnxError::ort(format!("reading {what}"), e))?;
            Ok((to_shape(s), d.to_vec()))
        }
        Dtype::Fp16 => {
            let (s, d) = value
                .try_extract_tensor::<half::f16>()
                .map_err(|e| OnnxError::ort(format!("reading {what}"), e))?;
            Ok((to_shape(s), d.iter().map(|x| x.to_f32()).collect()))
        }
    }
}
