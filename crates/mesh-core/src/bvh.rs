//! A bounding-volume hierarchy over the triangles of a mesh: closest points, rays, boxes and the
//! self-overlap traversal, with a refit after the vertices move.
//!
//! The tree is an axis-aligned box hierarchy built once from `(positions, faces)` by median splits:
//! every node's faces are split in two equal halves along the longest axis of their centroids'
//! bounding box (ties by face index, so the tree is a pure function of the input), down to leaves
//! of at most [`LEAF_SIZE`] faces. The depth is therefore at most `⌈log₂(F / LEAF_SIZE)⌉ + 1`
//! (≤ 32 for any `u32` face count). Nodes are stored in pre-order, so every child has a larger
//! index than its parent and [`Bvh::refit`] recomputes the boxes bottom-up in one backward pass
//! without touching the tree's shape. (The self-intersection checker builds only the pair traversal's
//! compact tree, by a Morton sort, straight from the vertices: `PairTree::for_mesh`.)
//!
//! Conventions:
//! - boxes are closed: two boxes that touch at a face, edge or corner overlap;
//! - a face's box is the bounding box of its three corners, so degenerate (zero-area, even
//!   repeated-vertex) faces are ordinary members: their closest point is the closest point of the
//!   segment or point they collapse to, and they take part in box and pair queries;
//! - rays never hit a degenerate face or a face parallel to the ray (the Möller–Trumbore
//!   determinant is zero); hits on edges and corners count (barycentrics ≥ 0 inclusive);
//! - barycentrics `[w0, w1, w2]` weight the face's corners in the order the face lists them, so
//!   `point = w0·p0 + w1·p1 + w2·p2` and `w0 + w1 + w2 = 1`;
//! - ties are broken by the lowest face index (closest point, equal ray `t`), so every answer is
//!   deterministic and equal to the brute-force scan over faces in index order.

use crate::geometry::{cross, dot, sub};

/// Most faces per leaf.
pub const LEAF_SIZE: usize = 4;

/// What [`Bvh::new`] and [`Bvh::refit`] refuse.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum BvhError {
    /// A face names a vertex that does not exist.
    #[error("face {face} uses vertex {index}, but the mesh has only {num_vertices} vertices")]
    FaceIndex {
        /// The face.
        face: usize,
        /// The out-of-range vertex index.
        index: u32,
        /// The number of positions given.
        num_vertices: usize,
    },
    /// A vertex used by a face has a NaN or infinite coordinate.
    #[error("vertex {vertex} has a non-finite coordinate {position:?}")]
    NonFinite {
        /// The vertex.
        vertex: usize,
        /// Its position.
        position: [f64; 3],
    },
    /// [`Bvh::refit`] was given a different number of vertices than the tree was built with.
    #[error("refit: the tree was built over {expected} vertices, got {got}")]
    VertexCount {
        /// Vertices at build time.
        expected: usize,
        /// Vertices given to refit.
        got: usize,
    },
}

/// An axis-aligned box `[lo, hi]` (closed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub lo: [f64; 3],
    /// Largest corner.
    pub hi: [f64; 3],
}

impl Aabb {
    /// The empty box (`lo = +∞`, `hi = −∞`): the identity of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb {
        lo: [f64::INFINITY; 3],
        hi: [f64::NEG_INFINITY; 3],
    };

    /// The bounding box of some points.
    pub fn of_points(points: &[[f64; 3]]) -> Aabb {
        let mut b = Aabb::EMPTY;
        for &p in points {
            b.grow(p);
        }
        b
    }

    /// Enlarges the box to contain `p`.
    #[inline]
    pub fn grow(&mut self, p: [f64; 3]) {
        for k in 0..3 {
            self.lo[k] = self.lo[k].min(p[k]);
            self.hi[k] = self.hi[k].max(p[k]);
        }
    }

    /// The smallest box containing both.
    #[inline]
    pub fn union(&self, other: &Aabb) -> Aabb {
        let mut b = *self;
        for k in 0..3 {
            b.lo[k] = b.lo[k].min(other.lo[k]);
            b.hi[k] = b.hi[k].max(other.hi[k]);
        }
        b
    }

    /// Whether the closed boxes share a point.
    #[inline]
    pub fn overlaps(&self, other: &Aabb) -> bool {
        (0..3).all(|k| self.lo[k] <= other.hi[k] && other.lo[k] <= self.hi[k])
    }

    /// Squared distance from `p` to the box (0 inside).
    #[inline]
    pub fn distance_squared(&self, p: [f64; 3]) -> f64 {
        let mut d2 = 0.0;
        for k in 0..3 {
            let d = if p[k] < self.lo[k] {
                self.lo[k] - p[k]
            } else if p[k] > self.hi[k] {
                p[k] - self.hi[k]
            } else {
                0.0
            };
            d2 += d * d;
        }
        d2
    }

    /// The parameter interval `[t0, t1]` (clipped to `[0, t_max]`) where the ray
    /// `origin + t·direction` is inside the box, or `None`.
    fn ray_interval(
        &self,
        origin: [f64; 3],
        inv: [f64; 3],
        dir: [f64; 3],
        t_max: f64,
    ) -> Option<f64> {
        let mut t0 = 0.0f64;
        let mut t1 = t_max;
        for k in 0..3 {
            if dir[k] == 0.0 {
                if origin[k] < self.lo[k] || origin[k] > self.hi[k] {
                    return None;
                }
                continue;
            }
            let a = (self.lo[k] - origin[k]) * inv[k];
            let b = (self.hi[k] - origin[k]) * inv[k];
            let (near, far) = if a <= b { (a, b) } else { (b, a) };
            t0 = t0.max(near);
            t1 = t1.min(far);
            if t0 > t1 {
                return None;
            }
        }
        Some(t0)
    }
}

