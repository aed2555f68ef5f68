//! Exact self-intersection detection: every pair of triangles of a mesh that intersect.
//!
//! Candidates come from a bounding-volume hierarchy's self-overlap traversal (the checker's own
//! pair tree of outward-rounded `f32` boxes in [`crate::bvh`], built from the vertices: pairs of
//! faces whose closed boxes overlap); each candidate is decided by an exact triangle–triangle test built only on the
//! [`predicates`](crate::predicates) (`orient3d`, and `orient2d` on a coordinate projection for
//! coplanar configurations), so the answer is the exact answer for the given `f64` coordinates —
//! no tolerance, no epsilon.
//!
//! # Definitions
//!
//! Triangles are closed point sets (edges and corners included). Adjacency is by vertex
//! **index** (two faces are adjacent when their index triples share an index; two distinct
//! vertices at the same position are not the same vertex — weld first, see
//! [`validate`](crate::validate), or an unwelded seam reports its touching faces).
//!
//! - **Degenerate faces** (zero area: the three corners exactly collinear, repeated corners
//!   included) have no interior; they are **reported separately** in
//!   [`SelfIntersections::degenerate`] and are never part of a pair.
//! - **Non-adjacent faces** (no shared index) intersect when the closed triangles share at least
//!   one point: crossing, touching at a point or along an edge, and coplanar overlap all count.
//! - **Faces sharing exactly one vertex** intersect when they meet anywhere other than that
//!   vertex (the intersection of the two closed triangles is more than the shared corner).
//! - **Faces sharing an edge** intersect when they meet anywhere other than the shared edge. For
//!   two non-degenerate triangles this happens exactly when they **fold onto each other**: the two
//!   opposite vertices are coplanar with the edge and on the same side of it, so the interiors
//!   overlap. (A flat neighbour — coplanar, opposite sides — and any dihedral angle other than a
//!   full fold do not count.)
//! - **Faces with the same three vertices** (a duplicated face, either orientation) intersect.
//!
//! # The exact triangle–triangle test
//!
//! Two closed triangles meet iff an edge of one meets the other (the intersection is a convex
//! set; one of its extreme points lies on the relative boundary of a triangle). An edge `pq`
//! against a triangle `T`: if both endpoints are strictly on one side of `T`'s plane, no; if both
//! are in the plane, a 2-D segment–triangle test on the projection that drops an axis along which
//! `T` projects to a non-degenerate triangle (chosen exactly: `orient2d` of `T` there is non-zero);
//! otherwise the segment crosses the plane in one point, which is in `T` iff
//! `orient3d(p, q, tᵢ, tᵢ₊₁)` has no two opposite signs over the three edges of `T`. The adjacent
//! cases reduce to the same predicates: a shared edge is a fold iff `orient3d(u, v, a, b) = 0` and
//! `orient2d(u, v, a)`, `orient2d(u, v, b)` agree; a shared vertex `v` of `(v, a₁, b₁)` and
//! `(v, a₂, b₂)` is exceeded iff an opposite edge `aᵢbᵢ` meets the other triangle or one of the
//! edges leaving `v` enters the other triangle's corner cone at `v`. Two shortcuts decide the
//! generic crossing configurations with fewer signs, from the same exact predicates: triangles
//! that straddle each other's planes with no corner on the other plane meet iff the segments
//! they cut on the planes' common line overlap (two `orient3d`, Guigue and Devillers), and faces
//! sharing a corner that straddle each other's planes meet elsewhere iff they cut that line on
//! the same side of the corner (one `orient3d`).
//!
//! # Cost and limits
//!
//! The check costs one BVH refit (`O(F)`), a certificate per vertex fan (`O(V)`: a vertex whose
//! faces project to a simple star around it — along a coordinate axis, or along the fan's summed
//! normal for a fan folded at a crease — has no intersecting pair among them, so every
//! candidate sharing such a vertex is skipped untested), the self-overlap traversal, and one exact
//! test per remaining candidate ([`SelfIntersectionChecker::set_threads`] splits the traversal
//! over threads; the answer does not change). The candidate set is every pair of faces whose bounding boxes overlap: on a clean
//! mesh about `O(F)` (each face's neighbours), in the worst case — every box overlapping every
//! other, e.g. a mesh crumpled into a ball — `F(F − 1)/2`. Each test is `O(1)`: at most about 30
//! filtered predicates, and the exact fallback's integers have at most about 6,300 bits, so there
//! is no unbounded work per pair. Every finite `f64` coordinate is supported (see the predicates'
//! range); NaN or infinite coordinates of a vertex used by a face, an out-of-range index and a
//! mesh with no faces are refused with an [`IntersectError`].

use crate::bvh::{BvhError, PairTree};
use crate::predicates::{PlaneFilter, Sign, orient2d_projected, orient3d_unchecked};

/// What the self-intersection check refuses.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum IntersectError {
    /// The mesh has no faces.
    #[error("self-intersection check: the mesh has no faces")]
    Empty,
    /// An out-of-range index, a non-finite vertex, or a refit with another vertex count.
    #[error("self-intersection check: {0}")]
    Mesh(#[from] BvhError),
    /// [`new_pairs`] was given results for meshes with different face counts.
    #[error(
        "self-intersection check: the source has {source_faces} faces and the deformed mesh \
         {deformed_faces} (new intersections need the same connectivity)"
    )]
    DifferentMeshes {
        /// Faces of the source.
        source_faces: usize,
        /// Faces of the deformed mesh.
        deformed_faces: usize,
    },
    /// More faces than the check indexes (its per-corner counts are `u32`: `3·faces < 2³²`).
    #[error(
        "self-intersection check: the mesh has {faces} faces, more than the {max} it can index"
    )]
    TooLarge {
        /// Faces given.
        faces: usize,
        /// The most faces the check takes.
        max: usize,
    },
}

/// The self-intersection figures of one connected component (faces joined through shared
/// vertices along edges, as [`topology::connected_components`](crate::topology::connected_components)
/// labels them; numbered in order of each component's smallest vertex index).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ComponentIntersections {
    /// Faces in the component.
    pub faces: usize,
    /// Of those, faces in at least one intersecting pair.
    pub involved_faces: usize,
    /// Intersecting pairs with both faces in this component.
    pub pairs_within: usize,
    /// Intersecting pairs with one face here and the other in another component.
    pub pairs_across: usize,
}

/// The answer of a self-intersection check (see the [module docs](self) for the definitions).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SelfIntersections {
    /// Intersecting face pairs `(a, b)`, `a < b`, sorted.
    pub pairs: Vec<(u32, u32)>,
    /// Faces in at least one pair, sorted.
    pub faces: Vec<u32>,
    /// Zero-area faces (never paired), sorted.
    pub degenerate: Vec<u32>,
    /// Per connected component.
    pub per_component: Vec<ComponentIntersections>,
    /// Faces of the mesh checked.
    pub num_faces: usize,
    /// Candidate pairs the BVH produced (overlapping boxes, compared in `f32` rounded outward, so
    /// a pair whose boxes are apart by less than that rounding may count too) — the work done;
    /// those sharing a certified vertex are skipped without a test (see `docs/self_intersections.md`).
    pub candidates: usize,
}

