//! Isotropic remeshing (Botsch & Kobbelt 2004, "A remeshing approach to multiresolution
//! modeling"), with a triangle-quality report and a sampled Hausdorff distance.
//!
//! # Algorithm
//! Given a target edge length `L`, each of [`RemeshOptions::iterations`] rounds runs, in order:
//! 1. **split** every edge longer than `4/3·L` at its midpoint, longest first (until none is);
//! 2. **collapse** every edge shorter than `4/5·L`: to its midpoint when both ends are free (not on
//!    a feature or boundary), else into the end that may not move; refusing a collapse that would
//!    - create an edge longer than `4/3·L`,
//!    - break the link condition (the two ends share a neighbour other than the edge's opposite
//!      corners), leave a vertex of valence < 3, pinch a boundary (an interior edge between two
//!      boundary vertices) or close a three-edge hole,
//!    - fold a face (its normal turns by more than 90°),
//!    - leave a near-degenerate face (a corner under 5°, unless no worse than the worst face it
//!      replaces),
//!    - move the surface by more than [`SURFACE_GUARD`]`·L` (`Remesher::collapse_keeps_surface`:
//!      the removed vertex's old position too far from the new faces, or a new face's centroid or
//!      edge midpoint too far from the input),
//!    - move a corner, move a feature vertex off its feature line (a feature vertex collapses only
//!      along a feature edge), or collapse across a feature;
//! 3. **flip** every interior, non-feature edge whose flip lowers `Σ (valence − target)²` over its
//!    four vertices (target 6 inside, 4 on the boundary), unless the flip lowers the smaller minimum
//!    angle of the two triangles below `min(before, 30°)`, folds them, duplicates an edge, or
//!    moves the surface by more than [`SURFACE_GUARD`]`·L` (`Remesher::flip_keeps_surface`); a pair with a corner under 10°
//!    (a needle or a zero-area face) is also flipped whenever that raises its minimum angle;
//! 4. **tangential relaxation**, [`SMOOTHING_STEPS`] times: every free vertex moves to the
//!    area-weighted centroid of its incident faces' centroids, projected into its tangent plane
//!    (vertex normal); a feature vertex moves, along its feature line, toward the midpoint of its two
//!    feature neighbours; then **every moved vertex is projected back onto the input**: a free
//!    vertex onto the input surface, a feature vertex onto the input's feature lines — both by the
//!    closest point through a [`Bvh`] over a frozen copy of the input; a free vertex whose closest
//!    point lies on an input face facing against the vertex's normal (the other sheet of a part
//!    thinner than `L`) takes the closest point on the faces facing its way instead, when that is
//!    within `L`.
//!
//! 5. after the last round, a **clean-up** (`Remesher::clean_up`), up to five passes: every free
//!    vertex of a face with a corner under 20° moves to the centroid of its neighbours (or a
//!    quarter, half or three quarters of the way), projected onto the input, and every feature
//!    vertex (two feature edges, not a corner) a quarter or half of the way to either feature
//!    neighbour, projected onto the input's feature lines, when that raises the
//!    smallest angle of its faces, folds none, does not jump to an input sheet facing the other way
//!    and keeps its faces' centroids within `max(before, 0.2·L)` of the input; the shortest edge of
//!    every face with a corner under 10° is collapsed when it is shorter than `4/5·L` and the
//!    collapse rules allow it; a corner closer than [`CORNER_ONTO_LINE`]`·L` to a feature edge
//!    of a face with a corner under 20° joins that line (the edge is flipped to the corner,
//!    `Remesher::merge_corners_onto_lines`); every non-feature pair with a corner under 20° is flipped when that
//!    raises its minimum angle without folding or bending it beyond the feature angle (the last
//!    relaxation can leave such slivers where a vertex was pulled against a feature line).
//!
//! 6. last, a **repair of new self-intersections** (`Remesher::repair_new_intersections`): the
//!    mesh is checked exactly ([`crate::intersect::self_intersections`]); a pair is inherited when
//!    an input face that is itself in an intersecting pair lies within `L` of either face's
//!    centroid (the input is checked only when the output has a pair); every other pair is
//!    repaired by the first local candidate — a vertex moved toward its neighbours' centroid or
//!    slid along its feature line, an edge of the pair flipped or collapsed (under the rounds'
//!    rules; last, a collapse that waives the removed vertex's feature rules) — that lowers the
//!    number of intersecting pairs among the faces within two edges of the pair, in up to ten
//!    passes and at most 20,000 tried candidates (2,000 flips and collapses) in all. Collapses can fold a new fan over faces that share one vertex with it (a fold no
//!    per-face normal test sees); that is what this repairs.
//!
//! # Features and boundaries
//! An input edge is a *feature* when its dihedral angle (the angle between its two faces' normals)
//! exceeds [`RemeshOptions::feature_angle_deg`], and every boundary edge is one too — except crease
//! chains that are noise at the target length `L`: isolated open chains and closed loops shorter
//! than `L`, and tails (from an open end to a junction) shorter than `L/2`; kept, they would lock
//! their ends as corners with a sliver between (`prune_short_feature_chains`); and the two edges
//! of a hairpin (two crease edges meeting at under 30° at a vertex, sides of one face whose third
//! edge is a crease too: a tilted sliver), which would make a corner with a 30° sector
//! (`unmark_hairpins`). Feature lines and corners closer than `0.2·L` merge: an edge that
//! short may collapse a corner into a corner, or a feature vertex into a feature vertex or corner,
//! across lines. A vertex with
//! exactly two feature edges slides along its feature line; a vertex with one or more than two,
//! or where its feature line turns by more than the feature angle (the corners of a flat
//! square's boundary), is a *corner*: it never moves and is removed only by merging into another corner closer than `0.2·L`. Feature edges are split (both halves stay
//! features) and may be collapsed along the line, never flipped, and collapsed across only to merge
//! lines closer than `0.2·L` (never moving a boundary vertex). So boundary
//! edges are split, collapsed only along the boundary and never flipped; boundary vertices slide
//! along the boundary. Collapses keep the topology (link condition), so the number of components,
//! the genus (Euler characteristic) and the number of boundary loops are preserved, with one
//! exception: a closed component smaller than a few target edges cannot go below a tetrahedron and
//! keeps its short edges.
//!
//! # Input
//! Faces must be consistently oriented and manifold: an edge used by more than two faces, or twice
//! in the same direction, is refused with [`RemeshError::NonManifoldEdge`] naming it, and a vertex
//! whose faces form two or more fans with [`RemeshError::NonManifoldVertex`] (run
//! [`crate::validate::repair`] first to orient and clean a mesh from a file). A face with a repeated
//! vertex is dropped (it has no area and no well-defined edges); zero-area faces with three distinct
//! vertices are kept and usually vanish in the first round (their short edges collapse, their long
//! edges split and flip). Vertices no face uses are dropped. Out-of-range indices and NaN or infinite
//! coordinates are refused.
//!
//! Bounded work: coordinates must be at most [`MAX_COORDINATE`] in magnitude and the bounding-box
//! diagonal at least [`MIN_DIAGONAL`] ([`RemeshError::Scale`]: squared areas must not overflow or
//! underflow); the target length must be finite, positive and at most the bounding-box diagonal
//! (else the mesh is smaller than one edge: [`RemeshError::MeshSmallerThanEdge`]); the output's face
//! count is predicted up front as `max(1.2·area / (√3/4·L²), Σ edge length / L)` and refused over
//! [`RemeshOptions::max_faces`] before any work ([`RemeshError::TooManyFaces`]); the running face
//! count is checked against the same limit after every split pass; at most [`MAX_ITERATIONS`] rounds.
//!
//! # Guarantees and limits
//! The output is a pure function of the input and the options (no hashing order, no threads), its
//! faces are CCW like the input's, and every vertex lies on the input surface (up to the closest-point
//! arithmetic) — corners exactly at their input positions. Features are kept only where the dihedral
//! angle test finds them: a smooth crease below the threshold is remeshed as smooth surface. Edge
//! lengths are not guaranteed to end inside `[4/5·L, 4/3·L]`: the collapse and flip refusals, corners
//! and short feature lines leave some outside (on smooth closed meshes ≥ 90 % end inside, see the
//! tests). Self-intersecting face pairs the remeshing creates (not within `L` of an intersecting
//! part of the input) are repaired where a local repair helps; what none helps stays (measured:
//! none on the fixtures and the 15 benchmark meshes at 1.5 % of the diagonal; `turbine.off` at 3 %
//! keeps 4, see `docs/remeshing.md`).

mod halfedge;
mod quality;
mod transfer;

use halfedge::{HalfEdgeMesh, NONE, dist, opp};
pub use quality::{Hausdorff, Quality, hausdorff, quality};
pub use transfer::{TransferSource, transfer_parts};

use crate::bvh::{Bvh, BvhError};
use crate::geometry::{cross, dot, norm, sub};

/// Tangential relaxation steps (each followed by the projection) per round.
pub const SMOOTHING_STEPS: usize = 3;

/// The largest coordinate magnitude [`remesh`] accepts: squared face areas (fourth powers of
/// lengths) of such points stay finite in `f64`.
pub const MAX_COORDINATE: f64 = 1e70;

/// The smallest bounding-box diagonal [`remesh`] accepts (a mesh of one point is
/// [`RemeshError::MeshSmallerThanEdge`]): fourth powers of lengths stay normal `f64` numbers.
pub const MIN_DIAGONAL: f64 = 1e-70;

/// The most rounds [`remesh`] accepts.
pub const MAX_ITERATIONS: usize = 1000;

/// What to remesh to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RemeshOptions {
    /// Target edge length `L`, in the mesh's units.
    pub target_edge_length: f64,
    /// Rounds of split, collapse, flip, relax (default 10).
    pub iterations: usize,
    /// Dihedral angle in degrees above which an edge is a feature (default 30; 180 turns feature
    /// detection off except for boundaries).
    pub feature_angle_deg: f64,
    /// The largest output face count accepted (default 2,000,000), checked up front from the
    /// predicted count and while remeshing.
    pub max_faces: usize,
}

impl RemeshOptions {
    /// The defaults with a given target edge length.
    pub fn new(target_edge_length: f64) -> Self {
        Self {
            target_edge_length,
            iterations: 10,
            feature_angle_deg: 30.0,
            max_faces: 2_000_000,
        }
    }
}

