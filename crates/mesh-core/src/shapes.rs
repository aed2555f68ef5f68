//! Procedural meshes for tests, gradient checks, examples and benchmarks: the one place the
//! workspace's test shapes are typed (the other crates and `xtask` take them from here).
//!
//! | shape | `V` | `F` | closed | use |
//! |---|---|---|---|---|
//! | [`tetrahedron`] | 4 | 4 | yes | closed-form volumes, areas, normals |
//! | [`octahedron`] | 6 | 8 | yes | closed-form cotangent weights |
//! | [`icosphere`] | `10·4^l + 2` | `20·4^l` | yes | smooth closed surface at any size |
//! | [`obtuse_wavy_grid`] | `(k+1)²` | `2k²` | no (boundary) | negative cotangent weights |

use crate::TriMesh;
use crate::subdivide;

/// The unit corner tetrahedron with vertices `0, e_x, e_y, e_z` (in that order); faces CCW seen
/// from outside: `[0, 2, 1]` (in the plane z = 0, normal −z), `[0, 1, 3]` (−y), `[0, 3, 2]` (−x),
/// `[1, 2, 3]` (the slanted face, normal `(1, 1, 1)/√3`). `V = 4`, `F = 4`, volume `1/6`.
pub fn tetrahedron() -> TriMesh {
    TriMesh::new(
        vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ],
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    )
}

/// The regular octahedron with vertices `±e_x, ±e_y, ±e_z` (in that order: +x, −x, +y, −y, +z, −z);
/// faces CCW seen from outside. `V = 6`, `F = 8`.
pub fn octahedron() -> TriMesh {
    let positions = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let faces = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    TriMesh::new(positions, faces)
}

/// A unit-radius icosphere: the regular icosahedron, then `level` rounds of midpoint subdivision
/// ([`subdivide::midpoint`]), every vertex projected back to the unit sphere after each round (so
/// the triangles stay nearly equilateral; all cotangent weights are positive). Faces are CCW seen
/// from outside. `V = 10·4^level + 2`, `F = 20·4^level` (level 3 → 1,280 faces, 4 → 5,120,
/// 5 → 20,480, 6 → 81,920).
pub fn icosphere(level: u32) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let corners = vec![
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ];
    let faces = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let mut mesh = TriMesh::new(corners, faces);
    project_to_unit_sphere(&mut mesh.positions);
    for _ in 0..level {
        mesh = subdivide::midpoint(&mesh);
        project_to_unit_sphere(&mut mesh.positions);
    }
    mesh
}

/// An open, wavy `k×k` grid over `[−1, 1]²` whose cells are sheared so that half of the triangles
/// are obtuse (negative cotangent weights): a stress case for the reference conventions.
/// `V = (k+1)²`, `F = 2k²` (`k` is clamped to at least 1); vertex `(i, j)` has index `j·(k+1) + i`.
pub fn obtuse_wavy_grid(k: usize) -> TriMesh {
    let k = k.max(1);
    let mut positions = Vec::with_capacity((k + 1) * (k + 1));
    for j in 0..=k {
        for i in 0..=k {
            let u = i as f64 / k as f64;
            let v = j as f64 / k as f64;
            let x = 2.0 * u - 1.0 + 0.9 * v / k as f64 * (j % 2) as f64;
            let y = (2.0 * v - 1.0) * 0.35;
            let z = 0.25 * (3.0 * x).sin() * (2.0 * y + 0.5).cos();
            positions.push([x, y, z]);
        }
    }
    let id = |i: usize, j: usize| (j * (k + 1) + i) as u32;
    let mut faces = Vec::with_capacity(2 * k * k);
    for j in 0..k {
        for i in 0..k {
            faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::new(positions, faces)
}

fn project_to_unit_sphere(positions: &mut [[f64; 3]]) {
    for p in positions {
        let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        *p = p.map(|c| c / n);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_is_closed_outward_and_on_the_unit_sphere() {
        let m = icosphere(2);
        assert_eq!(m.faces.len(), 320);
        assert_eq!(m.positions.len(), 162); // Euler: V − E + F = 2 with E = 3F/2.
        for p in &m.positions {
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!((r - 1.0).abs() < 1e-12, "radius {r}");
        }
        let vol = crate::geometry::signed_volume(&m.positions, &m.faces);
        // Positive signed volume (outward faces), a bit below 4π/3.
        let ball = 4.0 / 3.0 * std::f64::consts::PI;
        assert!(vol > 0.9 * ball && vol < ball, "volume {vol}");
    }

    #[test]
    fn octahedron_is_closed_and_outward() {
        let m = octahedron();
        assert_eq!((m.positions.len(), m.faces.len()), (6, 8));
        // Volume of the regular octahedron with unit circumradius is 4/3; positive = outward faces.
        let vol = crate::geometry::signed_volume(&m.positions, &m.faces);
        assert!((vol - 4.0 / 3.0).abs() < 1e-12, "volume {vol}");
    }

    #[test]
    fn tetrahedron_is_closed_and_outward_with_volume_one_sixth() {
        let m = tetrahedron();
        assert_eq!((m.positions.len(), m.faces.len()), (4, 4));
        let vol = crate::geometry::signed_volume(&m.positions, &m.faces);
        assert!((vol - 1.0 / 6.0).abs() < 1e-15, "volume {vol}");
        let ef = crate::topology::EdgeFaces::new(&m.faces);
        assert!(ef.boundary_edges().is_empty());
        assert!(ef.inconsistently_oriented_edges().is_empty());
    }

    #[test]
    fn obtuse_wavy_grid_has_the_stated_counts_and_obtuse_triangles() {
        let m = obtuse_wavy_grid(8);
        assert_eq!((m.positions.len(), m.faces.len()), (81, 128));
        // Some corner angle above 90°: a negative dot product of the two edges leaving it.
        let obtuse = m
            .faces
            .iter()
            .filter(|f| {
                (0..3).any(|c| {
                    let p = |i: usize| m.positions[f[(c + i) % 3] as usize];
                    let (a, b, o) = (p(1), p(2), p(0));
                    (0..3).map(|k| (a[k] - o[k]) * (b[k] - o[k])).sum::<f64>() < 0.0
                })
            })
            .count();
        assert!(
            obtuse >= m.faces.len() / 4,
            "{obtuse} obtuse of {}",
            m.faces.len()
        );
        assert_eq!(obtuse_wavy_grid(0).faces.len(), 2, "k is clamped to 1");
    }
}