/// The answer of [`Bvh::closest_point`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClosestPoint {
    /// The face the closest point lies on (lowest index among equally close faces).
    pub face: u32,
    /// The closest point.
    pub point: [f64; 3],
    /// Its barycentric coordinates in the face (corner order as the face lists them).
    pub barycentric: [f64; 3],
    /// Squared distance from the query point.
    pub distance_squared: f64,
}

/// One ray–triangle intersection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// The face hit.
    pub face: u32,
    /// Ray parameter: the hit point is `origin + t·direction`.
    pub t: f64,
    /// Barycentric coordinates of the hit point in the face.
    pub barycentric: [f64; 3],
}

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first index into `order`; interior: index of the right child (the left child is the
    /// next node).
    start: u32,
    /// Leaf: number of faces (≥ 1); interior: 0.
    count: u32,
}

/// A box hierarchy over a triangle mesh (see the [module docs](self) for the conventions).
#[derive(Clone, Debug)]
pub struct Bvh {
    nodes: Vec<Node>,
    order: Vec<u32>,
    faces: Vec<[u32; 3]>,
    tris: Vec<[[f64; 3]; 3]>,
    boxes: Vec<Aabb>,
    num_vertices: usize,
}

/// The corners of face `fi`, refusing an index out of range and a non-finite corner.
pub(crate) fn face_triangle(
    positions: &[[f64; 3]],
    fi: usize,
    f: [u32; 3],
) -> Result<[[f64; 3]; 3], BvhError> {
    let mut t = [[0.0; 3]; 3];
    for (k, &v) in f.iter().enumerate() {
        let p = *positions.get(v as usize).ok_or(BvhError::FaceIndex {
            face: fi,
            index: v,
            num_vertices: positions.len(),
        })?;
        if !p.iter().all(|c| c.is_finite()) {
            return Err(BvhError::NonFinite {
                vertex: v as usize,
                position: p,
            });
        }
        t[k] = p;
    }
    Ok(t)
}