/// What [`remesh`], [`quality`] and [`hausdorff`] refuse.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RemeshError {
    /// An out-of-range face index or a non-finite vertex.
    #[error("{0}")]
    Input(#[from] BvhError),
    /// No face to remesh.
    #[error("the mesh has no faces")]
    Empty,
    /// The target edge length is zero, negative, NaN or infinite.
    #[error("the target edge length must be a positive finite number, got {0}")]
    EdgeLength(f64),
    /// Coordinates too large or a mesh too small for the arithmetic (normalize it first, e.g. to
    /// the side-2 cube of [`crate::normalize::side2_cube`]).
    #[error(
        "the mesh's scale is outside what remeshing handles (largest coordinate {size:e}, bounding-box diagonal {diagonal:e}; accepted: coordinates up to 1e70, diagonal at least 1e-70); normalize it first"
    )]
    Scale {
        /// The largest coordinate magnitude.
        size: f64,
        /// The bounding-box diagonal.
        diagonal: f64,
    },
    /// The target edge length exceeds the bounding-box diagonal.
    #[error(
        "the target edge length {length} exceeds the mesh's bounding-box diagonal {diagonal}: the mesh is smaller than one target edge"
    )]
    MeshSmallerThanEdge {
        /// The target edge length.
        length: f64,
        /// The bounding-box diagonal.
        diagonal: f64,
    },
    /// The feature angle is outside `[0, 180]` degrees or NaN.
    #[error("the feature angle must be between 0 and 180 degrees, got {0}")]
    FeatureAngle(f64),
    /// Too many rounds.
    #[error("at most {max} remeshing iterations are accepted, got {got}")]
    Iterations {
        /// Requested.
        got: usize,
        /// [`MAX_ITERATIONS`].
        max: usize,
    },
    /// The predicted output is over the face limit.
    #[error(
        "remeshing to edge length {length} would make about {predicted} faces, over the limit of {max}; choose a longer edge length"
    )]
    TooManyFaces {
        /// The target edge length.
        length: f64,
        /// The predicted face count.
        predicted: usize,
        /// [`RemeshOptions::max_faces`].
        max: usize,
    },
    /// The mesh grew past the face limit while remeshing (the prediction was too low, e.g. for
    /// long zero-area faces).
    #[error("remeshing stopped: the mesh grew past the limit of {max} faces")]
    FaceBudget {
        /// [`RemeshOptions::max_faces`].
        max: usize,
    },
    /// An edge with more than two faces, or used twice in the same direction.
    #[error(
        "non-manifold edge ({a}, {b}): used by more than two faces or twice in the same direction (inconsistent orientation); repair the mesh first"
    )]
    NonManifoldEdge {
        /// First vertex.
        a: u32,
        /// Second vertex.
        b: u32,
    },
    /// Attributes could not be carried onto the remeshed mesh ([`transfer_parts`]): inconsistent
    /// source faces.
    #[error("cannot carry attributes onto the remeshed mesh: {0}")]
    Transfer(String),
    /// A vertex whose faces form more than one fan.
    #[error(
        "non-manifold vertex {vertex}: its faces form more than one fan (two parts touch there); repair the mesh first"
    )]
    NonManifoldVertex {
        /// The vertex.
        vertex: u32,
    },
}

/// The result of [`remesh`].
#[derive(Clone, Debug, PartialEq)]
pub struct Remeshed {
    /// New vertex positions.
    pub positions: Vec<[f64; 3]>,
    /// New faces, CCW like the input's.
    pub faces: Vec<[u32; 3]>,
    /// For every new face, the input face its centroid's closest point lies on (an index into the
    /// input's face list), so per-face labels can follow.
    pub source_faces: Vec<u32>,
}

/// The predicted output face count for target length `l`: `max(1.2·A / (√3/4·L²), Σ ℓ_e / L)`.
pub fn predicted_faces(positions: &[[f64; 3]], faces: &[[u32; 3]], l: f64) -> f64 {
    let area: f64 = faces
        .iter()
        .map(|f| 0.5 * norm(tri_cross(positions, *f)))
        .sum();
    let perimeter: f64 = faces
        .iter()
        .map(|f| {
            (0..3)
                .map(|k| dist(positions[f[k] as usize], positions[f[(k + 1) % 3] as usize]))
                .sum::<f64>()
        })
        .sum::<f64>()
        / 2.0;
    let by_area = 1.2 * area / (3f64.sqrt() / 4.0 * l * l);
    by_area.max(perimeter / l)
}

fn tri_cross(p: &[[f64; 3]], f: [u32; 3]) -> [f64; 3] {
    let (a, b, c) = (p[f[0] as usize], p[f[1] as usize], p[f[2] as usize]);
    cross(sub(b, a), sub(c, a))
}

/// The unit normal of a face, `None` for a (numerically) zero-area one: `|N| ≤ 1e-10·ℓ_max²`, so a
/// collinear face's rounding noise is not taken for a direction.
fn face_normal(p: &[[f64; 3]], f: [u32; 3]) -> Option<[f64; 3]> {
    let (a, b, c) = (p[f[0] as usize], p[f[1] as usize], p[f[2] as usize]);
    let n = cross(sub(b, a), sub(c, a));
    let l2 = dot(sub(b, a), sub(b, a))
        .max(dot(sub(c, a), sub(c, a)))
        .max(dot(sub(c, b), sub(c, b)));
    if norm(n) <= 1e-10 * l2 {
        None
    } else {
        normalized(n)
    }
}

fn normalized(v: [f64; 3]) -> Option<[f64; 3]> {
    let n = norm(v);
    (n > 0.0 && n.is_finite()).then(|| [v[0] / n, v[1] / n, v[2] / n])
}

/// The smallest corner angle of a triangle, in radians (0 for a degenerate one).
fn min_angle(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let corner = |p: [f64; 3], q: [f64; 3], r: [f64; 3]| {
        let (u, v) = (sub(q, p), sub(r, p));
        norm(cross(u, v)).atan2(dot(u, v))
    };
    corner(a, b, c).min(corner(b, c, a)).min(corner(c, a, b))
}

/// A collapse may not make a face with a smaller corner (unless no worse than before).
const MIN_NEW_ANGLE: f64 = 5.0 * std::f64::consts::PI / 180.0;

/// A valence-improving flip may lower the pair's minimum angle, but never below this (or below
/// the minimum before, when that is smaller).
const FLIP_KEEP_ANGLE: f64 = 30.0 * std::f64::consts::PI / 180.0;

/// A face pair with a corner under this is flipped whenever that raises its minimum angle.
const NEEDLE_ANGLE: f64 = 10.0 * std::f64::consts::PI / 180.0;

/// Checks the input and the options; returns the mesh's faces without repeated-vertex faces.
fn check(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    o: &RemeshOptions,
) -> Result<Vec<[u32; 3]>, RemeshError> {
    let l = o.target_edge_length;
    if !(l.is_finite() && l > 0.0) {
        return Err(RemeshError::EdgeLength(l));
    }
    let a = o.feature_angle_deg;
    if !(0.0..=180.0).contains(&a) {
        return Err(RemeshError::FeatureAngle(a));
    }
    if o.iterations > MAX_ITERATIONS {
        return Err(RemeshError::Iterations {
            got: o.iterations,
            max: MAX_ITERATIONS,
        });
    }
    quality::check_faces(positions, faces)?;
    let kept: Vec<[u32; 3]> = faces
        .iter()
        .copied()
        .filter(|f| f[0] != f[1] && f[1] != f[2] && f[2] != f[0])
        .collect();
    if kept.is_empty() {
        return Err(RemeshError::Empty);
    }
    let mut bb = crate::bvh::Aabb::EMPTY;
    for f in &kept {
        for &v in f {
            bb.grow(positions[v as usize]);
        }
    }
    let size = (0..3)
        .map(|k| bb.lo[k].abs().max(bb.hi[k].abs()))
        .fold(0.0, f64::max);
    let diagonal = norm(sub(bb.hi, bb.lo));
    if size > MAX_COORDINATE || (diagonal > 0.0 && diagonal < MIN_DIAGONAL) || !diagonal.is_finite()
    {
        return Err(RemeshError::Scale { size, diagonal });
    }
    if l > diagonal {
        return Err(RemeshError::MeshSmallerThanEdge {
            length: l,
            diagonal,
        });
    }
    let predicted = predicted_faces(positions, &kept, l);
    if predicted.is_nan() || predicted > o.max_faces as f64 {
        return Err(RemeshError::TooManyFaces {
            length: l,
            predicted: if predicted.is_finite() {
                predicted.ceil() as usize
            } else {
                usize::MAX
            },
            max: o.max_faces,
        });
    }
    Ok(kept)
}

/// Remeshes `(positions, faces)` isotropically to `options.target_edge_length` (see the
/// [module docs](self) for the algorithm, what it preserves and what it refuses).
pub fn remesh(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    options: &RemeshOptions,
) -> Result<Remeshed, RemeshError> {
    let kept = check(positions, faces, options)?;
    let surface = Bvh::new(positions, faces)?;
    let mut mesh = HalfEdgeMesh::new(positions, &kept)?;
    let mut r = Remesher::new(&mut mesh, positions, &kept, options, &surface)?;
    for _ in 0..options.iterations {
        r.split_long_edges()?;
        r.collapse_short_edges();
        r.flip_edges();
        for _ in 0..SMOOTHING_STEPS {
            r.relax_and_project(&surface);
        }
    }
    if options.iterations > 0 {
        r.clean_up(&surface);
        r.repair_new_intersections(positions, &kept, &surface)?;
    }
    let (positions, faces) = r.mesh.compact();
    let source_faces = faces
        .iter()
        .map(|f| {
            let c = centroid(&positions, *f);
            surface.closest_point(c).map_or(0, |q| q.face)
        })
        .collect();
    Ok(Remeshed {
        positions,
        faces,
        source_faces,
    })
}

fn centroid(p: &[[f64; 3]], f: [u32; 3]) -> [f64; 3] {
    let (a, b, c) = (p[f[0] as usize], p[f[1] as usize], p[f[2] as usize]);
    [
        (a[0] + b[0] + c[0]) / 3.0,
        (a[1] + b[1] + c[1]) / 3.0,
        (a[2] + b[2] + c[2]) / 3.0,
    ]
}

/// The two faces of an edge `a→b` that a flip would replace: `c` opposite the edge in the face of
/// the half-edge `a→b`, `d` in the face of `b→a`, with their positions. After the flip the faces
/// are `(a, d, c)` and `(d, b, c)`.
struct FlipQuad {
    a: u32,
    b: u32,
    c: u32,
    d: u32,
    pa: [f64; 3],
    pb: [f64; 3],
    pc: [f64; 3],
    pd: [f64; 3],
}