/// The pairs `deformed` has that `source` does not (same connectivity: same faces in the same
/// order), sorted. Refuses results of meshes with different face counts.
pub fn new_pairs(
    source: &SelfIntersections,
    deformed: &SelfIntersections,
) -> Result<Vec<(u32, u32)>, IntersectError> {
    if source.num_faces != deformed.num_faces {
        return Err(IntersectError::DifferentMeshes {
            source_faces: source.num_faces,
            deformed_faces: deformed.num_faces,
        });
    }
    let mut out = Vec::new();
    let mut i = 0;
    for &p in &deformed.pairs {
        while i < source.pairs.len() && source.pairs[i] < p {
            i += 1;
        }
        if i >= source.pairs.len() || source.pairs[i] != p {
            out.push(p);
        }
    }
    Ok(out)
}

/// All intersecting face pairs of `(positions, faces)` (a one-off [`SelfIntersectionChecker`]).
pub fn self_intersections(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
) -> Result<SelfIntersections, IntersectError> {
    Ok(SelfIntersectionChecker::new(positions, faces)?.check())
}

/// A reusable checker: keeps the BVH and the component labels of one connectivity, and only
/// refits the tree when the positions move ([`check_moved`](Self::check_moved)), for callers that
/// check the same mesh at many deformations (a λ slider).
#[derive(Clone, Debug)]
pub struct SelfIntersectionChecker {
    /// The pair traversal's tree ([`PairTree::for_mesh`]).
    tree: PairTree,
    /// Leaf order → face.
    order: Vec<u32>,
    /// The faces in leaf order.
    slots: Vec<[u32; 3]>,
    /// Face → component (empty when there is one: every face's is 0).
    face_component: Vec<u32>,
    /// Faces per component.
    component_faces: Vec<usize>,
    /// The current positions (the fans' certificates read them).
    positions: Vec<[f64; 3]>,
    fans: Fans,
    /// Threads of [`check`](Self::check) (1: the calling thread only).
    threads: usize,
}

impl SelfIntersectionChecker {
    /// The most faces the check takes: its counts of corners (`3·faces`) are `u32`.
    pub const MAX_FACES: usize = (u32::MAX / 3) as usize;

    /// Builds the tree over the mesh. Refuses an empty face list, more than
    /// [`MAX_FACES`](Self::MAX_FACES) faces, an out-of-range index and a non-finite vertex used
    /// by a face.
    pub fn new(
        positions: &[[f64; 3]],
        faces: &[[u32; 3]],
    ) -> Result<SelfIntersectionChecker, IntersectError> {
        if faces.is_empty() {
            return Err(IntersectError::Empty);
        }
        if faces.len() > Self::MAX_FACES {
            return Err(IntersectError::TooLarge {
                faces: faces.len(),
                max: Self::MAX_FACES,
            });
        }
        let (tree, order, slots) = PairTree::for_mesh(positions, faces)?;
        // Two edges per face join its three corners (the third edge adds nothing); the indices
        // were checked by the tree.
        let (labels, num_labels) = crate::topology::graph_components(
            positions.len(),
            faces.iter().flat_map(|f| [[f[0], f[1]], [f[1], f[2]]]),
        );
        // Renumber the components that own faces, in order of their smallest vertex label.
        let mut remap = vec![u32::MAX; num_labels];
        for f in faces {
            remap[labels[f[0] as usize] as usize] = 0;
        }
        let mut num_used = 0u32;
        for r in remap.iter_mut().filter(|r| **r == 0) {
            *r = num_used;
            num_used += 1;
        }
        // One component (the usual case) needs no per-face table.
        let (face_component, component_faces) = if num_used == 1 {
            (Vec::new(), vec![faces.len()])
        } else {
            let face_component: Vec<u32> = faces
                .iter()
                .map(|f| remap[labels[f[0] as usize] as usize])
                .collect();
            let mut component_faces = vec![0usize; num_used as usize];
            for &c in &face_component {
                component_faces[c as usize] += 1;
            }
            (face_component, component_faces)
        };
        Ok(SelfIntersectionChecker {
            tree,
            order,
            slots,
            face_component,
            component_faces,
            positions: positions.to_vec(),
            fans: Fans::new(positions.len(), faces),
            threads: 1,
        })
    }

    /// Runs [`check`](Self::check) on `threads` threads (scoped, started per check; 0 counts as
    /// 1, the default): the traversal is split into tasks of about equal numbers of faces. A
    /// speed setting only: the answer is the same for any number.
    pub fn set_threads(&mut self, threads: usize) {
        self.threads = threads.max(1);
    }

    /// The component of face `f`.
    fn component_of(&self, f: u32) -> usize {
        self.face_component
            .get(f as usize)
            .map_or(0, |&c| c as usize)
    }

    /// Number of faces.
    pub fn num_faces(&self) -> usize {
        self.order.len()
    }

    /// Moves the vertices (refits the tree; same vertex count). Refuses a different vertex count
    /// or a non-finite vertex, leaving the checker unchanged.
    pub fn update(&mut self, positions: &[[f64; 3]]) -> Result<(), IntersectError> {
        if positions.len() != self.positions.len() {
            return Err(BvhError::VertexCount {
                expected: self.positions.len(),
                got: positions.len(),
            }
            .into());
        }
        // The first face (in index order) with a non-finite corner, and its first such corner.
        let finite = |v: u32| positions[v as usize].iter().all(|c| c.is_finite());
        let bad_face = (0..self.slots.len())
            .filter(|&x| !self.slots[x].iter().all(|&v| finite(v)))
            .min_by_key(|&x| self.order[x]);
        if let Some(x) = bad_face
            && let Some(&v) = self.slots[x].iter().find(|&&v| !finite(v))
        {
            return Err(BvhError::NonFinite {
                vertex: v as usize,
                position: positions[v as usize],
            }
            .into());
        }
        self.positions.clear();
        self.positions.extend_from_slice(positions);
        let (slots, positions) = (&self.slots, &self.positions);
        self.tree.refit(|x| slots[x].map(|v| positions[v as usize]));
        Ok(())
    }

    /// [`update`](Self::update) then [`check`](Self::check).
    pub fn check_moved(
        &mut self,
        positions: &[[f64; 3]],
    ) -> Result<SelfIntersections, IntersectError> {
        self.update(positions)?;
        Ok(self.check())
    }

