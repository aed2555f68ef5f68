//! Triangle meshes for Geometry in Style.
//!
//! Conventions used throughout the crate:
//! - positions are `f64` triples `[x, y, z]` (no units; meshes are usually normalized to the side-2
//!   cube of [`normalize::side2_cube`] before anything else happens);
//! - faces are `u32` index triples in counter-clockwise order seen from outside, so the right-hand
//!   rule `(p1 − p0) × (p2 − p0)` gives the outward normal;
//! - vectors are column vectors in the math of the docs; arrays are row-major (`Vec<[f64; 3]>`).
//!
//! Layers: plain slice functions ([`geometry`], [`normals`], [`normalize`], [`topology`],
//! [`subdivide`], [`shapes`], [`region`]) work on `&[[f64; 3]]` / `&[[u32; 3]]`; [`bvh`] is the one
//! box hierarchy over a mesh's triangles (closest points, rays, box and self-overlap queries, refit);
//! [`remesh`] remeshes isotropically on it (no I/O); [`intersect`] finds the pairs of faces that
//! intersect, exactly, on the BVH and the robust orientation tests of [`predicates`]; [`validate`] checks and repairs a
//! [`TriMesh`]; with the default feature `io`, [`io`] reads and writes OBJ, OFF, PLY and glTF/GLB.
//! NumPy files live in the `npy` crate, the reference's saved-deformation `.npz` in `stylize`.

pub mod bvh;
mod error;
pub mod geometry;
pub mod intersect;
pub mod normalize;
pub mod normals;
pub mod predicates;
pub mod region;
pub mod remesh;
pub mod shapes;
pub mod subdivide;
pub mod topology;
pub mod validate;

#[cfg(feature = "io")]
pub mod io;

pub use error::MeshError;

/// An indexed triangle mesh: `f64` positions, `u32` CCW faces.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<[f64; 3]>,
    /// Triangles as vertex indices, counter-clockwise seen from outside.
    pub faces: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Builds a mesh from positions and faces without checking anything (see the validation module).
    pub fn new(positions: Vec<[f64; 3]>, faces: Vec<[u32; 3]>) -> Self {
        Self { positions, faces }
    }

    /// The `(positions, faces)` pair, for the slice APIs (`cotan`, `darap`, `raster-diff`).
    pub fn into_parts(self) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        (self.positions, self.faces)
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// Number of faces.
    pub fn num_faces(&self) -> usize {
        self.faces.len()
    }
}
