//! Area-weighted vertex normals (spec §1.2).

use crate::geometry::{dot, face_cross};

/// Rest vertex normals `n0`, area weighted (spec §1.2): per face `N_f = (p1 − p0) × (p2 − p0)`
/// (length = 2·area, outward for CCW faces) is added to each of its three corners; each sum `x` is
/// normalized as `x / max(|x|, 1e-6)`.
///
/// Unreferenced vertices (and vertices whose face normals cancel) get a zero vector, never NaN.
/// Faces must index into `positions`.
pub fn vertex_normals_area_weighted(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<[f64; 3]> {
    let mut acc = vec![[0.0f64; 3]; positions.len()];
    for &f in faces {
        let n = face_cross(positions, f);
        for &v in &f {
            let a = &mut acc[v as usize];
            a[0] += n[0];
            a[1] += n[1];
            a[2] += n[2];
        }
    }
    for a in acc.iter_mut() {
        let inv = 1.0 / dot(*a, *a).sqrt().max(1e-6);
        a[0] *= inv;
        a[1] *= inv;
        a[2] *= inv;
    }
    acc
}

/// Unit face normals `N_f / |N_f|`; a zero-area face gets `[0, 0, 0]`.
pub fn face_normals(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<[f64; 3]> {
    faces
        .iter()
        .map(|&f| {
            let n = face_cross(positions, f);
            let l = dot(n, n).sqrt();
            if l > 0.0 {
                [n[0] / l, n[1] / l, n[2] / l]
            } else {
                [0.0; 3]
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_form_weights_on_a_tetrahedron_corner() {
        // Corner at the origin of the unit tetrahedron: three faces with normals −x, −y, −z,
        // each of area 1/2, so the area-weighted sum is −(1,1,1) and the normal −(1,1,1)/√3.
        let tet = crate::shapes::tetrahedron();
        let n = vertex_normals_area_weighted(&tet.positions, &tet.faces);
        let s = -1.0 / 3f64.sqrt();
        for k in 0..3 {
            assert!((n[0][k] - s).abs() < 1e-15);
        }
        for v in &n {
            assert!((dot(*v, *v) - 1.0).abs() < 1e-14);
        }
    }

    #[test]
    fn tiny_sums_are_divided_by_the_floor_not_normalized() {
        // A face with |N_f| = 2e-8 < 1e-6: x / 1e-6 keeps the direction with length 0.02.
        let p = vec![
            [0.0, 0.0, 0.0],
            [1e-4, 0.0, 0.0],
            [0.0, 2e-4, 0.0],
            [5.0, 5.0, 5.0],
        ];
        let f = vec![[0, 1, 2]];
        let n = vertex_normals_area_weighted(&p, &f);
        assert!((n[0][2] - 0.02).abs() < 1e-12);
        assert_eq!(n[3], [0.0; 3], "unreferenced vertex gets zero, not NaN");
    }
}
