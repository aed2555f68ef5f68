//! Python bindings of the dARAP layer: the extension module `darap._darap`, re-exported by the
//! pure-Python package `darap` (`python/darap/`). Conventions are the Rust crate's
//! (`docs/darap.md`); the Python API is described in `docs/python.md`.
//!
//! # Arrays
//! - Positions, targets and gradients: NumPy `float64` or `float32` arrays of shape `(V, 3)`, any
//!   memory layout (C order, Fortran order, strided views). Each is read once, while the GIL is
//!   held, into the layer's own `f64` buffer — the one copy the Rust API needs anyway (it stores the
//!   targets for the backward pass) and the one that makes releasing the GIL safe: another Python
//!   thread may write to the caller's array while the layer computes.
//! - Faces: `int32`, `int64`, `uint32` or `uint64` arrays of shape `(F, 3)`, 0-based, CCW.
//! - Outputs are new C-ordered `float64` arrays owned by the caller.
//!
//! The GIL is released during the precompute (`Darap(...)`), `forward` and `backward`.
//!
//! # Threads
//! A layer may be used from several Python threads at once (`forward`/`backward` in a thread pool,
//! a setter from another thread): it holds its state behind a read-write lock, taken with the GIL
//! released and never held while waiting for the GIL, so calls run side by side (reads) or one
//! after another (setters) instead of raising "Already borrowed". A `forward` records the λ, rule
//! and mask it ran with, whatever a setter changes meanwhile.
//!
//! # Errors
//! Bad array types or dtypes raise `TypeError`, bad shapes and option values `ValueError`, and
//! every error of the Rust layer (non-finite input, out-of-range face index, singular Laplacian, …)
//! raises `darap.DarapError` (a `ValueError`) carrying the Rust message. Nothing here panics on
//! user input.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{PoisonError, RwLock};

use darap::{Darap, DarapOptions, Deformation, PostProcess, RotationRule};
use numpy::ndarray::ArrayView2;
use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyTuple;

pyo3::create_exception!(
    darap,
    DarapError,
    PyValueError,
    "An error reported by the Rust dARAP layer (the message is the Rust one)."
);

fn layer_error(e: darap::DarapError) -> PyErr {
    DarapError::new_err(e.to_string())
}

/// Every layer gets a distinct id so that `backward` can refuse a `Deformation` of another layer.
static NEXT_LAYER_ID: AtomicU64 = AtomicU64::new(1);

/// Largest icosphere level offered (level 7 has 163 842 vertices).
const MAX_ICOSPHERE_LEVEL: u32 = 7;

// ---------------------------------------------------------------------------------------------
// Reading arrays

