//! DeepFloyd IF through ONNX Runtime, behind the `csd` traits.
