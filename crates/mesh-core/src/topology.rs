//! Combinatorial structure of a triangle list: edges, vertex→face adjacency (CSR), connected
//! components, boundary and non-manifold edges, orientation consistency.
//!
//! Everything here looks at indices only (no positions). Faces must index below `num_vertices`
//! where a function takes it; functions that only take `faces` accept any indices.

/// Labels every vertex with its connected component (two vertices are connected when a chain of
/// face edges joins them). Returns `(label per vertex, number of components)`.
///
/// Labels are numbered in order of each component's smallest vertex index, so the component of
/// vertex 0 is label 0 and "the first vertex of each component" is the one to pin. A vertex used by
/// no face is a component of its own. Face indices ≥ `num_vertices` are ignored.
pub fn connected_components(num_vertices: usize, faces: &[[u32; 3]]) -> (Vec<u32>, usize) {
    let edges = faces
        .iter()
        .filter(|f| f.iter().all(|&v| (v as usize) < num_vertices))
        .flat_map(|f| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]]);
    graph_components(num_vertices, edges)
}

/// [`connected_components`] of a graph given by its edges (each `[a, b]` joins `a` and `b`; any
/// order, repeats and self-loops allowed), e.g. the sparsity pattern of a matrix. Same labels:
/// numbered in order of each component's smallest vertex, an isolated vertex is a component of
/// its own. Edges with an endpoint ≥ `num_vertices` are ignored.
pub fn graph_components(
    num_vertices: usize,
    edges: impl IntoIterator<Item = [u32; 2]>,
) -> (Vec<u32>, usize) {
    let mut parent: Vec<u32> = (0..num_vertices as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            let p = parent[x as usize];
            parent[x as usize] = parent[p as usize];
            x = p;
        }
        x
    }
    for [a, b] in edges {
        if a as usize >= num_vertices || b as usize >= num_vertices {
            continue;
        }
        let a = find(&mut parent, a);
        let b = find(&mut parent, b);
        if a != b {
            // Keep the smaller index as the root so roots are each component's minimum.
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            parent[hi as usize] = lo;
        }
    }
    let mut label = vec![u32::MAX; num_vertices];
    let mut count = 0usize;
    for v in 0..num_vertices {
        let r = find(&mut parent, v as u32) as usize;
        if label[r] == u32::MAX {
            label[r] = count as u32;
            count += 1;
        }
        label[v] = label[r];
    }
    (label, count)
}

/// One vertex per component: the smallest vertex index of each (index = component label).
pub fn component_representatives(labels: &[u32], count: usize) -> Vec<u32> {
    let mut rep = vec![u32::MAX; count];
    for (v, &l) in labels.iter().enumerate() {
        if rep[l as usize] == u32::MAX {
            rep[l as usize] = v as u32;
        }
    }
    rep
}

/// Vertex → incident faces in compressed sparse row form: the faces around vertex `v` are
/// `faces[offsets[v]..offsets[v + 1]]`, in increasing face order. A face with a repeated vertex is
/// listed once per corner.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VertexFaces {
    /// `num_vertices + 1` offsets into `faces`.
    pub offsets: Vec<u32>,
    /// Face indices, grouped by vertex.
    pub faces: Vec<u32>,
}

impl VertexFaces {
    /// Faces incident to vertex `v`.
    pub fn of(&self, v: usize) -> &[u32] {
        &self.faces[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }
}

/// Builds the vertex → face CSR. Face indices ≥ `num_vertices` are skipped.
pub fn vertex_faces(num_vertices: usize, faces: &[[u32; 3]]) -> VertexFaces {
    let mut counts = vec![0u32; num_vertices + 1];
    for f in faces {
        for &v in f {
            if (v as usize) < num_vertices {
                counts[v as usize + 1] += 1;
            }
        }
    }
    for i in 0..num_vertices {
        counts[i + 1] += counts[i];
    }
    let offsets = counts.clone();
    let mut next = counts;
    let mut out = vec![0u32; offsets[num_vertices] as usize];
    for (fi, f) in faces.iter().enumerate() {
        for &v in f {
            if (v as usize) < num_vertices {
                out[next[v as usize] as usize] = fi as u32;
                next[v as usize] += 1;
            }
        }
    }
    VertexFaces {
        offsets,
        faces: out,
    }
}

/// A face's use of an undirected edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EdgeUse {
    /// The face.
    pub face: u32,
    /// `true` when the face traverses the edge as `a → b` (with `a < b` the edge's key),
    /// `false` for `b → a`.
    pub forward: bool,
}

/// All undirected edges with the faces that use them (CSR over edges).
///
/// Edges are keyed `[a, b]` with `a < b`, sorted lexicographically. Edges of a face with a
/// repeated vertex (`a == b`) are left out.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EdgeFaces {
    /// Undirected edges `[a, b]`, `a < b`, sorted.
    pub edges: Vec<[u32; 2]>,
    /// `edges.len() + 1` offsets into `uses`.
    pub offsets: Vec<u32>,
    /// Face uses of each edge, grouped by edge, in increasing face order.
    pub uses: Vec<EdgeUse>,
}

