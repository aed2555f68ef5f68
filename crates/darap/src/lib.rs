//! Differentiable ARAP (dARAP): per-vertex target normals to a deformed mesh, with adjoints.
