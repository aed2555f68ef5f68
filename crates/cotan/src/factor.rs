//! The Cholesky factor `G` (of `P A Pᵀ = G Gᵀ`) grouped into fundamental supernodes, and forward
//! and backward substitution for three right-hand sides at once.
//!
//! faer computes the factor (simplicial or supernodal, whichever its heuristic picks); this copy
//! makes the solves independent of that choice. Rows of the right-hand side are `[f64; 3]` in the
//! factor's (fill-reducing) order, padded to four lanes, so each factor entry is loaded once for
//! the three columns and the solve walks memory in order. faer's own solve would permute into
//! scratch space and, for a supernodal factor, call dense kernels once per supernode (thousands of
//! tiny ones on a mesh); here a supernode shares one row-index list among its columns and the
//! kernels keep its right-hand-side rows in registers.

use crate::CotanError;
use faer::sparse::linalg::cholesky::{SymbolicCholesky, SymbolicCholeskyRaw};
use std::cell::Cell;

/// [`SupernodalFactor::substitute`] as a `pulp` kernel: `with_simd` is inlined into the function pulp
/// compiles for the CPU's instruction set (a closure would be compiled for the baseline SSE2).
struct Substitute<'a> {
    factor: &'a SupernodalFactor,
    x: &'a mut [[f64; 4]],
}

impl pulp::WithSimd for Substitute<'_> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, simd: S) {
        // Where one SIMD register holds exactly one padded row (AVX2), rows are registers.
        match pulp::bytemuck::try_cast_slice_mut::<[f64; 4], S::f64s>(self.x) {
            Ok(rows) if S::F64_LANES == 4 => self.factor.substitute(VectorRows(simd), rows),
            _ => self.factor.substitute(ArrayRows, self.x),
        }
    }
}

thread_local! {
    /// Padded rows for [`SupernodalFactor::solve_in_place`], kept between calls (no allocation per solve).
    static SCRATCH: Cell<Vec<[f64; 4]>> = const { Cell::new(Vec::new()) };
}

/// Lower-triangular factor `G`, grouped into supernodes: runs of consecutive columns `c0..c1` whose
/// strictly-lower patterns are nested, so that the diagonal block `G[c0..c1, c0..c1]` is a full
/// lower triangle and every column of the run has the same rows below `c1` (the supernode's
/// *pattern*). Those rows are stored once, with their `c1 − c0` values side by side, so a
/// substitution loads each row index and each right-hand-side row once per supernode instead of once
/// per column.
///
/// The supernodes are the *fundamental* ones of the stored pattern (a column joins the previous one's
/// run exactly when its rows are the previous column's rows without the first): no zero is added,
/// the stored entries are exactly the simplicial factor's nonzeros.
///
/// Entries that are exactly zero are not stored: a supernodal factor from faer keeps explicit zeros
/// where its relaxed supernodes pad the pattern (on fandisk 245k stored entries, of which ~37k are
/// such zeros), and each would cost a load and three multiply–adds in both substitutions for
/// nothing (`x − 0·y = x`, so the solution is unchanged).
#[derive(Clone, Debug, Default)]
pub(crate) struct SupernodalFactor {
    /// `1 / G_jj`: the substitutions multiply by it (a division's latency would sit on their
    /// critical path, which runs through every column).
    inv_diag: Vec<f64>,
    /// Supernode `s` holds the columns `start[s]..start[s + 1]`.
    start: Vec<u32>,
    /// The strictly lower triangle of supernode `s`'s diagonal block, column after column (column
    /// `k` of the block holds rows `k + 1..w`), at `block_ptr[s]..block_ptr[s + 1]`.
    block_ptr: Vec<usize>,
    block: Vec<f64>,
    /// The rows below supernode `s`, ascending, at `pattern_ptr[s]..pattern_ptr[s + 1]`.
    pattern_ptr: Vec<usize>,
    pattern: Vec<u32>,
    /// Their values row after row, each row's `w` values in column order: row `p` of supernode
    /// `s` (width `w`) at `below_ptr[s] + p·w ..+ w`.
    below_ptr: Vec<usize>,
    below: Vec<f64>,
    /// Number of stored strictly-lower entries.
    off_diagonal: usize,
}

