//! The cotangent Laplacian `L = diag(Σ_j c_ij) − C` as a symmetric sparse matrix.

use crate::{CotWeights, CotanError, cot_weights};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};

/// A symmetric sparse matrix stored in full (both triangles) compressed-row form with sorted
/// column indices and an explicit diagonal entry in every row.
///
/// Because the matrix is symmetric, the same arrays are also its compressed-column form; see
/// [`SymmetricCsr::to_faer`].
#[derive(Clone, Debug, PartialEq)]
pub struct SymmetricCsr {
    n: usize,
    row_ptr: Vec<usize>,
    col_idx: Vec<usize>,
    values: Vec<f64>,
}

impl SymmetricCsr {
    /// Number of rows (= columns).
    pub fn size(&self) -> usize {
        self.n
    }

    /// Row pointers (`size() + 1` entries).
    pub fn row_ptr(&self) -> &[usize] {
        &self.row_ptr
    }

    /// Column indices, sorted within each row.
    pub fn col_idx(&self) -> &[usize] {
        &self.col_idx
    }

    /// Stored values, aligned with [`SymmetricCsr::col_idx`].
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Column indices and values of row `i`.
    pub fn row(&self, i: usize) -> (&[usize], &[f64]) {
        let r = self.row_ptr[i]..self.row_ptr[i + 1];
        (&self.col_idx[r.clone()], &self.values[r])
    }

    /// Entry `(i, j)`; zero when not stored or out of range.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        if i >= self.n || j >= self.n {
            return 0.0;
        }
        let (cols, vals) = self.row(i);
        cols.binary_search(&j).map_or(0.0, |k| vals[k])
    }

    /// `y = A x` for `x` with three columns (rows are vertices).
    pub fn mul_vec3(&self, x: &[[f64; 3]]) -> Vec<[f64; 3]> {
        (0..self.n)
            .map(|i| {
                let (cols, vals) = self.row(i);
                let mut acc = [0.0; 3];
                for (&j, &v) in cols.iter().zip(vals) {
                    for c in 0..3 {
                        acc[c] += v * x[j][c];
                    }
                }
                acc
            })
            .collect()
    }

    /// A copy as a faer compressed-column matrix (both triangles stored).
    pub fn to_faer(&self) -> SparseColMat<usize, f64> {
        // Sorted, in-range, duplicate-free by construction.
        let symbolic = SymbolicSparseColMat::new_checked(
            self.n,
            self.n,
            self.row_ptr.clone(),
            None,
            self.col_idx.clone(),
        );
        SparseColMat::new(symbolic, self.values.clone())
    }

    /// Builds a symmetric matrix from `(i, j, value)` triplets of its **upper or lower** part
    /// mirrored by the caller; duplicates are summed in input order. Used for tests and by
    /// callers with their own weights.
    pub fn from_symmetric_triplets(
        n: usize,
        triplets: &[(usize, usize, f64)],
    ) -> Result<Self, CotanError> {
        let mut entries: Vec<(usize, usize, f64)> = Vec::with_capacity(2 * triplets.len() + n);
        for &(i, j, v) in triplets {
            if i >= n || j >= n {
                return Err(CotanError::InvalidMatrix(format!(
                    "entry ({i}, {j}) outside a {n}×{n} matrix"
                )));
            }
            entries.push((i, j, v));
            if i != j {
                entries.push((j, i, v));
            }
        }
        entries.extend((0..n).map(|i| (i, i, 0.0)));
        entries.sort_by_key(|&(i, j, _)| (i, j));
        let mut row_ptr = vec![0usize; n + 1];
        let mut col_idx = Vec::with_capacity(entries.len());
        let mut values: Vec<f64> = Vec::with_capacity(entries.len());
        let mut last: Option<(usize, usize)> = None;
        for (i, j, v) in entries {
            if last == Some((i, j)) {
                if let Some(x) = values.last_mut() {
                    *x += v;
                }
            } else {
                col_idx.push(j);
                values.push(v);
                row_ptr[i + 1] += 1;
                last = Some((i, j));
            }
        }
        for i in 0..n {
            row_ptr[i + 1] += row_ptr[i];
        }
        Ok(Self {
            n,
            row_ptr,
            col_idx,
            values,
        })
    }
}