/// `(3,)`-style description of an array's shape for messages.
fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The error for an input that is not an array of an accepted dtype and dimension.
///
/// `dtype_ok` tells whether the array's dtype is one of the accepted ones (then the dimension is
/// what is wrong).
fn bad_array(
    obj: &Bound<'_, PyAny>,
    what: &str,
    accepted: &str,
    shape: &str,
    dtype_ok: impl Fn(&Bound<'_, PyUntypedArray>) -> bool,
) -> PyErr {
    match obj.cast::<PyUntypedArray>() {
        Ok(a) if dtype_ok(a) => PyValueError::new_err(format!(
            "{what} must have shape {shape}, got an array of shape {}",
            shape_text(a.shape())
        )),
        Ok(a) => {
            let dtype = a
                .dtype()
                .str()
                .map(|s| s.to_string())
                .unwrap_or_else(|_| "?".into());
            PyTypeError::new_err(format!(
                "{what} must be a NumPy array of dtype {accepted}, got dtype {dtype} \
                 (convert it with numpy.asarray(..., dtype=...))"
            ))
        }
        Err(_) => {
            let ty = obj
                .get_type()
                .fully_qualified_name()
                .map(|s| s.to_string())
                .unwrap_or_else(|_| "?".into());
            PyTypeError::new_err(format!(
                "{what} must be a NumPy array of dtype {accepted} and shape {shape}, got {ty} \
                 (a torch tensor: .detach().cpu().numpy())"
            ))
        }
    }
}

/// Reads a float64/float32 `(V,)` array of per-vertex region weights (range checked by the layer).
fn read_weights(obj: &Bound<'_, PyAny>, num_vertices: usize) -> PyResult<Vec<f64>> {
    let weights: Option<Vec<f64>> = if let Ok(a) = obj.cast::<PyArray1<f64>>() {
        Some(a.try_readonly()?.as_array().iter().copied().collect())
    } else if let Ok(a) = obj.cast::<PyArray1<f32>>() {
        Some(
            a.try_readonly()?
                .as_array()
                .iter()
                .map(|&w| f64::from(w))
                .collect(),
        )
    } else {
        None
    };
    match weights {
        Some(w) if w.len() == num_vertices => Ok(w),
        Some(w) => Err(PyValueError::new_err(format!(
            "region weights must have shape ({num_vertices},) (one entry per vertex), got an \
             array of shape ({},)",
            w.len()
        ))),
        None => Err(bad_array(
            obj,
            "region weights",
            "float64 or float32 (in [0, 1])",
            &format!("({num_vertices},)"),
            |a| {
                let py = a.py();
                a.ndim() != 1
                    && (a.dtype().is_equiv_to(&numpy::dtype::<f64>(py))
                        || a.dtype().is_equiv_to(&numpy::dtype::<f32>(py)))
            },
        )),
    }
}

fn is_float(a: &Bound<'_, PyUntypedArray>) -> bool {
    let py = a.py();
    let d = a.dtype();
    d.is_equiv_to(&numpy::dtype::<f64>(py)) || d.is_equiv_to(&numpy::dtype::<f32>(py))
}

fn is_index(a: &Bound<'_, PyUntypedArray>) -> bool {
    let py = a.py();
    let d = a.dtype();
    d.is_equiv_to(&numpy::dtype::<i64>(py))
        || d.is_equiv_to(&numpy::dtype::<i32>(py))
        || d.is_equiv_to(&numpy::dtype::<u64>(py))
        || d.is_equiv_to(&numpy::dtype::<u32>(py))
}

fn rows3_from<T: Copy + Into<f64>>(
    view: ArrayView2<'_, T>,
    what: &str,
    expected_rows: Option<usize>,
) -> PyResult<Vec<[f64; 3]>> {
    let (rows, cols) = view.dim();
    if cols != 3 || expected_rows.is_some_and(|n| n != rows) {
        let want = match expected_rows {
            Some(n) => format!("({n}, 3)"),
            None => "(V, 3)".into(),
        };
        return Err(PyValueError::new_err(format!(
            "{what} must have shape {want}, got an array of shape ({rows}, {cols})"
        )));
    }
    Ok(view
        .rows()
        .into_iter()
        .map(|r| [r[0].into(), r[1].into(), r[2].into()])
        .collect())
}

/// Reads a `(rows, 3)` float64/float32 array (any layout) into owned f64 triples.
fn read_rows3(
    obj: &Bound<'_, PyAny>,
    what: &str,
    expected_rows: Option<usize>,
) -> PyResult<Vec<[f64; 3]>> {
    if let Ok(a) = obj.cast::<PyArray2<f64>>() {
        return rows3_from(a.try_readonly()?.as_array(), what, expected_rows);
    }
    if let Ok(a) = obj.cast::<PyArray2<f32>>() {
        return rows3_from(a.try_readonly()?.as_array(), what, expected_rows);
    }
    let shape = match expected_rows {
        Some(n) => format!("({n}, 3)"),
        None => "(V, 3)".into(),
    };
    Err(bad_array(obj, what, "float64 or float32", &shape, is_float))
}

fn faces_from<T: Copy + Into<i128>>(view: ArrayView2<'_, T>) -> PyResult<Vec<[u32; 3]>> {
    let (rows, cols) = view.dim();
    if cols != 3 {
        return Err(PyValueError::new_err(format!(
            "faces must have shape (F, 3), got an array of shape ({rows}, {cols})"
        )));
    }
    let mut faces = Vec::with_capacity(rows);
    for (f, r) in view.rows().into_iter().enumerate() {
        let mut tri = [0u32; 3];
        for c in 0..3 {
            let v: i128 = r[c].into();
            tri[c] = u32::try_from(v).map_err(|_| {
                PyValueError::new_err(format!(
                    "face {f} refers to vertex {v}, which is not a valid vertex index \
                     (faces are 0-based indices below 2^32)"
                ))
            })?;
        }
        faces.push(tri);
    }
    Ok(faces)
}

/// Reads `(F, 3)` integer faces. Range against the vertex count is checked by the Rust layer.
fn read_faces(obj: &Bound<'_, PyAny>) -> PyResult<Vec<[u32; 3]>> {
    if let Ok(a) = obj.cast::<PyArray2<i64>>() {
        return faces_from(a.try_readonly()?.as_array());
    }
    if let Ok(a) = obj.cast::<PyArray2<i32>>() {
        return faces_from(a.try_readonly()?.as_array());
    }
    if let Ok(a) = obj.cast::<PyArray2<u32>>() {
        return faces_from(a.try_readonly()?.as_array());
    }
    if let Ok(a) = obj.cast::<PyArray2<u64>>() {
        return faces_from(a.try_readonly()?.as_array());
    }
    Err(bad_array(
        obj,
        "faces",
        "int32, int64, uint32 or uint64",
        "(F, 3)",
        is_index,
    ))
}

/// Reads a boolean `(V,)` mask (`True` = the vertex may rotate).
fn read_mask(obj: &Bound<'_, PyAny>, num_vertices: usize) -> PyResult<Vec<bool>> {
    if let Ok(a) = obj.cast::<PyArray1<bool>>() {
        let ro = a.try_readonly()?;
        let view = ro.as_array();
        if view.len() != num_vertices {
            return Err(PyValueError::new_err(format!(
                "mask must have shape ({num_vertices},) (one entry per vertex), got an array of \
                 shape ({},)",
                view.len()
            )));
        }
        return Ok(view.iter().copied().collect());
    }
    Err(bad_array(
        obj,
        "mask",
        "bool (True where the vertex may rotate)",
        &format!("({num_vertices},)"),
        |a| a.dtype().is_equiv_to(&numpy::dtype::<bool>(a.py())),
    ))
}

fn parse_rule(name: &str) -> PyResult<RotationRule> {
    match name {
        "gis" => Ok(RotationRule::Gis),
        "procrustes" => Ok(RotationRule::Procrustes),
        other => Err(PyValueError::new_err(format!(
            "rotation_rule must be \"gis\" or \"procrustes\", got {other:?}"
        ))),
    }
}

fn rule_name(rule: RotationRule) -> &'static str {
    match rule {
        RotationRule::Gis => "gis",
        RotationRule::Procrustes => "procrustes",
    }
}