    /// The self-intersections at the current positions.
    pub fn check(&self) -> SelfIntersections {
        let (order, slots, positions) = (&self.order, &self.slots, &self.positions);
        let corners = |f: [u32; 3]| f.map(|v| positions[v as usize]);
        // Per face in the tree's leaf order (which the traversal walks), a bit for each corner
        // whose fan is certified (`Fans`): a pair sharing such a corner cannot intersect.
        let certified = self.fans.certify(positions);
        let masks: Vec<u8> = slots
            .iter()
            .map(|f| (0..3).fold(0u8, |m, i| m | (u8::from(certified[f[i] as usize]) << i)))
            .collect();
        // A face with a certified corner is a proper triangle (its fan's projection keeps it
        // one); the others are tested exactly.
        let mut degenerate: Vec<u32> = (0..slots.len())
            .filter(|&x| masks[x] == 0 && Tri::new(corners(slots[x])).drop.is_none())
            .map(|x| order[x])
            .collect();
        degenerate.sort_unstable();
        // The traversal, each candidate sharing no certified vertex tested exactly; split into
        // tasks over `threads` threads when asked (the candidates and pairs are the same).
        let run = |tree: &PairTree, seeds: &[(u32, u32)]| {
            let mut pairs = Vec::new();
            let mut candidates = 0usize;
            // The tested faces' projection axes, in a small direct-mapped cache (a face of a
            // crumpled mesh is tested against many others; the tested pairs come in leaf order).
            let mut cache = vec![(u32::MAX, Tri::new([[0.0; 3]; 3])); TRI_CACHE];
            tree.traverse_masks(seeds, |x, start, mut overlaps| {
                // A face against a leaf's faces: the count and the certified-corner skip, which
                // decide most candidates; the rest is tested out of line.
                candidates += overlaps.count_ones() as usize;
                let (sx, mask) = (slots[x], masks[x]);
                // The certified corners of `x`, an uncertified one replaced by a certified one
                // (a repeat changes nothing), so the skip below is branch-free.
                let certified = if mask == 0 {
                    None
                } else {
                    let first = sx[mask.trailing_zeros() as usize];
                    Some([0, 1, 2].map(|i| if mask & (1 << i) != 0 { sx[i] } else { first }))
                };
                // The plane of `x`, made for its first tested candidate and kept for the rest
                // (a crumpled mesh tests three or four of a leaf's faces against `x`).
                let mut plane_x = None;
                while overlaps != 0 {
                    let y = start + overlaps.trailing_zeros() as usize;
                    overlaps &= overlaps - 1;
                    let sy = slots[y];
                    if let Some(c) = certified {
                        let has = |v: u32| (sy[0] == v) | (sy[1] == v) | (sy[2] == v);
                        if has(c[0]) | has(c[1]) | has(c[2]) {
                            continue;
                        }
                    }
                    if let Some(pair) =
                        test_candidate(order, positions, &mut cache, &mut plane_x, (x, sx), (y, sy))
                    {
                        pairs.push(pair);
                    }
                }
            });
            (pairs, candidates)
        };
        let tree = &self.tree;
        let (mut pairs, candidates) = match self.threads {
            0 | 1 => run(tree, &[(0, 0)]),
            _ => {
                // Tasks by weight, largest first, each to the least loaded thread.
                let mut tasks = tree.tasks(8 * self.threads);
                tasks.sort_by_key(|t| std::cmp::Reverse(t.1));
                let mut groups: Vec<(usize, Vec<(u32, u32)>)> = vec![(0, Vec::new()); self.threads];
                for (task, w) in tasks {
                    let g = (0..groups.len()).min_by_key(|&g| groups[g].0).unwrap_or(0);
                    groups[g].0 += w;
                    groups[g].1.push(task);
                }
                let run = &run;
                std::thread::scope(|scope| {
                    // The first group runs here; a thread the system refuses to start runs its
                    // group here too (same answer, later).
                    let handles: Vec<_> = groups[1..]
                        .iter()
                        .map(|(_, seeds)| {
                            std::thread::Builder::new()
                                .spawn_scoped(scope, move || run(tree, seeds))
                                .map_err(|_| seeds)
                        })
                        .collect();
                    let mut all = run(tree, &groups[0].1);
                    for h in handles {
                        let (p, c) = match h {
                            // A panic in a task is a bug: propagate it.
                            Ok(h) => h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)),
                            Err(seeds) => run(tree, seeds),
                        };
                        all.0.extend(p);
                        all.1 += c;
                    }
                    all
                })
            }
        };
        pairs.sort_unstable();
        let mut involved: Vec<u32> = pairs.iter().flat_map(|&(a, b)| [a, b]).collect();
        involved.sort_unstable();
        involved.dedup();
        let mut per_component: Vec<ComponentIntersections> = self
            .component_faces
            .iter()
            .map(|&n| ComponentIntersections {
                faces: n,
                ..Default::default()
            })
            .collect();
        for &f in &involved {
            per_component[self.component_of(f)].involved_faces += 1;
        }
        for &(a, b) in &pairs {
            let (ca, cb) = (self.component_of(a), self.component_of(b));
            if ca == cb {
                per_component[ca].pairs_within += 1;
            } else {
                per_component[ca].pairs_across += 1;
                per_component[cb].pairs_across += 1;
            }
        }
        SelfIntersections {
            pairs,
            faces: involved,
            degenerate,
            per_component,
            num_faces: slots.len(),
            candidates,
        }
    }
}

/// The fan of faces around each vertex, ordered along the vertex's link, for a certificate that
/// decides every pair of faces sharing that vertex at once.
///
/// A vertex `v` whose faces `(v, r₀, r₁), (v, r₁, r₂), …` form one consistently oriented chain —
/// closed (`k ≥ 3` faces, back to `r₀`: an interior manifold vertex) or open (a boundary vertex) —
/// has a fan. At given positions the fan is **certified** when, projected along one coordinate
/// axis (dropping the axis where the fan's summed normal is largest) or, failing that, along
/// the summed normal `n` itself (a fan folded at a crease, which no coordinate axis sees as a
/// star), every face of the fan is a triangle of one and the same orientation (exact
/// `orient2d`; along `n`, exact `orient3d(v − w, v, rᵢ, rⱼ) = w·((rᵢ − v) × (rⱼ − v))` with
/// `w = v − fl(v − n·s)`, the orientation in the projection along `w`) and the directions
/// `rᵢ − v` turn once around `v` at most: the sweep from `r₁` on never passes the direction of
/// `r₀` again before a closed fan's last face returns to it (exact signs; a zero counts as
/// passing). Then the projected faces are disjoint angular sectors of a star around `v` —
/// consecutive ones share a ray, others only `v` — and since the projection is injective on
/// each face, two faces of the fan meet only at `v` (sharing one vertex) or only along their
/// shared edge (sharing an edge, so no fold): **no pair of faces sharing `v` intersects** under
/// the module's definitions. A fan that fails the test, or a vertex without a fan (non-manifold,
/// inconsistently oriented, a face using it twice, more than [`Fans::MAX_FAN`] faces), leaves
/// its pairs to the per-pair test. Duplicated faces never form a fan, so they are still found.
#[derive(Clone, Debug)]
struct Fans {
    /// Per vertex, `link[offsets[v]..offsets[v + 1]]`: the link `r₀, r₁, …` (open fans repeat
    /// nothing: `k` faces, `k + 1` entries; closed fans: `k` faces, `k` entries).
    offsets: Vec<u32>,
    link: Vec<u32>,
    /// Per vertex: 0 no fan, 1 closed, 2 open.
    kind: Vec<u8>,
}

impl Fans {
    /// Vertices with more faces than this get no fan (the chain is built by a linear search).
    const MAX_FAN: usize = 64;

    fn new(num_vertices: usize, faces: &[[u32; 3]]) -> Fans {
        // Vertex → its faces, in face order (a face using the vertex twice is listed twice).
        let around = crate::topology::vertex_faces(num_vertices, faces);
        let mut offsets = Vec::with_capacity(num_vertices + 1);
        let mut link = Vec::with_capacity(around.faces.len() + num_vertices);
        let mut kind = vec![0u8; num_vertices];
        let mut edges = [(0u32, 0u32); Self::MAX_FAN + 1];
        offsets.push(0u32);
        for v in 0..num_vertices {
            let fs = around.of(v);
            // (a, b) for each face (v, a, b) around `v` (corners cycled so that v is first: at
            // its first corner that is `v`, so a face using `v` twice gives an edge holding
            // `v`, which `chain` refuses, as it must); a fan too large is refused by `chain` on
            // its length alone.
            let k = fs.len().min(Self::MAX_FAN + 1);
            for (e, &fi) in edges.iter_mut().zip(&fs[..k]) {
                let f = &faces[fi as usize];
                let i = f.iter().position(|&w| w as usize == v).unwrap_or(0);
                *e = (f[(i + 1) % 3], f[(i + 2) % 3]);
            }
            let start = link.len();
            if let Some(k) = Self::chain(v as u32, &edges[..k], &mut link) {
                kind[v] = k;
            } else {
                link.truncate(start);
            }
            offsets.push(link.len() as u32);
        }
        Fans {
            offsets,
            link,
            kind,
        }
    }

