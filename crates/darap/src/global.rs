//! The global step (spec §4.1–4.2): right-hand side from the rotations, pinned sparse solve.

use crate::lanes::dispatch;
use crate::local::PAR_MIN_LEN;
use crate::mat3::{Mat3, ZERO};
use cotan::CotWeights;
use rayon::prelude::*;

/// Everything the right-hand side needs that depends only on the rest mesh.
///
/// Per face `f = (i, j, k)` and corner `a` with other corners `b`, `e`, the rest vector
/// `g_{f,a} = (1/6)·[c_ab (p_a − p_b) + c_ae (p_a − p_e)]` (full edge weights `c`, not halved), so
/// that `b_a = Σ_{(f,a)} R_f g_{f,a}` with `R_f = R_i + R_j + R_k` (spec §4.1).
///
/// Stored fused: expanding `R_f` gives `b_a = Σ_v R_v h_{a,v}` with
/// `h_{a,v} = Σ_{f ∋ a, v} g_{f,a}` over the faces holding both `a` and `v` (`v = a` included) —
/// one 3-vector per nonzero of the Laplacian's pattern. The entries are kept twice, by row `a` for
/// [`rhs`] and by column `v` for [`rhs_vjp`], so both are gathers that walk memory in order.
///
/// Rows (the entries of `b`) and columns (the rotations) can be renumbered and rows dropped
/// ([`RhsPrecompute::with_order`]): the layer builds `b` directly in its solver's vertex order.
#[derive(Clone, Debug)]
pub struct RhsPrecompute {
    num_rows: usize,
    num_cols: usize,
    row_ptr: Vec<usize>,
    row_col: Vec<u32>,
    row_h: Vec<[f64; 3]>,
    col_ptr: Vec<usize>,
    col_row: Vec<u32>,
    col_h: Vec<[f64; 3]>,
}

impl RhsPrecompute {
    /// Builds the precompute in the mesh's own vertex order (row `a` of `b` is vertex `a`, column
    /// `v` is rotation `v`); `weights` are the mesh's cotangent weights.
    pub fn new(positions: &[[f64; 3]], faces: &[[u32; 3]], weights: &CotWeights) -> Self {
        let n = positions.len();
        let identity: Vec<usize> = (0..n).collect();
        let rows: Vec<Option<usize>> = (0..n).map(Some).collect();
        Self::with_order(positions, faces, weights, &rows, n, &identity)
    }