fn parse_post(name: &str) -> PyResult<PostProcess> {
    match name {
        "recenter_rescale" => Ok(PostProcess::RecenterRescale),
        "recenter_only" => Ok(PostProcess::RecenterOnly),
        "none" => Ok(PostProcess::None),
        other => Err(PyValueError::new_err(format!(
            "post_process must be \"recenter_rescale\", \"recenter_only\" or \"none\", got {other:?}"
        ))),
    }
}

fn post_name(mode: PostProcess) -> &'static str {
    match mode {
        PostProcess::RecenterRescale => "recenter_rescale",
        PostProcess::RecenterOnly => "recenter_only",
        PostProcess::None => "none",
    }
}

/// λ from Python: finite and ≥ 0 (a negative strength pulls the normals away from their targets;
/// `stylize` refuses it in configurations too).
fn check_lambda(lam: f64) -> PyResult<f64> {
    if lam.is_finite() && lam >= 0.0 {
        Ok(lam)
    } else {
        Err(PyValueError::new_err(format!(
            "lam must be a finite number >= 0, got {lam}"
        )))
    }
}

// ---------------------------------------------------------------------------------------------
// Writing arrays

fn rows3_to_numpy<'py>(py: Python<'py>, rows: &[[f64; 3]]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    PyArray1::from_slice(py, rows.as_flattened()).reshape([rows.len(), 3])
}