/// The quad of edge `e` when a flip of it is allowed by the connectivity: a live, interior,
/// non-feature edge whose opposite corners `c` and `d` differ and are not already joined (the
/// flip would duplicate that edge). `ring` is scratch space.
fn flip_quad(m: &HalfEdgeMesh, e: usize, ring: &mut Vec<u32>) -> Option<FlipQuad> {
    if !m.edge_live(e) || m.feature[e] || m.is_boundary_edge(e) {
        return None;
    }
    let h = 2 * e as u32;
    let (a, b) = (m.from(h), m.to(h));
    let c = m.to(m.next(h));
    let d = m.to(m.next(opp(h)));
    if c == d {
        return None;
    }
    m.outgoing(c, ring);
    if ring.iter().any(|&g| m.to(g) == d) {
        return None;
    }
    let p = |v: u32| m.pos[v as usize];
    Some(FlipQuad {
        a,
        b,
        c,
        d,
        pa: p(a),
        pb: p(b),
        pc: p(c),
        pd: p(d),
    })
}

/// The sum of the (area-weighted) normals of the faces `(a, b, c)` and `(b, a, d)` of a flip quad
/// before the flip: the side a flipped pair must keep facing.
fn pair_normal(pa: [f64; 3], pb: [f64; 3], pc: [f64; 3], pd: [f64; 3]) -> [f64; 3] {
    let n1 = cross(sub(pb, pa), sub(pc, pa));
    let n2 = cross(sub(pa, pb), sub(pd, pb));
    [n1[0] + n2[0], n1[1] + n2[1], n1[2] + n2[2]]
}

struct Remesher<'a> {
    mesh: &'a mut HalfEdgeMesh,
    /// The input's feature lines as degenerate triangles `[a, b, b]` over the input positions.
    lines: Bvh,
    lo: f64,
    hi: f64,
    /// Edges shorter than this may merge two feature lines or two corners.
    snap: f64,
    /// A corner closer than this to a feature edge of its face joins that line
    /// ([`CORNER_ONTO_LINE`]`·L`).
    onto_line: f64,
    /// The cosine of the feature angle.
    cos_feature: f64,
    max_faces: usize,
    buf: Vec<u32>,
    buf2: Vec<u32>,
    /// Per vertex: the input face it last projected onto (`NONE` before its first projection), the
    /// closest-point search's starting guess.
    hints: Vec<u32>,
    /// The frozen input surface.
    surface: &'a Bvh,
    /// The surface-distance bound of the local operations ([`SURFACE_GUARD`]`·L`).
    guard: f64,
    /// The side-aware projection takes a point on an input face facing the vertex's way at most
    /// this far (`L`) over a closer one on a face facing against the vertex's normal.
    side_reach: f64,
}

impl<'a> Remesher<'a> {
    fn new(
        mesh: &'a mut HalfEdgeMesh,
        positions: &[[f64; 3]],
        faces: &[[u32; 3]],
        o: &RemeshOptions,
        surface: &'a Bvh,
    ) -> Result<Self, RemeshError> {
        let cos_limit = o.feature_angle_deg.to_radians().cos();
        let normals: Vec<Option<[f64; 3]>> =
            faces.iter().map(|f| face_normal(positions, *f)).collect();
        let mut segments = Vec::new();
        for e in 0..mesh.num_edges() {
            let h = 2 * e as u32;
            let (f0, f1) = (mesh.face_of(h), mesh.face_of(opp(h)));
            let is_feature = if f0 == NONE || f1 == NONE {
                true
            } else {
                match (normals[f0 as usize], normals[f1 as usize]) {
                    (Some(a), Some(b)) => o.feature_angle_deg < 180.0 && dot(a, b) < cos_limit,
                    _ => false,
                }
            };
            mesh.feature[e] = is_feature;
        }
        let l = o.target_edge_length;
        unmark_hairpins(mesh);
        prune_short_feature_chains(mesh, MIN_FEATURE_CHAIN * l);
        for e in 0..mesh.num_edges() {
            if mesh.feature[e] {
                let h = 2 * e as u32;
                let b = mesh.to(h);
                segments.push([mesh.from(h), b, b]);
            }
        }
        let lines = Bvh::new(positions, &segments)?;
        let r = Remesher {
            mesh,
            lines,
            lo: 0.8 * l,
            hi: 4.0 / 3.0 * l,
            snap: FEATURE_SNAP * l,
            onto_line: CORNER_ONTO_LINE * l,
            cos_feature: cos_limit,
            max_faces: o.max_faces,
            buf: Vec::new(),
            buf2: Vec::new(),
            hints: Vec::new(),
            surface,
            guard: SURFACE_GUARD * l,
            side_reach: l,
        };
        let counts = r.feature_counts();
        let mut ring = Vec::new();
        for v in 0..r.mesh.num_vertices() {
            r.mesh.locked[v] = counts[v] != 0 && counts[v] != 2;
            if counts[v] == 2 {
                // A feature line that turns by more than the feature angle here has a corner.
                r.mesh.outgoing(v as u32, &mut ring);
                let dirs: Vec<[f64; 3]> = ring
                    .iter()
                    .filter(|&&g| r.mesh.feature[(g / 2) as usize])
                    .filter_map(|&g| {
                        normalized(sub(r.mesh.pos[r.mesh.to(g) as usize], r.mesh.pos[v]))
                    })
                    .collect();
                if dirs.len() == 2 && -dot(dirs[0], dirs[1]) < cos_limit {
                    r.mesh.locked[v] = true;
                }
            }
        }
        Ok(r)
    }

    /// Feature edges at every vertex.
    fn feature_counts(&self) -> Vec<u8> {
        let mut c = vec![0u8; self.mesh.num_vertices()];
        for e in 0..self.mesh.num_edges() {
            if self.mesh.edge_live(e) && self.mesh.feature[e] {
                let h = 2 * e as u32;
                for v in [self.mesh.from(h), self.mesh.to(h)] {
                    c[v as usize] = c[v as usize].saturating_add(1);
                }
            }
        }
        c
    }

    /// Splits the longest edge first (longest-edge bisection), so a needle or zero-area face is
    /// cut across its long side instead of sprouting new long edges from its short ones.
    fn split_long_edges(&mut self) -> Result<(), RemeshError> {
        use std::cmp::Reverse;
        use std::collections::BinaryHeap;
        // Positive finite lengths order like their bit patterns; ties go to the lower index.
        let mut heap: BinaryHeap<(u64, Reverse<usize>)> = (0..self.mesh.num_edges())
            .filter(|&e| self.mesh.edge_live(e))
            .map(|e| (self.mesh.edge_length(e), e))
            .filter(|&(l, _)| l > self.hi)
            .map(|(l, e)| (l.to_bits(), Reverse(e)))
            .collect();
        while let Some((bits, Reverse(e))) = heap.pop() {
            if !self.mesh.edge_live(e) || self.mesh.edge_length(e).to_bits() != bits {
                continue; // stale: the edge was split since it was queued
            }
            let h = 2 * e as u32;
            let (a, b) = (
                self.mesh.pos[self.mesh.from(h) as usize],
                self.mesh.pos[self.mesh.to(h) as usize],
            );
            let mid = [
                (a[0] + b[0]) / 2.0,
                (a[1] + b[1]) / 2.0,
                (a[2] + b[2]) / 2.0,
            ];
            let first_new = self.mesh.num_edges();
            self.mesh.split(e, mid);
            if self.mesh.live_faces() > self.max_faces {
                return Err(RemeshError::FaceBudget {
                    max: self.max_faces,
                });
            }
            for g in std::iter::once(e).chain(first_new..self.mesh.num_edges()) {
                let l = self.mesh.edge_length(g);
                if l > self.hi {
                    heap.push((l.to_bits(), Reverse(g)));
                }
            }
        }
        Ok(())
    }

    fn collapse_short_edges(&mut self) {
        let mut counts = self.feature_counts();
        for e in 0..self.mesh.num_edges() {
            if !self.mesh.edge_live(e) || self.mesh.edge_length(e) >= self.lo {
                continue;
            }
            let h = 2 * e as u32;
            let (a, b) = (self.mesh.from(h) as usize, self.mesh.to(h) as usize);
            let (pa, pb) = (self.mesh.pos[a], self.mesh.pos[b]);
            // Two free ends meet at the midpoint; otherwise one end stays where it is.
            let free = |v: usize| counts[v] == 0 && !self.mesh.locked[v];
            let mid = [
                (pa[0] + pb[0]) / 2.0,
                (pa[1] + pb[1]) / 2.0,
                (pa[2] + pb[2]) / 2.0,
            ];
            let chosen = if free(a) && free(b) && self.collapse_ok(h, &counts, mid) {
                Some((h, mid))
            } else {
                // Remove the end with the lower valence (`a` on a tie) when both may go; the
                // other is tried only when the preferred one may not (each try queries the input).
                let preferred = if self.mesh.valence(a as u32) <= self.mesh.valence(b as u32) {
                    [(h, pb), (opp(h), pa)]
                } else {
                    [(opp(h), pa), (h, pb)]
                };
                preferred
                    .into_iter()
                    .find(|&(g, target)| self.collapse_ok(g, &counts, target))
            };
            let Some((g, target)) = chosen else {
                continue;
            };
            let v1 = self.mesh.to(g);
            self.collapse_and_recount(g, &mut counts);
            self.mesh.pos[v1 as usize] = target;
        }
    }

    /// Collapses half-edge `g` (removing `from(g)`; `to(g)` keeps its position) and recounts the
    /// feature edges around the kept vertex: edges merged at the opposite corners may have become
    /// features.
    fn collapse_and_recount(&mut self, g: u32, counts: &mut [u8]) {
        let v1 = self.mesh.to(g);
        let mut scratch = std::mem::take(&mut self.buf);
        self.mesh.collapse(g, &mut scratch);
        self.mesh.outgoing(v1, &mut scratch);
        let ring: Vec<u32> = scratch.iter().map(|&k| self.mesh.to(k)).collect();
        self.buf = scratch;
        counts[v1 as usize] = self.count_at(v1);
        for w in ring {
            counts[w as usize] = self.count_at(w);
        }
    }

