//! Image resizes as explicit separable linear operators, each with its exact adjoint (transpose).
//!
//! Images are planar `(N, C, H, W)`, row-major. A 2-D resize is `A = A_rows ⊗ A_cols`: every output pixel
//! `(i, j)` is `Σ_{k,l} R[i,k] · C[j,l] · in[k,l]` with 1-D operators `R` (height) and `C` (width). Both 1-D
//! operators here have rows that sum to 1, so constants are preserved and `resize(2·img − 1) =
//! 2·resize(img) − 1`. The adjoint applies `Aᵀ = R_rowsᵀ ⊗ C_colsᵀ`, accumulating in `f64`.
//!
//! Kernels (they reproduce PyTorch's `F.interpolate` for these modes, apart from the border rule stated):
//! - [`Resize1d::cubic_antialias`]: Keys cubic with a = −0.5 (as `mode="bicubic", antialias=True`). With
//!   scale = in/out ≥ 1 (downsampling) the kernel is stretched by `scale` (support 2·scale input pixels
//!   each side); output pixel i is centred at `scale·(i + 0.5)` in input pixel units. Taps that fall
//!   outside the image are dropped and the remaining weights are renormalized to sum to 1 (no zero
//!   padding, so borders are not darkened).
//! - [`Resize1d::bilinear`]: `align_corners=False`, no antialias (as `mode="bilinear"`). Source coordinate
//!   `src = (i + 0.5)·in/out − 0.5`, clamped below at 0; taps `⌊src⌋` and `⌊src⌋ + 1` (clamped to the last
//!   pixel) with weights `1 − λ`, `λ`.

use crate::GuidanceError;
use rayon::prelude::*;

/// One output sample of a 1-D resize: `out = Σ_k weights[k] · in[start + k]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Taps {
    /// First input index.
    pub start: usize,
    /// Weights of inputs `start, start + 1, …`.
    pub weights: Vec<f64>,
}

/// A 1-D resize `in_len → out_len` as a sparse matrix of `out_len` rows.
#[derive(Clone, Debug, PartialEq)]
pub struct Resize1d {
    in_len: usize,
    rows: Vec<Taps>,
}

fn check_lengths(in_len: usize, out_len: usize) -> Result<(), GuidanceError> {
    if in_len == 0 || out_len == 0 {
        return Err(GuidanceError::InvalidInput(format!(
            "cannot resize {in_len} → {out_len} pixels"
        )));
    }
    Ok(())
}

/// Keys' cubic convolution kernel with a = −0.5.
fn keys_cubic(x: f64) -> f64 {
    const A: f64 = -0.5;
    let x = x.abs();
    if x < 1.0 {
        ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0
    } else if x < 2.0 {
        (((x - 5.0) * x + 8.0) * x - 4.0) * A
    } else {
        0.0
    }
}

impl Resize1d {
    /// Antialiased Keys cubic (a = −0.5), weights renormalized over the taps inside the image.
    pub fn cubic_antialias(in_len: usize, out_len: usize) -> Result<Self, GuidanceError> {
        check_lengths(in_len, out_len)?;
        let scale = in_len as f64 / out_len as f64;
        let (support, inv_scale) = if scale >= 1.0 {
            (2.0 * scale, 1.0 / scale)
        } else {
            (2.0, 1.0)
        };
        let mut rows = Vec::with_capacity(out_len);
        for i in 0..out_len {
            let center = scale * (i as f64 + 0.5);
            // Same tap window as PyTorch's antialiased kernels: [⌊c − s + ½⌋, ⌊c + s + ½⌋) ∩ [0, in).
            let lo = ((center - support + 0.5).floor().max(0.0)) as usize;
            let hi = ((center + support + 0.5).floor() as usize).min(in_len);
            let mut weights: Vec<f64> = (lo..hi)
                .map(|j| keys_cubic((j as f64 - center + 0.5) * inv_scale))
                .collect();
            let total: f64 = weights.iter().sum();
            if total != 0.0 {
                weights.iter_mut().for_each(|w| *w /= total);
            }
            rows.push(Taps { start: lo, weights });
        }
        Ok(Self { in_len, rows })
    }

    /// Bilinear, `align_corners = False`, no antialias.
    pub fn bilinear(in_len: usize, out_len: usize) -> Result<Self, GuidanceError> {
        check_lengths(in_len, out_len)?;
        let scale = in_len as f64 / out_len as f64;
        let rows = (0..out_len)
            .map(|i| {
                let src = ((i as f64 + 0.5) * scale - 0.5).max(0.0);
                let i0 = (src.floor() as usize).min(in_len - 1);
                let lambda = (src - i0 as f64).clamp(0.0, 1.0);
                if i0 + 1 < in_len {
                    Taps {
                        start: i0,
                        weights: vec![1.0 - lambda, lambda],
                    }
                } else {
                    // Both taps hit the last pixel: weights (1 − λ) + λ = 1.
                    Taps {
                        start: i0,
                        weights: vec![1.0],
                    }
                }
            })
            .collect();
        Ok(Self { in_len, rows })
    }

    /// Input length.
    pub fn in_len(&self) -> usize {
        self.in_len
    }

    /// Output length.
    pub fn out_len(&self) -> usize {
        self.rows.len()
    }

    /// The sparse rows of the matrix.
    pub fn rows(&self) -> &[Taps] {
        &self.rows
    }

    /// The dense `out_len × in_len` matrix (row-major), for tests and inspection.
    pub fn to_dense(&self) -> Vec<f64> {
        let mut m = vec![0.0; self.out_len() * self.in_len];
        for (i, row) in self.rows.iter().enumerate() {
            for (k, &w) in row.weights.iter().enumerate() {
                m[i * self.in_len + row.start + k] += w;
            }
        }
        m
    }
}

/// A scalar type images can be stored in: `f32` (the product path) or `f64` (finite-difference checks).
/// Arithmetic is done in `f64` either way.
pub trait Sample: Copy + Send + Sync + Default + 'static {
    /// Widens to `f64`.
    fn to_f64(self) -> f64;
    /// Rounds from `f64` (to nearest; out-of-range values become ±∞ for `f32`).
    fn from_f64(v: f64) -> Self;
}

impl Sample for f32 {
    fn to_f64(self) -> f64 {
        self as f64
    }
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}

impl Sample for f64 {
    fn to_f64(self) -> f64 {
        self
    }
    fn from_f64(v: f64) -> Self {
        v
    }
}