// ---------------------------------------------------------------------------------------------
// Classes

/// A dARAP layer for one rest mesh; everything λ-independent is precomputed here (GIL released).
///
/// verts (V, 3) float64/float32 are used as given: normalize them to the side-2 cube first
/// (normalize_side2_cube) to reproduce the reference and saved files. faces (F, 3) int32/int64/
/// uint32/uint64, CCW. lam: strength λ (cotangent weights cot α + cot β, twice libigl's).
/// rotation_rule: "gis" (the reference's) or "procrustes". mask: (V,) bool, True where the vertex
/// may rotate. post_process: "recenter_rescale", "recenter_only" or "none". The lowest vertex of
/// each connected component is pinned at rest.
#[pyclass(name = "Darap", module = "darap", frozen)]
struct PyDarap {
    /// The layer; see the module documentation ("Threads").
    inner: RwLock<Darap>,
    id: u64,
}

impl PyDarap {
    /// `f` on the layer under the shared lock, waited for and run with the GIL released.
    fn read<T: Send>(&self, py: Python<'_>, f: impl FnOnce(&Darap) -> T + Send) -> T {
        py.detach(|| f(&self.inner.read().unwrap_or_else(PoisonError::into_inner)))
    }

    /// A Deformation of raw target normals `x` (`n` rows, read and checked here) made by `pass`
    /// on the layer under the shared lock with the GIL released (`forward` or
    /// `forward_at_strength`), with the layer's λ.
    fn deformation(
        &self,
        py: Python<'_>,
        x: &Bound<'_, PyAny>,
        pass: impl FnOnce(&Darap, &[[f64; 3]]) -> Result<Deformation, darap::DarapError> + Send,
    ) -> PyResult<PyDeformation> {
        let n = self.read(py, Darap::num_vertices);
        let targets = read_rows3(x, "x", Some(n))?;
        let (state, lambda) =
            self.read(py, |layer| (pass(layer, &targets), layer.options().lambda));
        let state = state.map_err(layer_error)?;
        let positions = rows3_to_numpy(py, &state.positions)?.unbind();
        Ok(PyDeformation {
            state,
            layer_id: self.id,
            lambda,
            positions,
        })
    }

    /// `f` on the layer under the exclusive lock, waited for and run with the GIL released.
    fn write<T: Send>(&self, py: Python<'_>, f: impl FnOnce(&mut Darap) -> T + Send) -> T {
        py.detach(|| f(&mut self.inner.write().unwrap_or_else(PoisonError::into_inner)))
    }
}

/// The result of Darap.forward: deformed positions plus the record Darap.backward needs
/// (opaque; valid only with the layer that produced it).
#[pyclass(name = "Deformation", module = "darap", frozen)]
struct PyDeformation {
    state: Deformation,
    layer_id: u64,
    lambda: f64,
    positions: Py<PyArray2<f64>>,
}

#[pymethods]
impl PyDarap {
    #[new]
    #[pyo3(signature = (verts, faces, lam = 8.0, rotation_rule = "gis", mask = None, post_process = "recenter_rescale"))]
    fn new(
        py: Python<'_>,
        verts: &Bound<'_, PyAny>,
        faces: &Bound<'_, PyAny>,
        lam: f64,
        rotation_rule: &str,
        mask: Option<&Bound<'_, PyAny>>,
        post_process: &str,
    ) -> PyResult<Self> {
        let positions = read_rows3(verts, "verts", None)?;
        let faces = read_faces(faces)?;
        let options = DarapOptions {
            lambda: check_lambda(lam)?,
            rotation_rule: parse_rule(rotation_rule)?,
            post_process: parse_post(post_process)?,
        };
        let free = match mask {
            Some(m) if !m.is_none() => Some(read_mask(m, positions.len())?),
            _ => None,
        };
        let mut inner = py
            .detach(|| Darap::new(&positions, &faces, options))
            .map_err(layer_error)?;
        inner.set_mask(free).map_err(layer_error)?;
        Ok(Self {
            inner: RwLock::new(inner),
            id: NEXT_LAYER_ID.fetch_add(1, Ordering::Relaxed),
        })
    }