fn triangles(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<Vec<[[f64; 3]; 3]>, BvhError> {
    faces
        .iter()
        .enumerate()
        .map(|(fi, &f)| face_triangle(positions, fi, f))
        .collect()
}

impl Bvh {
    /// Builds the tree. Refuses a face index out of range and a non-finite vertex used by a face;
    /// an empty face list gives an empty tree (every query answers nothing).
    pub fn new(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<Bvh, BvhError> {
        let tris = triangles(positions, faces)?;
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(2 * faces.len() / LEAF_SIZE + 1),
            order: Vec::new(),
            faces: faces.to_vec(),
            boxes: tris.iter().map(|t| Aabb::of_points(t)).collect(),
            tris,
            num_vertices: positions.len(),
        };
        if !faces.is_empty() {
            // The faces carry their centroids through the partitions (no indirection per
            // comparison); the boxes are filled bottom-up afterwards.
            let mut items: Vec<(u32, [f64; 3])> = bvh
                .tris
                .iter()
                .enumerate()
                .map(|(f, t)| {
                    let mut c = [0.0; 3];
                    for k in 0..3 {
                        c[k] = (t[0][k] + t[1][k] + t[2][k]) / 3.0;
                    }
                    (f as u32, c)
                })
                .collect();
            bvh.build(&mut items, 0);
            bvh.order = items.iter().map(|&(f, _)| f).collect();
            bvh.fill_bounds();
        }
        Ok(bvh)
    }

    /// Every node's box from its faces' (leaves) or children's (interior nodes), bottom-up.
    fn fill_bounds(&mut self) {
        for i in (0..self.nodes.len()).rev() {
            let n = self.nodes[i];
            let bounds = if n.count > 0 {
                let mut b = Aabb::EMPTY;
                for &f in &self.order[n.start as usize..(n.start + n.count) as usize] {
                    b = b.union(&self.boxes[f as usize]);
                }
                b
            } else {
                self.nodes[i + 1]
                    .bounds
                    .union(&self.nodes[n.start as usize].bounds)
            };
            self.nodes[i].bounds = bounds;
        }
    }

    #[inline]
    fn face_bounds(&self, f: u32) -> Aabb {
        self.boxes[f as usize]
    }

    /// Builds the subtree over `items[..]` (faces with their centroids; the slice starts at
    /// `offset` in the full order). Node boxes are left empty for [`Bvh::fill_bounds`].
    fn build(&mut self, items: &mut [(u32, [f64; 3])], offset: usize) {
        let me = self.nodes.len();
        self.nodes.push(Node {
            bounds: Aabb::EMPTY,
            start: offset as u32,
            count: items.len() as u32,
        });
        if items.len() <= LEAF_SIZE {
            return;
        }
        let mut cbounds = Aabb::EMPTY;
        for (_, c) in items.iter() {
            cbounds.grow(*c);
        }
        let ext = sub(cbounds.hi, cbounds.lo);
        let axis = if ext[0] >= ext[1] && ext[0] >= ext[2] {
            0
        } else if ext[1] >= ext[2] {
            1
        } else {
            2
        };
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |a, b| {
            a.1[axis].total_cmp(&b.1[axis]).then(a.0.cmp(&b.0))
        });
        let (left, right) = items.split_at_mut(mid);
        self.build(left, offset);
        let right_index = self.nodes.len() as u32;
        self.build(right, offset + mid);
        self.nodes[me].start = right_index;
        self.nodes[me].count = 0;
    }

    /// Number of faces in the tree.
    pub fn len(&self) -> usize {
        self.faces.len()
    }

    /// Whether the tree holds no face.
    pub fn is_empty(&self) -> bool {
        self.faces.is_empty()
    }

    /// The faces the tree was built over.
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.faces
    }

    /// The corners of face `f` as the tree currently sees them (after the last refit).
    pub fn triangle(&self, f: u32) -> [[f64; 3]; 3] {
        self.tris[f as usize]
    }

    /// Number of nodes and the depth of the deepest leaf (the root has depth 1; 0 when empty).
    pub fn shape(&self) -> (usize, usize) {
        fn depth(nodes: &[Node], i: usize) -> usize {
            let n = &nodes[i];
            if n.count > 0 {
                1
            } else {
                1 + depth(nodes, i + 1).max(depth(nodes, n.start as usize))
            }
        }
        if self.nodes.is_empty() {
            (0, 0)
        } else {
            (self.nodes.len(), depth(&self.nodes, 0))
        }
    }

    /// Recomputes every box for moved vertices (same faces, same tree): `O(F)`, no allocation.
    /// Queries afterwards answer for the new positions exactly as a rebuilt tree would (the tree's
    /// shape may be less tight than a rebuild's, never wrong). Refuses a different vertex count or
    /// a non-finite vertex (the tree is left unchanged then).
    pub fn refit(&mut self, positions: &[[f64; 3]]) -> Result<(), BvhError> {
        if positions.len() != self.num_vertices {
            return Err(BvhError::VertexCount {
                expected: self.num_vertices,
                got: positions.len(),
            });
        }
        for f in &self.faces {
            for &v in f {
                let p = positions[v as usize];
                if !p.iter().all(|c| c.is_finite()) {
                    return Err(BvhError::NonFinite {
                        vertex: v as usize,
                        position: p,
                    });
                }
            }
        }
        for ((t, b), f) in self.tris.iter_mut().zip(&mut self.boxes).zip(&self.faces) {
            *t = [
                positions[f[0] as usize],
                positions[f[1] as usize],
                positions[f[2] as usize],
            ];
            *b = Aabb::of_points(t);
        }
        self.fill_bounds();
        Ok(())
    }

    /// The closest point of the surface to `p` (`None` for an empty tree or a non-finite `p`).
    pub fn closest_point(&self, p: [f64; 3]) -> Option<ClosestPoint> {
        self.closest_point_filtered(p, |_| true)
    }

    /// [`closest_point`](Self::closest_point) among the faces `accept` returns true for.
    pub fn closest_point_filtered(
        &self,
        p: [f64; 3],
        accept: impl Fn(u32) -> bool,
    ) -> Option<ClosestPoint> {
        self.closest_inner(p, accept, None)
    }

    /// [`closest_point`](Self::closest_point) with a guess: the search starts from face `hint`'s
    /// distance (e.g. the face a point projected onto before it moved a little), which prunes more
    /// of the tree. The answer is the same as without the hint; an out-of-range hint is ignored.
    pub fn closest_point_hinted(&self, p: [f64; 3], hint: u32) -> Option<ClosestPoint> {
        self.closest_inner(p, |_| true, Some(hint))
    }

    /// [`closest_point_filtered`](Self::closest_point_filtered) with a guess, as
    /// [`closest_point_hinted`](Self::closest_point_hinted) (a hint `accept` rejects is ignored):
    /// the same answer as without the hint.
    pub fn closest_point_filtered_hinted(
        &self,
        p: [f64; 3],
        hint: u32,
        accept: impl Fn(u32) -> bool,
    ) -> Option<ClosestPoint> {
        self.closest_inner(p, accept, Some(hint))
    }

    fn closest_inner(
        &self,
        p: [f64; 3],
        accept: impl Fn(u32) -> bool,
        hint: Option<u32>,
    ) -> Option<ClosestPoint> {
        if self.nodes.is_empty() || !p.iter().all(|c| c.is_finite()) {
            return None;
        }
        let mut best: Option<ClosestPoint> = None;
        let mut best_d2 = f64::INFINITY;
        if let Some(f) = hint
            && (f as usize) < self.tris.len()
            && accept(f)
        {
            let (q, w) = closest_on_triangle(p, &self.tris[f as usize]);
            let d = sub(q, p);
            best_d2 = dot(d, d);
            best = Some(ClosestPoint {
                face: f,
                point: q,
                barycentric: w,
                distance_squared: best_d2,
            });
        }
        // Depth-first with the nearer child on top: at most depth + 1 ≤ 34 entries (module docs).
        let mut stack = [0u32; 128];
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let i = stack[top];
            let n = &self.nodes[i as usize];
            // Prune only boxes clearly farther than the best (a little slack covers the rounding
            // of the box distance against the triangle distance, so no closer face is missed).
            if n.bounds.distance_squared(p) * (1.0 - 1e-9) > best_d2 {
                continue;
            }
            if n.count > 0 {
                for &f in &self.order[n.start as usize..(n.start + n.count) as usize] {
                    if !accept(f) {
                        continue;
                    }
                    let (q, w) = closest_on_triangle(p, &self.tris[f as usize]);
                    let d = sub(q, p);
                    let d2 = dot(d, d);
                    let better = match best {
                        None => true,
                        Some(b) => d2 < best_d2 || (d2 == best_d2 && f < b.face),
                    };
                    if better {
                        best_d2 = d2;
                        best = Some(ClosestPoint {
                            face: f,
                            point: q,
                            barycentric: w,
                            distance_squared: d2,
                        });
                    }
                }
            } else {
                // Visit the nearer child first.
                let l = i + 1;
                let r = n.start;
                let dl = self.nodes[l as usize].bounds.distance_squared(p);
                let dr = self.nodes[r as usize].bounds.distance_squared(p);
                let (near, far) = if dl <= dr { (l, r) } else { (r, l) };
                stack[top] = far;
                stack[top + 1] = near;
                top += 2;
            }
        }
        best
    }

    /// The first hit of the ray `origin + t·direction`, `0 ≤ t ≤ t_max` (`f64::INFINITY` for no
    /// limit); ties in `t` go to the lowest face index. `direction` need not be unit length (`t`
    /// is in its units). `None` for no hit, a zero or non-finite direction or origin.
    pub fn ray_first_hit(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        t_max: f64,
    ) -> Option<RayHit> {
        let mut best: Option<RayHit> = None;
        self.ray_walk(origin, direction, t_max, |bvh, f, lim| {
            if let Some((t, w)) = ray_triangle(origin, direction, &bvh.tris[f as usize])
                && t <= *lim
            {
                let better = match best {
                    None => true,
                    Some(b) => t < b.t || (t == b.t && f < b.face),
                };
                if better {
                    *lim = t;
                    best = Some(RayHit {
                        face: f,
                        t,
                        barycentric: w,
                    });
                }
            }
        });
        best
    }

    /// Every hit of the ray with `0 ≤ t ≤ t_max`, sorted by `t` then face index.
    pub fn ray_hits(&self, origin: [f64; 3], direction: [f64; 3], t_max: f64) -> Vec<RayHit> {
        let mut hits = Vec::new();
        self.ray_walk(origin, direction, t_max, |bvh, f, _| {
            if let Some((t, w)) = ray_triangle(origin, direction, &bvh.tris[f as usize])
                && t <= t_max
            {
                hits.push(RayHit {
                    face: f,
                    t,
                    barycentric: w,
                });
            }
        });
        hits.sort_by(|a, b| a.t.total_cmp(&b.t).then(a.face.cmp(&b.face)));
        hits
    }

    fn ray_walk(
        &self,
        origin: [f64; 3],
        dir: [f64; 3],
        t_max: f64,
        mut visit: impl FnMut(&Bvh, u32, &mut f64),
    ) {
        let finite = origin.iter().chain(dir.iter()).all(|c| c.is_finite());
        if self.nodes.is_empty() || !finite || dir == [0.0; 3] || t_max.is_nan() || t_max < 0.0 {
            return;
        }
        let inv = [1.0 / dir[0], 1.0 / dir[1], 1.0 / dir[2]];
        let mut limit = t_max;
        let mut stack: Vec<u32> = vec![0];
        while let Some(i) = stack.pop() {
            let n = &self.nodes[i as usize];
            if n.bounds.ray_interval(origin, inv, dir, limit).is_none() {
                continue;
            }
            if n.count > 0 {
                for &f in &self.order[n.start as usize..(n.start + n.count) as usize] {
                    visit(self, f, &mut limit);
                }
            } else {
                stack.push(n.start);
                stack.push(i + 1);
            }
        }
    }

    /// The faces whose boxes overlap `query` (closed boxes), in increasing order.
    pub fn faces_overlapping(&self, query: &Aabb) -> Vec<u32> {
        let mut out = Vec::new();
        if self.nodes.is_empty() {
            return out;
        }
        let mut stack: Vec<u32> = vec![0];
        while let Some(i) = stack.pop() {
            let n = &self.nodes[i as usize];
            if !n.bounds.overlaps(query) {
                continue;
            }
            if n.count > 0 {
                for &f in &self.order[n.start as usize..(n.start + n.count) as usize] {
                    if self.face_bounds(f).overlaps(query) {
                        out.push(f);
                    }
                }
            } else {
                stack.push(n.start);
                stack.push(i + 1);
            }
        }
        out.sort_unstable();
        out
    }

    /// Calls `pair(a, b)` once for every pair of distinct faces `a < b` whose boxes overlap (a face
    /// is never paired with itself; faces sharing a vertex are included — the caller decides what
    /// adjacency means). The order of the calls follows the tree.
    pub fn for_each_overlapping_pair(&self, mut pair: impl FnMut(u32, u32)) {
        let boxes = &self.boxes;
        self.for_each_candidate_pair(|f, g| {
            if boxes[f as usize].overlaps(&boxes[g as usize]) {
                pair(f, g);
            }
        });
    }

    /// [`for_each_overlapping_pair`](Self::for_each_overlapping_pair) without its final `f64` box
    /// test: every overlapping pair once, plus the rare pairs whose boxes are apart by less than
    /// their `f32` rounding (a relative 2⁻²⁴) — for callers that test each pair exactly anyway.
    ///
    /// The traversal works on a compact copy of the tree: boxes in `f32`, each rounded outward
    /// (so no overlapping pair is missed), the faces' boxes in leaf order, one array per
    /// coordinate, and every subtree of at most `PAIR_LEAF` (32) faces treated as one leaf: a
    /// face is tested against all the faces of a leaf at once, without branches, into a bit
    /// mask. A node pair is pushed only after its boxes were found to overlap, and each face of
    /// one leaf is tested against the other leaf's box first.
    pub fn for_each_candidate_pair(&self, mut pair: impl FnMut(u32, u32)) {
        let order = &self.order;
        if let Some(tree) = self.pair_tree() {
            tree.traverse(&[(0, 0)], |x, y| {
                let (f, g) = (order[x], order[y]);
                pair(f.min(g), f.max(g));
            });
        }
    }

    /// The compact tree the pair traversal walks (`None` for an empty tree), for callers that
    /// split the traversal into tasks ([`PairTree::tasks`]).
    pub(crate) fn pair_tree(&self) -> Option<PairTree> {
        if self.nodes.is_empty() {
            return None;
        }
        Some(PairTree {
            nodes: self.pair_nodes(),
            leaf: LeafBoxes::new(self.order.iter().map(|&f| &self.boxes[f as usize])),
        })
    }

    /// The compact tree of [`for_each_overlapping_pair`](Self::for_each_overlapping_pair).
    fn pair_nodes(&self) -> Vec<PairNode> {
        let mut out: Vec<PairNode> = self
            .nodes
            .iter()
            .map(|n| PairNode {
                bounds: Box32::outward(&n.bounds),
                right: if n.count > 0 { 0 } else { n.start },
                first: n.start,
                count: n.count,
            })
            .collect();
        // Children come after their parent: fill the subtrees' face ranges backwards.
        for i in (0..out.len()).rev() {
            if self.nodes[i].count == 0 {
                let (l, r) = (&out[i + 1], &out[out[i].right as usize]);
                let (first, count) = (l.first, l.count + r.count);
                out[i].first = first;
                out[i].count = count;
            }
        }
        out
    }

    /// [`for_each_overlapping_pair`](Self::for_each_overlapping_pair) collected and sorted.
    pub fn overlapping_pairs(&self) -> Vec<[u32; 2]> {
        let mut out = Vec::new();
        self.for_each_overlapping_pair(|a, b| out.push([a, b]));
        out.sort_unstable();
        out
    }
}