impl SupernodalFactor {
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
        // Rows ascending within each column (what the supernode grouping compares).
        for j in 0..n {
            let range = col_ptr[j]..col_ptr[j + 1];
            if !row[range.clone()].is_sorted() {
                let mut pairs: Vec<(u32, f64)> = row[range.clone()]
                    .iter()
                    .copied()
                    .zip(val[range.clone()].iter().copied())
                    .collect();
                pairs.sort_by_key(|&(i, _)| i);
                for (k, (i, x)) in range.zip(pairs) {
                    row[k] = i;
                    val[k] = x;
                }
            }
        }
        Ok(Self::from_columns(diag, &col_ptr, &row, &val))
    }

    /// Groups compressed columns (strictly-lower rows ascending within each column) into
    /// fundamental supernodes (see the type's docs).
    fn from_columns(diag: Vec<f64>, col_ptr: &[usize], row: &[u32], val: &[f64]) -> Self {
        let n = diag.len();
        let rows = |j: usize| &row[col_ptr[j]..col_ptr[j + 1]];
        let vals = |j: usize| &val[col_ptr[j]..col_ptr[j + 1]];
        let mut out = Self {
            inv_diag: diag.iter().map(|d| 1.0 / d).collect(),
            start: vec![0],
            block_ptr: vec![0],
            pattern_ptr: vec![0],
            below_ptr: vec![0],
            off_diagonal: row.len(),
            ..Self::default()
        };
        let mut c0 = 0;
        while c0 < n {
            // Extend the run while column j + 1's rows are column j's without its first (= j + 1).
            let mut c1 = c0 + 1;
            while c1 < n
                && rows(c1 - 1).first() == Some(&(c1 as u32))
                && rows(c1 - 1)[1..] == *rows(c1)
            {
                c1 += 1;
            }
            let w = c1 - c0;
            for k in 0..w {
                out.block.extend_from_slice(&vals(c0 + k)[..w - 1 - k]);
            }
            let pattern = &rows(c0)[w - 1..];
            out.pattern.extend_from_slice(pattern);
            for p in 0..pattern.len() {
                for k in 0..w {
                    out.below.push(vals(c0 + k)[w - 1 - k + p]);
                }
            }
            out.start.push(c1 as u32);
            out.block_ptr.push(out.block.len());
            out.pattern_ptr.push(out.pattern.len());
            out.below_ptr.push(out.below.len());
            c0 = c1;
        }
        out
    }

    /// Supernode `s`: its first column `c0`, its end `c1`, the strictly lower triangle of its
    /// diagonal block, the rows below it and their values (see the fields).
    #[inline(always)]
    fn supernode(&self, s: usize) -> (usize, usize, &[f64], &[u32], &[f64]) {
        (
            self.start[s] as usize,
            self.start[s + 1] as usize,
            &self.block[self.block_ptr[s]..self.block_ptr[s + 1]],
            &self.pattern[self.pattern_ptr[s]..self.pattern_ptr[s + 1]],
            &self.below[self.below_ptr[s]..self.below_ptr[s + 1]],
        )
    }

    /// Number of supernodes.
    pub(crate) fn num_supernodes(&self) -> usize {
        self.start.len().saturating_sub(1)
    }

    /// Width of the widest supernode (0 for an empty factor).
    #[cfg(test)]
    pub(crate) fn widest_supernode(&self) -> usize {
        self.start
            .windows(2)
            .map(|w| (w[1] - w[0]) as usize)
            .max()
            .unwrap_or(0)
    }

    /// The substitutions with the portable row arithmetic, whatever the CPU (for tests).
    #[cfg(test)]
    pub(crate) fn substitute_portable(&self, x: &mut [[f64; 4]]) {
        self.substitute(ArrayRows, x);
    }

    /// Number of rows.
    pub(crate) fn size(&self) -> usize {
        self.inv_diag.len()
    }

    /// Number of stored entries (diagonal included).
    pub(crate) fn nnz(&self) -> usize {
        self.inv_diag.len() + self.off_diagonal
    }

    /// Solves `G Gᵀ x = b` in place (`x` holds `b` on entry), rows in the factor's order.
    ///
    /// The rows are copied into a per-thread scratch of `[f64; 4]` rows (the fourth lane stays 0)
    /// so that one row is one 256-bit vector, and the substitutions run compiled for the widest
    /// instruction set the CPU has (AVX2 where available, chosen at run time by `pulp`). Every
    /// lane operation is an exactly rounded `+`, `−` or `×` (no fused multiply–add), so the result
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
            self.solve_padded_in_place(&mut work);
            for (o, r) in x.iter_mut().zip(&work) {
                *o = [r[0], r[1], r[2]];
            }
            cell.set(work);
        });
    }

    /// [`SupernodalFactor::solve_in_place`] on rows already padded to `[f64; 4]` (no copy in or
    /// out). Every operation is lane-wise, so the fourth lane is solved as a fourth right-hand side
    /// and the first three come out bit for bit as from [`SupernodalFactor::solve_in_place`],
    /// whatever the fourth holds.
    pub(crate) fn solve_padded_in_place(&self, x: &mut [[f64; 4]]) {
        assert_eq!(
            x.len(),
            self.size(),
            "right-hand side has the wrong number of rows"
        );
        pulp::Arch::new().dispatch(Substitute { factor: self, x });
    }

    /// Forward then backward substitution on padded rows (see [`SupernodalFactor::solve_in_place`]),
    /// with the row arithmetic `ops`.
    ///
    /// Forward (`G y = b`), supernode after supernode: the diagonal block column by column, then
    /// each pattern row `i` once, `x_i −= Σ_k G[i, c0 + k]·y_{c0 + k}` for up to [`GROUP`]
    /// columns at a time (the products summed pairwise, a short dependency chain).
    ///
    /// Backward (`Gᵀ x = y`), last supernode first: the pattern rows' contributions to all `w`
    /// columns at once (`w` accumulators, split further into partial sums over the rows when `w`
    /// is small so that at least four independent chains hide the addition latency), then the
    /// diagonal block, last column first.
    ///
    /// Every sum is taken in a fixed order and every lane operation is an exactly rounded IEEE
    /// `+`, `−` or `×` (no fused multiply–add), so the result is deterministic and the same for
    /// every `ops` (see the bit-for-bit test).
    #[inline(always)]
    fn substitute<O: RowOps>(&self, ops: O, x: &mut [O::Row]) {
        for s in 0..self.num_supernodes() {
            let (c0, c1, block, pattern, below) = self.supernode(s);
            let (head, tail) = x.split_at_mut(c1);
            let y = &mut head[c0..];
            let mut off = 0;
            for k in 0..y.len() {
                let yk = ops.scale(self.inv_diag[c0 + k], y[k]);
                y[k] = yk;
                for yi in &mut y[k + 1..] {
                    *yi = ops.sub(*yi, ops.scale(block[off], yk));
                    off += 1;
                }
            }
            let w = y.len();
            let mut k0 = 0;
            while k0 < w {
                let g = (w - k0).min(GROUP);
                let (y, c) = (&y[k0..k0 + g], Cols { k0, w });
                match g {
                    1 => forward_group::<O, 1>(ops, y, c, pattern, below, tail, c1),
                    2 => forward_group::<O, 2>(ops, y, c, pattern, below, tail, c1),
                    3 => forward_group::<O, 3>(ops, y, c, pattern, below, tail, c1),
                    4 => forward_group::<O, 4>(ops, y, c, pattern, below, tail, c1),
                    5 => forward_group::<O, 5>(ops, y, c, pattern, below, tail, c1),
                    6 => forward_group::<O, 6>(ops, y, c, pattern, below, tail, c1),
                    7 => forward_group::<O, 7>(ops, y, c, pattern, below, tail, c1),
                    _ => forward_group::<O, GROUP>(ops, y, c, pattern, below, tail, c1),
                }
                k0 += g;
            }
        }
        for s in (0..self.num_supernodes()).rev() {
            let (c0, c1, block, pattern, below) = self.supernode(s);
            let (head, tail) = x.split_at_mut(c1);
            let xs = &mut head[c0..];
            let w = xs.len();
            let mut k0 = 0;
            while k0 < w {
                let g = (w - k0).min(GROUP);
                let (xg, c) = (&mut xs[k0..k0 + g], Cols { k0, w });
                match g {
                    1 => backward_group::<O, 1, 4>(ops, xg, c, pattern, below, tail, c1),
                    2 => backward_group::<O, 2, 2>(ops, xg, c, pattern, below, tail, c1),
                    3 => backward_group::<O, 3, 2>(ops, xg, c, pattern, below, tail, c1),
                    4 => backward_group::<O, 4, 1>(ops, xg, c, pattern, below, tail, c1),
                    5 => backward_group::<O, 5, 1>(ops, xg, c, pattern, below, tail, c1),
                    6 => backward_group::<O, 6, 1>(ops, xg, c, pattern, below, tail, c1),
                    7 => backward_group::<O, 7, 1>(ops, xg, c, pattern, below, tail, c1),
                    _ => backward_group::<O, GROUP, 1>(ops, xg, c, pattern, below, tail, c1),
                }
                k0 += g;
            }
            // Column k of the block holds rows k + 1..w, starting at Σ_{t<k} (w − 1 − t).
            for k in (0..w).rev() {
                let first = k * (2 * w - k - 1) / 2;
                let (rows, vals) = (&xs[k + 1..], &block[first..first + (w - 1 - k)]);
                // Last row first (see `backward_group`).
                let mut acc = [ops.zero(); 4];
                for (r, l) in rows.rchunks_exact(4).zip(vals.rchunks_exact(4)) {
                    for q in 0..4 {
                        acc[q] = ops.add(acc[q], ops.scale(l[3 - q], r[3 - q]));
                    }
                }
                let rest = rows.len() % 4;
                for (q, (xi, &l)) in rows[..rest].iter().zip(&vals[..rest]).rev().enumerate() {
                    acc[q] = ops.add(acc[q], ops.scale(l, *xi));
                }
                let sum = ops.add(ops.add(acc[0], acc[1]), ops.add(acc[2], acc[3]));
                xs[k] = ops.scale(self.inv_diag[c0 + k], ops.sub(xs[k], sum));
            }
        }
    }
}

