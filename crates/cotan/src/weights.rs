//! Per-corner cotangents and per-edge cotangent weights (reference convention, not halved).

use crate::CotanError;

/// Heron area of a triangle with edge lengths `a`, `b`, `c`, clamped as the reference does:
/// `sqrt(max(s(s−a)(s−b)(s−c), 1e-12))` with `s = (a + b + c)/2`. Never below `1e-6`.
pub fn heron_area_clamped(a: f64, b: f64, c: f64) -> f64 {
    let s = 0.5 * (a + b + c);
    (s * (s - a) * (s - b) * (s - c)).max(1e-12).sqrt()
}

fn dist2(p: [f64; 3], q: [f64; 3]) -> f64 {
    let d = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// Checks that every face index is in range and every position is finite.
pub(crate) fn validate(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<(), CotanError> {
    for (index, p) in positions.iter().enumerate() {
        if !p.iter().all(|c| c.is_finite()) {
            return Err(CotanError::NonFinite {
                what: "vertex",
                index,
            });
        }
    }
    let n = positions.len();
    for (face, f) in faces.iter().enumerate() {
        for &vertex in f {
            if vertex as usize >= n {
                return Err(CotanError::FaceIndexOutOfRange {
                    face,
                    vertex,
                    num_vertices: n,
                });
            }
        }
    }
    Ok(())
}

/// Cotangent of each corner of each face: `out[f][k] = cot θ_k` where `θ_k` is the angle at
/// corner `k` of face `f`.
///
/// With `A = |p1 − p2|`, `B = |p0 − p2|`, `C = |p0 − p1|` (the edge opposite corner 0, 1, 2) and
/// the clamped Heron area ([`heron_area_clamped`]): `cot θ_0 = (B² + C² − A²) / (4·area)`, and
/// likewise for corners 1 and 2. Corner `k`'s cotangent belongs to the edge opposite it.
pub fn corner_cotangents(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
) -> Result<Vec<[f64; 3]>, CotanError> {
    validate(positions, faces)?;
    faces
        .iter()
        .enumerate()
        .map(|(face, f)| {
            let [p0, p1, p2] = f.map(|v| positions[v as usize]);
            let a2 = dist2(p1, p2);
            let b2 = dist2(p0, p2);
            let c2 = dist2(p0, p1);
            let area = heron_area_clamped(a2.sqrt(), b2.sqrt(), c2.sqrt());
            // Finite positions can still overflow `s⁴` (edges of ~1e77) or the squared lengths.
            if !area.is_finite() || !(a2 + b2 + c2).is_finite() {
                return Err(CotanError::Overflow { face });
            }
            let inv = 1.0 / (4.0 * area);
            Ok([
                (b2 + c2 - a2) * inv,
                (a2 + c2 - b2) * inv,
                (a2 + b2 - c2) * inv,
            ])
        })
        .collect()
}

/// Cotangent weights of the undirected edges of a mesh.
///
/// `edges[e] = [i, j]` with `i < j`, sorted lexicographically; `weights[e] = c_ij = cot α + cot β`
/// summed over the faces that contain the edge (**not halved**; one term on a boundary edge).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CotWeights {
    /// Undirected edges `[i, j]`, `i < j`, sorted.
    pub edges: Vec<[u32; 2]>,
    /// `c_ij` for each edge.
    pub weights: Vec<f64>,
}

impl CotWeights {
    /// The weight of edge `{i, j}` (either order), or `None` if it is not an edge.
    pub fn get(&self, i: u32, j: u32) -> Option<f64> {
        let key = if i < j { [i, j] } else { [j, i] };
        self.edges.binary_search(&key).ok().map(|e| self.weights[e])
    }
}

/// Per-edge cotangent weights `c_ij = cot α_ij + cot β_ij` (see [`CotWeights`]).
///
/// Faces with a repeated vertex contribute nothing to the edge between equal indices.
pub fn cot_weights(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<CotWeights, CotanError> {
    let cots = corner_cotangents(positions, faces)?;
    let mut entries: Vec<([u32; 2], f64)> = Vec::with_capacity(3 * faces.len());
    for (f, c) in faces.iter().zip(&cots) {
        for k in 0..3 {
            let i = f[(k + 1) % 3];
            let j = f[(k + 2) % 3];
            if i != j {
                entries.push((if i < j { [i, j] } else { [j, i] }, c[k]));
            }
        }
    }
    // Stable sort keeps the face order within an edge, so sums are deterministic.
    entries.sort_by_key(|e| e.0);
    let mut out = CotWeights::default();
    for (edge, w) in entries {
        if out.edges.last() == Some(&edge) {
            if let Some(last) = out.weights.last_mut() {
                *last += w;
            }
        } else {
            out.edges.push(edge);
            out.weights.push(w);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equilateral_triangle_cotangents_are_one_over_sqrt3() {
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 3f64.sqrt() / 2.0, 0.0],
        ];
        let c = corner_cotangents(&p, &[[0, 1, 2]]).unwrap();
        for k in 0..3 {
            assert!((c[0][k] - 1.0 / 3f64.sqrt()).abs() < 1e-14);
        }
    }

    #[test]
    fn huge_faces_are_an_overflow_error_and_large_ones_are_exact() {
        let tri = |k: f64| [[0.0, 0.0, 0.0], [3.0 * k, 0.0, 0.0], [0.0, 4.0 * k, 0.0]];
        // Heron's s⁴ is about 1e304 here: still finite, cotangents as at unit scale.
        let c = corner_cotangents(&tri(1e75), &[[0, 1, 2]]).unwrap();
        assert!((c[0][1] - 3.0 / 4.0).abs() < 1e-14 && (c[0][2] - 4.0 / 3.0).abs() < 1e-14);
        for k in [1e78, 1e160, 1e300] {
            assert_eq!(
                corner_cotangents(&tri(k), &[[0, 1, 2], [0, 2, 1]]),
                Err(CotanError::Overflow { face: 0 }),
                "scale {k:e}"
            );
        }
    }

    #[test]
    fn right_triangle_cotangents_match_closed_form() {
        // Legs 3 (along x) and 4 (along y): angle at corner 1 = atan(4/3), corner 2 = atan(3/4).
        let p = [[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 4.0, 0.0]];
        let c = corner_cotangents(&p, &[[0, 1, 2]]).unwrap();
        assert!(c[0][0].abs() < 1e-14);
        assert!((c[0][1] - 3.0 / 4.0).abs() < 1e-14);
        assert!((c[0][2] - 4.0 / 3.0).abs() < 1e-14);
    }

    #[test]
    fn obtuse_corner_has_negative_cotangent() {
        let p = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.2, 0.0]];
        let c = corner_cotangents(&p, &[[0, 1, 2]]).unwrap();
        let angle = std::f64::consts::PI - 2.0 * (0.2f64).atan2(1.0);
        assert!((c[0][2] - 1.0 / angle.tan()).abs() < 1e-12);
        assert!(c[0][2] < 0.0);
    }

    #[test]
    fn shared_edge_weight_sums_both_opposite_cotangents() {
        // Unit square split along the diagonal 0–2: both opposite angles are 90°, so c_02 = 0;
        // each side edge has one 45° opposite angle, so c = 1.
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let w = cot_weights(&p, &[[0, 1, 2], [0, 2, 3]]).unwrap();
        assert_eq!(w.edges.len(), 5);
        assert!(w.get(0, 2).unwrap().abs() < 1e-14);
        for (i, j) in [(0, 1), (1, 2), (2, 3), (3, 0)] {
            assert!((w.get(i, j).unwrap() - 1.0).abs() < 1e-14);
        }
    }

    #[test]
    fn degenerate_face_gives_finite_cotangents() {
        let p = [[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0; 3]];
        let c = corner_cotangents(&p, &[[0, 1, 2], [0, 3, 1]]).unwrap();
        assert!(c.iter().flatten().all(|x| x.is_finite()));
    }

    #[test]
    fn out_of_range_face_is_an_error() {
        let p = [[0.0; 3]; 3];
        assert!(matches!(
            cot_weights(&p, &[[0, 1, 3]]),
            Err(CotanError::FaceIndexOutOfRange {
                face: 0,
                vertex: 3,
                ..
            })
        ));
    }
}