    /// Deformed positions for raw target normals x (V, 3) float64/float32; only directions
    /// matter. Returns a Deformation (GIL released). Raises DarapError for non-finite targets.
    fn forward(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<PyDeformation> {
        self.deformation(py, x, |layer, targets| layer.forward(targets))
    }

    /// The strength control (docs/strength.md): the deformation for x at this layer's λ, pushed
    /// `strength` (≥ 1 is the intended use; any > 0 is accepted) times as far by the
    /// `procrustes` rule's increment, R_v(s) = P_v(s·λ)·P_v(λ)ᵀ·R_v(λ), then the global step.
    /// strength = 1 is `forward(x)` exactly. Returns a Deformation whose `backward` raises
    /// DarapError unless strength = 1 (a re-application control keeps no tape). Raises
    /// DarapError for a non-finite or non-positive strength (GIL released).
    fn forward_at_strength(
        &self,
        py: Python<'_>,
        x: &Bound<'_, PyAny>,
        strength: f64,
    ) -> PyResult<PyDeformation> {
        self.deformation(py, x, |layer, targets| {
            layer.forward_at_strength(targets, strength)
        })
    }

    /// The vector-Jacobian product ∂ℓ/∂x (V, 3) for ∂ℓ/∂positions (V, 3) at a Deformation of
    /// this layer, with the λ, rule and mask of that forward (GIL released).
    fn backward<'py>(
        &self,
        py: Python<'py>,
        deformation: &Bound<'py, PyDeformation>,
        grad_positions: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let d = deformation.get();
        if d.layer_id != self.id {
            return Err(PyValueError::new_err(
                "this Deformation was computed by another Darap layer; call backward on the \
                 layer whose forward produced it",
            ));
        }
        let n = self.read(py, Darap::num_vertices);
        let grad = read_rows3(grad_positions, "grad_positions", Some(n))?;
        let state = &d.state;
        let grad_x = self
            .read(py, |layer| layer.try_backward(state, &grad))
            .map_err(layer_error)?;
        rows3_to_numpy(py, &grad_x)
    }