    /// Appends `v`'s ordered link to `link`; `Some(1)` closed, `Some(2)` open, `None` no fan.
    fn chain(v: u32, es: &[(u32, u32)], link: &mut Vec<u32>) -> Option<u8> {
        let k = es.len();
        if k == 0 || k > Self::MAX_FAN {
            return None;
        }
        // One pass over the pairs of edges: refuse a repeated start or end (so each edge has at
        // most one successor, whose start is its end, and at most one predecessor), and record
        // the successors and which edges have a predecessor.
        const NONE: u8 = u8::MAX;
        let mut succ = [NONE; Self::MAX_FAN];
        let mut has_pred = 0u64;
        for (i, &(a, b)) in es.iter().enumerate() {
            if a == v || b == v || a == b {
                return None;
            }
            for (j, &(c, d)) in es.iter().enumerate().skip(i + 1) {
                if c == a || d == b {
                    return None;
                }
                if c == b {
                    succ[i] = j as u8;
                    has_pred |= 1 << j;
                }
                if d == a {
                    succ[j] = i as u8;
                    has_pred |= 1 << i;
                }
            }
        }
        // Open: start at the (first) edge without a predecessor; closed: at the first edge.
        // Since predecessors are unique, the walk can only come back to where it started.
        let first = (0..k).find(|&i| has_pred & (1 << i) == 0);
        let open = first.is_some();
        let start = first.unwrap_or(0);
        let mut cur = start;
        link.push(es[cur].0);
        for n in 0..k {
            let b = es[cur].1;
            if n + 1 == k {
                if open {
                    link.push(b);
                    return Some(2);
                }
                return (b == link[link.len() - k] && k >= 3).then_some(1);
            }
            link.push(b);
            let next = succ[cur];
            if next == NONE || usize::from(next) == start {
                return None;
            }
            cur = usize::from(next);
        }
        None
    }

    /// Per vertex: whether its fan is certified at `positions` (see [`Fans`]).
    fn certify(&self, positions: &[[f64; 3]]) -> Vec<bool> {
        (0..self.kind.len())
            .map(|v| {
                let k = self.kind[v];
                k != 0 && {
                    let l = &self.link[self.offsets[v] as usize..self.offsets[v + 1] as usize];
                    fan_is_star(positions, positions[v], l, k == 1)
                }
            })
            .collect()
    }
}

/// The certificate of [`Fans`] for the fan of the vertex at `pv` with link `l` (closed: the faces
/// are `(v, lᵢ, lᵢ₊₁ mod k)`; open: `(v, lᵢ, lᵢ₊₁)`).
fn fan_is_star(positions: &[[f64; 3]], pv: [f64; 3], l: &[u32], closed: bool) -> bool {
    let faces = if closed { l.len() } else { l.len() - 1 };
    let at = |i: usize| positions[l[i % l.len()] as usize];
    // The links' differences from `v` (read once), rounded as the 2-D filter rounds them.
    const SMALL: usize = 16;
    let small = l.len() <= SMALL;
    let mut d3 = [[0.0f64; 3]; SMALL];
    if small {
        for (i, d) in d3.iter_mut().enumerate().take(l.len()) {
            *d = crate::geometry::sub(at(i), pv);
        }
    }
    let diff = |i: usize| {
        if small {
            d3[i % l.len()]
        } else {
            crate::geometry::sub(at(i), pv)
        }
    };
    let mut n = [0.0f64; 3];
    for i in 0..faces {
        let c = crate::geometry::cross(diff(i), diff(i + 1));
        for k in 0..3 {
            n[k] += c[k];
        }
    }
    let axis = if n[0].abs() >= n[1].abs() && n[0].abs() >= n[2].abs() {
        0
    } else if n[1].abs() >= n[2].abs() {
        1
    } else {
        2
    };
    let want = if n[axis] > 0.0 {
        Sign::Positive
    } else if n[axis] < 0.0 {
        Sign::Negative
    } else {
        return false;
    };
    // Every sign below is an orientation around `v`, `orient2d(v, rᵢ, rⱼ) = orient2d(rᵢ, rⱼ, v)`:
    // decided from the projected differences against one static bound for the whole fan
    // (`orient2d_static_bound`: the same signs as the predicate's filter), the predicate itself
    // where that bound cannot.
    let (pi, pj) = match axis {
        0 => (1, 2),
        1 => (2, 0),
        _ => (0, 1),
    };
    let mut d2 = [[0.0f64; 2]; SMALL];
    let bound = if small {
        for (e, d) in d2.iter_mut().zip(&d3).take(l.len()) {
            *e = [d[pi], d[pj]];
        }
        crate::predicates::orient2d_static_bound(&d2[..l.len()])
    } else {
        f64::INFINITY
    };
    let orient = |i: usize, j: usize| {
        let (a, b) = (d2[i % SMALL], d2[j % SMALL]);
        let det = a[0] * b[1] - a[1] * b[0];
        if det > bound {
            Sign::Positive
        } else if det < -bound {
            Sign::Negative
        } else {
            orient2d_projected(pv, at(i), at(j), axis)
        }
    };
    if star_signs(l.len(), faces, closed, want, orient) {
        return true;
    }
    // No star along a coordinate axis (e.g. a fan folded at a crease of a CAD mesh): the same
    // signs in the projection along `n` itself, `orient3d(v − w, v, rᵢ, rⱼ) = w·((rᵢ − v) × (rⱼ −
    // v))` with `w = v − (v − w)` (exactly, whatever the rounding of `v − w`), `w` a multiple of
    // `n` of about the links' size: exact `orient3d` signs, the same certificate.
    // A quick `f64` look first (a heuristic only: it can refuse, never certify): every face's
    // normal on `n`'s side. A crumpled fan fails here, at its first folded face.
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    if !(0..faces).all(|i| dot(crate::geometry::cross(diff(i), diff(i + 1)), n) > 0.0) {
        return false;
    }
    let scale = {
        let d0 = diff(0);
        let m = |a: [f64; 3]| a[0].abs().max(a[1].abs()).max(a[2].abs());
        m(d0) / m(n)
    };
    let q = [
        pv[0] - n[0] * scale,
        pv[1] - n[1] * scale,
        pv[2] - n[2] * scale,
    ];
    if !q.iter().all(|c| c.is_finite()) || q == pv {
        return false;
    }
    star_signs(
        l.len(),
        faces,
        closed,
        Sign::Positive,
        |i: usize, j: usize| crate::predicates::orient3d_unchecked(q, pv, at(i), at(j)),
    )
}

