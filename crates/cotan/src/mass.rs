//! Mixed-Voronoi vertex areas (Meyer et al.; libigl `massmatrix` VORONOI).

use crate::CotanError;
use crate::weights::validate;

/// Numerically stable Heron area from edge lengths (Kahan's ordering), never NaN.
fn stable_area(l: [f64; 3]) -> f64 {
    let mut s = l;
    s.sort_by(|a, b| b.total_cmp(a));
    let [a, b, c] = s;
    let q = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c));
    0.25 * q.max(0.0).sqrt()
}

/// Mixed-Voronoi area `a_k` of every vertex (spec §1.3). `Σ_k a_k` = total surface area.
///
/// Per face with corner angles `θ_i`, opposite edge lengths `l_i` and area `A`: circumcentric
/// barycentric weights `b_i ∝ cos θ_i · l_i` (normalized to sum 1), partial areas `q_i = b_i·A`,
/// corner area of corner `i` = `(q_j + q_k)/2`. Obtuse override, checked in corner order 0, 1, 2
/// (at most one fires): if `θ_k` is obtuse, corner `k` gets `A/2` and the two others `A/4`.
/// A face with a zero-length edge (or otherwise undefined weights) gives `A/3` to each corner.
/// Unreferenced vertices get 0.
pub fn voronoi_mass(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<Vec<f64>, CotanError> {
    validate(positions, faces)?;
    let mut mass = vec![0.0; positions.len()];
    for f in faces {
        let p = f.map(|v| positions[v as usize]);
        let len = |a: usize, b: usize| {
            let d = [p[a][0] - p[b][0], p[a][1] - p[b][1], p[a][2] - p[b][2]];
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        };
        // l[i] is the edge opposite corner i.
        let l = [len(1, 2), len(0, 2), len(0, 1)];
        let area = stable_area(l);
        let corner = corner_areas(l, area);
        for k in 0..3 {
            mass[f[k] as usize] += corner[k];
        }
    }
    Ok(mass)
}

fn corner_areas(l: [f64; 3], area: f64) -> [f64; 3] {
    let third = [area / 3.0; 3];
    if l.iter().any(|&x| x <= 0.0) {
        return third;
    }
    let cos = |i: usize| {
        let (j, k) = ((i + 1) % 3, (i + 2) % 3);
        (l[j] * l[j] + l[k] * l[k] - l[i] * l[i]) / (2.0 * l[j] * l[k])
    };
    let c = [cos(0), cos(1), cos(2)];
    for k in 0..3 {
        if c[k] < 0.0 {
            let mut out = [0.25 * area; 3];
            out[k] = 0.5 * area;
            return out;
        }
    }
    let b = [c[0] * l[0], c[1] * l[1], c[2] * l[2]];
    let sum = b[0] + b[1] + b[2];
    if sum <= 0.0 || !sum.is_finite() {
        return third;
    }
    let q = b.map(|x| x / sum * area);
    [
        0.5 * (q[1] + q[2]),
        0.5 * (q[0] + q[2]),
        0.5 * (q[0] + q[1]),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equilateral_triangle_splits_area_in_thirds() {
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 3f64.sqrt() / 2.0, 0.0],
        ];
        let m = voronoi_mass(&p, &[[0, 1, 2]]).unwrap();
        let a = 3f64.sqrt() / 4.0;
        for x in m {
            assert!((x - a / 3.0).abs() < 1e-15);
        }
    }

    #[test]
    fn right_triangle_gives_voronoi_regions_of_circumcentre_on_hypotenuse() {
        // Legs 1, 1: circumcentre is the hypotenuse midpoint; the right-angle corner gets A/2,
        // the two others A/4 (the cells of the perpendicular bisectors).
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let m = voronoi_mass(&p, &[[0, 1, 2]]).unwrap();
        assert!((m[0] - 0.25).abs() < 1e-15);
        assert!((m[1] - 0.125).abs() < 1e-15);
        assert!((m[2] - 0.125).abs() < 1e-15);
    }

    #[test]
    fn obtuse_override_gives_half_to_obtuse_corner() {
        let p = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.2, 0.0]];
        let m = voronoi_mass(&p, &[[0, 1, 2]]).unwrap();
        let a = 0.2;
        assert!((m[2] - a / 2.0).abs() < 1e-14);
        assert!((m[0] - a / 4.0).abs() < 1e-14);
        assert!((m[1] - a / 4.0).abs() < 1e-14);
    }

    #[test]
    fn masses_sum_to_surface_area_and_stay_finite_on_degenerate_faces() {
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.3],
            [0.0, 1.0, 0.0],
            [2.0, 0.0, 0.0],
        ];
        let f = [[0, 1, 2], [0, 2, 3], [0, 1, 4], [1, 1, 2]];
        let m = voronoi_mass(&p, &f).unwrap();
        assert!(m.iter().all(|x| x.is_finite()));
        let cross = |t: [u32; 3]| {
            let [a, b, c] = t.map(|v| p[v as usize]);
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let w = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let n = [
                u[1] * w[2] - u[2] * w[1],
                u[2] * w[0] - u[0] * w[2],
                u[0] * w[1] - u[1] * w[0],
            ];
            0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
        };
        let total: f64 = f.iter().map(|&t| cross(t)).sum();
        assert!((m.iter().sum::<f64>() - total).abs() < 1e-14);
    }
}