/// Subtrees of at most this many faces are one leaf of the pair traversal (at most 32: the
/// overlap masks are `u32`). Measured on 93k–235k faces: 8 → 32 took the traversal from 24 to 17
/// ms on the 200k-face torus (docs/benchmarks.md).
const PAIR_LEAF: u32 = 32;
const _: () = assert!(PAIR_LEAF <= 32);

/// Bits per axis of [`PairTree::for_mesh`]'s Morton codes.
const MORTON_BITS: u32 = 10;

/// Sorts `keys` by their bits 32..62 (the Morton code of [`PairTree::for_mesh`]), stably: keys
/// with equal codes keep their order. Three least-significant-digit passes of 10 bits (a pass
/// whose digit is the same in every key is skipped).
fn radix_sort_high_bits(keys: &mut Vec<u64>) {
    const DIGIT: u32 = 10;
    const BUCKETS: usize = 1 << DIGIT;
    let n = keys.len();
    let mut counts = vec![[0usize; BUCKETS]; 3];
    for &k in keys.iter() {
        for (pass, count) in counts.iter_mut().enumerate() {
            count[((k >> (32 + DIGIT * pass as u32)) as usize) & (BUCKETS - 1)] += 1;
        }
    }
    let mut tmp = vec![0u64; n];
    for (pass, count) in counts.iter_mut().enumerate() {
        if count.contains(&n) {
            continue;
        }
        let mut sum = 0;
        for c in count.iter_mut() {
            let here = *c;
            *c = sum;
            sum += here;
        }
        let shift = 32 + DIGIT * pass as u32;
        for &k in keys.iter() {
            let d = ((k >> shift) as usize) & (BUCKETS - 1);
            tmp[count[d]] = k;
            count[d] += 1;
        }
        std::mem::swap(keys, &mut tmp);
    }
}