/// The two conditions of [`Fans`]' certificate from the orientation signs `orient(i, j)` of
/// the links `rᵢ`, `rⱼ` around `v` in some parallel projection (`len` links, `faces` faces):
/// every face `(v, rᵢ, rᵢ₊₁)` has orientation `want`, and the sweep from `r₁` on never passes
/// the direction of `r₀` again (it passes it during face i ≥ 1 when `r₀` is strictly after `rᵢ`
/// and not strictly before `rᵢ₊₁`: both turns are less than a half turn).
#[inline(always)]
fn star_signs(
    len: usize,
    faces: usize,
    closed: bool,
    want: Sign,
    orient: impl Fn(usize, usize) -> Sign,
) -> bool {
    if (0..faces).any(|i| orient(i % len, (i + 1) % len) != want) {
        return false;
    }
    let last = if closed { faces - 1 } else { faces };
    !(1..last).any(|i| orient(i, 0) == want && orient(0, i + 1) != want.flip())
}

/// The exact test of the candidate at leaf positions `x` and `y` (with their faces `sx`, `sy`):
/// the pair `(a, b)`, `a < b`, when the faces intersect. `cache` holds recently tested faces'
/// [`Tri`]s (direct-mapped by face index, [`TRI_CACHE`] entries); `plane_x` is the plane of `x`
/// (its corners in `sx`'s order), made here if `None`. Kept out of line, so that the traversal's
/// loop, which calls it for a few per cent of the candidates, stays small.
#[inline(never)]
fn test_candidate(
    order: &[u32],
    positions: &[[f64; 3]],
    cache: &mut [(u32, Tri)],
    plane_x: &mut Option<PlaneFilter>,
    (x, sx): (usize, [u32; 3]),
    (y, sy): (usize, [u32; 3]),
) -> Option<(u32, u32)> {
    // The corners by reference: read where they are, never copied on this path.
    let corners = |f: [u32; 3]| f.map(|v| &positions[v as usize]);
    let (ox, oy) = (order[x], order[y]);
    let (cx, cy) = (corners(sx), corners(sy));
    let plane = *plane_x.get_or_insert_with(|| PlaneFilter::new(*cx[0], *cx[1], *cx[2]));
    if let Some(hit) = decide_by_planes(sx, cx, &plane, sy, cy) {
        return hit.then_some(if ox < oy { (ox, oy) } else { (oy, ox) });
    }
    let corners = |f: [u32; 3]| f.map(|v| positions[v as usize]);
    let (px, py) = (corners(sx), corners(sy));
    if ox < oy {
        test_in_full(cache, (ox, sx, &px), (oy, sy, &py))
    } else {
        test_in_full(cache, (oy, sy, &py), (ox, sx, &px))
    }
}

/// The rest of [`test_candidate`] for faces `a < b` (with their indices and corners): the
/// separating-plane filters, then the full exact test. Out of line, so that the planes' path
/// stays small.
#[inline(never)]
fn test_in_full(
    cache: &mut [(u32, Tri)],
    (a, fa, pa): (u32, [u32; 3], &[[f64; 3]; 3]),
    (b, fb, pb): (u32, [u32; 3], &[[f64; 3]; 3]),
) -> Option<(u32, u32)> {
    let (pa, pb) = (*pa, *pb);
    if quickly_apart(fa, &pa, fb, &pb) {
        return None;
    }
    let mut tri = |f: u32, p: [[f64; 3]; 3]| {
        let e = &mut cache[f as usize % TRI_CACHE];
        if e.0 != f {
            *e = (f, Tri::new(p));
        }
        e.1
    };
    let (ta, tb) = (tri(a, pa), tri(b, pb));
    faces_intersect_filtered::<false>(fa, &ta, fb, &tb).then_some((a, b))
}

/// Entries of the check's cache of [`Tri`]s (per thread).
const TRI_CACHE: usize = 1024;

/// The sign of bit `k` of [`PlaneFilter::strict_sides`]'s sets (both clear: zero; only read
/// where one is set).
#[inline(always)]
fn sign_bit((pos, _): (u8, u8), k: usize) -> Sign {
    if pos & (1 << k) != 0 {
        Sign::Positive
    } else {
        Sign::Negative
    }
}

/// The decision of [`faces_intersect`] for the common configurations of faces `fa`, `fb` with
/// corners `pa`, `pb`, from the planes' filtered sides ([`PlaneFilter`]: an answer only where it
/// is the exact sign) and, for crossing faces, the exact `orient3d` of the straddling shortcuts;
/// `None` leaves the pair to the full test. The same decisions as the full test's (its steps on
/// exact signs, taken where the filtered signs are known): no shared vertex — a face strictly on
/// one side of the other's plane, or both straddling with no corner on the other plane
/// ([`straddling_overlap`]); one shared vertex — one face's other two corners strictly on one
/// side of the other's plane, or both straddling ([`straddling_at_corner`]); a shared edge — the
/// opposite corner strictly off the plane (no fold). A corner of `fb` with an undecided or zero
/// side of `fa`'s plane (nearly coplanar faces, which the full test's separating-plane filter
/// settles) hands the pair over before `fb`'s plane is made. Faces with a repeated index are left
/// to the full test. A decided `true` has every relevant sign non-zero, so neither face is
/// degenerate; a `false` is right for degenerate faces too (they are never paired). `plane_a` is
/// `PlaneFilter::new(pa[0], pa[1], pa[2])` (made by the caller, who may reuse it).
#[inline]
fn decide_by_planes(
    fa: [u32; 3],
    pa: [&[f64; 3]; 3],
    plane_a: &PlaneFilter,
    fb: [u32; 3],
    pb: [&[f64; 3]; 3],
) -> Option<bool> {
    let repeats = |f: [u32; 3]| f[0] == f[1] || f[1] == f[2] || f[2] == f[0];
    if repeats(fa) || repeats(fb) {
        return None;
    }
    let (shared, n) = shared_corners(fa, fb);
    let plane = |p: [&[f64; 3]; 3]| PlaneFilter::new(*p[0], *p[1], *p[2]);
    match n {
        0 => {
            let sb = plane_a.strict_sides(pb);
            if sb.0 | sb.1 != 7 {
                return None;
            }
            if sb.0 == 7 || sb.1 == 7 {
                return Some(false);
            }
            let sa = plane(pb).strict_sides(pa);
            if sa.0 == 7 || sa.1 == 7 {
                return Some(false);
            }
            if sa.0 | sa.1 == 7 {
                let known = |s: (u8, u8)| [0, 1, 2].map(|k| sign_bit(s, k));
                let corners = |p: [&[f64; 3]; 3]| [*p[0], *p[1], *p[2]];
                return Some(straddling_overlap(
                    &corners(pa),
                    &corners(pb),
                    known(sa),
                    known(sb),
                ));
            }
            None
        }
        1 => {
            let (i, j) = shared[0];
            let [v, a1, b1] = [pa[i], pa[(i + 1) % 3], pa[(i + 2) % 3]];
            let [a2, b2] = [pb[(j + 1) % 3], pb[(j + 2) % 3]];
            // Cycling a face's corners keeps its orientation: these are the full test's signs.
            let sb = plane_a.strict_sides([a2, b2]);
            if sb.0 | sb.1 != 3 {
                return None;
            }
            if sb.0 == 3 || sb.1 == 3 {
                return Some(false);
            }
            let sa = plane(pb).strict_sides([a1, b1]);
            if sa.0 == 3 || sa.1 == 3 {
                return Some(false);
            }
            if sa.0 | sa.1 == 3 {
                return Some(straddling_at_corner([*v, *a1], [*a2, *b2], sign_bit(sb, 1)));
            }
            None
        }
        2 => {
            let ((_, j0), (_, j1)) = (shared[0], shared[1]);
            let (pos, neg) = plane_a.strict_sides([pb[3 - j0 - j1]]);
            (pos | neg != 0).then_some(false)
        }
        _ => None,
    }
}