/// A separable 2-D resize `(in_h, in_w) → (out_h, out_w)` of planar images.
#[derive(Clone, Debug, PartialEq)]
pub struct Resize2d {
    /// Operator along the height (rows).
    pub rows: Resize1d,
    /// Operator along the width (columns).
    pub cols: Resize1d,
}

impl Resize2d {
    /// Antialiased Keys cubic in both directions (the 512 → 224 resize of spec §6).
    pub fn cubic_antialias(
        in_hw: (usize, usize),
        out_hw: (usize, usize),
    ) -> Result<Self, GuidanceError> {
        Ok(Self {
            rows: Resize1d::cubic_antialias(in_hw.0, out_hw.0)?,
            cols: Resize1d::cubic_antialias(in_hw.1, out_hw.1)?,
        })
    }

    /// Bilinear (`align_corners = False`, no antialias) in both directions.
    pub fn bilinear(in_hw: (usize, usize), out_hw: (usize, usize)) -> Result<Self, GuidanceError> {
        Ok(Self {
            rows: Resize1d::bilinear(in_hw.0, out_hw.0)?,
            cols: Resize1d::bilinear(in_hw.1, out_hw.1)?,
        })
    }

    /// Input plane size `(h, w)`.
    pub fn in_hw(&self) -> (usize, usize) {
        (self.rows.in_len(), self.cols.in_len())
    }

    /// Output plane size `(h, w)`.
    pub fn out_hw(&self) -> (usize, usize) {
        (self.rows.out_len(), self.cols.out_len())
    }

    fn planes(&self, len: usize, plane: usize, what: &str) -> Result<usize, GuidanceError> {
        if plane == 0 || !len.is_multiple_of(plane) {
            return Err(GuidanceError::InvalidInput(format!(
                "{what}: {len} values are not a whole number of {plane}-value planes"
            )));
        }
        Ok(len / plane)
    }

    /// Applies the resize to every plane of `input` (`planes × in_h × in_w` values).
    pub fn apply<T: Sample>(&self, input: &[T]) -> Result<Vec<T>, GuidanceError> {
        self.apply_as::<T, T>(input)
    }

    /// Applies the adjoint (transpose) to every plane of `grad_out` (`planes × out_h × out_w` values).
    pub fn adjoint<T: Sample>(&self, grad_out: &[T]) -> Result<Vec<T>, GuidanceError> {
        self.adjoint_as::<T, T>(grad_out)
    }

    /// [`Self::apply`] reading `I` and writing `O` (e.g. `f64` in, `f32` out); arithmetic in `f64`.
    pub fn apply_as<I: Sample, O: Sample>(&self, input: &[I]) -> Result<Vec<O>, GuidanceError> {
        let (ih, iw) = self.in_hw();
        let (oh, ow) = self.out_hw();
        let n = self.planes(input.len(), ih * iw, "resize")?;
        let mut out = vec![O::default(); n * oh * ow];
        out.par_chunks_mut(oh * ow)
            .zip(input.par_chunks(ih * iw))
            .for_each(|(o, i)| self.apply_plane(i, o));
        Ok(out)
    }

    /// [`Self::adjoint`] reading `I` and writing `O` (e.g. `f64` in, `f32` out); arithmetic in `f64`.
    pub fn adjoint_as<I: Sample, O: Sample>(
        &self,
        grad_out: &[I],
    ) -> Result<Vec<O>, GuidanceError> {
        let (ih, iw) = self.in_hw();
        let (oh, ow) = self.out_hw();
        let n = self.planes(grad_out.len(), oh * ow, "resize adjoint")?;
        let mut out = vec![O::default(); n * ih * iw];
        out.par_chunks_mut(ih * iw)
            .zip(grad_out.par_chunks(oh * ow))
            .for_each(|(gi, go)| self.adjoint_plane(go, gi));
        Ok(out)
    }

    fn apply_plane<I: Sample, O: Sample>(&self, input: &[I], out: &mut [O]) {
        let (ih, iw) = self.in_hw();
        let ow = self.cols.out_len();
        // Columns first: tmp (ih × ow).
        let mut tmp = vec![0.0f64; ih * ow];
        for r in 0..ih {
            let src = &input[r * iw..(r + 1) * iw];
            for (j, taps) in self.cols.rows.iter().enumerate() {
                tmp[r * ow + j] = taps
                    .weights
                    .iter()
                    .zip(&src[taps.start..])
                    .map(|(w, x)| w * x.to_f64())
                    .sum::<f64>();
            }
        }
        // Then rows: out (oh × ow).
        let mut acc = vec![0.0f64; ow];
        for (i, taps) in self.rows.rows.iter().enumerate() {
            acc.iter_mut().for_each(|a| *a = 0.0);
            for (k, &w) in taps.weights.iter().enumerate() {
                let r = taps.start + k;
                for (a, t) in acc.iter_mut().zip(&tmp[r * ow..(r + 1) * ow]) {
                    *a += w * t;
                }
            }
            for (o, a) in out[i * ow..(i + 1) * ow].iter_mut().zip(&acc) {
                *o = O::from_f64(*a);
            }
        }
    }

    fn adjoint_plane<I: Sample, O: Sample>(&self, grad_out: &[I], grad_in: &mut [O]) {
        let (ih, iw) = self.in_hw();
        let ow = self.cols.out_len();
        // Rowsᵀ: tmp (ih × ow).
        let mut tmp = vec![0.0f64; ih * ow];
        for (i, taps) in self.rows.rows.iter().enumerate() {
            let g = &grad_out[i * ow..(i + 1) * ow];
            for (k, &w) in taps.weights.iter().enumerate() {
                let r = taps.start + k;
                for (t, x) in tmp[r * ow..(r + 1) * ow].iter_mut().zip(g) {
                    *t += w * x.to_f64();
                }
            }
        }
        // Colsᵀ: grad_in (ih × iw).
        let mut acc = vec![0.0f64; iw];
        for r in 0..ih {
            acc.iter_mut().for_each(|a| *a = 0.0);
            for (j, taps) in self.cols.rows.iter().enumerate() {
                let g = tmp[r * ow + j];
                for (a, &w) in acc[taps.start..].iter_mut().zip(&taps.weights) {
                    *a += w * g;
                }
            }
            for (o, a) in grad_in[r * iw..(r + 1) * iw].iter_mut().zip(&acc) {
                *o = O::from_f64(*a);
            }
        }
    }
}