/// Arithmetic on one padded right-hand-side row (three columns and a zero), each operation the
/// exactly rounded IEEE one per lane (no fused multiply–add), so results do not depend on the
/// implementation.
trait RowOps: Copy {
    type Row: Copy;
    /// `a − b`.
    fn sub(self, a: Self::Row, b: Self::Row) -> Self::Row;
    /// `a + b`.
    fn add(self, a: Self::Row, b: Self::Row) -> Self::Row;
    /// `l·a`.
    fn scale(self, l: f64, a: Self::Row) -> Self::Row;
    /// The zero row.
    fn zero(self) -> Self::Row;
}

/// Rows as `[f64; 4]` arrays (any instruction set; the compiler vectorizes what it can).
#[derive(Clone, Copy)]
struct ArrayRows;

impl RowOps for ArrayRows {
    type Row = [f64; 4];
    #[inline(always)]
    fn sub(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        std::array::from_fn(|c| a[c] - b[c])
    }
    #[inline(always)]
    fn add(self, a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
        std::array::from_fn(|c| a[c] + b[c])
    }
    #[inline(always)]
    fn scale(self, l: f64, a: [f64; 4]) -> [f64; 4] {
        a.map(|v| l * v)
    }
    #[inline(always)]
    fn zero(self) -> [f64; 4] {
        [0.0; 4]
    }
}

