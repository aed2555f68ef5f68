//! Triangle meshes for Geometry in Style.
//!
//! Conventions: positions are `f64` triples, faces are `u32` index triples in counter-clockwise
//! order (outward normals by the right-hand rule). Vectors are column vectors in the math docs.

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

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// Number of faces.
    pub fn num_faces(&self) -> usize {
        self.faces.len()
    }
}