/// A 1-D operator in gather form with `f32` weights, stored flat: output `i` is
/// `Σ_k weights[offset[i] + k] · in[start[i] + k]` for `k < offset[i + 1] − offset[i]`.
///
/// Built from a [`Resize1d`] (the operator itself) or from its transpose, so that adjoints run as
/// gathers too (every output written once, no scatter).
#[derive(Clone, Debug, PartialEq)]
pub struct Gather1d {
    in_len: usize,
    start: Vec<usize>,
    offset: Vec<usize>,
    weights: Vec<f32>,
}

impl Gather1d {
    /// The operator `op`.
    pub fn of(op: &Resize1d) -> Self {
        let mut g = Self {
            in_len: op.in_len(),
            start: Vec::with_capacity(op.out_len()),
            offset: vec![0],
            weights: Vec::new(),
        };
        for taps in op.rows() {
            g.start.push(taps.start);
            g.weights.extend(taps.weights.iter().map(|&w| w as f32));
            g.offset.push(g.weights.len());
        }
        g
    }

    /// The transpose `opᵀ` (`op.out_len() → op.in_len()`): output `k` gathers every row `i` of `op`
    /// whose taps include `k`, over the contiguous range of such rows (zeros fill any gap).
    pub fn transpose_of(op: &Resize1d) -> Self {
        let mut entries: Vec<Vec<(usize, f64)>> = vec![Vec::new(); op.in_len()];
        for (i, taps) in op.rows().iter().enumerate() {
            for (k, &w) in taps.weights.iter().enumerate() {
                entries[taps.start + k].push((i, w));
            }
        }
        let mut g = Self {
            in_len: op.out_len(),
            start: Vec::with_capacity(op.in_len()),
            offset: vec![0],
            weights: Vec::new(),
        };
        for list in &entries {
            let lo = list.iter().map(|e| e.0).min().unwrap_or(0);
            let hi = list.iter().map(|e| e.0 + 1).max().unwrap_or(lo);
            let mut dense = vec![0.0f64; hi - lo];
            for &(i, w) in list {
                dense[i - lo] += w;
            }
            g.start.push(lo);
            g.weights.extend(dense.iter().map(|&w| w as f32));
            g.offset.push(g.weights.len());
        }
        g
    }

    /// Input length.
    pub fn in_len(&self) -> usize {
        self.in_len
    }

    /// Output length.
    pub fn out_len(&self) -> usize {
        self.start.len()
    }

    fn taps(&self) -> usize {
        self.weights.len()
    }

    #[inline(always)]
    fn row(&self, i: usize) -> (usize, &[f32]) {
        (
            self.start[i],
            &self.weights[self.offset[i]..self.offset[i + 1]],
        )
    }

    /// Along the height: `src` is `in_len × width`, `dst` is `out_len × width`. Each output row is an
    /// `f32` sum of whole input rows (vectorizes over the width).
    #[inline(always)]
    fn vertical(&self, src: &[f32], width: usize, dst: &mut [f32]) {
        self.vertical_then(src, width, dst, |_| {});
    }

    /// [`Gather1d::vertical`], calling `finish` on each output row as soon as it is summed (while
    /// it is in cache: one pass over the output instead of two).
    #[inline(always)]
    fn vertical_then(
        &self,
        src: &[f32],
        width: usize,
        dst: &mut [f32],
        mut finish: impl FnMut(&mut [f32]),
    ) {
        for (i, d) in dst.chunks_exact_mut(width).enumerate() {
            let (start, weights) = self.row(i);
            let rows = src[start * width..].chunks_exact(width);
            let mut taps = weights.iter().zip(rows);
            // The first tap initializes the row (`0 + w·x = w·x`): one pass fewer than zeroing.
            match taps.next() {
                Some((&w, x)) => d.iter_mut().zip(x).for_each(|(o, &x)| *o = w * x),
                None => d.fill(0.0),
            }
            for (&w, x) in taps {
                for (o, &x) in d.iter_mut().zip(x) {
                    *o += w * x;
                }
            }
            finish(d);
        }
    }

    /// Along the width: `src` is `height × in_len`, `dst` is `height × out_len`;
    /// `dst[i][j] = Σ_k w_jk · src[i][start_j + k]`, summed from 0 in tap order.
    ///
    /// Blocked over [`ROW_BLOCK`] rows like [`Gather1d::rgb_rows_to_planes`]: the rows are
    /// transposed into lanes, every tap is one vector multiply and add over the block, and the
    /// sums are transposed back (bit-identical to the one-row-at-a-time loop; tested).
    #[inline(always)]
    fn horizontal(&self, src: &[f32], dst: &mut [f32]) {
        let (iw, ow) = (self.in_len, self.out_len());
        let mut block = vec![[0.0f32; ROW_BLOCK]; iw];
        let mut acc = vec![[0.0f32; ROW_BLOCK]; ow];
        for (rows, out_rows) in src
            .chunks(ROW_BLOCK * iw)
            .zip(dst.chunks_mut(ROW_BLOCK * ow))
        {
            for (l, r) in rows.chunks_exact(iw).enumerate() {
                for (lanes, &x) in block.iter_mut().zip(r) {
                    lanes[l] = x;
                }
            }
            for (j, a) in acc.iter_mut().enumerate() {
                let (start, weights) = self.row(j);
                let mut sum = [0.0f32; ROW_BLOCK];
                for (&w, &x) in weights.iter().zip(&block[start..]) {
                    sum = add_scaled(sum, w, x);
                }
                *a = sum;
            }
            for (l, o) in out_rows.chunks_exact_mut(ow).enumerate() {
                for (v, a) in o.iter_mut().zip(&acc) {
                    *v = a[l];
                }
            }
        }
    }
}

/// Rows per block of the width passes ([`Gather1d::horizontal`], [`Gather1d::rgb_rows_to_planes`],
/// [`Gather1d::planes_to_rgb_rows`]): one `f32` lane per image row, 8 lanes = one 256-bit register.
const ROW_BLOCK: usize = 8;

/// One value per row of a block of [`ROW_BLOCK`] image rows.
type RowLanes = [f32; ROW_BLOCK];

/// `acc + w · x` for every lane (the scalar operations, lane by lane; no fused multiply–add).
/// By value, so the compiler keeps the lanes in vector registers.
#[inline(always)]
fn add_scaled(acc: RowLanes, w: f32, x: RowLanes) -> RowLanes {
    let mut r = acc;
    for l in 0..ROW_BLOCK {
        r[l] = acc[l] + w * x[l];
    }
    r
}