/// Pre-order nodes over the leaf positions `start..end` of `keys` (sorted by their codes, bits
/// 32 and up), split as [`PairTree::for_mesh`] says; boxes are left for [`PairTree::refit`].
fn build_by_codes(keys: &[u64], start: usize, end: usize, nodes: &mut Vec<PairNode>) {
    let me = nodes.len();
    nodes.push(PairNode {
        bounds: Box32::EMPTY,
        right: 0,
        first: start as u32,
        count: (end - start) as u32,
    });
    if end - start <= PAIR_LEAF as usize {
        return;
    }
    let code = |x: usize| keys[x] >> 32;
    let (a, b) = (code(start), code(end - 1));
    let mid = if a == b {
        start + (end - start) / 2
    } else {
        let bit = 63 - (a ^ b).leading_zeros();
        start + keys[start..end].partition_point(|&k| (k >> 32) & (1 << bit) == 0)
    };
    build_by_codes(keys, start, mid, nodes);
    nodes[me].right = nodes.len() as u32;
    build_by_codes(keys, mid, end, nodes);
}

/// A node of the pair traversal's compact tree.
#[derive(Clone, Copy, Debug)]
struct PairNode {
    bounds: Box32,
    /// The right child (the left one is the next node); unused for leaves.
    right: u32,
    /// The subtree's faces: `order[first..first + count]`.
    first: u32,
    count: u32,
}

impl PairNode {
    #[inline]
    fn is_leaf(&self) -> bool {
        self.count <= PAIR_LEAF
    }

    #[inline]
    fn faces(&self) -> std::ops::Range<usize> {
        self.first as usize..(self.first + self.count) as usize
    }
}

/// What [`PairTree::for_mesh`] builds: the tree, its leaf order (`slot → face`) and the faces in
/// that order.
pub(crate) type PairTreeOfMesh = (PairTree, Vec<u32>, Vec<[u32; 3]>);

/// The pair traversal's compact tree: its nodes and the faces' boxes in leaf order.
#[derive(Clone, Debug)]
pub(crate) struct PairTree {
    nodes: Vec<PairNode>,
    leaf: LeafBoxes,
}

