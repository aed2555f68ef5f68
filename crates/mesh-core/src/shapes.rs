//! Procedural meshes for tests, gradient checks, examples and benchmarks.

use crate::TriMesh;
use crate::subdivide;

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
}
