//! Small procedural meshes for tests, gradient checks, examples and benchmarks.

use mesh_core::TriMesh;

/// An icosphere: the icosahedron subdivided `level` times (midpoint) and projected to the unit
/// sphere. Well-shaped (all weights positive). `V = 10·4^level + 2`.
pub fn icosphere(level: u32) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let raw = [
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
    let mut mesh = TriMesh::new(raw.to_vec(), faces);
    for _ in 0..level {
        mesh = mesh_core::subdivide::midpoint(&mesh);
    }
    for p in &mut mesh.positions {
        let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        *p = p.map(|c| c / n);
    }
    mesh
}

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