impl PairTree {
    /// The pair traversal's tree over a mesh, built straight from the vertices for callers that
    /// need no other query (the self-intersection checker), with its leaf order (`slot → face`)
    /// and the faces in that order. Refuses a face index out of range and a non-finite vertex used by a face
    /// (the first such face in index order, its first such corner), as [`Bvh::new`] does.
    ///
    /// The faces are sorted by the 30-bit Morton code of their centroids (10 bits per axis over
    /// the centroids' bounding cube, the bits interleaved `x` lowest; ties by face index: a
    /// stable radix sort of the face-ordered codes), then each range is split where the highest
    /// bit on which its first and last codes differ turns from 0 to 1 (in halves by count when
    /// all its codes are equal), down to ranges of at most [`PAIR_LEAF`] faces, the leaves. A
    /// pure function of the input. The faces' `f32` boxes (outward-rounded) are made in leaf
    /// order from the vertices, and the nodes' boxes are their unions: since rounding outward
    /// is monotone, the same `f32` boxes as [`Bvh::pair_tree`]'s rounded `f64` unions. The
    /// candidate pairs do not depend on the tree (they are the pairs whose outward-rounded `f32`
    /// boxes overlap), so they are the same as on [`Bvh::new`]'s tree; only the traversal's
    /// speed does. No `f64` triangles or boxes are stored.
    pub(crate) fn for_mesh(
        positions: &[[f64; 3]],
        faces: &[[u32; 3]],
    ) -> Result<PairTreeOfMesh, BvhError> {
        // The centroids' bounds (as sums of the corners: the factor 1/3 does not change the
        // order), checking every face on the way.
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (fi, &f) in faces.iter().enumerate() {
            let t = face_triangle(positions, fi, f)?;
            for k in 0..3 {
                let c = t[0][k] + t[1][k] + t[2][k];
                lo[k] = lo[k].min(c);
                hi[k] = hi[k].max(c);
            }
        }
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f64, f64::max);
        const CELLS: f64 = ((1u32 << MORTON_BITS) - 1) as f64;
        // A finite extent (a sum of three finite values may overflow to ∞: then every code is 0,
        // which only makes the tree split by count).
        let scale = if extent > 0.0 && extent.is_finite() {
            CELLS / extent
        } else {
            0.0
        };
        // Spreads the low 10 bits of `x` to every third bit.
        fn spread(x: u64) -> u64 {
            let mut x = x & 0x3ff;
            x = (x | (x << 16)) & 0x0300_00ff;
            x = (x | (x << 8)) & 0x0300_f00f;
            x = (x | (x << 4)) & 0x030c_30c3;
            x = (x | (x << 2)) & 0x0924_9249;
            x
        }
        // (code << 32) | face, in face order.
        let mut keys: Vec<u64> = faces
            .iter()
            .enumerate()
            .map(|(f, v)| {
                let p = v.map(|i| positions[i as usize]);
                // In [0, CELLS] (the float-to-int cast saturates; NaN, from ∞ − ∞, gives 0).
                let q = |k: usize| {
                    ((p[0][k] + p[1][k] + p[2][k] - lo[k]) * scale).clamp(0.0, CELLS) as u64
                };
                ((spread(q(0)) | (spread(q(1)) << 1) | (spread(q(2)) << 2)) << 32) | f as u64
            })
            .collect();
        radix_sort_high_bits(&mut keys);
        let mut nodes = Vec::with_capacity(2 * faces.len() / PAIR_LEAF as usize + 1);
        if !faces.is_empty() {
            build_by_codes(&keys, 0, keys.len(), &mut nodes);
        }
        let order: Vec<u32> = keys.iter().map(|&k| k as u32).collect();
        drop(keys);
        let mut tree = PairTree {
            nodes,
            leaf: LeafBoxes::empty(faces.len()),
        };
        let leaf_faces: Vec<[u32; 3]> = order.iter().map(|&f| faces[f as usize]).collect();
        tree.refit(|x| leaf_faces[x].map(|i| positions[i as usize]));
        Ok((tree, order, leaf_faces))
    }

    /// Recomputes every box for moved corners, in place (no allocation): `corners(x)` gives the
    /// corners of the face at leaf position `x` (the tree's shape is kept).
    pub(crate) fn refit(&mut self, corners: impl Fn(usize) -> [[f64; 3]; 3]) {
        for x in 0..self.leaf.len() {
            self.leaf
                .set(x, &Box32::outward(&Aabb::of_points(&corners(x))));
        }
        // Children come after their parent: fill the boxes backwards.
        for i in (0..self.nodes.len()).rev() {
            let n = self.nodes[i];
            let bounds = if n.is_leaf() {
                let mut b = Box32::EMPTY;
                for x in n.faces() {
                    b = b.union(&self.leaf.get(x));
                }
                b
            } else {
                self.nodes[i + 1]
                    .bounds
                    .union(&self.nodes[n.right as usize].bounds)
            };
            self.nodes[i].bounds = bounds;
        }
    }

    /// The traversal's work as at least `n` independent tasks (node pairs, `(i, i)` for all pairs
    /// within subtree `i`), each with its number of faces as a weight: the root task split into
    /// its children's (the largest first) until there are `n` or no task can be split. Traversing
    /// every task once visits every candidate pair once.
    pub(crate) fn tasks(&self, n: usize) -> Vec<((u32, u32), usize)> {
        let weight = |(i, j): (u32, u32)| {
            let c = |k: u32| self.nodes[k as usize].count as usize;
            if i == j { c(i) } else { (c(i) + c(j)) / 2 }
        };
        if self.nodes.is_empty() {
            return Vec::new();
        }
        let mut tasks = vec![((0u32, 0u32), weight((0, 0)))];
        while tasks.len() < n {
            let Some(k) = (0..tasks.len())
                .filter(|&k| {
                    let (i, j) = tasks[k].0;
                    i == j && !self.nodes[i as usize].is_leaf()
                })
                .max_by_key(|&k| tasks[k].1)
            else {
                break;
            };
            let (i, _) = tasks.swap_remove(k).0;
            let (l, r) = (i + 1, self.nodes[i as usize].right);
            tasks.push(((l, l), weight((l, l))));
            tasks.push(((r, r), weight((r, r))));
            if self.nodes[l as usize]
                .bounds
                .overlaps(&self.nodes[r as usize].bounds)
            {
                tasks.push(((l, r), weight((l, r))));
            }
        }
        tasks
    }

    /// Calls `emit(x, y)` (positions in leaf order, `x ≠ y`) for every candidate pair under the
    /// node pairs `seeds` (see [`Bvh::for_each_candidate_pair`]).
    pub(crate) fn traverse(&self, seeds: &[(u32, u32)], mut emit: impl FnMut(usize, usize)) {
        self.traverse_masks(seeds, |x, start, mut mask| {
            while mask != 0 {
                emit(x, start + mask.trailing_zeros() as usize);
                mask &= mask - 1;
            }
        });
    }

    /// [`traverse`](Self::traverse) by face and leaf: `emit(x, start, mask)` stands for the
    /// candidates `(x, start + t)` for each bit `t` set in `mask` (never 0; `start + t ≠ x`), so
    /// a caller can handle a face against a leaf's faces at once.
    pub(crate) fn traverse_masks(
        &self,
        seeds: &[(u32, u32)],
        mut emit: impl FnMut(usize, usize, u32),
    ) {
        let (nodes, leaf) = (&self.nodes, &self.leaf);
        if nodes.is_empty() {
            return;
        }
        // Node pairs (i, j) to visit: i == j for all pairs within one subtree, i != j for the
        // pairs across two subtrees whose boxes overlap.
        let mut stack: Vec<(u32, u32)> = Vec::with_capacity(256);
        stack.extend_from_slice(seeds);
        while let Some((i, j)) = stack.pop() {
            let a = &nodes[i as usize];
            if i == j {
                if a.is_leaf() {
                    let r = a.faces();
                    for x in r.clone() {
                        let bx = leaf.get(x);
                        let mask = leaf.overlap_mask(&bx, x + 1..r.end);
                        if mask != 0 {
                            emit(x, x + 1, mask);
                        }
                    }
                } else {
                    let (l, r) = (i + 1, a.right);
                    stack.push((l, l));
                    stack.push((r, r));
                    if nodes[l as usize].bounds.overlaps(&nodes[r as usize].bounds) {
                        stack.push((l, r));
                    }
                }
                continue;
            }
            let b = &nodes[j as usize];
            if a.is_leaf() && b.is_leaf() {
                let (ra, rb) = (a.faces(), b.faces());
                // The faces of `a` whose boxes overlap `b`'s, found at once.
                let mut near = leaf.overlap_mask(&b.bounds, ra.clone());
                while near != 0 {
                    let x = ra.start + near.trailing_zeros() as usize;
                    near &= near - 1;
                    let bx = leaf.get(x);
                    let mask = leaf.overlap_mask(&bx, rb.clone());
                    if mask != 0 {
                        emit(x, rb.start, mask);
                    }
                }
                continue;
            }
            // Split the interior node (the larger one when both are).
            let split_a = b.is_leaf() || (!a.is_leaf() && a.bounds.size() >= b.bounds.size());
            let (split, other) = if split_a { (i, j) } else { (j, i) };
            let ob = &nodes[other as usize].bounds;
            for c in [split + 1, nodes[split as usize].right] {
                if nodes[c as usize].bounds.overlaps(ob) {
                    stack.push((c, other));
                }
            }
        }
    }
}