impl Gather1d {
    /// The width pass of interleaved RGB rows (`src`: rows of `in_len` pixels × 3) into three
    /// planes (`out[c]`: rows of `out_len` values): `out[c][i][j] = Σ_k w_jk · src[i][start_j + k][c]`,
    /// summed from 0 in tap order.
    ///
    /// A width pass is a short dot product per output, which does not vectorize along a row; here
    /// [`ROW_BLOCK`] rows are transposed into lanes (`block[pixel·3 + c][row]`), so every tap is one
    /// vector multiply–add over 8 rows, and each lane performs exactly the scalar sum's operations in
    /// the same order (bit-identical to the one-row-at-a-time loop; tested).
    #[inline(always)]
    fn rgb_rows_to_planes(&self, src: &[f32], out: [&mut [f32]; 3]) {
        let (iw, ow) = (self.in_len, self.out_len());
        let row = 3 * iw;
        let mut block = vec![[0.0f32; ROW_BLOCK]; row];
        let mut acc = vec![[[0.0f32; ROW_BLOCK]; 3]; ow];
        let [o0, o1, o2] = out;
        for (b, rows) in src.chunks(ROW_BLOCK * row).enumerate() {
            let n = rows.len() / row;
            for (l, r) in rows.chunks_exact(row).enumerate() {
                for (lanes, &x) in block.iter_mut().zip(r) {
                    lanes[l] = x;
                }
            }
            for (j, a) in acc.iter_mut().enumerate() {
                let (start, weights) = self.row(j);
                let (mut a0, mut a1, mut a2) =
                    ([0.0; ROW_BLOCK], [0.0; ROW_BLOCK], [0.0; ROW_BLOCK]);
                for (&w, px) in weights.iter().zip(block[3 * start..].chunks_exact(3)) {
                    a0 = add_scaled(a0, w, px[0]);
                    a1 = add_scaled(a1, w, px[1]);
                    a2 = add_scaled(a2, w, px[2]);
                }
                *a = [a0, a1, a2];
            }
            for l in 0..n {
                let i = b * ROW_BLOCK + l;
                let (r0, r1, r2) = (
                    &mut o0[i * ow..(i + 1) * ow],
                    &mut o1[i * ow..(i + 1) * ow],
                    &mut o2[i * ow..(i + 1) * ow],
                );
                for (j, a) in acc.iter().enumerate() {
                    r0[j] = a[0][l];
                    r1[j] = a[1][l];
                    r2[j] = a[2][l];
                }
            }
        }
    }

    /// The width pass of three planes (`planes[c]`: rows of `in_len` values) into interleaved RGB
    /// rows (`dst`: rows of `out_len` pixels × 3): `dst[i][j][c] = Σ_k w_jk · planes[c][i][start_j + k]`,
    /// summed from 0 in tap order; blocked over [`ROW_BLOCK`] rows like
    /// [`Gather1d::rgb_rows_to_planes`] (bit-identical to the one-row-at-a-time loop; tested).
    #[inline(always)]
    fn planes_to_rgb_rows(&self, planes: [&[f32]; 3], dst: &mut [f32]) {
        let (iw, ow) = (self.in_len, self.out_len());
        let row = 3 * ow;
        let mut block = vec![[[0.0f32; ROW_BLOCK]; 3]; iw];
        for (b, out_rows) in dst.chunks_mut(ROW_BLOCK * row).enumerate() {
            let n = out_rows.len() / row;
            for l in 0..n {
                let i = b * ROW_BLOCK + l;
                for (c, plane) in planes.iter().enumerate() {
                    for (lanes, &x) in block.iter_mut().zip(&plane[i * iw..(i + 1) * iw]) {
                        lanes[c][l] = x;
                    }
                }
            }
            for j in 0..ow {
                let (start, weights) = self.row(j);
                let (mut a0, mut a1, mut a2) =
                    ([0.0f32; ROW_BLOCK], [0.0; ROW_BLOCK], [0.0; ROW_BLOCK]);
                for (&w, x) in weights.iter().zip(&block[start..]) {
                    a0 = add_scaled(a0, w, x[0]);
                    a1 = add_scaled(a1, w, x[1]);
                    a2 = add_scaled(a2, w, x[2]);
                }
                let a = [a0, a1, a2];
                for (l, r) in out_rows.chunks_exact_mut(row).enumerate() {
                    r[3 * j] = a[0][l];
                    r[3 * j + 1] = a[1][l];
                    r[3 * j + 2] = a[2][l];
                }
            }
        }
    }
}

/// [`PlaneResize::apply_plane`]'s arguments, as a [`dispatch`] kernel. (A struct, not a
/// closure: a closure's body is compiled as a function of its own, for the baseline instruction
/// set, and need not be inlined into the dispatched function.)
struct PlaneOp<'a> {
    op: &'a PlaneResize,
    input: &'a [f32],
    out: &'a mut [f32],
    tmp: &'a mut Vec<f32>,
}

impl pulp::WithSimd for PlaneOp<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        self.op.plane_kernel(self.input, self.out, self.tmp)
    }
}

/// [`PlaneResize::apply_from_interleaved`]'s arguments, as a [`dispatch`] kernel.
struct FromInterleavedOp<'a> {
    op: &'a PlaneResize,
    src: &'a [f32],
    channels: usize,
    out: &'a mut [f32],
    tmp: &'a mut Vec<f32>,
}

impl pulp::WithSimd for FromInterleavedOp<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        self.op
            .interleaved_in_kernel(self.src, self.channels, self.out, self.tmp)
    }
}

/// [`PlaneResize::apply_to_interleaved`]'s arguments, as a [`dispatch`] kernel.
struct ToInterleavedOp<'a, F> {
    op: &'a PlaneResize,
    planes: &'a [f32],
    channels: usize,
    out: &'a mut [f32],
    tmp: &'a mut Vec<f32>,
    finish: F,
}

impl<F: Fn(f32) -> f32> pulp::WithSimd for ToInterleavedOp<'_, F> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        self.op
            .interleaved_out_kernel(self.planes, self.channels, self.out, self.tmp, self.finish)
    }
}