    fn count_at(&mut self, v: u32) -> u8 {
        let mut buf = std::mem::take(&mut self.buf2);
        self.mesh.outgoing(v, &mut buf);
        let n = buf
            .iter()
            .filter(|&&g| self.mesh.feature[(g / 2) as usize])
            .count();
        self.buf2 = buf;
        n.min(255) as u8
    }

    /// Whether collapsing half-edge `h` (removing `from(h)`, moving `to(h)` to `target`) is
    /// allowed.
    fn collapse_ok(&mut self, h: u32, counts: &[u8], target: [f64; 3]) -> bool {
        let m = &*self.mesh;
        let o = opp(h);
        let (v0, v1) = (m.from(h), m.to(h));
        let e = (h / 2) as usize;
        // Feature lines closer than `snap` merge: a corner may collapse into a corner, a feature
        // vertex into a feature vertex or corner, along any edge that short (never a boundary
        // vertex: the boundary stays where it is).
        let snap = m.edge_length(e) < self.snap && !m.is_boundary_vertex(v0);
        if m.locked[v0 as usize] && !(snap && m.locked[v1 as usize]) {
            return false;
        }
        let feature_edge = m.feature[e];
        if counts[v0 as usize] > 0
            && !feature_edge
            && !(snap && (counts[v1 as usize] > 0 || m.locked[v1 as usize]))
        {
            return false; // a feature vertex moves only along its feature line
        }
        let boundary_edge = m.is_boundary_edge(e);
        if !boundary_edge && m.is_boundary_vertex(v0) && m.is_boundary_vertex(v1) {
            return false;
        }
        if m.is_boundary_halfedge(h) && m.boundary_loop_is_triangle(h) {
            return false;
        }
        if m.is_boundary_halfedge(o) && m.boundary_loop_is_triangle(o) {
            return false;
        }
        let vl = (!m.is_boundary_halfedge(h)).then(|| m.to(m.next(h)));
        let vr = (!m.is_boundary_halfedge(o)).then(|| m.to(m.next(o)));
        for v in [vl, vr].into_iter().flatten() {
            let need = if m.is_boundary_vertex(v) { 3 } else { 4 };
            if m.valence(v) < need {
                return false;
            }
        }
        // An ear: both other edges of a side face on the boundary.
        for side in [h, o] {
            if !m.is_boundary_halfedge(side) {
                let s1 = m.next(side);
                let s2 = m.next(s1);
                if m.is_boundary_halfedge(opp(s1)) && m.is_boundary_halfedge(opp(s2)) {
                    return false;
                }
            }
        }
        // Link condition: the common neighbours are exactly the opposite corners.
        let mut r0 = std::mem::take(&mut self.buf);
        let mut r1 = std::mem::take(&mut self.buf2);
        m.outgoing(v0, &mut r0);
        m.outgoing(v1, &mut r1);
        let common = r0
            .iter()
            .filter(|&&g| {
                let w = m.to(g);
                r1.iter().any(|&k| m.to(k) == w)
            })
            .count();
        let expected = vl.is_some() as usize + vr.is_some() as usize;
        let ok = common == expected
            && r0.len() + r1.len() - 2 - expected >= 3
            && ring_ok(m, v0, v1, target, &r0, self.hi)
            && (target == m.pos[v1 as usize] || ring_ok(m, v1, v0, target, &r1, self.hi))
            && self.collapse_keeps_surface(v0, v1, target, &r0, &r1);
        self.buf = r0;
        self.buf2 = r1;
        ok
    }

    /// The distance from `p` to the input surface (`∞` when there is none), searched from the
    /// input face `hint`.
    fn off_input(&self, p: [f64; 3], hint: u32) -> f64 {
        self.surface
            .closest_point_hinted(p, hint)
            .map_or(f64::INFINITY, |c| c.distance_squared.sqrt())
    }

    /// The surface-distance guard of a collapse of `v0` into `v1` (rings `r0`, `r1`) with `v1`
    /// moved to `target`: the new faces around `target` must stay within [`Self::guard`] of the
    /// input both ways — every input point the collapse takes away (the old positions of `v0`,
    /// and of `v1` when it moves; vertices lie on the input) within `guard` of the new faces, and
    /// the new faces' centroids and their edges' midpoints at `target` within `guard` of the input.
    /// Without it collapses erode sharp tips and cut across parts thinner than `L`.
    fn collapse_keeps_surface(
        &self,
        v0: u32,
        v1: u32,
        target: [f64; 3],
        r0: &[u32],
        r1: &[u32],
    ) -> bool {
        let m = &*self.mesh;
        let mut fan: Vec<[[f64; 3]; 3]> = Vec::with_capacity(r0.len() + r1.len());
        for (ring, other) in [(r0, v1), (r1, v0)] {
            for (a, b) in m.surviving_far_edges(ring, other) {
                fan.push([target, m.pos[a as usize], m.pos[b as usize]]);
            }
        }
        let p1 = m.pos[v1 as usize];
        let mut gone = vec![m.pos[v0 as usize]];
        if target != p1 {
            gone.push(p1);
        }
        if gone.iter().any(|&p| fan_distance(p, &fan) > self.guard) {
            return false;
        }
        let hint = self.hints.get(v1 as usize).copied().unwrap_or(NONE);
        // A sample within the guard of a ring vertex (on the input) needs no query.
        let near_ring = |s: [f64; 3]| {
            fan.iter()
                .any(|t| dist(s, t[1]) <= self.guard || dist(s, t[2]) <= self.guard)
        };
        fan.iter().all(|t| {
            let c = [0, 1, 2].map(|k| (t[0][k] + t[1][k] + t[2][k]) / 3.0);
            let mid = [0, 1, 2].map(|k| (t[0][k] + t[1][k]) / 2.0);
            (near_ring(c) || self.off_input(c, hint) <= self.guard)
                && (near_ring(mid) || self.off_input(mid, hint) <= self.guard)
        })
    }

    /// The surface-distance guard of flipping edge `a–b` of the quad `(a, b, c, d)` (positions
    /// `pa`…`pd`) to `c–d`: the old edge's midpoint (on the input when the old faces are) within
    /// [`Self::guard`] of the new pair, and the new edge's midpoint within `guard` of the input
    /// (searched from the input face `a` last projected onto). Without it valence flips cut
    /// across ridges that are not features.
    fn flip_keeps_surface(&self, a: u32, q: [[f64; 3]; 4]) -> bool {
        let [pa, pb, pc, pd] = q;
        let old_mid = [0, 1, 2].map(|k| (pa[k] + pb[k]) / 2.0);
        let new_mid = [0, 1, 2].map(|k| (pc[k] + pd[k]) / 2.0);
        let hint = self.hints.get(a as usize).copied().unwrap_or(NONE);
        fan_distance(old_mid, &[[pa, pd, pc], [pd, pb, pc]]) <= self.guard
            && self.off_input(new_mid, hint) <= self.guard
    }

    fn flip_edges(&mut self) {
        let mut ring = Vec::new();
        for e in 0..self.mesh.num_edges() {
            let m = &*self.mesh;
            let Some(FlipQuad {
                a,
                b,
                c,
                d,
                pa,
                pb,
                pc,
                pd,
            }) = flip_quad(m, e, &mut ring)
            else {
                continue;
            };
            let target = |v: u32| if m.is_boundary_vertex(v) { 4i64 } else { 6 };
            let val = |v: u32| m.valence(v) as i64;
            let (va, vb, vc, vd) = (val(a), val(b), val(c), val(d));
            if va <= 3 || vb <= 3 {
                continue;
            }
            let dev = |x: i64, t: i64| (x - t) * (x - t);
            let before =
                dev(va, target(a)) + dev(vb, target(b)) + dev(vc, target(c)) + dev(vd, target(d));
            let after = dev(va - 1, target(a))
                + dev(vb - 1, target(b))
                + dev(vc + 1, target(c))
                + dev(vd + 1, target(d));
            let old_min = min_angle(pa, pb, pc).min(min_angle(pb, pa, pd));
            let new_min = min_angle(pa, pd, pc).min(min_angle(pd, pb, pc));
            // Toward valence 6 without lowering the minimum angle below min(before, 30°), or, for
            // a needle pair, toward a larger minimum angle whatever the valences.
            let wanted = (after < before && new_min >= old_min.min(FLIP_KEEP_ANGLE))
                || (old_min < NEEDLE_ANGLE && new_min > old_min);
            if !wanted {
                continue;
            }
            let n_old = pair_normal(pa, pb, pc, pd);
            let n1 = cross(sub(pd, pa), sub(pc, pa));
            let n2 = cross(sub(pb, pd), sub(pc, pd));
            if dot(n1, n2) <= 0.0 || dot(n1, n_old) <= 0.0 || dot(n2, n_old) <= 0.0 {
                continue;
            }
            if !self.flip_keeps_surface(a, [pa, pb, pc, pd]) {
                continue;
            }
            self.mesh.flip(e);
        }
    }

    /// The final clean-up after the last relaxation (which can leave a sliver where a free vertex
    /// was pulled against a feature line): up to [`CLEANUP_PASSES`] passes of
    /// - moving the free corners of slivers ([`Self::move_needle_corners`]);
    /// - collapsing the shortest edge of every face with a corner under [`NEEDLE_ANGLE`] when it
    ///   is shorter than `4/5·L`, into one of its ends (so every vertex stays on the input), under
    ///   the collapse rules of the rounds;
    /// - flipping every interior non-feature edge whose pair has a corner under
    ///   [`CLEANUP_FLIP_ANGLE`] when that raises the pair's minimum angle, without folding it or
    ///   bending it by more than the feature angle.
    fn clean_up(&mut self, surface: &Bvh) {
        for _ in 0..CLEANUP_PASSES {
            let mut changed = self.move_needle_corners(surface);
            let mut counts = self.feature_counts();
            for f in 0..self.mesh.num_face_slots() {
                let m = &*self.mesh;
                if !m.face_live(f) {
                    continue;
                }
                let vs = m.face_vertices(f as u32);
                let p = vs.map(|v| m.pos[v as usize]);
                if min_angle(p[0], p[1], p[2]) >= NEEDLE_ANGLE {
                    continue;
                }
                // The shortest edge's half-edge inside the face.
                let mut h = m.face_halfedge(f as u32);
                let mut best = (f64::INFINITY, h);
                for _ in 0..3 {
                    let len = m.edge_length((h / 2) as usize);
                    if len < best.0 {
                        best = (len, h);
                    }
                    h = m.next(h);
                }
                let (len, h) = best;
                if len >= self.lo {
                    continue;
                }
                let (a, b) = (m.from(h), m.to(h));
                let (pa, pb) = (m.pos[a as usize], m.pos[b as usize]);
                let chosen = if self.collapse_ok(h, &counts, pb) {
                    Some(h)
                } else if self.collapse_ok(opp(h), &counts, pa) {
                    Some(opp(h))
                } else {
                    None
                };
                let Some(g) = chosen else {
                    continue;
                };
                self.collapse_and_recount(g, &mut counts);
                changed = true;
            }
            changed |= self.merge_corners_onto_lines();
            changed |= self.flip_for_angles();
            if !changed {
                break;
            }
        }
    }