/// The faces' boxes of the pair traversal in leaf order, one array per coordinate, each followed
/// by [`PAIR_LEAF`] empty boxes (`lo = +∞`, `hi = −∞`, which overlap nothing) so that a mask over
/// any range reads a whole window of `PAIR_LEAF` boxes (see [`overlap_mask`](Self::overlap_mask)).
#[derive(Clone, Debug)]
struct LeafBoxes {
    lo: [Vec<f32>; 3],
    hi: [Vec<f32>; 3],
}

/// Boxes in one window of [`LeafBoxes::overlap_mask`].
const WINDOW: usize = PAIR_LEAF as usize;

impl LeafBoxes {
    /// `n` boxes, all empty (to be filled by [`set`](Self::set)).
    fn empty(n: usize) -> LeafBoxes {
        LeafBoxes {
            lo: [(); 3].map(|_| vec![f32::INFINITY; n + WINDOW]),
            hi: [(); 3].map(|_| vec![f32::NEG_INFINITY; n + WINDOW]),
        }
    }

    fn new<'a>(boxes: impl ExactSizeIterator<Item = &'a Aabb>) -> LeafBoxes {
        let mut out = LeafBoxes::empty(boxes.len());
        for (x, b) in boxes.enumerate() {
            out.set(x, &Box32::outward(b));
        }
        out
    }

    /// Number of boxes (without the padding).
    fn len(&self) -> usize {
        self.lo[0].len() - WINDOW
    }

    #[inline]
    fn set(&mut self, x: usize, b: &Box32) {
        for k in 0..3 {
            self.lo[k][x] = b.lo[k];
            self.hi[k][x] = b.hi[k];
        }
    }

    #[inline]
    fn get(&self, x: usize) -> Box32 {
        Box32 {
            lo: [self.lo[0][x], self.lo[1][x], self.lo[2][x]],
            hi: [self.hi[0][x], self.hi[1][x], self.hi[2][x]],
        }
    }

    /// Bit `t` set when the box of face `range.start + t` overlaps `b` (at most 32 faces).
    /// Branch-free over a fixed window of [`WINDOW`] boxes from `range.start` (the padding keeps
    /// it in bounds), which the compiler turns into packed compares; bits past the range are
    /// cleared.
    #[inline(always)]
    fn overlap_mask(&self, b: &Box32, range: std::ops::Range<usize>) -> u32 {
        fn window(v: &[f32], start: usize) -> &[f32; WINDOW] {
            v[start..start + WINDOW]
                .try_into()
                .unwrap_or_else(|_| unreachable!("the padding holds a whole window"))
        }
        debug_assert!(range.len() <= WINDOW);
        let s = range.start;
        let (lx, ly, lz) = (
            window(&self.lo[0], s),
            window(&self.lo[1], s),
            window(&self.lo[2], s),
        );
        let (hx, hy, hz) = (
            window(&self.hi[0], s),
            window(&self.hi[1], s),
            window(&self.hi[2], s),
        );
        let mut mask = 0u32;
        for t in 0..WINDOW {
            let o = (b.lo[0] <= hx[t])
                & (lx[t] <= b.hi[0])
                & (b.lo[1] <= hy[t])
                & (ly[t] <= b.hi[1])
                & (b.lo[2] <= hz[t])
                & (lz[t] <= b.hi[2]);
            // A select of constants, not a shift of a bool: vectorizes as compare-and-mask.
            mask |= if o { 1 << t } else { 0 };
        }
        let len = range.len();
        if len < WINDOW {
            mask & ((1 << len) - 1)
        } else {
            mask
        }
    }
}

/// A box in `f32` (the pair traversal's compact copy).
#[derive(Clone, Copy, Debug)]
struct Box32 {
    lo: [f32; 3],
    hi: [f32; 3],
}

impl Box32 {
    /// The empty box (`lo = +∞`, `hi = −∞`): the identity of [`Box32::union`].
    const EMPTY: Box32 = Box32 {
        lo: [f32::INFINITY; 3],
        hi: [f32::NEG_INFINITY; 3],
    };