    /// Builds the precompute with vertex `a`'s entry of `b` at row `row_of[a]` (`None`: not
    /// computed, e.g. a pinned vertex) of `num_rows`, and vertex `v`'s rotation at position
    /// `col_of[v]` of the rotations slice.
    ///
    /// # Panics
    /// If a row or column number is out of range or `u32` cannot hold it (programming errors).
    pub fn with_order(
        positions: &[[f64; 3]],
        faces: &[[u32; 3]],
        weights: &CotWeights,
        row_of: &[Option<usize>],
        num_rows: usize,
        col_of: &[usize],
    ) -> Self {
        let n = positions.len();
        assert_eq!(row_of.len(), n, "one row number per vertex");
        assert_eq!(col_of.len(), n, "one column number per vertex");
        assert!(u32::try_from(n.max(num_rows)).is_ok(), "too many vertices");
        // (row, column, g) for every corner a of every face and every corner v of that face, in
        // face order; equal (row, column) pairs are summed in that order.
        let mut triplets: Vec<(u32, u32, [f64; 3])> = Vec::with_capacity(9 * faces.len());
        for f in faces {
            for a in 0..3 {
                let pa = f[a];
                let Some(row) = row_of[pa as usize] else {
                    continue;
                };
                let p = positions[pa as usize];
                let mut g = [0.0; 3];
                for other in [f[(a + 1) % 3], f[(a + 2) % 3]] {
                    if other == pa {
                        continue;
                    }
                    let c = weights.get(pa, other).unwrap_or(0.0);
                    let q = positions[other as usize];
                    for d in 0..3 {
                        g[d] += c * (p[d] - q[d]) / 6.0;
                    }
                }
                for &v in f {
                    assert!(row < num_rows, "row out of range");
                    triplets.push((row as u32, col_of[v as usize] as u32, g));
                }
            }
        }
        triplets.sort_by_key(|&(r, c, _)| (r, c));
        let mut entries: Vec<(u32, u32, [f64; 3])> = Vec::with_capacity(triplets.len() / 2);
        for (r, c, g) in triplets {
            match entries.last_mut() {
                Some(last) if last.0 == r && last.1 == c => {
                    for d in 0..3 {
                        last.2[d] += g[d];
                    }
                }
                _ => entries.push((r, c, g)),
            }
        }
        let num_cols = n;
        let mut row_ptr = vec![0usize; num_rows + 1];
        let mut col_ptr = vec![0usize; num_cols + 1];
        for &(r, c, _) in &entries {
            row_ptr[r as usize + 1] += 1;
            col_ptr[c as usize + 1] += 1;
        }
        for i in 0..num_rows {
            row_ptr[i + 1] += row_ptr[i];
        }
        for i in 0..num_cols {
            col_ptr[i + 1] += col_ptr[i];
        }
        let row_col = entries.iter().map(|e| e.1).collect();
        let row_h = entries.iter().map(|e| e.2).collect();
        // By column: a stable counting sort keeps rows increasing within a column.
        let mut fill = col_ptr.clone();
        let mut col_row = vec![0u32; entries.len()];
        let mut col_h = vec![[0.0; 3]; entries.len()];
        for &(r, c, h) in &entries {
            let k = fill[c as usize];
            col_row[k] = r;
            col_h[k] = h;
            fill[c as usize] += 1;
        }
        Self {
            num_rows,
            num_cols,
            row_ptr,
            row_col,
            row_h,
            col_ptr,
            col_row,
            col_h,
        }
    }

    /// Number of rows of `b`.
    pub fn num_rows(&self) -> usize {
        self.num_rows
    }

    /// Number of rotations (columns).
    pub fn num_vertices(&self) -> usize {
        self.num_cols
    }
}

/// A rotation as its three columns, each padded to four lanes: `c[j] = [R_0j, R_1j, R_2j, 0]`, so
/// that `R h = h₀ c₀ + h₁ c₁ + h₂ c₂` is three 4-lane products.
pub(crate) type PaddedColumns = [[f64; 4]; 3];

/// `R` as [`PaddedColumns`].
#[inline]
pub(crate) fn padded_columns(r: &Mat3) -> PaddedColumns {
    std::array::from_fn(|j| [r[0][j], r[1][j], r[2][j], 0.0])
}

/// The rotation that [`padded_columns`] stored.
#[inline]
pub(crate) fn from_padded_columns(c: &PaddedColumns) -> Mat3 {
    std::array::from_fn(|i| [c[0][i], c[1][i], c[2][i]])
}

/// `b_a = Σ_v R_v h_{a,v}` added to the rows `out` covers, for rotations given as
/// [`PaddedColumns`] (as the layer's local step writes them). Rows are padded,
/// `[b_0, b_1, b_2, ·]` (the solver's layout); `out[a]` holds an offset on entry (zero for plain
/// [`rhs`]) and the fourth lane is left as it is.
pub(crate) fn rhs_add_columns_into(
    pre: &RhsPrecompute,
    columns: &[PaddedColumns],
    out: &mut [[f64; 4]],
) {
    assert_eq!(columns.len(), pre.num_cols, "one rotation per vertex");
    assert_eq!(out.len(), pre.num_rows, "one row per entry of b");
    out.par_chunks_mut(PAR_MIN_LEN)
        .enumerate()
        .for_each(|(c, rows)| {
            dispatch(RhsRows {
                pre,
                columns,
                first: c * PAR_MIN_LEN,
                rows,
            })
        });
}