/// Rows as one SIMD register of an instruction set with four f64 lanes (AVX2): the compiler's
/// vectorizer is not relied on (it split `[f64; 4]` accumulations into 1 + 2 + 1 lanes).
#[derive(Clone, Copy)]
struct VectorRows<S: pulp::Simd>(S);

impl<S: pulp::Simd> RowOps for VectorRows<S> {
    type Row = S::f64s;
    #[inline(always)]
    fn sub(self, a: S::f64s, b: S::f64s) -> S::f64s {
        self.0.sub_f64s(a, b)
    }
    #[inline(always)]
    fn add(self, a: S::f64s, b: S::f64s) -> S::f64s {
        self.0.add_f64s(a, b)
    }
    #[inline(always)]
    fn scale(self, l: f64, a: S::f64s) -> S::f64s {
        self.0.mul_f64s(self.0.splat_f64s(l), a)
    }
    #[inline(always)]
    fn zero(self) -> S::f64s {
        self.0.splat_f64s(0.0)
    }
}

/// Widest supernode slice a substitution kernel keeps in registers; wider supernodes are taken in
/// groups of this many columns.
const GROUP: usize = 8;

/// Columns `k0..k0 + G` of a supernode of width `w` (values row `p` at `p·w..(p + 1)·w`).
#[derive(Clone, Copy)]
struct Cols {
    k0: usize,
    w: usize,
}