    /// The smallest box containing both.
    #[inline]
    fn union(&self, o: &Box32) -> Box32 {
        Box32 {
            lo: [0, 1, 2].map(|k| self.lo[k].min(o.lo[k])),
            hi: [0, 1, 2].map(|k| self.hi[k].max(o.hi[k])),
        }
    }

    /// The smallest `f32` box containing `b` (corners rounded outward).
    #[inline]
    fn outward(b: &Aabb) -> Box32 {
        let down = |x: f64| f32_outward(x, true);
        let up = |x: f64| f32_outward(x, false);
        Box32 {
            lo: b.lo.map(down),
            hi: b.hi.map(up),
        }
    }

    #[inline]
    fn overlaps(&self, o: &Box32) -> bool {
        (self.lo[0] <= o.hi[0])
            & (o.lo[0] <= self.hi[0])
            & (self.lo[1] <= o.hi[1])
            & (o.lo[1] <= self.hi[1])
            & (self.lo[2] <= o.hi[2])
            & (o.lo[2] <= self.hi[2])
    }

    /// Sum of extents: a size measure that stays useful for flat boxes.
    #[inline]
    fn size(&self) -> f32 {
        (self.hi[0] - self.lo[0]) + (self.hi[1] - self.lo[1]) + (self.hi[2] - self.lo[2])
    }
}

/// `x` rounded to the nearest `f32` at or below it (`toward_lower`), or at or above it: the
/// corner of [`Box32::outward`]. Rounding to nearest goes the wrong way about half the time,
/// unpredictably, so the step to the neighbour is integer arithmetic on the bits, not a branch
/// (a branch here cost three quarters of the tree's refit: 7.9 → 2.2 ms on 200k faces). For a
/// non-zero `f32` `y` (an infinity included: `x` beyond `f32::MAX` steps back to it) the next one
/// below is bits − 1 when positive, bits + 1 when negative; from ±0 it is −2⁻¹⁴⁹ (a rare,
/// predictable branch). Above likewise. NaN stays NaN (no comparison holds).
#[inline(always)]
fn f32_outward(x: f64, toward_lower: bool) -> f32 {
    let y = x as f32;
    let b = y.to_bits();
    let wrong = u32::from(if toward_lower {
        f64::from(y) > x
    } else {
        f64::from(y) < x
    });
    if b & 0x7fff_ffff == 0 {
        let tiny = if toward_lower { 0x8000_0001 } else { 1 };
        return if wrong != 0 { f32::from_bits(tiny) } else { y };
    }
    // Away from zero (+1 on the bits) when the step's direction and the sign agree.
    let away = u32::from((b >> 31 != 0) == toward_lower);
    f32::from_bits(b.wrapping_add(wrong.wrapping_mul(2 * away).wrapping_sub(wrong)))
}

/// The closest point of the segment `a b` to `p` and its parameter `s` (point = a + s·(b − a)).
fn closest_on_segment(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> ([f64; 3], f64) {
    let ab = sub(b, a);
    let l2 = dot(ab, ab);
    let s = if l2 > 0.0 {
        (dot(sub(p, a), ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ([a[0] + s * ab[0], a[1] + s * ab[1], a[2] + s * ab[2]], s)
}

/// The closest point of triangle `t` to `p`, with its barycentric coordinates (Ericson's Voronoi
/// region walk; a degenerate triangle falls back to the closest of its three edges).
pub fn closest_on_triangle(p: [f64; 3], t: &[[f64; 3]; 3]) -> ([f64; 3], [f64; 3]) {
    let [a, b, c] = *t;
    let ab = sub(b, a);
    let ac = sub(c, a);
    let n = cross(ab, ac);
    let nn = dot(n, n);
    let scale = dot(ab, ab).max(dot(ac, ac));
    if nn.partial_cmp(&(1e-24 * scale * scale)) != Some(std::cmp::Ordering::Greater) {
        // Degenerate: the closest of the three segments.
        let mut best = ([0.0; 3], [1.0, 0.0, 0.0], f64::INFINITY);
        for (i, j) in [(0usize, 1usize), (1, 2), (2, 0)] {
            let (q, s) = closest_on_segment(p, t[i], t[j]);
            let d = sub(q, p);
            let d2 = dot(d, d);
            if d2 < best.2 {
                let mut w = [0.0; 3];
                w[i] = 1.0 - s;
                w[j] += s;
                best = (q, w, d2);
            }
        }
        return (best.0, best.1);
    }
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (
            [a[0] + v * ab[0], a[1] + v * ab[1], a[2] + v * ab[2]],
            [1.0 - v, v, 0.0],
        );
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (
            [a[0] + w * ac[0], a[1] + w * ac[1], a[2] + w * ac[2]],
            [1.0 - w, 0.0, w],
        );
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        let bc = sub(c, b);
        return (
            [b[0] + w * bc[0], b[1] + w * bc[1], b[2] + w * bc[2]],
            [0.0, 1.0 - w, w],
        );
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    (
        [
            a[0] + ab[0] * v + ac[0] * w,
            a[1] + ab[1] * v + ac[1] * w,
            a[2] + ab[2] * v + ac[2] * w,
        ],
        [1.0 - v - w, v, w],
    )
}

/// Möller–Trumbore: `(t, barycentrics)` of the ray's hit with triangle `t`, `t ≥ 0`, edges
/// inclusive; `None` when it misses or the determinant is zero.
pub fn ray_triangle(
    origin: [f64; 3],
    dir: [f64; 3],
    tri: &[[f64; 3]; 3],
) -> Option<(f64, [f64; 3])> {
    let e1 = sub(tri[1], tri[0]);
    let e2 = sub(tri[2], tri[0]);
    let pv = cross(dir, e2);
    let det = dot(e1, pv);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let tv = sub(origin, tri[0]);
    let u = dot(tv, pv) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let qv = cross(tv, e1);
    let v = dot(dir, qv) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = dot(e2, qv) * inv;
    if t.is_finite() && t >= 0.0 {
        Some((t, [1.0 - u - v, u, v]))
    } else {
        None
    }
}

#[cfg(test)]
mod tests;