/// Rows `first..first + rows.len()` of [`rhs_add_columns_into`] as a `pulp` kernel, so the gathers and
/// 3×3 products are compiled for the CPU's instruction set (see [`crate::lanes::dispatch`]).
/// Row `i` of the update is `(R_i0·h₀ + R_i1·h₁) + R_i2·h₂`, added to the sum — the scalar
/// expression's operations in its order (no fused multiply–add), so the result does not depend on
/// the instruction set.
struct RhsRows<'a> {
    pre: &'a RhsPrecompute,
    columns: &'a [[[f64; 4]; 3]],
    first: usize,
    rows: &'a mut [[f64; 4]],
}

impl pulp::WithSimd for RhsRows<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        let pre = self.pre;
        // Where one SIMD register holds one padded column (AVX2), columns are registers.
        let vector_columns =
            pulp::bytemuck::try_cast_slice::<[[f64; 4]; 3], [S::f64s; 3]>(self.columns)
                .ok()
                .filter(|_| S::F64_LANES == 4);
        for (k, acc) in self.rows.iter_mut().enumerate() {
            let a = self.first + k;
            let range = pre.row_ptr[a]..pre.row_ptr[a + 1];
            let entries = pre.row_col[range.clone()].iter().zip(&pre.row_h[range]);
            if let Some(columns) = vector_columns {
                let mut s: S::f64s = pulp::bytemuck::cast([acc[0], acc[1], acc[2], 0.0]);
                for (&v, h) in entries {
                    let c = &columns[v as usize];
                    let t = simd.add_f64s(
                        simd.mul_f64s(c[0], simd.splat_f64s(h[0])),
                        simd.mul_f64s(c[1], simd.splat_f64s(h[1])),
                    );
                    s = simd.add_f64s(
                        s,
                        simd.add_f64s(t, simd.mul_f64s(c[2], simd.splat_f64s(h[2]))),
                    );
                }
                let s: [f64; 4] = pulp::bytemuck::cast(s);
                *acc = [s[0], s[1], s[2], acc[3]];
            } else {
                let mut s = *acc;
                for (&v, h) in entries {
                    let c = &self.columns[v as usize];
                    for i in 0..3 {
                        s[i] += c[0][i] * h[0] + c[1][i] * h[1] + c[2][i] * h[2];
                    }
                }
                *acc = s;
            }
        }
    }
}

/// The right-hand side `b` of the global step (spec §4.1), one row per row of `pre`. With every
/// `R = I`, `b = L p` up to rounding. Deterministic (a gather per row in a fixed order).
pub fn rhs(pre: &RhsPrecompute, rotations: &[Mat3]) -> Vec<[f64; 3]> {
    assert_eq!(rotations.len(), pre.num_cols, "one rotation per vertex");
    let columns: Vec<PaddedColumns> = rotations.iter().map(padded_columns).collect();
    let mut b = vec![[0.0; 4]; pre.num_rows];
    rhs_add_columns_into(pre, &columns, &mut b);
    b.iter().map(|r| [r[0], r[1], r[2]]).collect()
}

/// Adjoint of [`rhs`]: given `∂ℓ/∂b` (one row per row of `pre`), returns
/// `∂ℓ/∂R_v = Σ_a (∂ℓ/∂b_a) h_{a,v}ᵀ` for every rotation.
pub fn rhs_vjp(pre: &RhsPrecompute, grad_b: &[[f64; 3]]) -> Vec<Mat3> {
    let mut out = vec![ZERO; pre.num_cols];
    rhs_vjp_into(pre, grad_b, &mut out);
    out
}

