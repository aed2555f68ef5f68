//! Procedural meshes for tests, gradient checks and benchmarks, as the plain slices the renderer
//! takes.

/// [`mesh_core::shapes::icosphere`] as `(positions, faces)`: a unit-radius icosphere with
/// `20·4^subdivisions` faces (3 → 1,280, 4 → 5,120, 5 → 20,480, 6 → 81,920), CCW seen from outside.
pub fn icosphere(subdivisions: u32) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let m = mesh_core::shapes::icosphere(subdivisions);
    (m.positions, m.faces)
}