    /// Moves every free vertex of a face with a corner under [`CLEANUP_MOVE_ANGLE`] to the best of
    /// the centroid of its neighbours and the points 3/4, 1/2 and 1/4 of the way there, each
    /// projected onto the input, and every feature vertex of such a face (two feature edges, not a
    /// corner) to the best of the points 1/2 and 1/4 of the way to either feature neighbour, each
    /// projected onto the input's feature lines, when that raises the smallest angle of its faces, folds none of
    /// them (turns a normal by 90° or more), lands on an input face that does not face against the
    /// one the vertex lies on (another sheet of a thin part), and keeps its faces' centroids within
    /// `max(before, CLEANUP_MOVE_DEVIATION·L)` of the input. Whether any vertex moved.
    fn move_needle_corners(&mut self, surface: &Bvh) -> bool {
        let counts = self.feature_counts();
        let mut ring = Vec::new();
        let mut any = false;
        let mut visited = vec![false; self.mesh.num_vertices()];
        for f in 0..self.mesh.num_face_slots() {
            let m = &*self.mesh;
            if !m.face_live(f) {
                continue;
            }
            let vs = m.face_vertices(f as u32);
            let p = vs.map(|v| m.pos[v as usize]);
            if min_angle(p[0], p[1], p[2]) >= CLEANUP_MOVE_ANGLE {
                continue;
            }
            for v in vs {
                let m = &*self.mesh;
                let vi = v as usize;
                if !(counts[vi] == 0 || counts[vi] == 2) || m.locked[vi] || visited[vi] {
                    continue;
                }
                visited[vi] = true;
                m.outgoing(v, &mut ring);
                let p0 = m.pos[vi];
                // Candidates: toward the centroid of the neighbours (a free vertex) or along the
                // feature line, toward either feature neighbour (a feature vertex).
                let mut candidates: Vec<[f64; 3]> = Vec::new();
                if counts[vi] == 0 {
                    let mut c = [0.0; 3];
                    for &g in &ring {
                        let q = m.pos[m.to(g) as usize];
                        for k in 0..3 {
                            c[k] += q[k] / ring.len() as f64;
                        }
                    }
                    for t in [1.0, 0.75, 0.5, 0.25] {
                        candidates.push([0, 1, 2].map(|k| p0[k] + t * (c[k] - p0[k])));
                    }
                } else {
                    for &g in &ring {
                        if m.feature[(g / 2) as usize] {
                            let q = m.pos[m.to(g) as usize];
                            for t in [0.5, 0.25] {
                                candidates.push([0, 1, 2].map(|k| p0[k] + t * (q[k] - p0[k])));
                            }
                        }
                    }
                }
                // With v at `q`: the smallest angle of v's faces; None when one would fold.
                let worst_at = |q: [f64; 3]| {
                    let mut worst = f64::INFINITY;
                    for &g in &ring {
                        if m.is_boundary_halfedge(g) {
                            continue;
                        }
                        let (a, b) = (m.pos[m.to(g) as usize], m.pos[m.to(m.next(g)) as usize]);
                        let n0 = cross(sub(a, p0), sub(b, p0));
                        let n1 = cross(sub(a, q), sub(b, q));
                        if dot(n0, n1) <= 0.0 {
                            return None;
                        }
                        worst = worst.min(min_angle(q, a, b));
                    }
                    Some(worst)
                };
                // With v at `q`: the largest distance of v's faces' centroids from the input.
                let hint = self.hints.get(vi).copied().unwrap_or(NONE);
                let off_at = |q: [f64; 3]| {
                    let mut off = 0.0f64;
                    for &g in &ring {
                        if m.is_boundary_halfedge(g) {
                            continue;
                        }
                        let (a, b) = (m.pos[m.to(g) as usize], m.pos[m.to(m.next(g)) as usize]);
                        let ctr = [0, 1, 2].map(|k| (q[k] + a[k] + b[k]) / 3.0);
                        if let Some(on) = surface.closest_point_hinted(ctr, hint) {
                            off = off.max(on.distance_squared.sqrt());
                        }
                    }
                    off
                };
                let Some(worst0) = worst_at(p0) else {
                    continue;
                };
                // A move may not take v's faces farther from the input than they are (or than
                // CLEANUP_MOVE_DEVIATION·L, when they are closer); measured only when a candidate
                // raises the angle.
                // The normal of the input face v lies on, to refuse a jump onto another sheet.
                let n_v = if hint == NONE {
                    [0.0; 3]
                } else {
                    let [a, b, cc] = surface.triangle(hint);
                    cross(sub(b, a), sub(cc, a))
                };
                // Candidates that raise the angle, best first (ties: candidate order).
                let mut better: Vec<(f64, usize, [f64; 3], u32)> = Vec::new();
                for (i, q) in candidates.into_iter().enumerate() {
                    // A feature vertex stays on the input's feature lines.
                    let on = if counts[vi] == 2 {
                        self.lines.closest_point(q).and_then(|c| {
                            surface.closest_point_hinted(c.point, hint).map(|s| {
                                crate::bvh::ClosestPoint {
                                    point: c.point,
                                    ..s
                                }
                            })
                        })
                    } else {
                        surface.closest_point_hinted(q, hint)
                    };
                    let Some(on) = on else {
                        continue;
                    };
                    let [a, b, cc] = surface.triangle(on.face);
                    if dot(cross(sub(b, a), sub(cc, a)), n_v) < 0.0 {
                        continue;
                    }
                    if let Some(w) = worst_at(on.point)
                        && w > worst0
                    {
                        better.push((w, i, on.point, on.face));
                    }
                }
                better.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
                // A move may not take v's faces farther from the input than they are (or than
                // CLEANUP_MOVE_DEVIATION·L, when they are closer).
                let mut best = (worst0, p0, NONE);
                if !better.is_empty() {
                    let limit = off_at(p0).max(CLEANUP_MOVE_DEVIATION * self.lo / 0.8);
                    if let Some(&(w, _, q, face)) = better.iter().find(|c| off_at(c.2) <= limit) {
                        best = (w, q, face);
                    }
                }
                if best.2 != NONE {
                    self.mesh.pos[vi] = best.1;
                    self.hints[vi] = best.2;
                    any = true;
                }
            }
        }
        any
    }

    /// Merges corners into feature lines that pass closer than [`CORNER_ONTO_LINE`]`·L`: where a
    /// corner `v` is the apex of a face `(a, b, v)` with a corner under [`CLEANUP_FLIP_ANGLE`]
    /// whose edge `a–b` is an interior feature edge passing that close to `v` (a cap: a line
    /// running past a junction), the edge `a–b` is
    /// flipped to `v–d` (`d` the far corner of the face across it) and the line runs `a–v–b`:
    /// `a–v` and `v–b` become feature edges, the new edge is none. Only when that raises the two
    /// faces' minimum angle, folds neither (against the face across `a–b`), duplicates no edge,
    /// leaves `a` and `b` with valence 3 or more and passes the surface-distance guard. Whether
    /// any edge was flipped.
    fn merge_corners_onto_lines(&mut self) -> bool {
        let mut ring = Vec::new();
        let mut any = false;
        for e in 0..self.mesh.num_edges() {
            let m = &*self.mesh;
            if !m.edge_live(e) || !m.feature[e] || m.is_boundary_edge(e) {
                continue;
            }
            let h = 2 * e as u32;
            let o = opp(h);
            let (a, b) = (m.from(h), m.to(h));
            let (c, d) = (m.to(m.next(h)), m.to(m.next(o)));
            if c == d || m.valence(a) <= 3 || m.valence(b) <= 3 {
                continue;
            }
            let p = |v: u32| m.pos[v as usize];
            let (pa, pb, pc, pd) = (p(a), p(b), p(c), p(d));
            let old_min = min_angle(pa, pb, pc).min(min_angle(pb, pa, pd));
            if old_min >= CLEANUP_FLIP_ANGLE {
                continue;
            }
            // The apex: a corner whose face with a–b is the one with the small angle.
            let apex = if m.locked[c as usize] && min_angle(pa, pb, pc) < CLEANUP_FLIP_ANGLE {
                c
            } else if m.locked[d as usize] && min_angle(pb, pa, pd) < CLEANUP_FLIP_ANGLE {
                d
            } else {
                continue;
            };
            let (q, _) = crate::bvh::closest_on_triangle(p(apex), &[pa, pb, pb]);
            if dist(q, p(apex)) >= self.onto_line {
                continue;
            }
            m.outgoing(c, &mut ring);
            if ring.iter().any(|&g| m.to(g) == d) {
                continue;
            }
            let new_min = min_angle(pa, pd, pc).min(min_angle(pd, pb, pc));
            if new_min <= old_min {
                continue;
            }
            // The face across a–b from the apex is the one the new pair must keep facing.
            let n_ref = if apex == c {
                cross(sub(pa, pb), sub(pd, pb))
            } else {
                cross(sub(pb, pa), sub(pc, pa))
            };
            let n1 = cross(sub(pd, pa), sub(pc, pa));
            let n2 = cross(sub(pb, pd), sub(pc, pd));
            if dot(n1, n_ref) <= 0.0 || dot(n2, n_ref) <= 0.0 {
                continue;
            }
            if !self.flip_keeps_surface(a, [pa, pb, pc, pd]) {
                continue;
            }
            let (h1, h2) = (m.next(h), m.next(m.next(h))); // b→c, c→a
            let (o1, o2) = (m.next(o), m.next(m.next(o))); // a→d, d→b
            self.mesh.flip(e);
            self.mesh.feature[e] = false;
            let (s1, s2) = if apex == c { (h1, h2) } else { (o1, o2) };
            self.mesh.feature[(s1 / 2) as usize] = true;
            self.mesh.feature[(s2 / 2) as usize] = true;
            any = true;
        }
        any
    }

