//! Smooth vertex normals of the deformed mesh (spec §6) and their adjoint.
//!
//! Per face, g_f = (x1 − x0) × (x2 − x0) (length = twice the area, CCW faces give outward normals);
//! n_v = Σ_{f ∋ v} g_f, normalized as n / sqrt(max(|n|², 1e-20)); a vertex with |n|² ≤ 1e-20 gets
//! (0, 0, 1) and no gradient.

use glam::DVec3;

use super::math::{NORMALIZE_EPS2, cross_adjoint, normalize_adjoint, v3};

/// Unnormalized face normals g_f = (x1 − x0) × (x2 − x0).
pub fn face_normals_raw(vertices: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<DVec3> {
    faces
        .iter()
        .map(|f| {
            let x0 = v3(vertices, f[0]);
            (v3(vertices, f[1]) - x0).cross(v3(vertices, f[2]) - x0)
        })
        .collect()
}

/// Smooth vertex normals with their unnormalized sums: returns (n_v, Σ g_f).
pub fn smooth_normals(
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    face_raw: &[DVec3],
) -> (Vec<DVec3>, Vec<DVec3>) {
    let mut sum = vec![DVec3::ZERO; vertices.len()];
    for (f, g) in faces.iter().zip(face_raw) {
        for &v in f {
            sum[v as usize] += *g;
        }
    }
    let normals = sum
        .iter()
        .map(|n| {
            if n.length_squared() <= NORMALIZE_EPS2 {
                DVec3::Z
            } else {
                *n / n.length()
            }
        })
        .collect();
    (normals, sum)
}

/// Adjoint of [`smooth_normals`] (through the face cross products): adds dL/dx to `d_vertices`.
pub fn smooth_normals_adjoint(
    vertices: &[[f64; 3]],
    faces: &[[u32; 3]],
    normals: &[DVec3],
    sums: &[DVec3],
    d_normals: &[DVec3],
    d_vertices: &mut [DVec3],
) {
    let d_sum: Vec<DVec3> = (0..normals.len())
        .map(|v| {
            if sums[v].length_squared() <= NORMALIZE_EPS2 {
                DVec3::ZERO
            } else {
                normalize_adjoint(sums[v], normals[v], 1.0 / sums[v].length(), d_normals[v])
            }
        })
        .collect();
    for f in faces {
        let dg = d_sum[f[0] as usize] + d_sum[f[1] as usize] + d_sum[f[2] as usize];
        if dg == DVec3::ZERO {
            continue;
        }
        let x0 = v3(vertices, f[0]);
        let (e1, e2) = (v3(vertices, f[1]) - x0, v3(vertices, f[2]) - x0);
        let (de1, de2) = cross_adjoint(e1, e2, dg);
        d_vertices[f[1] as usize] += de1;
        d_vertices[f[2] as usize] += de2;
        d_vertices[f[0] as usize] -= de1 + de2;
    }
}
