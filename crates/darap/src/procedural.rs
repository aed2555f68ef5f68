//! Small procedural meshes for tests, gradient checks, examples and benchmarks.

use mesh_core::TriMesh;

pub use mesh_core::shapes::icosphere;

/// An open, wavy `k×k` grid over `[−1, 1]²` whose cells are sheared so that half of the triangles
/// are obtuse (negative cotangent weights): a stress case for the reference conventions.
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