/// The forward substitution's update of the rows below one supernode, columns `cols`:
/// `tail[i − c1] −= Σ_k below[p·w + k]·y[k]` for pattern row `p` (row index `i`), `k` ascending.
#[inline(always)]
fn forward_group<O: RowOps, const G: usize>(
    ops: O,
    y: &[O::Row],
    cols: Cols,
    pattern: &[u32],
    below: &[f64],
    tail: &mut [O::Row],
    c1: usize,
) {
    let ys: [O::Row; G] = std::array::from_fn(|k| y[k]);
    for (&i, l) in pattern.iter().zip(below.chunks_exact(cols.w)) {
        let l: &[f64; G] = l[cols.k0..cols.k0 + G].try_into().expect("group width");
        let xi = &mut tail[i as usize - c1];
        let mut prod: [O::Row; G] = std::array::from_fn(|k| ops.scale(l[k], ys[k]));
        let mut width = G;
        while width > 1 {
            let half = width / 2;
            for k in 0..half {
                prod[k] = ops.add(prod[k], prod[width - half + k]);
            }
            width -= half;
        }
        *xi = ops.sub(*xi, prod[0]);
    }
}

/// The backward substitution's use of the rows below one supernode, columns `cols`:
/// `xs[k] −= Σ_p below[p·w + k]·tail[i_p − c1]`, with `P` partial sums per column (pattern rows
/// `p mod P`) added in a fixed order at the end.
#[inline(always)]
fn backward_group<O: RowOps, const G: usize, const P: usize>(
    ops: O,
    xs: &mut [O::Row],
    cols: Cols,
    pattern: &[u32],
    below: &[f64],
    tail: &[O::Row],
    c1: usize,
) {
    // Last pattern row first, so the rows solved most recently (the parent and its nearest
    // ancestors) are added last. Meant to shorten the dependency chain; measured, it made no
    // difference (the substitutions are throughput-bound, see docs/benchmarks.md). The order is
    // fixed either way, so the result is deterministic.
    let mut acc = [[ops.zero(); G]; P];
    let rows = pattern.rchunks_exact(P);
    let rest = rows.remainder();
    let mut vals = below.rchunks_exact(cols.w);
    for r in rows {
        for (q, &i) in r.iter().rev().enumerate() {
            let l = vals.next().expect("one value row per pattern row");
            backward_row(ops, &mut acc[q], tail[i as usize - c1], l, cols);
        }
    }
    for (q, &i) in rest.iter().rev().enumerate() {
        let l = vals.next().expect("one value row per pattern row");
        backward_row(ops, &mut acc[q], tail[i as usize - c1], l, cols);
    }
    for k in 0..G {
        let mut sum = acc[0][k];
        for part in &acc[1..] {
            sum = ops.add(sum, part[k]);
        }
        xs[k] = ops.sub(xs[k], sum);
    }
}

/// One pattern row of [`backward_group`]: `acc[k] += l[k0 + k]·x_i`.
#[inline(always)]
fn backward_row<O: RowOps, const G: usize>(
    ops: O,
    acc: &mut [O::Row; G],
    xi: O::Row,
    l: &[f64],
    cols: Cols,
) {
    let l: &[f64; G] = l[cols.k0..cols.k0 + G].try_into().expect("group width");
    for k in 0..G {
        acc[k] = ops.add(acc[k], ops.scale(l[k], xi));
    }
}