/// Runs `op` compiled for the widest SIMD instruction set the CPU has (AVX2 on x86-64 where
/// present, detected at run time, safely, by `pulp`; SSE2 otherwise). The results do not depend
/// on which: the kernels are lane-wise IEEE multiplies and adds, never contracted into fused
/// multiply–adds. The kernels' helpers are `#[inline(always)]`, so that they are compiled inside
/// the dispatched function rather than once for the baseline instruction set.
#[inline(always)]
fn dispatch<Op: pulp::WithSimd>(op: Op) -> Op::Output {
    pulp::Arch::new().dispatch(op)
}

/// A separable 2-D resize (or the adjoint of one) on single `f32` planes with `f32` weights and
/// arithmetic: the guidance's product path (the reference computes in fp32 too). [`Resize2d`] keeps
/// the `f64` arithmetic for checks. The pass order (height or width first) is the cheaper one for the
/// sizes: the height pass vectorizes along whole rows, the width pass over blocks of rows transposed
/// into lanes (and back).
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneResize {
    rows: Gather1d,
    cols: Gather1d,
    rows_first: bool,
}

impl PlaneResize {
    fn new(rows: Gather1d, cols: Gather1d) -> Self {
        let (ih, iw) = (rows.in_len(), cols.in_len());
        let (oh, ow) = (rows.out_len(), cols.out_len());
        let (tr, tc) = (
            rows.taps() as f64 / oh.max(1) as f64,
            cols.taps() as f64 / ow.max(1) as f64,
        );
        // A width pass costs ~4× a height pass per multiply-add (its rows are transposed into lanes
        // and back). Timed in both orders for the guidance's five plane resizes (2026-12-01): this
        // picks the faster order, or one within 2 %, for each.
        let rows_first = 0.25 * (oh * iw) as f64 * tr + (oh * ow) as f64 * tc;
        let cols_first = (ih * ow) as f64 * tc + 0.25 * (oh * ow) as f64 * tr;
        Self {
            rows,
            cols,
            rows_first: rows_first <= cols_first,
        }
    }

    /// The resize `op`.
    pub fn forward(op: &Resize2d) -> Self {
        Self::new(Gather1d::of(&op.rows), Gather1d::of(&op.cols))
    }

    /// The adjoint `opᵀ` as a resize from `op`'s output size to its input size.
    pub fn adjoint(op: &Resize2d) -> Self {
        Self::new(
            Gather1d::transpose_of(&op.rows),
            Gather1d::transpose_of(&op.cols),
        )
    }

    /// Input plane size `(h, w)`.
    pub fn in_hw(&self) -> (usize, usize) {
        (self.rows.in_len(), self.cols.in_len())
    }

    /// Whether [`Self::apply_plane`] runs the height pass first, as
    /// [`Self::apply_from_interleaved`] always does: then the two compute each channel with the
    /// same operations in the same order (the same bits).
    pub fn height_first(&self) -> bool {
        self.rows_first
    }

    /// Output plane size `(h, w)`.
    pub fn out_hw(&self) -> (usize, usize) {
        (self.rows.out_len(), self.cols.out_len())
    }

    /// The body of [`Self::apply_from_interleaved`] (compiled inside [`dispatch`]).
    #[inline(always)]
    fn interleaved_in_kernel(
        &self,
        src: &[f32],
        channels: usize,
        out: &mut [f32],
        tmp: &mut Vec<f32>,
    ) {
        let (_, iw) = self.in_hw();
        let (oh, ow) = self.out_hw();
        let row = channels * iw;
        tmp.resize(oh * row, 0.0);
        self.rows
            .vertical(&src[..self.rows.in_len() * row], row, tmp);
        if channels == 3 {
            let (o0, rest) = out.split_at_mut(oh * ow);
            let (o1, o2) = rest.split_at_mut(oh * ow);
            self.cols.rgb_rows_to_planes(tmp, [o0, o1, o2]);
            return;
        }
        for (c, plane) in out.chunks_exact_mut(oh * ow).take(channels).enumerate() {
            for (t, o) in tmp.chunks_exact(row).zip(plane.chunks_exact_mut(ow)) {
                for (j, v) in o.iter_mut().enumerate() {
                    let (start, weights) = self.cols.row(j);
                    *v = weights
                        .iter()
                        .enumerate()
                        .map(|(k, &w)| w * t[(start + k) * channels + c])
                        .sum::<f32>();
                }
            }
        }
    }

    /// The body of [`Self::apply_to_interleaved`] (compiled inside [`dispatch`]).
    #[inline(always)]
    fn interleaved_out_kernel(
        &self,
        planes: &[f32],
        channels: usize,
        out: &mut [f32],
        tmp: &mut Vec<f32>,
        finish: impl Fn(f32) -> f32,
    ) {
        let (ih, iw) = self.in_hw();
        let (oh, ow) = self.out_hw();
        let row = channels * ow;
        tmp.resize(ih * row, 0.0);
        if channels == 3 {
            let (p0, rest) = planes.split_at(ih * iw);
            let (p1, p2) = rest.split_at(ih * iw);
            self.cols.planes_to_rgb_rows([p0, p1, &p2[..ih * iw]], tmp);
        } else {
            self.width_to_interleaved(planes, channels, tmp);
        }
        self.rows
            .vertical_then(tmp, row, &mut out[..oh * row], |d: &mut [f32]| {
                d.iter_mut().for_each(|v| *v = finish(*v));
            });
    }

    /// The width pass of [`Self::apply_to_interleaved`] for any channel count.
    #[inline(always)]
    fn width_to_interleaved(&self, planes: &[f32], channels: usize, tmp: &mut [f32]) {
        let (ih, iw) = self.in_hw();
        let ow = self.cols.out_len();
        let row = channels * ow;
        for (c, plane) in planes.chunks_exact(ih * iw).take(channels).enumerate() {
            for (s, t) in plane.chunks_exact(iw).zip(tmp.chunks_exact_mut(row)) {
                for j in 0..ow {
                    let (start, weights) = self.cols.row(j);
                    t[j * channels + c] = weights
                        .iter()
                        .zip(&s[start..])
                        .map(|(&w, &x)| w * x)
                        .sum::<f32>();
                }
            }
        }
    }

    /// The body of [`Self::apply_plane`] (compiled inside [`dispatch`]).
    #[inline(always)]
    fn plane_kernel(&self, input: &[f32], out: &mut [f32], tmp: &mut Vec<f32>) {
        let (ih, iw) = self.in_hw();
        let (oh, ow) = self.out_hw();
        let input = &input[..ih * iw];
        let out = &mut out[..oh * ow];
        if self.rows_first {
            tmp.resize(oh * iw, 0.0);
            self.rows.vertical(input, iw, tmp);
            self.cols.horizontal(tmp, out);
        } else {
            tmp.resize(ih * ow, 0.0);
            self.cols.horizontal(input, tmp);
            self.rows.vertical(tmp, ow, out);
        }
    }