    /// Flips every interior non-feature edge whose pair has a corner under [`CLEANUP_FLIP_ANGLE`]
    /// when that raises the pair's minimum angle and keeps the pair unfolded and within the
    /// feature angle of flat. Whether any edge was flipped.
    fn flip_for_angles(&mut self) -> bool {
        let mut ring = Vec::new();
        let mut any = false;
        for e in 0..self.mesh.num_edges() {
            let m = &*self.mesh;
            let Some(FlipQuad {
                a,
                b,
                pa,
                pb,
                pc,
                pd,
                ..
            }) = flip_quad(m, e, &mut ring)
            else {
                continue;
            };
            if m.valence(a) <= 3 || m.valence(b) <= 3 {
                continue;
            }
            let old_min = min_angle(pa, pb, pc).min(min_angle(pb, pa, pd));
            if old_min >= CLEANUP_FLIP_ANGLE {
                continue;
            }
            let new_min = min_angle(pa, pd, pc).min(min_angle(pd, pb, pc));
            if new_min <= old_min {
                continue;
            }
            let n_old = pair_normal(pa, pb, pc, pd);
            let (Some(n1), Some(n2)) = (
                normalized(cross(sub(pd, pa), sub(pc, pa))),
                normalized(cross(sub(pb, pd), sub(pc, pd))),
            ) else {
                continue;
            };
            if dot(n1, n2) < self.cos_feature || dot(n1, n_old) <= 0.0 || dot(n2, n_old) <= 0.0 {
                continue;
            }
            if !self.flip_keeps_surface(a, [pa, pb, pc, pd]) {
                continue;
            }
            self.mesh.flip(e);
            any = true;
        }
        any
    }

    fn relax_and_project(&mut self, surface: &Bvh) {
        let m = &*self.mesh;
        let nv = m.num_vertices();
        let counts = self.feature_counts();
        let mut normals = vec![[0.0; 3]; nv];
        let mut centroid_sum = vec![[0.0; 3]; nv];
        let mut area_sum = vec![0.0; nv];
        for f in 0..m.num_face_slots() {
            if !m.face_live(f) {
                continue;
            }
            let vs = m.face_vertices(f as u32);
            let (a, b, c) = (
                m.pos[vs[0] as usize],
                m.pos[vs[1] as usize],
                m.pos[vs[2] as usize],
            );
            let n = cross(sub(b, a), sub(c, a));
            let area = 0.5 * norm(n);
            let ctr = [
                (a[0] + b[0] + c[0]) / 3.0,
                (a[1] + b[1] + c[1]) / 3.0,
                (a[2] + b[2] + c[2]) / 3.0,
            ];
            for &v in &vs {
                let v = v as usize;
                for k in 0..3 {
                    normals[v][k] += n[k];
                    centroid_sum[v][k] += area * ctr[k];
                }
                area_sum[v] += area;
            }
        }
        let mut ring = Vec::new();
        let mut moved: Vec<(u32, [f64; 3], bool)> = Vec::new();
        for v in 0..nv as u32 {
            let vi = v as usize;
            if !m.vertex_live(vi) || m.locked[vi] {
                continue;
            }
            let p = m.pos[vi];
            if counts[vi] == 2 {
                m.outgoing(v, &mut ring);
                let fs: Vec<u32> = ring
                    .iter()
                    .filter(|&&g| m.feature[(g / 2) as usize])
                    .map(|&g| m.to(g))
                    .collect();
                if fs.len() != 2 {
                    continue;
                }
                let (q0, q1) = (m.pos[fs[0] as usize], m.pos[fs[1] as usize]);
                let Some(t) = normalized(sub(q1, q0)) else {
                    continue;
                };
                let mid = [
                    (q0[0] + q1[0]) / 2.0,
                    (q0[1] + q1[1]) / 2.0,
                    (q0[2] + q1[2]) / 2.0,
                ];
                let s = dot(sub(mid, p), t);
                moved.push((v, [p[0] + s * t[0], p[1] + s * t[1], p[2] + s * t[2]], true));
            } else if counts[vi] == 0 {
                let target = if area_sum[vi] > 0.0 {
                    let a = area_sum[vi];
                    [
                        centroid_sum[vi][0] / a,
                        centroid_sum[vi][1] / a,
                        centroid_sum[vi][2] / a,
                    ]
                } else {
                    m.outgoing(v, &mut ring);
                    let mut s = [0.0; 3];
                    for &g in &ring {
                        let q = m.pos[m.to(g) as usize];
                        for k in 0..3 {
                            s[k] += q[k] / ring.len() as f64;
                        }
                    }
                    s
                };
                let d = sub(target, p);
                let d = match normalized(normals[vi]) {
                    Some(n) => {
                        let s = dot(d, n);
                        [d[0] - s * n[0], d[1] - s * n[1], d[2] - s * n[2]]
                    }
                    None => d,
                };
                moved.push((v, [p[0] + d[0], p[1] + d[1], p[2] + d[2]], false));
            }
        }
        self.hints.resize(nv, NONE);
        for (v, p, on_line) in moved {
            let vi = v as usize;
            let q = if on_line {
                self.lines.closest_point(p)
            } else {
                let hint = self.hints[vi];
                let mut c = surface.closest_point_hinted(p, hint);
                // Side-aware: when the closest point lies on an input face facing against the
                // vertex's normal (the other sheet of a part thinner than `L`), the closest point
                // among the faces facing its way, if that is within `L`.
                if let Some(plain) = c {
                    let nf = |f: u32| {
                        let [a, b, cc] = surface.triangle(f);
                        cross(sub(b, a), sub(cc, a))
                    };
                    let reference = normals[vi];
                    if dot(nf(plain.face), reference) < 0.0
                        && let Some(same) = surface
                            .closest_point_filtered_hinted(p, hint, |f| dot(nf(f), reference) > 0.0)
                        && same.distance_squared <= self.side_reach * self.side_reach
                    {
                        c = Some(same);
                    }
                }
                if let Some(c) = c {
                    self.hints[vi] = c.face;
                }
                c
            };
            self.mesh.pos[vi] = q.map_or(p, |c| c.point);
        }
    }
}

/// How to take back an [`Untangle`] that did not help.
enum Undo {
    /// Put the vertex back here.
    Position(u32, [f64; 3]),
    /// The whole connectivity before a flip or collapse (`O(F)`; bounded by
    /// [`UNTANGLE_MAX_COPY_TRIALS`]).
    Mesh(Box<HalfEdgeMesh>),
}

/// What [`Remesher::repair_new_intersections`] may do to remove one intersecting pair.
#[derive(Clone, Copy, Debug)]
enum Untangle {
    /// Move a free vertex to this point (on the input).
    Move(u32, [f64; 3]),
    /// Flip this edge.
    Flip(usize),
    /// Collapse this half-edge into its head, which keeps its position.
    Collapse(u32),
    /// The same, also when the removed vertex lies on a feature line or is a corner (the last
    /// resort where crossing feature lines locked every other repair).
    CollapseAcrossFeatures(u32),
}

