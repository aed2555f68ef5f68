//! The Cholesky factor `G` (of `P A Pᵀ = G Gᵀ`) in plain compressed-column form, and forward and
//! backward substitution for three right-hand sides at once.
//!
//! faer computes the factor (simplicial or supernodal, whichever its heuristic picks); this copy
//! makes the solves independent of that choice. Rows of the right-hand side are `[f64; 3]` in the
//! factor's (fill-reducing) order, so each factor entry is loaded once for the three columns and
//! the solve walks memory in order. faer's own solve would permute into scratch space and, for a
//! supernodal factor, call dense kernels once per supernode (thousands of tiny ones on a mesh).

use crate::CotanError;
use faer::sparse::linalg::cholesky::{SymbolicCholesky, SymbolicCholeskyRaw};
use std::cell::Cell;

/// [`CscFactor::substitute`] as a `pulp` kernel: `with_simd` is inlined into the function pulp
/// compiles for the CPU's instruction set (a closure would be compiled for the baseline SSE2).
struct Substitute<'a> {
    factor: &'a CscFactor,
    x: &'a mut [[f64; 4]],
}

impl pulp::WithSimd for Substitute<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        self.factor.substitute(self.x);
    }
}

thread_local! {
    /// Padded rows for [`CscFactor::solve_in_place`], kept between calls (no allocation per solve).
    static SCRATCH: Cell<Vec<[f64; 4]>> = const { Cell::new(Vec::new()) };
}

/// Lower-triangular factor, column by column: the diagonal apart, strictly-lower entries in
/// compressed columns with `u32` row indices.
///
/// Entries that are exactly zero are not stored: a supernodal factor keeps explicit zeros where
/// its relaxed supernodes pad the pattern (on fandisk 245k stored entries, of which ~37k are such
/// zeros), and each would cost a load and three multiply–adds in both substitutions for nothing
/// (`x − 0·y = x`, so the solution is unchanged).
#[derive(Clone, Debug, Default)]
pub(crate) struct CscFactor {
    diag: Vec<f64>,
    col_ptr: Vec<usize>,
    row: Vec<u32>,
    val: Vec<f64>,
}

impl CscFactor {
    /// Copies faer's numeric factor `values` for `symbolic` (either storage).
    pub(crate) fn from_faer(
        symbolic: &SymbolicCholesky<usize>,
        values: &[f64],
    ) -> Result<Self, CotanError> {
        let n = symbolic.nrows();
        if u32::try_from(n).is_err() {
            return Err(CotanError::Factorization(format!(
                "{n} rows do not fit the solver's 32-bit row indices"
            )));
        }
        let mut diag = vec![0.0; n];
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row = Vec::new();
        let mut val = Vec::new();
        col_ptr.push(0);
        let bad =
            |what: &str| CotanError::Factorization(format!("unexpected factor layout: {what}"));
        match symbolic.raw() {
            SymbolicCholeskyRaw::Simplicial(s) => {
                let ptr = s.col_ptr();
                let idx = s.row_idx();
                row.reserve(idx.len().saturating_sub(n));
                val.reserve(idx.len().saturating_sub(n));
                for j in 0..n {
                    let mut has_diag = false;
                    for p in ptr[j]..ptr[j + 1] {
                        let i = idx[p];
                        let x = *values.get(p).ok_or_else(|| bad("short values"))?;
                        if i == j {
                            diag[j] = x;
                            has_diag = true;
                        } else if i > j && i < n {
                            if x != 0.0 {
                                row.push(i as u32);
                                val.push(x);
                            }
                        } else {
                            return Err(bad("entry above the diagonal"));
                        }
                    }
                    if !has_diag {
                        return Err(bad("missing diagonal"));
                    }
                    col_ptr.push(row.len());
                }
            }
            SymbolicCholeskyRaw::Supernodal(s) => {
                let begin = s.supernode_begin();
                let end = s.supernode_end();
                let row_ptr = s.col_ptr_for_row_idx();
                let val_ptr = s.col_ptr_for_val();
                let pattern_all = s.row_idx();
                for k in 0..s.n_supernodes() {
                    let (start, stop) = (begin[k], end[k]);
                    let ncols = stop - start;
                    let pattern = &pattern_all[row_ptr[k]..row_ptr[k + 1]];
                    let nrows = ncols + pattern.len();
                    let block = values
                        .get(val_ptr[k]..val_ptr[k + 1])
                        .filter(|b| b.len() == nrows * ncols)
                        .ok_or_else(|| bad("supernode size"))?;
                    for jj in 0..ncols {
                        let column = &block[jj * nrows..(jj + 1) * nrows];
                        diag[start + jj] = column[jj];
                        for (ii, &x) in column.iter().enumerate().take(ncols).skip(jj + 1) {
                            if x != 0.0 {
                                row.push((start + ii) as u32);
                                val.push(x);
                            }
                        }
                        for (&i, &x) in pattern.iter().zip(&column[ncols..]) {
                            if i <= start + jj || i >= n {
                                return Err(bad("supernode pattern"));
                            }
                            if x != 0.0 {
                                row.push(i as u32);
                                val.push(x);
                            }
                        }
                        col_ptr.push(row.len());
                    }
                }
                if col_ptr.len() != n + 1 {
                    return Err(bad("supernodes do not cover the matrix"));
                }
            }
        }
        Ok(Self {
            diag,
            col_ptr,
            row,
            val,
        })
    }