    /// Resizes the `channels` interleaved planes of `src` (in_h × in_w × channels, e.g. RGB pixels)
    /// into planar `out` (channels × out_h × out_w). Height first, over whole interleaved rows (the
    /// channels ride along in the vectorized pass), then the width per channel.
    ///
    /// # Panics
    /// If the slices are shorter than the sizes.
    pub fn apply_from_interleaved(
        &self,
        src: &[f32],
        channels: usize,
        out: &mut [f32],
        tmp: &mut Vec<f32>,
    ) {
        dispatch(FromInterleavedOp {
            op: self,
            src,
            channels,
            out,
            tmp,
        });
    }

    /// Resizes planar `planes` (channels × in_h × in_w) into interleaved `out` (out_h × out_w ×
    /// channels), applying `finish` to every output value. Width first per channel (written
    /// interleaved), then the height over whole interleaved rows.
    ///
    /// # Panics
    /// If the slices are shorter than the sizes.
    pub fn apply_to_interleaved(
        &self,
        planes: &[f32],
        channels: usize,
        out: &mut [f32],
        tmp: &mut Vec<f32>,
        finish: impl Fn(f32) -> f32,
    ) {
        dispatch(ToInterleavedOp {
            op: self,
            planes,
            channels,
            out,
            tmp,
            finish,
        });
    }