impl Remesher<'_> {
    /// The live face slots in the order [`HalfEdgeMesh::compact`] numbers the faces.
    fn live_face_slots(&self) -> Vec<u32> {
        (0..self.mesh.num_face_slots())
            .filter(|&f| self.mesh.face_live(f))
            .map(|f| f as u32)
            .collect()
    }

    /// Intersecting face pairs (`mesh_core::intersect`, exact) among the faces around the
    /// vertices within [`UNTANGLE_RINGS`] edges of the live vertices of `seeds`.
    fn local_pairs(&self, seeds: &[u32]) -> Result<usize, RemeshError> {
        let m = &*self.mesh;
        let mut ring = Vec::new();
        let mut verts: Vec<u32> = seeds
            .iter()
            .copied()
            .filter(|&v| m.vertex_live(v as usize))
            .collect();
        verts.sort_unstable();
        verts.dedup();
        let mut frontier = verts.clone();
        for _ in 0..UNTANGLE_RINGS {
            let mut next = Vec::new();
            for &v in &frontier {
                m.outgoing(v, &mut ring);
                next.extend(ring.iter().map(|&g| m.to(g)));
            }
            next.sort_unstable();
            next.dedup();
            next.retain(|v| verts.binary_search(v).is_err());
            verts.extend(&next);
            verts.sort_unstable();
            frontier = next;
        }
        let mut faces: Vec<u32> = Vec::new();
        for &v in &verts {
            m.outgoing(v, &mut ring);
            faces.extend(
                ring.iter()
                    .filter(|&&g| !m.is_boundary_halfedge(g))
                    .map(|&g| m.face_of(g)),
            );
        }
        faces.sort_unstable();
        faces.dedup();
        let mut index = std::collections::BTreeMap::new();
        let mut positions = Vec::new();
        let local: Vec<[u32; 3]> = faces
            .iter()
            .map(|&f| {
                m.face_vertices(f).map(|v| {
                    *index.entry(v).or_insert_with(|| {
                        positions.push(m.pos[v as usize]);
                        (positions.len() - 1) as u32
                    })
                })
            })
            .collect();
        match crate::intersect::self_intersections(&positions, &local) {
            Ok(s) => Ok(s.pairs.len()),
            Err(crate::intersect::IntersectError::Mesh(e)) => Err(e.into()),
            Err(_) => Ok(0),
        }
    }

    /// The local repairs of the pair of face slots `fa`, `fb`, in the order they are tried:
    /// moving each free vertex of the two faces to the centroid of its neighbours (or half-way),
    /// projected onto the input; flipping each of their edges; collapsing each of their edges
    /// shorter than `4/3·L` into either end.
    fn untangle_candidates(&mut self, fa: u32, fb: u32, surface: &Bvh) -> Vec<Untangle> {
        let counts = self.feature_counts();
        let mut out = Vec::new();
        let mut ring = Vec::new();
        let mut seen = Vec::new();
        // The pair's vertices first, then their neighbours.
        let mut near: Vec<u32> = Vec::new();
        for f in [fa, fb] {
            near.extend(self.mesh.face_vertices(f));
        }
        let first = near.clone();
        for &v in &first {
            self.mesh.outgoing(v, &mut ring);
            near.extend(ring.iter().map(|&g| self.mesh.to(g)));
        }
        for v in near {
            let vi = v as usize;
            if seen.contains(&v) || self.mesh.locked[vi] {
                continue;
            }
            seen.push(v);
            if counts[vi] == 2 {
                // A feature vertex slides along its line: half or a quarter of the way to either
                // feature neighbour, onto the input's feature lines.
                self.mesh.outgoing(v, &mut ring);
                let p = self.mesh.pos[vi];
                for &g in &ring {
                    if !self.mesh.feature[(g / 2) as usize] {
                        continue;
                    }
                    let q = self.mesh.pos[self.mesh.to(g) as usize];
                    for t in [0.5, 0.25] {
                        let x = [0, 1, 2].map(|k| p[k] + t * (q[k] - p[k]));
                        if let Some(c) = self.lines.closest_point(x) {
                            out.push(Untangle::Move(v, c.point));
                        }
                    }
                }
                continue;
            }
            if counts[vi] != 0 || self.mesh.is_boundary_vertex(v) {
                continue;
            }
            {
                self.mesh.outgoing(v, &mut ring);
                let n = ring.len() as f64;
                let mut c = [0.0; 3];
                for &g in &ring {
                    let q = self.mesh.pos[self.mesh.to(g) as usize];
                    for k in 0..3 {
                        c[k] += q[k] / n;
                    }
                }
                let p = self.mesh.pos[vi];
                for t in [1.0, 0.5] {
                    let x = [0, 1, 2].map(|k| p[k] + t * (c[k] - p[k]));
                    if let Some(q) = surface.closest_point(x) {
                        out.push(Untangle::Move(v, q.point));
                    }
                }
            }
        }
        let mut edges = Vec::new();
        for f in [fa, fb] {
            let mut h = self.mesh.face_halfedge(f);
            for _ in 0..3 {
                edges.push(h);
                h = self.mesh.next(h);
            }
        }
        for &h in &edges {
            out.push(Untangle::Flip((h / 2) as usize));
        }
        for &h in &edges {
            if self.mesh.edge_length((h / 2) as usize) < self.hi {
                out.push(Untangle::Collapse(h));
                out.push(Untangle::Collapse(opp(h)));
            }
        }
        for &h in &edges {
            if self.mesh.edge_length((h / 2) as usize) < self.hi {
                out.push(Untangle::CollapseAcrossFeatures(h));
                out.push(Untangle::CollapseAcrossFeatures(opp(h)));
            }
        }
        out
    }

    /// Applies `op` when it is legal (the rules of the rounds: a flip of a non-feature interior
    /// edge that folds neither new face and passes the surface-distance guard; a collapse that
    /// [`Self::collapse_ok`] allows; a move after which every face around the vertex faces the
    /// way the input does under it). Returns what restores the state before, or `None` when `op`
    /// is not legal.
    fn apply_untangle(&mut self, op: Untangle) -> Option<Undo> {
        let m = &*self.mesh;
        match op {
            Untangle::Move(v, q) => {
                // Every face around the moved vertex must face the way the input does under its
                // centroid (the face it replaces may already be folded, so the face's own old
                // normal is no reference).
                let mut ring = Vec::new();
                m.outgoing(v, &mut ring);
                for &g in &ring {
                    if m.is_boundary_halfedge(g) {
                        continue;
                    }
                    let f = m.face_vertices(m.face_of(g));
                    let p = f.map(|w| if w == v { q } else { m.pos[w as usize] });
                    let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
                    let c = [0, 1, 2].map(|k| (p[0][k] + p[1][k] + p[2][k]) / 3.0);
                    let on = self.surface.closest_point(c)?;
                    let [a, b, cc] = self.surface.triangle(on.face);
                    if dot(n, cross(sub(b, a), sub(cc, a))) <= 0.0 {
                        return None;
                    }
                }
                let saved = Undo::Position(v, m.pos[v as usize]);
                self.mesh.pos[v as usize] = q;
                Some(saved)
            }
            Untangle::Flip(e) => {
                let mut ring = Vec::new();
                let FlipQuad {
                    a,
                    b,
                    pa,
                    pb,
                    pc,
                    pd,
                    ..
                } = flip_quad(m, e, &mut ring)?;
                if m.valence(a) <= 3 || m.valence(b) <= 3 {
                    return None;
                }
                let n_old = pair_normal(pa, pb, pc, pd);
                let n1 = cross(sub(pd, pa), sub(pc, pa));
                let n2 = cross(sub(pb, pd), sub(pc, pd));
                if dot(n1, n2) <= 0.0 || dot(n1, n_old) <= 0.0 || dot(n2, n_old) <= 0.0 {
                    return None;
                }
                if !self.flip_keeps_surface(a, [pa, pb, pc, pd]) {
                    return None;
                }
                let saved = Undo::Mesh(Box::new(m.clone()));
                self.mesh.flip(e);
                Some(saved)
            }
            Untangle::Collapse(h) | Untangle::CollapseAcrossFeatures(h) => {
                if !m.edge_live((h / 2) as usize) {
                    return None;
                }
                let counts = self.feature_counts();
                let target = m.pos[m.to(h) as usize];
                let ok = if let Untangle::CollapseAcrossFeatures(_) = op {
                    // The removed vertex's feature rules are waived (the kept one's stay): its
                    // lock lifted, no feature edge counted.
                    let v0 = m.from(h) as usize;
                    let was_locked = m.locked[v0];
                    self.mesh.locked[v0] = false;
                    let ok = self.collapse_ok(h, &vec![0; counts.len()], target);
                    self.mesh.locked[v0] = was_locked;
                    ok
                } else {
                    self.collapse_ok(h, &counts, target)
                };
                if !ok {
                    return None;
                }
                let saved = Undo::Mesh(Box::new(self.mesh.clone()));
                let mut counts = counts;
                self.collapse_and_recount(h, &mut counts);
                Some(saved)
            }
        }
    }

    /// The final pass that removes self-intersections the remeshing created: finds every
    /// intersecting face pair of the current mesh (`mesh_core::intersect`, exact predicates); a
    /// pair is *inherited* when the input itself intersects within `L` of either face's centroid
    /// (the input is checked only when the output has a pair); every other pair is *new* and is
    /// repaired locally by the first candidate of [`Self::untangle_candidates`] that is legal
    /// ([`Self::apply_untangle`]) and lowers the number of intersecting pairs among the faces within
    /// [`UNTANGLE_RINGS`] edges of the pair, repeated (up to [`UNTANGLE_PASSES`] passes) until
    /// no new pair is left or no candidate helps, within [`UNTANGLE_MAX_TRIALS`] tried candidates
    /// ([`UNTANGLE_MAX_COPY_TRIALS`] flips and collapses).
    fn repair_new_intersections(
        &mut self,
        input_positions: &[[f64; 3]],
        input_faces: &[[u32; 3]],
        surface: &Bvh,
    ) -> Result<(), RemeshError> {
        let mut inherited_near: Option<Option<Bvh>> = None;
        let (mut trials, mut copy_trials) = (0usize, 0usize);
        for _ in 0..UNTANGLE_PASSES {
            let (p, f) = self.mesh.compact();
            let slots = self.live_face_slots();
            let pairs = match crate::intersect::self_intersections(&p, &f) {
                Ok(s) => s.pairs,
                Err(crate::intersect::IntersectError::Mesh(e)) => return Err(e.into()),
                Err(_) => return Ok(()),
            };
            if pairs.is_empty() {
                return Ok(());
            }
            if inherited_near.is_none() {
                let input = match crate::intersect::self_intersections(input_positions, input_faces)
                {
                    Ok(s) => s,
                    Err(crate::intersect::IntersectError::Mesh(e)) => return Err(e.into()),
                    Err(_) => return Ok(()),
                };
                let involved: Vec<[u32; 3]> = input
                    .faces
                    .iter()
                    .map(|&i| input_faces[i as usize])
                    .collect();
                inherited_near = Some(if involved.is_empty() {
                    None
                } else {
                    Some(Bvh::new(input_positions, &involved)?)
                });
            }
            // A face is near the input's intersections when its centroid is within L of an
            // input face in an intersecting pair; each face of a pair is asked once per pass
            // (a crumpled mesh has many pairs per face).
            let reach = self.hi * 0.75; // L
            let mut near_input_pairs = vec![false; f.len()];
            if let Some(b) = inherited_near.as_ref().and_then(|b| b.as_ref()) {
                let mut asked = vec![false; f.len()];
                for k in pairs.iter().flat_map(|&(i, j)| [i as usize, j as usize]) {
                    if !std::mem::replace(&mut asked[k], true) {
                        near_input_pairs[k] = b
                            .closest_point(centroid(&p, f[k]))
                            .is_some_and(|c| c.distance_squared.sqrt() <= reach);
                    }
                }
            }
            let is_new =
                |i: u32, j: u32| !(near_input_pairs[i as usize] || near_input_pairs[j as usize]);
            let mut progress = false;
            let mut any_new = false;
            for &(i, j) in &pairs {
                if !is_new(i, j) {
                    continue;
                }
                any_new = true;
                let (fa, fb) = (slots[i as usize], slots[j as usize]);
                // An earlier repair in this pass may have removed or changed these faces.
                if !self.mesh.face_live(fa as usize) || !self.mesh.face_live(fb as usize) {
                    continue;
                }
                let seeds: Vec<u32> = [fa, fb]
                    .iter()
                    .flat_map(|&g| self.mesh.face_vertices(g))
                    .collect();
                let before = self.local_pairs(&seeds)?;
                if before == 0 {
                    continue; // already repaired by a neighbour's repair
                }
                for op in self.untangle_candidates(fa, fb, surface) {
                    let copies = !matches!(op, Untangle::Move(..));
                    if trials >= UNTANGLE_MAX_TRIALS
                        || (copies && copy_trials >= UNTANGLE_MAX_COPY_TRIALS)
                    {
                        continue;
                    }
                    let Some(undo) = self.apply_untangle(op) else {
                        continue;
                    };
                    trials += 1;
                    copy_trials += copies as usize;
                    if self.local_pairs(&seeds)? < before {
                        progress = true;
                        break;
                    }
                    match undo {
                        Undo::Position(v, p) => self.mesh.pos[v as usize] = p,
                        Undo::Mesh(m) => *self.mesh = *m,
                    }
                }
            }
            if !any_new || !progress {
                return Ok(());
            }
        }
        Ok(())
    }
}

/// The distance from `p` to the nearest of the triangles `fan` (`∞` for none).
fn fan_distance(p: [f64; 3], fan: &[[[f64; 3]; 3]]) -> f64 {
    fan.iter()
        .map(|t| {
            let (q, _) = crate::bvh::closest_on_triangle(p, t);
            norm(sub(q, p))
        })
        .fold(f64::INFINITY, f64::min)
}