/// A face's corners and the axis its exact 2-D projection drops (`None`: degenerate).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tri {
    pub(crate) p: [[f64; 3]; 3],
    pub(crate) drop: Option<usize>,
}

impl Tri {
    pub(crate) fn new(p: [[f64; 3]; 3]) -> Tri {
        // Try the axes in order of the float normal's magnitude; accept the first whose exact
        // projected orientation is non-zero (the projection is then injective on the plane).
        let u = crate::geometry::sub(p[1], p[0]);
        let v = crate::geometry::sub(p[2], p[0]);
        let n = crate::geometry::cross(u, v);
        let mut axes = [0usize, 1, 2];
        axes.sort_by(|&i, &j| n[j].abs().total_cmp(&n[i].abs()));
        let drop = axes
            .into_iter()
            .find(|&k| orient2d_projected(p[0], p[1], p[2], k) != Sign::Zero);
        Tri { p, drop }
    }
}

/// Whether two faces (indices and their [`Tri`]s) intersect under the module's definitions.
#[cfg(test)]
pub(crate) fn faces_intersect(fa: [u32; 3], ta: &Tri, fb: [u32; 3], tb: &Tri) -> bool {
    faces_intersect_filtered::<true>(fa, ta, fb, tb)
}

/// [`faces_intersect`]; `FILTERS = false` skips the `f64` filters of [`quickly_apart`] (for a
/// caller that just ran them and got no answer), otherwise the same.
pub(crate) fn faces_intersect_filtered<const FILTERS: bool>(
    fa: [u32; 3],
    ta: &Tri,
    fb: [u32; 3],
    tb: &Tri,
) -> bool {
    let (Some(_), Some(_)) = (ta.drop, tb.drop) else {
        return false;
    };
    let (shared, n) = shared_corners(fa, fb);
    match n {
        0 => triangles_intersect_filtered::<FILTERS>(ta, tb),
        1 => {
            let (i, j) = shared[0];
            vertex_adjacent_intersect::<FILTERS>(&rotate(ta, i), &rotate(tb, j))
        }
        2 => {
            let ((i0, j0), (i1, j1)) = (shared[0], shared[1]);
            let a = ta.p[3 - i0 - i1];
            let b = tb.p[3 - j0 - j1];
            edge_fold_filtered::<FILTERS>(ta.p[i0], ta.p[i1], a, b, ta)
        }
        _ => true,
    }
}

/// The `f64` filters of [`faces_intersect`] alone, on the corners (before the exact projection
/// axes of [`Tri::new`] are computed): `true` only when the faces certainly do not intersect under
/// the module's definitions (faces sharing all three vertices: never).
fn quickly_apart(fa: [u32; 3], pa: &[[f64; 3]; 3], fb: [u32; 3], pb: &[[f64; 3]; 3]) -> bool {
    let repeats = |f: [u32; 3]| f[0] == f[1] || f[1] == f[2] || f[2] == f[0];
    if repeats(fa) || repeats(fb) {
        // Degenerate (never paired): left to faces_intersect, which says so.
        return false;
    }
    let (shared, n) = shared_corners(fa, fb);
    match n {
        0 => {
            let d = centroid_direction(pa, pb);
            certainly_separated(centroids_midpoint(pa, pb), d, pa, pb)
        }
        1 => {
            let (i, j) = shared[0];
            let v = pa[i];
            let (a1, b1) = (pa[(i + 1) % 3], pa[(i + 2) % 3]);
            let (a2, b2) = (pb[(j + 1) % 3], pb[(j + 2) % 3]);
            certainly_separated(
                v,
                centroid_direction(&[a1, b1], &[a2, b2]),
                &[a1, b1],
                &[a2, b2],
            )
        }
        2 => {
            let ((i0, j0), (i1, j1)) = (shared[0], shared[1]);
            clearly_opposite_sides(pa[i0], pa[i1], pa[3 - i0 - i1], pb[3 - j0 - j1])
        }
        _ => false,
    }
}

/// The triangle with its corners cycled so that corner `i` comes first.
/// The corners two faces share, as (index in `fa`, index in `fb`) in `fa`'s order, and how many
/// (the first `n` entries); no allocation, since this runs for every tested pair.
#[inline]
fn shared_corners(fa: [u32; 3], fb: [u32; 3]) -> ([(usize, usize); 3], usize) {
    let mut shared = [(0usize, 0usize); 3];
    let mut n = 0;
    for (i, &v) in fa.iter().enumerate() {
        if let Some(j) = fb.iter().position(|&w| w == v) {
            shared[n] = (i, j);
            n += 1;
        }
    }
    (shared, n)
}

fn rotate(t: &Tri, i: usize) -> Tri {
    Tri {
        p: [t.p[i], t.p[(i + 1) % 3], t.p[(i + 2) % 3]],
        drop: t.drop,
    }
}