    /// Resizes one plane `input` (in_h × in_w) into `out` (out_h × out_w); `tmp` holds the
    /// intermediate (grown as needed, reused across calls).
    ///
    /// # Panics
    /// If the slices are shorter than the plane sizes (callers size them from `in_hw`/`out_hw`).
    pub fn apply_plane(&self, input: &[f32], out: &mut [f32], tmp: &mut Vec<f32>) {
        dispatch(PlaneOp {
            op: self,
            input,
            out,
            tmp,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_plane_resize_and_its_adjoint_match_the_f64_operators() {
        // Every operator of the guidance (and an odd-sized one): the f32 gather path agrees with the
        // f64 separable path to f32 rounding, forward and adjoint.
        for (op, name) in [
            (
                Resize2d::cubic_antialias((512, 512), (224, 224)),
                "cubic 512→224",
            ),
            (
                Resize2d::cubic_antialias((100, 90), (224, 224)),
                "cubic 100×90→224",
            ),
            (Resize2d::bilinear((224, 224), (64, 64)), "bilinear 224→64"),
            (
                Resize2d::bilinear((224, 224), (256, 256)),
                "bilinear 224→256",
            ),
            (Resize2d::bilinear((64, 64), (256, 256)), "bilinear 64→256"),
        ] {
            let op = op.expect("sizes");
            let (ih, iw) = op.in_hw();
            let (oh, ow) = op.out_hw();
            let x = random(ih * iw, 5);
            let y = random(oh * ow, 6);
            let mut tmp = Vec::new();
            for (fast, input, want) in [
                (PlaneResize::forward(&op), &x, op.apply(&x).expect("shape")),
                (
                    PlaneResize::adjoint(&op),
                    &y,
                    op.adjoint(&y).expect("shape"),
                ),
            ] {
                let input32: Vec<f32> = input.iter().map(|&v| v as f32).collect();
                let mut got = vec![0.0f32; want.len()];
                fast.apply_plane(&input32, &mut got, &mut tmp);
                let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let err = got
                    .iter()
                    .zip(&want)
                    .fold(0.0f64, |m, (&g, &w)| m.max((g as f64 - w).abs()));
                assert!(err < 2e-6 * scale.max(1.0), "{name}: max error {err}");
            }
        }
    }

    /// The blocked width passes (RGB and single planes) against the plain one-row-at-a-time loops
    /// they replaced, bit for bit, on sizes whose row counts are not multiples of the block
    /// (remainder blocks).
    #[test]
    fn blocked_width_passes_are_the_row_loops_bit_for_bit() {
        for (in_hw, out_hw) in [
            ((37, 50), (21, 19)),
            ((9, 7), (30, 41)),
            ((5, 64), (3, 224)),
        ] {
            let op = Resize2d::cubic_antialias(in_hw, out_hw).expect("sizes");
            for g in [Gather1d::of(&op.cols), Gather1d::transpose_of(&op.cols)] {
                let (iw, ow) = (g.in_len(), g.out_len());
                let h = 13;
                let rgb: Vec<f32> = random(h * iw * 3, 21).iter().map(|&v| v as f32).collect();
                let mut planes = vec![0.0f32; 3 * h * ow];
                {
                    let (o0, rest) = planes.split_at_mut(h * ow);
                    let (o1, o2) = rest.split_at_mut(h * ow);
                    g.rgb_rows_to_planes(&rgb, [o0, o1, o2]);
                }
                for i in 0..h {
                    for j in 0..ow {
                        let (start, weights) = g.row(j);
                        let mut want = [0.0f32; 3];
                        for (k, &w) in weights.iter().enumerate() {
                            for (c, acc) in want.iter_mut().enumerate() {
                                *acc += w * rgb[(i * iw + start + k) * 3 + c];
                            }
                        }
                        for (c, &v) in want.iter().enumerate() {
                            assert_eq!(planes[(c * h + i) * ow + j].to_bits(), v.to_bits());
                        }
                    }
                }
                let plane: Vec<f32> = random(h * iw, 23).iter().map(|&v| v as f32).collect();
                let mut out = vec![0.0f32; h * ow];
                g.horizontal(&plane, &mut out);
                for i in 0..h {
                    for j in 0..ow {
                        let (start, weights) = g.row(j);
                        let mut want = 0.0f32;
                        for (k, &w) in weights.iter().enumerate() {
                            want += w * plane[i * iw + start + k];
                        }
                        assert_eq!(out[i * ow + j].to_bits(), want.to_bits());
                    }
                }
                let src: Vec<f32> = random(3 * h * iw, 22).iter().map(|&v| v as f32).collect();
                let (p0, rest) = src.split_at(h * iw);
                let (p1, p2) = rest.split_at(h * iw);
                let mut rows = vec![0.0f32; h * ow * 3];
                g.planes_to_rgb_rows([p0, p1, p2], &mut rows);
                for i in 0..h {
                    for j in 0..ow {
                        let (start, weights) = g.row(j);
                        for (c, p) in [p0, p1, p2].iter().enumerate() {
                            let mut want = 0.0f32;
                            for (k, &w) in weights.iter().enumerate() {
                                want += w * p[i * iw + start + k];
                            }
                            assert_eq!(rows[(i * ow + j) * 3 + c].to_bits(), want.to_bits());
                        }
                    }
                }
            }
        }
    }

    /// The public entry points run the kernels under [`dispatch`] (AVX2 where the CPU has it);
    /// calling a kernel directly from this test compiles it for the baseline instruction set.
    /// Both must give the same bits (no contraction into fused multiply–adds, no reordering).
    #[test]
    fn dispatched_kernels_equal_the_baseline_ones_bit_for_bit() {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for (in_hw, out_hw) in [
            ((61, 53), (24, 29)),
            ((24, 29), (61, 53)),
            ((64, 64), (256, 256)),
        ] {
            let op = Resize2d::cubic_antialias(in_hw, out_hw).expect("sizes");
            for r in [PlaneResize::forward(&op), PlaneResize::adjoint(&op)] {
                let ((ih, iw), (oh, ow)) = (r.in_hw(), r.out_hw());
                let (mut t1, mut t2) = (Vec::new(), Vec::new());
                let plane: Vec<f32> = random(ih * iw, 31).iter().map(|&v| v as f32).collect();
                let (mut a, mut b) = (vec![0.0f32; oh * ow], vec![0.0f32; oh * ow]);
                r.apply_plane(&plane, &mut a, &mut t1);
                r.plane_kernel(&plane, &mut b, &mut t2);
                assert_eq!(bits(&a), bits(&b));
                let rgb: Vec<f32> = random(3 * ih * iw, 32).iter().map(|&v| v as f32).collect();
                let (mut a, mut b) = (vec![0.0f32; 3 * oh * ow], vec![0.0f32; 3 * oh * ow]);
                r.apply_from_interleaved(&rgb, 3, &mut a, &mut t1);
                r.interleaved_in_kernel(&rgb, 3, &mut b, &mut t2);
                assert_eq!(bits(&a), bits(&b));
                let (mut a, mut b) = (vec![0.0f32; 3 * oh * ow], vec![0.0f32; 3 * oh * ow]);
                r.apply_to_interleaved(&rgb, 3, &mut a, &mut t1, |v| 2.0 * v - 1.0);
                r.interleaved_out_kernel(&rgb, 3, &mut b, &mut t2, |v| 2.0 * v - 1.0);
                assert_eq!(bits(&a), bits(&b));
            }
        }
    }

    #[test]
    fn interleaved_resizes_equal_the_planar_ones() {
        // 3 interleaved channels (pixel-major) in, planes out, and back.
        let op = Resize2d::cubic_antialias((60, 50), (24, 24)).expect("sizes");
        let (fwd, adj) = (PlaneResize::forward(&op), PlaneResize::adjoint(&op));
        let img: Vec<f32> = random(60 * 50 * 3, 8).iter().map(|&v| v as f32).collect();
        let mut tmp = Vec::new();
        let mut planes = vec![0.0f32; 3 * 24 * 24];
        fwd.apply_from_interleaved(&img, 3, &mut planes, &mut tmp);
        let mut back = vec![0.0f32; img.len()];
        adj.apply_to_interleaved(&planes, 3, &mut back, &mut tmp, |v| 2.0 * v);
        for c in 0..3 {
            let plane_in: Vec<f32> = img.iter().skip(c).step_by(3).copied().collect();
            let mut want = vec![0.0f32; 24 * 24];
            fwd.apply_plane(&plane_in, &mut want, &mut tmp);
            let got = &planes[c * 576..(c + 1) * 576];
            let err = got
                .iter()
                .zip(&want)
                .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
            assert!(err < 1e-6, "forward channel {c}: {err}");
            let mut want_back = vec![0.0f32; 60 * 50];
            adj.apply_plane(got, &mut want_back, &mut tmp);
            let got_back: Vec<f32> = back.iter().skip(c).step_by(3).copied().collect();
            let err = got_back
                .iter()
                .zip(&want_back)
                .fold(0.0f32, |m, (a, b)| m.max((a - 2.0 * b).abs()));
            assert!(err < 1e-6, "adjoint channel {c}: {err}");
        }
    }
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n).map(|_| rng.random::<f64>() * 2.0 - 1.0).collect()
    }

    fn dot(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    #[test]
    fn keys_cubic_kernel_values() {
        // Keys (a = −0.5): 1 at 0, 0 at the integers ±1, ±2, C¹ and symmetric.
        assert_eq!(keys_cubic(0.0), 1.0);
        assert_eq!(keys_cubic(1.0), 0.0);
        assert_eq!(keys_cubic(-2.0), 0.0);
        assert_eq!(keys_cubic(0.5), keys_cubic(-0.5));
        // At 0.5: (1.5·0.5 − 2.5)·0.25 + 1 = 0.5625; at 1.5: ((−3.5·1.5 + 8)·1.5 − 4)·(−0.5) = −0.0625.
        assert!((keys_cubic(0.5) - 0.5625).abs() < 1e-15);
        assert!((keys_cubic(1.5) + 0.0625).abs() < 1e-15);
    }

    #[test]
    fn cubic_antialias_weights_match_hand_derivation_for_4_to_2() {
        // scale 2, support 4, inverse scale ½. Output 0 is centred at 1.0: window [⌊1 − 4 + ½⌋, ⌊1 + 4 + ½⌋)
        // ∩ [0, 4) = {0, 1, 2, 3}; arguments (j − 1 + ½)/2 = −0.25, 0.25, 0.75, 1.25 with kernel values
        // 0.8671875, 0.8671875, 0.2265625, −0.0703125, sum 1.890625 (the taps −1, −2, … outside the image
        // are dropped, then the weights are renormalized).
        let r = Resize1d::cubic_antialias(4, 2).expect("valid sizes");
        let raw = [0.8671875, 0.8671875, 0.2265625, -0.0703125];
        let total = 1.890625;
        assert_eq!(r.rows()[0].start, 0);
        for (w, e) in r.rows()[0].weights.iter().zip(raw) {
            assert!((w - e / total).abs() < 1e-15, "{w} vs {}", e / total);
        }
        // Output 1 mirrors output 0.
        let mirrored: Vec<f64> = r.rows()[1].weights.iter().rev().copied().collect();
        for (a, b) in mirrored.iter().zip(&r.rows()[0].weights) {
            assert!((a - b).abs() < 1e-15);
        }
    }

    #[test]
    fn cubic_antialias_at_scale_one_is_the_identity() {
        let r = Resize1d::cubic_antialias(7, 7).expect("valid sizes");
        let m = r.to_dense();
        for i in 0..7 {
            for j in 0..7 {
                assert!((m[i * 7 + j] - f64::from(u8::from(i == j))).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn every_row_sums_to_one_so_constants_survive_up_to_the_border() {
        for r in [
            Resize1d::cubic_antialias(512, 224),
            Resize1d::cubic_antialias(100, 37),
            Resize1d::cubic_antialias(20, 50),
            Resize1d::bilinear(224, 64),
            Resize1d::bilinear(224, 256),
            Resize1d::bilinear(64, 256),
        ] {
            let r = r.expect("valid sizes");
            for taps in r.rows() {
                let s: f64 = taps.weights.iter().sum();
                assert!((s - 1.0).abs() < 1e-12, "row sum {s}");
                assert!(taps.start + taps.weights.len() <= r.in_len());
            }
        }
        // A constant image stays constant, borders included (zero padding would darken them).
        let a = Resize2d::cubic_antialias((512, 512), (224, 224)).expect("valid sizes");
        let out = a.apply(&vec![0.7f32; 512 * 512]).expect("one plane");
        assert!(out.iter().all(|&v| (v - 0.7).abs() < 1e-6));
    }

    #[test]
    fn bilinear_matches_align_corners_false_closed_form() {
        // 64 → 256 (scale ¼): output i samples src = (i + ½)/4 − ½. Output 0, 1: src < 0 → clamped to 0 →
        // pixel 0. Output 2: src = 0.125 → 0.875·p0 + 0.125·p1. Output 255: src = 63.375 → pixel 63 only.
        let up = Resize1d::bilinear(64, 256).expect("valid sizes");
        assert_eq!(
            up.rows()[0],
            Taps {
                start: 0,
                weights: vec![1.0, 0.0]
            }
        );
        assert_eq!(
            up.rows()[1],
            Taps {
                start: 0,
                weights: vec![1.0, 0.0]
            }
        );
        assert_eq!(
            up.rows()[2],
            Taps {
                start: 0,
                weights: vec![0.875, 0.125]
            }
        );
        assert_eq!(
            up.rows()[255],
            Taps {
                start: 63,
                weights: vec![1.0]
            }
        );
        // 224 → 64 (scale 3.5): output 0 samples src = 1.25 → 0.75·p1 + 0.25·p2 (no antialias: 2 taps).
        let down = Resize1d::bilinear(224, 64).expect("valid sizes");
        assert_eq!(down.rows()[0].start, 1);
        assert!((down.rows()[0].weights[0] - 0.75).abs() < 1e-15);
        assert!((down.rows()[0].weights[1] - 0.25).abs() < 1e-15);
        // A linear ramp is reproduced exactly away from the clamped borders.
        let ramp: Vec<f64> = (0..64).map(|k| k as f64).collect();
        let a = Resize2d {
            rows: Resize1d::bilinear(1, 1).expect("valid"),
            cols: up,
        };
        let out = a.apply(&ramp).expect("one plane");
        for i in 2..254 {
            let src = (i as f64 + 0.5) / 4.0 - 0.5;
            assert!((out[i] - src).abs() < 1e-12);
        }
    }

    #[test]
    fn adjoint_identity_holds_for_every_resize() {
        // ⟨A x, y⟩ = ⟨x, Aᵀ y⟩ for random x, y over 2 planes, in f64.
        let cases = [
            Resize2d::cubic_antialias((512, 480), (224, 224)),
            Resize2d::cubic_antialias((30, 20), (45, 11)),
            Resize2d::bilinear((224, 224), (64, 64)),
            Resize2d::bilinear((224, 224), (256, 256)),
            Resize2d::bilinear((64, 64), (256, 256)),
        ];
        for (k, a) in cases.into_iter().enumerate() {
            let a = a.expect("valid sizes");
            let (ih, iw) = a.in_hw();
            let (oh, ow) = a.out_hw();
            let x = random(2 * ih * iw, 10 + k as u64);
            let y = random(2 * oh * ow, 20 + k as u64);
            let lhs = dot(&a.apply(&x).expect("shape"), &y);
            let rhs = dot(&x, &a.adjoint(&y).expect("shape"));
            assert!(
                (lhs - rhs).abs() <= 1e-12 * lhs.abs().max(1.0),
                "case {k}: {lhs} vs {rhs}"
            );
        }
    }

    #[test]
    fn separable_apply_equals_dense_kronecker_product() {
        let a = Resize2d {
            rows: Resize1d::cubic_antialias(9, 4).expect("valid"),
            cols: Resize1d::bilinear(5, 7).expect("valid"),
        };
        let (r, c) = (a.rows.to_dense(), a.cols.to_dense());
        let x = random(9 * 5, 1);
        let out = a.apply(&x).expect("one plane");
        for i in 0..4 {
            for j in 0..7 {
                let mut e = 0.0;
                for k in 0..9 {
                    for l in 0..5 {
                        e += r[i * 9 + k] * c[j * 5 + l] * x[k * 5 + l];
                    }
                }
                assert!((out[i * 7 + j] - e).abs() < 1e-13);
            }
        }
    }

    #[test]
    fn f32_and_f64_paths_agree() {
        let a = Resize2d::cubic_antialias((64, 64), (24, 24)).expect("valid sizes");
        let x = random(64 * 64, 4);
        let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let y64 = a.apply(&x).expect("shape");
        let y32 = a.apply(&x32).expect("shape");
        for (p, q) in y64.iter().zip(&y32) {
            assert!((p - *q as f64).abs() < 1e-6);
        }
    }

    #[test]
    fn bad_shapes_are_errors() {
        assert!(Resize1d::bilinear(0, 4).is_err());
        assert!(Resize1d::cubic_antialias(4, 0).is_err());
        let a = Resize2d::bilinear((4, 4), (2, 2)).expect("valid sizes");
        assert!(a.apply(&[0.0f32; 15]).is_err());
        assert!(a.adjoint(&[0.0f32; 5]).is_err());
        assert!(a.apply::<f32>(&[]).is_ok_and(|v| v.is_empty()));
    }
}