/// The surface-distance bound of collapses and flips, in target lengths
/// (`Remesher::collapse_keeps_surface`, `Remesher::flip_keeps_surface`). pymeshlab's
/// `maxsurfdist` plays the same part (default 1 % of the diagonal, `2/3·L` at its default target
/// 1.5 %); a quarter of `L` keeps sharp tips and parts thinner than `L` (measured:
/// `docs/remeshing.md`).
const SURFACE_GUARD: f64 = 0.25;

/// Clean-up passes after the last round (`Remesher::clean_up`).
const CLEANUP_PASSES: usize = 5;

/// The repair of self-intersections the remeshing created
/// (`Remesher::repair_new_intersections`) runs at most this many passes over the pairs.
const UNTANGLE_PASSES: usize = 10;

/// The repair tries at most this many legal candidates in all (each costs an exact check of the
/// faces around the pair), so its time is bounded whatever the number of pairs.
const UNTANGLE_MAX_TRIALS: usize = 20_000;

/// Of those, at most this many flips and collapses (each also copies the connectivity, `O(F)`).
const UNTANGLE_MAX_COPY_TRIALS: usize = 2_000;

/// The repair judges a candidate by the intersecting pairs among the faces around the vertices
/// within this many edges of the pair's vertices.
const UNTANGLE_RINGS: usize = 2;

/// The clean-up flips a pair with a corner under this whenever that raises its minimum angle.
const CLEANUP_FLIP_ANGLE: f64 = 20.0 * std::f64::consts::PI / 180.0;

/// The clean-up moves the free corners of a face with a corner under this
/// ([`Remesher::move_needle_corners`]).
const CLEANUP_MOVE_ANGLE: f64 = 20.0 * std::f64::consts::PI / 180.0;

/// The clean-up's moves keep the centroids of the moved vertex's faces within this many target
/// lengths of the input, or no farther than they were.
const CLEANUP_MOVE_DEVIATION: f64 = 0.2;

/// Feature lines and corners closer than this many target lengths merge (collapse into each
/// other): at the target length they are one crease (or noise), and kept apart they leave a
/// sliver between them.
const FEATURE_SNAP: f64 = 0.2;

/// A corner closer than this many target lengths to a feature edge of one of its faces joins that
/// line in the clean-up (`Remesher::merge_corners_onto_lines`). Smaller than [`FEATURE_SNAP`]:
/// at `0.2·L` merges cascaded along a ridge of `triceratops.off`'s horn (each moving the line by
/// up to `0.2·L`) and cost it 0.357 → 0.454 % of the diagonal in Hausdorff; at `0.1·L`
/// `armadillo.off` kept a 6.1° cap that `0.15·L` removes.
const CORNER_ONTO_LINE: f64 = 0.15;

/// An isolated open feature chain (both ends with one feature edge) or a closed feature loop
/// shorter than this many target lengths is not a feature.
const MIN_FEATURE_CHAIN: f64 = 1.0;

/// A tail (a chain from an open end to a junction of three or more feature edges) shorter than this
/// share of [`MIN_FEATURE_CHAIN`] is not a feature. Shorter than for isolated chains: the ridges
/// meeting at a sharp tip (a claw, an ear) are such tails, and dropping them rounds the tip (on
/// `armadillo.off` at 1.5 %, dropping tails up to `L` doubled the Hausdorff distance).
const TAIL_FRACTION: f64 = 0.5;

/// Two crease edges meeting at a vertex at less than this angle (a feature line folding back on
/// itself) are not features ([`unmark_hairpins`]).
const HAIRPIN_ANGLE: f64 = 30.0 * std::f64::consts::PI / 180.0;

/// Unmarks both feature edges of every *hairpin*: a vertex with exactly two feature edges, neither
/// on the boundary, that meet at less than [`HAIRPIN_ANGLE`]. Kept, such a vertex is a corner (its
/// line turns by more than the feature angle) and every triangle in the sector between its two
/// edges has a corner under that angle; on the meshes measured hairpins are the sides of sliver
/// faces tilted against their neighbours (`bunny.obj`: a sliver whose three edges all pass the
/// dihedral test), not creases of the shape. The surface-distance guard still keeps the surface
/// there. Decided on the input in vertex order (an edge unmarked at one hairpin no longer counts at
/// its other end), so the result is deterministic.
fn unmark_hairpins(m: &mut HalfEdgeMesh) {
    let mut ring = Vec::new();
    for v in 0..m.num_vertices() as u32 {
        if !m.vertex_live(v as usize) || m.is_boundary_vertex(v) {
            continue;
        }
        m.outgoing(v, &mut ring);
        let edges: Vec<u32> = ring
            .iter()
            .copied()
            .filter(|&g| m.feature[(g / 2) as usize])
            .collect();
        if edges.len() != 2 {
            continue;
        }
        let p = m.pos[v as usize];
        let (Some(d0), Some(d1)) = (
            normalized(sub(m.pos[m.to(edges[0]) as usize], p)),
            normalized(sub(m.pos[m.to(edges[1]) as usize], p)),
        ) else {
            continue;
        };
        // The two edges bound one face whose third edge is a feature too.
        let (w0, w1) = (m.to(edges[0]), m.to(edges[1]));
        let feature_triangle = [(edges[0], w1), (edges[1], w0)].iter().any(|&(g, w)| {
            !m.is_boundary_halfedge(g)
                && m.to(m.next(g)) == w
                && m.feature[(m.next(g) / 2) as usize]
        });
        if feature_triangle && norm(cross(d0, d1)).atan2(dot(d0, d1)) < HAIRPIN_ANGLE {
            for g in edges {
                m.feature[(g / 2) as usize] = false;
            }
        }
    }
}

/// Unmarks the crease (non-boundary) feature chains that are noise at the target length: isolated
/// open chains and closed loops shorter than `min_len`, and tails shorter than
/// `TAIL_FRACTION·min_len` (a chain runs through vertices with two feature edges; its ends are
/// vertices with one, an open end, or with three or more, a junction). Kept, they would lock their
/// ends as corners with a sliver between them (a scan's ridge of a few tiny faces). Chains between
/// two junctions stay, whatever their length. Repeated until nothing changes (dropping a tail can
/// leave a junction with two feature edges, joining two chains, or with one, making a new open
/// end). Deterministic: vertices in index order.
fn prune_short_feature_chains(m: &mut HalfEdgeMesh, min_len: f64) {
    let nv = m.num_vertices();
    let mut ring = Vec::new();
    let feature_edges_at = |m: &HalfEdgeMesh, v: u32, ring: &mut Vec<u32>| -> Vec<u32> {
        m.outgoing(v, ring);
        ring.iter()
            .copied()
            .filter(|&g| m.feature[(g / 2) as usize])
            .collect()
    };
    let mut count = vec![0u32; nv];
    for e in 0..m.num_edges() {
        if m.feature[e] {
            let h = 2 * e as u32;
            count[m.from(h) as usize] += 1;
            count[m.to(h) as usize] += 1;
        }
    }
    loop {
        let mut changed = false;
        let mut seen = vec![false; nv];
        for start in 0..nv as u32 {
            let c = count[start as usize];
            if !(c == 1 || (c == 2 && !seen[start as usize])) {
                continue;
            }
            // Walk from `start` along its (first) feature edge through vertices with two.
            let mut chain: Vec<u32> = Vec::new();
            let mut length = 0.0;
            let mut cur = start;
            let mut from_edge = u32::MAX;
            let mut closed = false;
            let mut boundary = false;
            loop {
                seen[cur as usize] = true;
                let Some(&g) = feature_edges_at(m, cur, &mut ring)
                    .iter()
                    .find(|&&g| g / 2 != from_edge)
                else {
                    break;
                };
                let e = g / 2;
                chain.push(e);
                boundary |= m.is_boundary_edge(e as usize);
                length += m.edge_length(e as usize);
                from_edge = e;
                cur = m.to(g);
                if cur == start {
                    closed = true;
                    break;
                }
                if count[cur as usize] != 2 || length >= min_len || boundary {
                    break;
                }
            }
            // A count-2 start is only pruned as a closed loop (its open chains are walked from
            // their ends).
            let isolated = c == 1 && count[cur as usize] == 1 && length < min_len;
            let tail = c == 1 && count[cur as usize] >= 3 && length < TAIL_FRACTION * min_len;
            let small_loop = closed && length < min_len;
            if boundary || !(isolated || tail || small_loop) {
                continue;
            }
            for &e in &chain {
                m.feature[e as usize] = false;
                let h = 2 * e;
                count[m.from(h) as usize] -= 1;
                count[m.to(h) as usize] -= 1;
            }
            changed = true;
        }
        if !changed {
            break;
        }
    }
}

/// Whether moving vertex `v` (outgoing half-edges `ring`) to `p1` as it merges with `other` keeps
/// every edge to a neighbour at most `hi` long, and every face that survives (those without
/// `other`) unfolded (its normal turns by less than 90°) and not near-degenerate (no corner under
/// [`MIN_NEW_ANGLE`] unless no worse than the worst face around `v` before).
fn ring_ok(m: &HalfEdgeMesh, v: u32, other: u32, p1: [f64; 3], ring: &[u32], hi: f64) -> bool {
    let p0 = m.pos[v as usize];
    let mut ring_normal = [0.0; 3];
    let mut worst_old = f64::INFINITY;
    for &g in ring {
        let w = m.to(g);
        if w != other && dist(p1, m.pos[w as usize]) > hi {
            return false;
        }
        if m.is_boundary_halfedge(g) {
            continue;
        }
        let (pa, pb) = (m.pos[w as usize], m.pos[m.to(m.next(g)) as usize]);
        let n = cross(sub(pa, p0), sub(pb, p0));
        for k in 0..3 {
            ring_normal[k] += n[k];
        }
        worst_old = worst_old.min(min_angle(p0, pa, pb));
    }
    let ring_normal = normalized(ring_normal);
    for (a, b) in m.surviving_far_edges(ring, other) {
        let (pa, pb) = (m.pos[a as usize], m.pos[b as usize]);
        let old = normalized(cross(sub(pa, p0), sub(pb, p0))).or(ring_normal);
        let Some(new) = normalized(cross(sub(pa, p1), sub(pb, p1))) else {
            return false;
        };
        if let Some(old) = old
            && dot(old, new) <= 0.0
        {
            return false;
        }
        let angle = min_angle(p1, pa, pb);
        if angle < MIN_NEW_ANGLE && angle < worst_old {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests;