    /// Number of rows.
    pub(crate) fn size(&self) -> usize {
        self.diag.len()
    }

    /// Number of stored entries (diagonal included).
    pub(crate) fn nnz(&self) -> usize {
        self.diag.len() + self.val.len()
    }

    /// Solves `G Gᵀ x = b` in place (`x` holds `b` on entry), rows in the factor's order.
    ///
    /// The rows are copied into a per-thread scratch of `[f64; 4]` rows (the fourth lane stays 0)
    /// so that one row is one 256-bit vector, and the substitutions run compiled for the widest
    /// instruction set the CPU has (AVX2 where available, chosen at run time by `pulp`). Every
    /// lane operation is an exactly rounded `−`, `×` or `÷` (no fused multiply–add), so the result
    /// does not depend on the instruction set.
    pub(crate) fn solve_in_place(&self, x: &mut [[f64; 3]]) {
        assert_eq!(
            x.len(),
            self.size(),
            "right-hand side has the wrong number of rows"
        );
        SCRATCH.with(|cell| {
            let mut work = cell.take();
            work.clear();
            work.extend(x.iter().map(|r| [r[0], r[1], r[2], 0.0]));
            pulp::Arch::new().dispatch(Substitute {
                factor: self,
                x: &mut work,
            });
            for (o, r) in x.iter_mut().zip(&work) {
                *o = [r[0], r[1], r[2]];
            }
            cell.set(work);
        });
    }

    /// Forward then backward substitution on padded rows (see [`CscFactor::solve_in_place`]).
    #[inline(always)]
    fn substitute(&self, x: &mut [[f64; 4]]) {
        // G y = b: column-oriented forward substitution (independent updates).
        for (j, &d) in self.diag.iter().enumerate() {
            let xj = x[j];
            let yj = [xj[0] / d, xj[1] / d, xj[2] / d, xj[3] / d];
            x[j] = yj;
            let range = self.col_ptr[j]..self.col_ptr[j + 1];
            for (&i, &l) in self.row[range.clone()].iter().zip(&self.val[range]) {
                let xi = &mut x[i as usize];
                for c in 0..4 {
                    xi[c] -= l * yj[c];
                }
            }
        }
        // Gᵀ x = y: row-oriented (dot products over column j of G), last row first. Four partial
        // sums (entries k mod 4) break the dependency chain of the subtractions; they are added
        // in a fixed order, so the result is deterministic.
        for (j, &d) in self.diag.iter().enumerate().rev() {
            let range = self.col_ptr[j]..self.col_ptr[j + 1];
            let (rows, vals) = (&self.row[range.clone()], &self.val[range]);
            let mut acc = [x[j], [0.0; 4], [0.0; 4], [0.0; 4]];
            let (rows4, vals4) = (rows.chunks_exact(4), vals.chunks_exact(4));
            let (rows_rest, vals_rest) = (rows4.remainder(), vals4.remainder());
            for (r, l) in rows4.zip(vals4) {
                for k in 0..4 {
                    let xi = x[r[k] as usize];
                    for c in 0..4 {
                        acc[k][c] -= l[k] * xi[c];
                    }
                }
            }
            for (k, (&i, &l)) in rows_rest.iter().zip(vals_rest).enumerate() {
                let xi = x[i as usize];
                for c in 0..4 {
                    acc[k][c] -= l * xi[c];
                }
            }
            let mut s = [0.0; 4];
            for c in 0..4 {
                s[c] = ((acc[0][c] + acc[1][c]) + (acc[2][c] + acc[3][c])) / d;
            }
            x[j] = s;
        }
    }
}