    /// Area-weighted rest vertex normals (V, 3): the usual initial x.
    fn rest_normals<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        rows3_to_numpy(py, &self.read(py, |l| l.rest_normals().to_vec()))
    }

    /// The rest positions as given (V, 3) float64.
    fn rest_positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        rows3_to_numpy(py, &self.read(py, |l| l.rest_positions().to_vec()))
    }

    /// Mixed-Voronoi vertex areas a_v (V,).
    fn mass<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.read(py, |l| l.mass().to_vec()))
    }

    /// Pinned vertices (sorted): the lowest vertex of each connected component.
    fn pins<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        let pins: Vec<i64> = self.read(py, |l| {
            l.pins()
                .iter()
                .map(|&p| i64::try_from(p).unwrap_or(i64::MAX))
                .collect()
        });
        PyArray1::from_vec(py, pins)
    }

    /// Changes λ (finite, ≥ 0); nothing is recomputed.
    fn set_lambda(&self, py: Python<'_>, lam: f64) -> PyResult<()> {
        let lam = check_lambda(lam)?;
        self.write(py, |l| l.set_lambda(lam));
        Ok(())
    }

    /// "gis" or "procrustes"; nothing is recomputed.
    fn set_rotation_rule(&self, py: Python<'_>, rotation_rule: &str) -> PyResult<()> {
        let rule = parse_rule(rotation_rule)?;
        self.write(py, |l| l.set_rotation_rule(rule));
        Ok(())
    }

    /// "recenter_rescale", "recenter_only" or "none".
    fn set_post_process(&self, py: Python<'_>, post_process: &str) -> PyResult<()> {
        let mode = parse_post(post_process)?;
        self.write(py, |l| l.set_post_process(mode));
        Ok(())
    }

    /// (V,) bool, True where the vertex may rotate; None lets every vertex rotate.
    #[pyo3(signature = (mask))]
    fn set_mask(&self, py: Python<'_>, mask: Option<&Bound<'_, PyAny>>) -> PyResult<()> {
        let free = match mask {
            Some(m) if !m.is_none() => Some(read_mask(m, self.read(py, Darap::num_vertices))?),
            _ => None,
        };
        self.write(py, |l| l.set_mask(free)).map_err(layer_error)
    }

    /// A feathered region: (V,) float64/float32 weights w in [0, 1] scaling the strength per
    /// vertex (λ·w_v·a_v; 0 = masked, R = I; 1 = free), as `stylize run --region-feather` and
    /// `stylize apply` use (`feather_weights` builds them). None lets every vertex rotate. Replaces
    /// any mask.
    #[pyo3(signature = (weights))]
    fn set_region_weights(
        &self,
        py: Python<'_>,
        weights: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let w = match weights {
            Some(w) if !w.is_none() => Some(read_weights(w, self.read(py, Darap::num_vertices))?),
            _ => None,
        };
        self.write(py, |l| l.set_region_weights(w))
            .map_err(layer_error)
    }

    /// The region's per-vertex weights (V,) float64 (1 free, 0 masked, the feather weight in
    /// between), or None when every vertex may rotate.
    fn region_weights<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.read(py, Darap::region_weights)
            .map(|w| PyArray1::from_vec(py, w))
    }

    /// Strength λ.
    #[getter]
    fn lam(&self, py: Python<'_>) -> f64 {
        self.read(py, |l| l.options().lambda)
    }

    /// "gis" or "procrustes".
    #[getter]
    fn rotation_rule(&self, py: Python<'_>) -> &'static str {
        rule_name(self.read(py, |l| l.options().rotation_rule))
    }

    /// "recenter_rescale", "recenter_only" or "none".
    #[getter]
    fn post_process(&self, py: Python<'_>) -> &'static str {
        post_name(self.read(py, |l| l.options().post_process))
    }

    /// Number of vertices V.
    #[getter]
    fn num_vertices(&self, py: Python<'_>) -> usize {
        self.read(py, Darap::num_vertices)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let (o, n) = self.read(py, |l| (l.options(), l.num_vertices()));
        format!(
            "darap.Darap({} vertices, lam={}, rotation_rule={:?}, post_process={:?})",
            n,
            o.lambda,
            rule_name(o.rotation_rule),
            post_name(o.post_process)
        )
    }
}

#[pymethods]
impl PyDeformation {
    /// Deformed positions (V, 3) float64 (the same array on every access; writing to it does
    /// not affect the backward pass).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        self.positions.bind(py).clone()
    }

    /// Rotations of the local step (V, 3, 3); R[v] @ e rotates a column vector.
    #[getter]
    fn rotations<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let rotations = &self.state.rotations;
        PyArray1::from_slice(py, rotations.as_flattened().as_flattened()).reshape([
            rotations.len(),
            3,
            3,
        ])
    }

    /// The λ of the forward pass that produced this deformation.
    #[getter]
    fn lam(&self) -> f64 {
        self.lambda
    }

    fn __repr__(&self) -> String {
        format!(
            "darap.Deformation({} vertices, lam={})",
            self.state.positions.len(),
            self.lambda
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Functions

/// Side-2 cube normalization (spec §1.1) in float64: p' = (p − centre)·scale, centre = bbox
/// centre, scale = 2 / longest bbox side (1 for a degenerate input); the centroid is not
/// subtracted. Returns (normalized (V, 3), centre (3,), scale).
#[pyfunction]
fn normalize_side2_cube<'py>(
    py: Python<'py>,
    verts: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyTuple>> {
    let mut positions = read_rows3(verts, "verts", None)?;
    let n = mesh_core::normalize::side2_cube(&mut positions);
    let centre = PyArray1::from_slice(py, &n.centre);
    PyTuple::new(
        py,
        [
            rows3_to_numpy(py, &positions)?.into_any(),
            centre.into_any(),
            n.scale.into_pyobject(py)?.into_any(),
        ],
    )
}

/// Feathered region weights (mesh_core::region::feather_weights, the same function `stylize run
/// --region-feather` and `stylize apply --region-feather` use): free (V,) bool, True inside the
/// region; faces (F, 3); rings K ≥ 0. A vertex at edge-hop distance d from the nearest vertex
/// outside the region gets min(d / (K + 1), 1); vertices outside get 0 (K = 0: the hard mask as
/// 0/1). Returns (V,) float64.
#[pyfunction]
fn feather_weights<'py>(
    py: Python<'py>,
    free: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
    rings: usize,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let n = match free.cast::<PyUntypedArray>() {
        Ok(a) if a.ndim() == 1 => a.shape()[0],
        _ => 0,
    };
    let free = read_mask(free, n)?;
    let faces = read_faces(faces)?;
    if let Some((f, v)) = faces
        .iter()
        .enumerate()
        .find_map(|(f, t)| t.iter().find(|&&v| v as usize >= n).map(|&v| (f, v)))
    {
        return Err(DarapError::new_err(format!(
            "face {f} refers to vertex {v}, but the mesh has only {n} vertices"
        )));
    }
    let w = py.detach(|| mesh_core::region::feather_weights(&free, &faces, rings));
    Ok(PyArray1::from_vec(py, w))
}

/// Exact self-intersections (`mesh_core::intersect::self_intersections`: what `stylize mesh
/// check`, `eval` and `apply` count; definitions in docs/self_intersections.md): positions (V, 3)
/// float64, faces (F, 3) integer. Returns the intersecting face pairs (K, 2) int64, each row
/// `(a, b)` with a < b, rows sorted. Raises DarapError for no faces, an index out of range or a
/// non-finite vertex used by a face.
#[pyfunction]
fn self_intersections<'py>(
    py: Python<'py>,
    positions: &Bound<'py, PyAny>,
    faces: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let positions = read_rows3(positions, "positions", None)?;
    let faces = read_faces(faces)?;
    let found = py
        .detach(|| mesh_core::intersect::self_intersections(&positions, &faces))
        .map_err(|e| DarapError::new_err(format!("self-intersection check: {e}")))?;
    let flat: Vec<i64> = found
        .pairs
        .iter()
        .flat_map(|&(a, b)| [i64::from(a), i64::from(b)])
        .collect();
    PyArray1::from_vec(py, flat).reshape([found.pairs.len(), 2])
}