/// [`rhs_vjp`] into `out` (overwritten).
pub(crate) fn rhs_vjp_into(pre: &RhsPrecompute, grad_b: &[[f64; 3]], out: &mut [Mat3]) {
    assert_eq!(
        grad_b.len(),
        pre.num_rows,
        "one gradient row per entry of b"
    );
    assert_eq!(out.len(), pre.num_cols, "one rotation per vertex");
    let padded = padded_rows(grad_b);
    out.par_chunks_mut(PAR_MIN_LEN)
        .enumerate()
        .for_each(|(c, cols)| {
            dispatch(RhsVjpCols {
                pre,
                grad_b: &padded,
                first: c * PAR_MIN_LEN,
                cols,
            })
        });
}

/// Columns `first..first + cols.len()` of [`rhs_vjp_into`] as a `pulp` kernel (see [`RhsRows`]):
/// column `j` of `∂ℓ/∂R_v` accumulates `h_j·(∂ℓ/∂b_a)` over the entries in order, the scalar
/// `m_ij += g_i·h_j` lane by lane.
struct RhsVjpCols<'a> {
    pre: &'a RhsPrecompute,
    grad_b: &'a [[f64; 4]],
    first: usize,
    cols: &'a mut [Mat3],
}

impl pulp::WithSimd for RhsVjpCols<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        let rows = RhsTransposed::new(self.pre, self.grad_b);
        for (k, acc) in self.cols.iter_mut().enumerate() {
            *acc = rows.column(simd, self.first + k);
        }
    }
}

/// `∂ℓ/∂b` as padded rows `[g_0, g_1, g_2, 0]` (see [`RhsTransposed`]).
pub(crate) fn padded_rows(grad_b: &[[f64; 3]]) -> Vec<[f64; 4]> {
    grad_b.iter().map(|g| [g[0], g[1], g[2], 0.0]).collect()
}

/// The adjoint of the right-hand side one rotation at a time: [`RhsTransposed::column`] is
/// `∂ℓ/∂R_v` of [`rhs_vjp`], so a kernel that needs the rotation gradients of a few vertices can
/// form them where it uses them (the layer's backward pass does, in the local step's adjoint).
#[derive(Clone, Copy)]
pub(crate) struct RhsTransposed<'a> {
    pre: &'a RhsPrecompute,
    /// `∂ℓ/∂b`, padded rows ([`padded_rows`]).
    grad_b: &'a [[f64; 4]],
}

impl<'a> RhsTransposed<'a> {
    pub(crate) fn new(pre: &'a RhsPrecompute, grad_b: &'a [[f64; 4]]) -> Self {
        assert_eq!(
            grad_b.len(),
            pre.num_rows,
            "one gradient row per entry of b"
        );
        Self { pre, grad_b }
    }

    /// `∂ℓ/∂R_v`: column `j` accumulates `h_j·(∂ℓ/∂b_a)` over the entries in order, the scalar
    /// `m_ij += g_i·h_j` lane by lane (4-lane vectors where `S` has them, the same operations).
    #[inline(always)]
    pub(crate) fn column<S: pulp::Simd>(self, simd: S, v: usize) -> Mat3 {
        let pre = self.pre;
        let range = pre.col_ptr[v]..pre.col_ptr[v + 1];
        let entries = pre.col_row[range.clone()].iter().zip(&pre.col_h[range]);
        let vector_rows = pulp::bytemuck::try_cast_slice::<[f64; 4], S::f64s>(self.grad_b)
            .ok()
            .filter(|_| S::F64_LANES == 4);
        let m: [[f64; 4]; 3] = if let Some(rows) = vector_rows {
            let mut m = [simd.splat_f64s(0.0); 3];
            for (&a, h) in entries {
                let g = rows[a as usize];
                for j in 0..3 {
                    m[j] = simd.add_f64s(m[j], simd.mul_f64s(g, simd.splat_f64s(h[j])));
                }
            }
            m.map(pulp::bytemuck::cast)
        } else {
            let mut m = [[0.0; 4]; 3];
            for (&a, h) in entries {
                let g = self.grad_b[a as usize];
                for j in 0..3 {
                    for i in 0..3 {
                        m[j][i] += g[i] * h[j];
                    }
                }
            }
            m
        };
        from_padded_columns(&m)
    }
}