impl EdgeFaces {
    /// Builds the edge table from a triangle list.
    pub fn new(faces: &[[u32; 3]]) -> Self {
        let mut half: Vec<(u32, u32, u32, bool)> = Vec::with_capacity(faces.len() * 3);
        for (fi, f) in faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                if a == b {
                    continue;
                }
                let forward = a < b;
                let (lo, hi) = if forward { (a, b) } else { (b, a) };
                half.push((lo, hi, fi as u32, forward));
            }
        }
        half.sort_unstable();
        let mut edges = Vec::new();
        let mut offsets = vec![0u32];
        let mut uses = Vec::with_capacity(half.len());
        for (i, &(a, b, face, forward)) in half.iter().enumerate() {
            if i > 0 && (half[i - 1].0, half[i - 1].1) != (a, b) {
                offsets.push(uses.len() as u32);
            }
            if i == 0 || (half[i - 1].0, half[i - 1].1) != (a, b) {
                edges.push([a, b]);
            }
            uses.push(EdgeUse { face, forward });
        }
        offsets.push(uses.len() as u32);
        if edges.is_empty() {
            offsets = vec![0];
        }
        Self {
            edges,
            offsets,
            uses,
        }
    }

    /// Number of undirected edges.
    pub fn len(&self) -> usize {
        self.edges.len()
    }

    /// `true` when there are no edges.
    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }

    /// Face uses of edge `e`.
    pub fn uses_of(&self, e: usize) -> &[EdgeUse] {
        &self.uses[self.offsets[e] as usize..self.offsets[e + 1] as usize]
    }

    /// Edges used by exactly one face, directed as that face traverses them (so a boundary loop
    /// runs CCW around the hole's outside).
    pub fn boundary_edges(&self) -> Vec<[u32; 2]> {
        (0..self.len())
            .filter_map(|e| match self.uses_of(e) {
                [u] => {
                    let [a, b] = self.edges[e];
                    Some(if u.forward { [a, b] } else { [b, a] })
                }
                _ => None,
            })
            .collect()
    }

    /// Edges used by more than two faces (`[a, b]`, `a < b`).
    pub fn non_manifold_edges(&self) -> Vec<[u32; 2]> {
        (0..self.len())
            .filter(|&e| self.uses_of(e).len() > 2)
            .map(|e| self.edges[e])
            .collect()
    }

    /// Manifold edges (exactly two faces) that both faces traverse in the same direction: the two
    /// faces disagree on which side is outside.
    pub fn inconsistently_oriented_edges(&self) -> Vec<[u32; 2]> {
        (0..self.len())
            .filter(|&e| matches!(self.uses_of(e), [u, w] if u.forward == w.forward))
            .map(|e| self.edges[e])
            .collect()
    }
}

/// Undirected edges `[a, b]` (`a < b`), sorted, each once.
pub fn edges(faces: &[[u32; 3]]) -> Vec<[u32; 2]> {
    EdgeFaces::new(faces).edges
}

/// Boundary edges (used by exactly one face), directed as their face traverses them.
pub fn boundary_edges(faces: &[[u32; 3]]) -> Vec<[u32; 2]> {
    EdgeFaces::new(faces).boundary_edges()
}

/// Edges used by more than two faces.
pub fn non_manifold_edges(faces: &[[u32; 3]]) -> Vec<[u32; 2]> {
    EdgeFaces::new(faces).non_manifold_edges()
}

/// Result of [`orient_consistently`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Orientation {
    /// The faces, some flipped (`[a, b, c] → [a, c, b]`) so that every manifold edge is traversed in
    /// opposite directions by its two faces, where that is possible.
    pub faces: Vec<[u32; 3]>,
    /// Indices of the faces that were flipped.
    pub flipped: Vec<u32>,
    /// `false` when some face patch is non-orientable (a Möbius-like strip): then some manifold
    /// edges stay inconsistent whatever is flipped.
    pub orientable: bool,
}