/// A unit icosphere subdivided `level` times (0..=7): (verts (V, 3) float64, faces (F, 3) int64).
#[pyfunction]
fn icosphere<'py>(py: Python<'py>, level: u32) -> PyResult<Bound<'py, PyTuple>> {
    if level > MAX_ICOSPHERE_LEVEL {
        return Err(PyValueError::new_err(format!(
            "icosphere level must be at most {MAX_ICOSPHERE_LEVEL}, got {level}"
        )));
    }
    let mesh = mesh_core::shapes::icosphere(level);
    let flat: Vec<i64> = mesh
        .faces
        .iter()
        .flat_map(|f| f.iter().map(|&v| i64::from(v)))
        .collect();
    let faces = PyArray1::from_vec(py, flat).reshape([mesh.faces.len(), 3])?;
    PyTuple::new(
        py,
        [
            rows3_to_numpy(py, &mesh.positions)?.into_any(),
            faces.into_any(),
        ],
    )
}

/// dARAP: per-vertex target normals to a deformed mesh, with exact gradients (Rust).
#[pymodule]
fn _darap(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyDarap>()?;
    m.add_class::<PyDeformation>()?;
    m.add("DarapError", m.py().get_type::<DarapError>())?;
    m.add_function(wrap_pyfunction!(normalize_side2_cube, m)?)?;
    m.add_function(wrap_pyfunction!(icosphere, m)?)?;
    m.add_function(wrap_pyfunction!(feather_weights, m)?)?;
    m.add_function(wrap_pyfunction!(self_intersections, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
