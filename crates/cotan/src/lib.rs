//! Cotangent Laplacian in the reference convention, mixed-Voronoi mass, pinned sparse Cholesky.