/// Flips faces so that neighbours across manifold edges agree (breadth-first over each face patch,
/// keeping the orientation of the patch's lowest-numbered face). Non-manifold edges (> 2 faces) do
/// not propagate orientation. Which of the two consistent orientations a patch ends in is decided by
/// its first face; use the signed volume to choose outward (see [`crate::validate::repair`]).
pub fn orient_consistently(faces: &[[u32; 3]]) -> Orientation {
    let ef = EdgeFaces::new(faces);
    // Face adjacency through manifold edges: (neighbour, same_direction).
    let mut adj: Vec<Vec<(u32, bool)>> = vec![Vec::new(); faces.len()];
    for e in 0..ef.len() {
        if let [u, w] = ef.uses_of(e)
            && u.face != w.face
        {
            let same = u.forward == w.forward;
            adj[u.face as usize].push((w.face, same));
            adj[w.face as usize].push((u.face, same));
        }
    }
    // flip[f] = Some(bool) once visited.
    let mut flip: Vec<Option<bool>> = vec![None; faces.len()];
    let mut orientable = true;
    let mut queue = std::collections::VecDeque::new();
    for start in 0..faces.len() {
        if flip[start].is_some() {
            continue;
        }
        flip[start] = Some(false);
        queue.push_back(start as u32);
        while let Some(f) = queue.pop_front() {
            let ff = flip[f as usize].unwrap_or(false);
            for &(g, same) in &adj[f as usize] {
                // If both traverse the edge the same way, exactly one of them must be flipped.
                let want = ff ^ same;
                match flip[g as usize] {
                    None => {
                        flip[g as usize] = Some(want);
                        queue.push_back(g);
                    }
                    Some(have) if have != want => orientable = false,
                    Some(_) => {}
                }
            }
        }
    }
    let mut out = faces.to_vec();
    let mut flipped = Vec::new();
    for (i, f) in out.iter_mut().enumerate() {
        if flip[i] == Some(true) {
            *f = [f[0], f[2], f[1]];
            flipped.push(i as u32);
        }
    }
    Orientation {
        faces: out,
        flipped,
        orientable,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tet_faces() -> Vec<[u32; 3]> {
        crate::shapes::tetrahedron().faces
    }

    #[test]
    fn closed_tetrahedron_has_six_edges_no_boundary_and_consistent_orientation() {
        let ef = EdgeFaces::new(&tet_faces());
        assert_eq!(ef.len(), 6);
        assert!(ef.boundary_edges().is_empty());
        assert!(ef.non_manifold_edges().is_empty());
        assert!(ef.inconsistently_oriented_edges().is_empty());
        // Euler characteristic of a sphere: V − E + F = 2.
        assert_eq!(4 - ef.len() as i64 + 4, 2);
    }

    #[test]
    fn graph_components_join_edge_endpoints_and_ignore_out_of_range_edges() {
        let (labels, n) = graph_components(5, [[4, 2], [2, 2], [1, 9]]);
        assert_eq!(n, 4, "{{2, 4}}, {{0}}, {{1}}, {{3}}");
        assert_eq!(labels, vec![0, 1, 2, 3, 2]);
    }

    #[test]
    fn two_disjoint_triangles_are_two_components_labelled_by_smallest_vertex() {
        let faces = vec![[3, 4, 5], [0, 1, 2]];
        let (labels, n) = connected_components(7, &faces);
        assert_eq!(n, 3, "two triangles plus the isolated vertex 6");
        assert_eq!(labels, vec![0, 0, 0, 1, 1, 1, 2]);
        assert_eq!(component_representatives(&labels, n), vec![0, 3, 6]);
    }

    #[test]
    fn single_triangle_boundary_follows_face_direction() {
        let b = boundary_edges(&[[0, 1, 2]]);
        let mut b2 = b.clone();
        b2.sort();
        assert_eq!(b2, vec![[0, 1], [1, 2], [2, 0]]);
    }

    #[test]
    fn three_faces_on_one_edge_are_non_manifold() {
        let faces = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        assert_eq!(non_manifold_edges(&faces), vec![[0, 1]]);
    }

    #[test]
    fn vertex_face_csr_lists_incident_faces() {
        let vf = vertex_faces(4, &tet_faces());
        assert_eq!(vf.of(0), &[0, 1, 2]);
        assert_eq!(vf.of(3), &[1, 2, 3]);
    }

    #[test]
    fn one_flipped_face_is_detected_and_reoriented() {
        let mut faces = tet_faces();
        faces[3] = [1, 3, 2];
        let ef = EdgeFaces::new(&faces);
        assert_eq!(ef.inconsistently_oriented_edges().len(), 3);
        let o = orient_consistently(&faces);
        assert!(o.orientable);
        assert!(
            EdgeFaces::new(&o.faces)
                .inconsistently_oriented_edges()
                .is_empty()
        );
        // Patch keeps face 0's orientation, so only face 3 flips back.
        assert_eq!(o.flipped, vec![3]);
        assert_eq!(o.faces, tet_faces());
    }

    #[test]
    fn mobius_strip_is_not_orientable() {
        // A 5-quad Möbius band triangulated (10 triangles), vertices 0..9 with a half twist.
        let n = 5u32;
        let mut faces = Vec::new();
        for i in 0..n {
            let (a, b) = (i, i + n);
            let (c, d) = if i + 1 < n {
                (i + 1, i + 1 + n)
            } else {
                (n, 0)
            };
            faces.push([a, c, b]);
            faces.push([b, c, d]);
        }
        let o = orient_consistently(&faces);
        assert!(!o.orientable);
    }
}