/// The Laplacian of given edge weights: `L_ij = −c_ij` for each edge, `L_ii = Σ_j c_ij`.
/// Every row stores its diagonal (zero for a vertex on no edge).
pub fn laplacian_from_weights(
    num_vertices: usize,
    weights: &CotWeights,
) -> Result<SymmetricCsr, CotanError> {
    let mut triplets = Vec::with_capacity(3 * weights.edges.len());
    for (&[i, j], &c) in weights.edges.iter().zip(&weights.weights) {
        let (i, j) = (i as usize, j as usize);
        triplets.push((i, j, -c));
        triplets.push((i, i, c));
        triplets.push((j, j, c));
    }
    SymmetricCsr::from_symmetric_triplets(num_vertices, &triplets)
}

/// The cotangent Laplacian in the reference convention: `L = diag(Σ_j c_ij) − C` with
/// `c_ij = cot α_ij + cot β_ij` (not halved). Symmetric positive semi-definite.
pub fn laplacian(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<SymmetricCsr, CotanError> {
    let w = cot_weights(positions, faces)?;
    laplacian_from_weights(positions.len(), &w)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shared regular octahedron ([`mesh_core::shapes::octahedron`]) as position/face lists.
    fn octahedron() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let m = mesh_core::shapes::octahedron();
        (m.positions, m.faces)
    }

    #[test]
    fn rows_sum_to_zero_and_matrix_is_symmetric() {
        let (p, f) = octahedron();
        let l = laplacian(&p, &f).unwrap();
        for i in 0..l.size() {
            let (cols, vals) = l.row(i);
            assert!(vals.iter().sum::<f64>().abs() < 1e-13);
            for (&j, &v) in cols.iter().zip(vals) {
                assert_eq!(v, l.get(j, i));
            }
        }
    }

    #[test]
    fn octahedron_weights_are_twice_libigl() {
        // Equilateral faces: every edge has two 60° opposite angles, c = 2/√3.
        let (p, f) = octahedron();
        let l = laplacian(&p, &f).unwrap();
        assert!((l.get(0, 2) + 2.0 / 3f64.sqrt()).abs() < 1e-13);
        assert_eq!(l.get(0, 1), 0.0); // 0 and 1 are antipodal: no edge
        assert!((l.get(0, 0) - 4.0 * 2.0 / 3f64.sqrt()).abs() < 1e-13);
    }

    #[test]
    fn dirichlet_energy_of_linear_function_is_twice_area_times_gradient_squared() {
        // For u = x on a flat mesh, uᵀ L u = 2 ∫ |∇u|² = 2 · area (weights are twice libigl's).
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.3, 0.9, 0.0],
            [0.1, 1.2, 0.0],
            [0.6, 0.5, 0.0],
        ];
        let f = vec![[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
        let l = laplacian(&p, &f).unwrap();
        let lu = l.mul_vec3(&p);
        let energy: f64 = (0..p.len()).map(|i| lu[i][0] * p[i][0]).sum();
        let area: f64 = f
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| p[v as usize]);
                0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])).abs()
            })
            .sum();
        assert!(
            (energy - 2.0 * area).abs() < 1e-12,
            "{energy} vs {}",
            2.0 * area
        );
    }

    #[test]
    fn faer_copy_has_same_entries() {
        let (p, f) = octahedron();
        let l = laplacian(&p, &f).unwrap();
        let m = l.to_faer();
        let mut count = 0;
        for t in m.triplet_iter() {
            assert_eq!(*t.val, l.get(t.row, t.col));
            count += 1;
        }
        assert_eq!(count, l.values().len());
    }
}