#[inline]
fn o3(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> Sign {
    orient3d_unchecked(a, b, c, d)
}

/// Faces `(u, v, a)` and `(v, u, b)` sharing edge `uv`: a fold (coplanar, same side).
#[cfg(test)]
fn edge_fold(u: [f64; 3], v: [f64; 3], a: [f64; 3], b: [f64; 3], ta: &Tri) -> bool {
    edge_fold_filtered::<true>(u, v, a, b, ta)
}

fn edge_fold_filtered<const FILTERS: bool>(
    u: [f64; 3],
    v: [f64; 3],
    a: [f64; 3],
    b: [f64; 3],
    ta: &Tri,
) -> bool {
    if FILTERS && clearly_opposite_sides(u, v, a, b) {
        return false;
    }
    if o3(u, v, a, b) != Sign::Zero {
        return false;
    }
    let Some(k) = ta.drop else { return false };
    orient2d_projected(u, v, a, k) == orient2d_projected(u, v, b, k)
}

/// A filter before the fold test: `true` only when `a` and `b` are certainly on opposite sides of
/// the line `uv` (their components perpendicular to `uv` make an angle over 90°), so the faces
/// cannot fold onto each other whatever the exact `orient3d` says. It decides the common case of
/// flat or nearly flat neighbours, where `orient3d(u, v, a, b)` is close to 0 and its filter would
/// hand the sign to the exact fallback.
///
/// By Binet–Cauchy, `(e × da)·(e × db) = |e|²·(a⊥·b⊥)` with `e = v − u`, `da = a − u`,
/// `db = b − u`. In `f64` its error is below about `12ε·M` with `M = |e|₁²·|da|₁·|db|₁`
/// (the differences, the cross products and the dot each add a few roundings), so a computed
/// value below `−1e-12·M` is certainly negative. Anything else — including differences whose
/// 1-norms leave `[2⁻¹⁰⁰, 2¹⁰⁰]` — is left to the exact test.
#[inline]
fn clearly_opposite_sides(u: [f64; 3], v: [f64; 3], a: [f64; 3], b: [f64; 3]) -> bool {
    let sub = |p: [f64; 3], q: [f64; 3]| [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    let cross = |p: [f64; 3], q: [f64; 3]| {
        [
            p[1] * q[2] - p[2] * q[1],
            p[2] * q[0] - p[0] * q[2],
            p[0] * q[1] - p[1] * q[0],
        ]
    };
    let norm1 = |p: [f64; 3]| p[0].abs() + p[1].abs() + p[2].abs();
    let (e, da, db) = (sub(v, u), sub(a, u), sub(b, u));
    let (ne, na, nb) = (norm1(e), norm1(da), norm1(db));
    // 2⁻¹⁰⁰ ≤ each 1-norm ≤ 2¹⁰⁰: no overflow, and underflow (absolute 2⁻¹⁰⁷⁴ per product,
    // times at most 2²⁰⁰) stays far below the margin 1e-12·M ≥ 2⁻⁴⁴⁰.
    let in_range = |x: f64| (7.9e-31..=1.26e30).contains(&x);
    if !(in_range(ne) && in_range(na) && in_range(nb)) {
        return false;
    }
    let (ca, cb) = (cross(e, da), cross(e, db));
    let dot = ca[0] * cb[0] + ca[1] * cb[1] + ca[2] * cb[2];
    dot < -1e-12 * (ne * ne * na * nb)
}

/// A filter before the exact tests: `true` only when the plane through `origin` with normal `d`
/// certainly separates `pos` (every point strictly on the `+d` side) from `neg` (strictly on the
/// `−d` side). Two triangles separated so — or two sharing the corner `origin`, with their other
/// corners separated so — meet nowhere else, whatever the exact predicates say; on flat regions,
/// where `orient3d` is near zero and goes to the exact fallback, this decides most pairs in `f64`.
///
/// Each `(p − origin)·d` is computed in `f64` with an error below about `8ε·|p − origin|₁·|d|₁`
/// (the difference, three products, two sums); a value beyond `1e-12·|p − origin|₁·|d|₁` has the
/// sign it shows. Differences and `d` with 1-norms outside `[2⁻¹⁰⁰, 2¹⁰⁰]` are left to the exact
/// tests (no overflow; underflow stays far below the margin).
#[inline]
fn certainly_separated(origin: [f64; 3], d: [f64; 3], pos: &[[f64; 3]], neg: &[[f64; 3]]) -> bool {
    let norm1 = |p: [f64; 3]| p[0].abs() + p[1].abs() + p[2].abs();
    let in_range = |x: f64| (7.9e-31..=1.26e30).contains(&x);
    let nd = norm1(d);
    if !in_range(nd) {
        return false;
    }
    let side = |p: [f64; 3], sign: f64| {
        let q = [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]];
        let nq = norm1(q);
        in_range(nq) && sign * (q[0] * d[0] + q[1] * d[1] + q[2] * d[2]) > 1e-12 * nq * nd
    };
    pos.iter().all(|&p| side(p, 1.0)) && neg.iter().all(|&p| side(p, -1.0))
}

/// The direction from the centroid of `b` to that of `a` (`N` times it; only the direction
/// matters) — the separating-plane normal [`certainly_separated`] tries.
#[inline]
fn centroid_direction<const N: usize>(a: &[[f64; 3]; N], b: &[[f64; 3]; N]) -> [f64; 3] {
    let mut d = [0.0; 3];
    for (k, dk) in d.iter_mut().enumerate() {
        let (mut sa, mut sb) = (0.0, 0.0);
        for i in 0..N {
            sa += a[i][k];
            sb += b[i][k];
        }
        *dk = sa - sb;
    }
    d
}

/// The midpoint of the two triangles' centroids (the separating plane's origin for faces without
/// a shared vertex; any point would be right, this one separates best).
#[inline]
fn centroids_midpoint(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [f64; 3] {
    let mut m = [0.0; 3];
    for (k, mk) in m.iter_mut().enumerate() {
        *mk = 0.5 * ((a[0][k] + a[1][k] + a[2][k]) / 3.0 + (b[0][k] + b[1][k] + b[2][k]) / 3.0);
    }
    m
}

/// `(v, a₁, b₁)` and `(v, a₂, b₂)` sharing corner `v`: do they meet other than at `v`?
fn vertex_adjacent_intersect<const FILTERS: bool>(ta: &Tri, tb: &Tri) -> bool {
    let [v, a1, b1] = ta.p;
    let [_, a2, b2] = tb.p;
    if FILTERS
        && certainly_separated(
            v,
            centroid_direction(&[a1, b1], &[a2, b2]),
            &[a1, b1],
            &[a2, b2],
        )
    {
        return false;
    }
    // The shared corner is on both planes; when the other two corners of one face are strictly
    // on one side of the other's plane, that face meets the plane only at the corner: no more.
    let sb = [Sign::Zero, o3(v, a1, b1, a2), o3(v, a1, b1, b2)];
    if sb[1] == sb[2] && sb[1] != Sign::Zero {
        return false;
    }
    let [_, x, y] = tb.p;
    let sa = [Sign::Zero, o3(v, x, y, a1), o3(v, x, y, b1)];
    if sa[1] == sa[2] && sa[1] != Sign::Zero {
        return false;
    }
    if sa[1] != Sign::Zero && sa[2] != Sign::Zero && sb[1] != Sign::Zero && sb[2] != Sign::Zero {
        return straddling_at_corner([v, a1], [a2, b2], sb[2]);
    }
    segment_meets(a1, b1, sa[1], sa[2], tb)
        || segment_meets(a2, b2, sb[1], sb[2], ta)
        || enters_corner(a1, sa[1], tb)
        || enters_corner(b1, sa[2], tb)
        || enters_corner(a2, sb[1], ta)
        || enters_corner(b2, sb[2], ta)
}

/// `P = (v, a₁, b₁)` and `Q = (v, a₂, b₂)` sharing corner `v`, each with its other two corners
/// strictly on both sides of the other's plane (`side_b2`: the side of `b₂` of `P`'s plane, the
/// sign of `n_P·(b₂ − v)`, `n_P = (a₁ − v) × (b₁ − v)`): do they meet other than at `v`? The
/// planes meet in a line through `v`; `P` cuts it in `[v, i]` (`i` strictly inside `a₁b₁`) and
/// `Q` in `[v, k]` (`k` strictly inside `a₂b₂`), and the faces meet elsewhere iff both go the
/// same way from `v` — iff `k` is inside `P`'s corner at `v` rather than in the opposite
/// direction, i.e. strictly left of the ray `v → a₁` in `P`'s plane. The directed line
/// `a₂ → b₂` pierces that plane at `k` going towards `b₂`'s side, so
/// `orient3d(v, a₁, a₂, b₂) = sign(λ)·side_b2` with `λ > 0` iff `k` is left of `v → a₁`
/// (`(a₁ − v) × (k − v) = λ·n_P`): one `orient3d` instead of the edges' crossings.
fn straddling_at_corner([v, a1]: [[f64; 3]; 2], [a2, b2]: [[f64; 3]; 2], side_b2: Sign) -> bool {
    o3(v, a1, a2, b2) == side_b2
}

/// Whether the segment from `t`'s first corner to `a` (with `a`'s side of `t`'s plane) contains
/// points of `t` other than that corner: `a` coplanar and inside the corner's cone.
fn enters_corner(a: [f64; 3], side: Sign, t: &Tri) -> bool {
    if side != Sign::Zero {
        return false;
    }
    let Some(k) = t.drop else { return false };
    let [v, x, y] = t.p;
    let s = orient2d_projected(v, x, y, k);
    let s1 = orient2d_projected(v, x, a, k);
    let s2 = orient2d_projected(v, a, y, k);
    (s1 == s || s1 == Sign::Zero) && (s2 == s || s2 == Sign::Zero) && a != v
}

/// The side of `t`'s plane each corner of `q` is on.
fn plane_sides(t: &Tri, q: &Tri) -> [Sign; 3] {
    let [a, b, c] = t.p;
    [
        o3(a, b, c, q.p[0]),
        o3(a, b, c, q.p[1]),
        o3(a, b, c, q.p[2]),
    ]
}

fn strictly_one_side(s: &[Sign; 3]) -> bool {
    s[0] != Sign::Zero && s[0] == s[1] && s[1] == s[2]
}

/// Two non-degenerate closed triangles share a point.
#[cfg(test)]
pub(crate) fn triangles_intersect(ta: &Tri, tb: &Tri) -> bool {
    triangles_intersect_filtered::<true>(ta, tb)
}

fn triangles_intersect_filtered<const FILTERS: bool>(ta: &Tri, tb: &Tri) -> bool {
    if FILTERS {
        let d = centroid_direction(&ta.p, &tb.p);
        if certainly_separated(centroids_midpoint(&ta.p, &tb.p), d, &ta.p, &tb.p) {
            return false;
        }
    }
    let sb = plane_sides(ta, tb);
    if strictly_one_side(&sb) {
        return false;
    }
    let sa = plane_sides(tb, ta);
    if strictly_one_side(&sa) {
        return false;
    }
    if !sa.contains(&Sign::Zero) && !sb.contains(&Sign::Zero) {
        return straddling_overlap(&ta.p, &tb.p, sa, sb);
    }
    if sb.iter().all(|&s| s == Sign::Zero) {
        let Some(k) = ta.drop else { return false };
        return (0..3).any(|i| segment_triangle_2d(tb.p[i], tb.p[(i + 1) % 3], ta, k))
            || point_in_triangle_2d(ta.p[0], tb, k);
    }
    (0..3).any(|i| {
        let j = (i + 1) % 3;
        segment_meets(tb.p[i], tb.p[j], sb[i], sb[j], ta)
    }) || (0..3).any(|i| {
        let j = (i + 1) % 3;
        segment_meets(ta.p[i], ta.p[j], sa[i], sa[j], tb)
    })
}

/// Two triangles `P = ta`, `Q = tb` that cross each other's planes with no corner on the other's
/// plane (`sa`: the sides of `P`'s corners of `Q`'s plane, `sb`: of `Q`'s corners of `P`'s; all
/// non-zero, neither all equal) meet iff the segments they cut on the planes' common line
/// overlap — two more `orient3d` (the test of Guigue and Devillers, 2003) instead of the edges'
/// crossings.
///
/// With `p₁` the corner of `P` alone on its side of `Q`'s plane, `q₁` that of `Q`, the corners
/// cycled so (orientation kept) and then `q₂, q₃` swapped if `p₁` is on the negative side of `Q`
/// and `p₂, p₃` if `q₁` is on the negative side of `P` (so `p₁` is on the side of
/// `n_Q = (q₂ − q₁) × (q₃ − q₁)` and `q₁` on that of `n_P`): along `d = n_P × n_Q`, `P` cuts
/// `[j, i]` (`i` on `p₁p₂`, `j` on `p₁p₃`) and `Q` cuts `[k, l]` (`k` on `q₁q₂`, `l` on `q₁q₃`),
/// and `orient3d(p₁, p₂, q₁, q₂)` is the sign of `k − i` along `d`, `orient3d(p₁, p₃, q₁, q₃)`
/// that of `l − j`. The closed segments overlap iff `k ≤ i` and `j ≤ l`.
fn straddling_overlap(
    pa: &[[f64; 3]; 3],
    pb: &[[f64; 3]; 3],
    sa: [Sign; 3],
    sb: [Sign; 3],
) -> bool {
    // The corner whose side differs from the other two's.
    let lone = |s: [Sign; 3]| {
        if s[1] == s[2] {
            0
        } else if s[0] == s[2] {
            1
        } else {
            2
        }
    };
    let (ip, iq) = (lone(sa), lone(sb));
    let p1 = pa[ip];
    let (mut p2, mut p3) = (pa[(ip + 1) % 3], pa[(ip + 2) % 3]);
    let q1 = pb[iq];
    let (mut q2, mut q3) = (pb[(iq + 1) % 3], pb[(iq + 2) % 3]);
    if sa[ip] == Sign::Negative {
        std::mem::swap(&mut q2, &mut q3);
    }
    if sb[iq] == Sign::Negative {
        std::mem::swap(&mut p2, &mut p3);
    }
    o3(p1, p2, q1, q2) != Sign::Positive && o3(p1, p3, q1, q3) != Sign::Negative
}

/// The closed segment `pq` (with the sides of `t`'s plane its ends are on) meets triangle `t`.
fn segment_meets(p: [f64; 3], q: [f64; 3], sp: Sign, sq: Sign, t: &Tri) -> bool {
    if sp == sq && sp != Sign::Zero {
        return false;
    }
    let Some(k) = t.drop else { return false };
    if sp == Sign::Zero && sq == Sign::Zero {
        return segment_triangle_2d(p, q, t, k);
    }
    // One crossing point, between p and q: inside iff no two opposite edge signs.
    let [a, b, c] = t.p;
    let s = [o3(p, q, a, b), o3(p, q, b, c), o3(p, q, c, a)];
    !(s.contains(&Sign::Positive) && s.contains(&Sign::Negative))
}

/// Coplanar: the closed segment `pq` meets `t`, both seen on the plane that drops axis `k`.
fn segment_triangle_2d(p: [f64; 3], q: [f64; 3], t: &Tri, k: usize) -> bool {
    point_in_triangle_2d(p, t, k)
        || point_in_triangle_2d(q, t, k)
        || (0..3).any(|i| segments_meet_2d(p, q, t.p[i], t.p[(i + 1) % 3], k))
}

/// Coplanar: `x` in the closed non-degenerate triangle `t` (either orientation).
fn point_in_triangle_2d(x: [f64; 3], t: &Tri, k: usize) -> bool {
    let [a, b, c] = t.p;
    let s = [
        orient2d_projected(a, b, x, k),
        orient2d_projected(b, c, x, k),
        orient2d_projected(c, a, x, k),
    ];
    !(s.contains(&Sign::Positive) && s.contains(&Sign::Negative))
}

/// `r` lies in the axis box of `p` and `q` on the projection dropping `k` (for collinear points:
/// on the closed segment).
fn in_box_2d(p: [f64; 3], q: [f64; 3], r: [f64; 3], k: usize) -> bool {
    (0..3)
        .filter(|&i| i != k)
        .all(|i| p[i].min(q[i]) <= r[i] && r[i] <= p[i].max(q[i]))
}

/// Coplanar: the closed segments `pq` and `rs` meet (projection dropping `k`).
fn segments_meet_2d(p: [f64; 3], q: [f64; 3], r: [f64; 3], s: [f64; 3], k: usize) -> bool {
    let o1 = orient2d_projected(p, q, r, k);
    let o2 = orient2d_projected(p, q, s, k);
    let o3 = orient2d_projected(r, s, p, k);
    let o4 = orient2d_projected(r, s, q, k);
    if o1.as_i8() * o2.as_i8() < 0 && o3.as_i8() * o4.as_i8() < 0 {
        return true;
    }
    (o1 == Sign::Zero && in_box_2d(p, q, r, k))
        || (o2 == Sign::Zero && in_box_2d(p, q, s, k))
        || (o3 == Sign::Zero && in_box_2d(r, s, p, k))
        || (o4 == Sign::Zero && in_box_2d(r, s, q, k))
}

#[cfg(test)]
mod tests;
