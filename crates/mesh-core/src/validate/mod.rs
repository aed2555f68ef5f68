//! Validation and repair of user meshes (spec §1.4 and §11).
//!
//! [`validate`] inspects a mesh and returns a [`ValidationReport`] without changing anything;
//! [`repair`] applies the same analysis and returns the cleaned mesh together with maps from the
//! input's numbering to the output's, or refuses with a [`MeshError::Invalid`] naming the problem
//! and where it is.
//!
//! Policy (defaults of [`RepairOptions`]), in the order it is applied:
//!
//! | problem | default action |
//! |---|---|
//! | NaN / infinite coordinates | **refuse** (option: drop those vertices and their faces) |
//! | face index ≥ number of vertices | **refuse** (option: drop those faces) |
//! | exact duplicate vertices (bitwise equal, −0 = +0) on a crack (one unused, or both on an open border) | weld onto the first occurrence |
//! | coincident vertices inside closed regions (the surface touches itself) | report, keep apart |
//! | face with a repeated vertex (after welding) | drop |
//! | zero-area face (area ≤ `zero_area_tolerance` · its own longest edge²) | drop |
//! | duplicate faces (same vertex set, any order) | keep the first, drop the rest |
//! | unreferenced vertices | drop |
//! | non-manifold edges (> 2 faces) | report, keep (option: refuse) |
//! | inconsistent orientation between neighbours | flip faces to agree (report if impossible) |
//! | closed part whose faces point inward (volume < 0) | flip that part |
//! | several connected parts | report (solvers pin one vertex per part) |
//! | needle triangles (smallest angle < `needle_angle_degrees`) | report, keep |
//! | nothing left | **refuse** |
//!
//! All indices in a report refer to the **input** mesh's numbering (vertex and face order of the
//! file), so an artist can find them.
//!
//! Each row of the table is a public pass function that can run alone (the libigl way), and
//! [`analyse`] composes them in the order above:
//!
//! | # | pass | state |
//! |---|---|---|
//! | 1 | [`drop_nonfinite_vertices`] | [`InputPass`] |
//! | 2 | [`drop_out_of_range_faces`] | [`InputPass`] |
//! | 3 | [`weld_duplicate_vertices`] (duplicates and touching vertices) | [`InputPass`] |
//! | 4 | [`drop_repeated_vertex_faces`] | [`InputPass`] |
//! | 5 | [`drop_zero_area_faces`] | [`InputPass`] |
//! | 6 | [`drop_duplicate_faces`] | [`InputPass`] |
//! | 7 | [`report_unreferenced_vertices`] | [`InputPass`] |
//! | – | [`compact`]: renumber, build the maps | [`InputPass`] → [`OutputPass`] |
//! | 8 | [`report_non_manifold_edges`] | [`OutputPass`] |
//! | 9 | [`fix_inconsistent_orientation`] | [`OutputPass`] |
//! | 10 | [`orient_closed_parts_outward`], [`report_components`], [`report_boundary_edges`] | [`OutputPass`] |
//! | 11 | [`report_needle_faces`] | [`OutputPass`] |
//! | 12 | [`refuse_empty`] | [`OutputPass`] |
//!
//! Passes 1–7 mark and weld in the input numbering without renumbering; passes 8–12 work on the
//! compacted mesh. Each appends its issues to the state's `issues`; a refusing issue is recorded
//! and the analysis goes on without the offending elements.
//!
//! ```
//! use mesh_core::validate::{InputPass, IssueKind, RepairOptions, weld_duplicate_vertices};
//! let mut m = mesh_core::shapes::tetrahedron();
//! m.positions.push(m.positions[0]); // an unused copy of vertex 0
//! let mut state = InputPass::new(&m);
//! weld_duplicate_vertices(&mut state, &RepairOptions::default());
//! assert_eq!(state.issues[0].kind, IssueKind::DuplicateVertices);
//! assert_eq!(state.rep[4], 0); // welded onto vertex 0
//! ```

use crate::geometry::{cross, dot, norm, sub};
use crate::{MeshError, TriMesh};

mod passes;
pub use passes::{
    InputPass, OutputPass, analyse, compact, drop_duplicate_faces, drop_nonfinite_vertices,
    drop_out_of_range_faces, drop_repeated_vertex_faces, drop_zero_area_faces,
    fix_inconsistent_orientation, orient_closed_parts_outward, refuse_empty, report_boundary_edges,
    report_components, report_needle_faces, report_non_manifold_edges,
    report_unreferenced_vertices, weld_duplicate_vertices,
};

/// How many example locations an issue keeps (the count is always complete).
pub const MAX_EXAMPLES: usize = 8;

/// Knobs of [`repair`] (see the module docs for the policy).
#[derive(Clone, Debug, PartialEq)]
pub struct RepairOptions {
    /// Drop vertices with NaN/infinite coordinates and every face using them, instead of refusing.
    pub drop_nonfinite_vertices: bool,
    /// Drop faces with an index ≥ the number of vertices, instead of refusing.
    pub drop_out_of_range_faces: bool,
    /// Weld vertices whose coordinates are bitwise equal (after −0 → +0) when that closes a
    /// crack: one of the two is unused, or both lie on an open border.
    pub weld_exact_duplicates: bool,
    /// Also weld coincident vertices that both lie inside closed surface regions (surfaces that
    /// touch at a point). Off by default: it pinches the surface into a non-manifold vertex.
    pub weld_touching_vertices: bool,
    /// Drop faces with a repeated vertex or (near) zero area.
    pub drop_degenerate_faces: bool,
    /// Drop all but the first of faces that use the same three vertices.
    pub drop_duplicate_faces: bool,
    /// Drop vertices that no face uses.
    pub drop_unreferenced_vertices: bool,
    /// Flip faces so neighbours agree on the outside, and flip closed parts that face inward.
    pub fix_orientation: bool,
    /// Refuse meshes with edges shared by more than two faces (kept and reported when `false`).
    pub refuse_non_manifold: bool,
    /// Refuse meshes with several connected parts (kept and reported when `false`).
    pub refuse_several_components: bool,
    /// A face is "zero area" when its area ≤ this × (its own longest edge)²: a test of shape
    /// (corners on a line or a point), independent of the mesh's scale and of far-away vertices.
    pub zero_area_tolerance: f64,
    /// A face is a "needle" when its smallest corner angle is below this many degrees.
    pub needle_angle_degrees: f64,
}

impl Default for RepairOptions {
    fn default() -> Self {
        Self {
            drop_nonfinite_vertices: false,
            drop_out_of_range_faces: false,
            weld_exact_duplicates: true,
            weld_touching_vertices: false,
            drop_degenerate_faces: true,
            drop_duplicate_faces: true,
            drop_unreferenced_vertices: true,
            fix_orientation: true,
            refuse_non_manifold: false,
            refuse_several_components: false,
            zero_area_tolerance: 1e-12,
            needle_angle_degrees: 1.0,
        }
    }
}

/// What kind of problem an [`Issue`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum IssueKind {
    /// Vertices with NaN or infinite coordinates.
    NonFiniteCoordinates,
    /// Faces that refer to a vertex that does not exist.
    IndexOutOfRange,
    /// Vertices at exactly the same position as an earlier vertex, on a crack (welded).
    DuplicateVertices,
    /// Coincident vertices inside closed surface regions: the surface touches itself (kept).
    TouchingVertices,
    /// Faces that use the same vertex twice.
    RepeatedVertexInFace,
    /// Faces whose three corners are (nearly) on a line or a point.
    ZeroAreaFaces,
    /// Faces that use the same three vertices as an earlier face.
    DuplicateFaces,
    /// Vertices that no face uses.
    UnreferencedVertices,
    /// Edges shared by more than two faces.
    NonManifoldEdges,
    /// Neighbouring faces that disagree about which side is outside.
    InconsistentOrientation,
    /// Closed parts whose faces all point inward.
    InwardFacing,
    /// The mesh has several separate parts.
    SeveralComponents,
    /// Edges with a face on one side only (holes or open borders).
    BoundaryEdges,
    /// Very thin triangles.
    NeedleFaces,
    /// No triangles remain.
    NoFaces,
}

impl IssueKind {
    /// Stable snake_case name (used in JSON).
    pub fn name(self) -> &'static str {
        match self {
            IssueKind::NonFiniteCoordinates => "non_finite_coordinates",
            IssueKind::IndexOutOfRange => "index_out_of_range",
            IssueKind::DuplicateVertices => "duplicate_vertices",
            IssueKind::TouchingVertices => "touching_vertices",
            IssueKind::RepeatedVertexInFace => "repeated_vertex_in_face",
            IssueKind::ZeroAreaFaces => "zero_area_faces",
            IssueKind::DuplicateFaces => "duplicate_faces",
            IssueKind::UnreferencedVertices => "unreferenced_vertices",
            IssueKind::NonManifoldEdges => "non_manifold_edges",
            IssueKind::InconsistentOrientation => "inconsistent_orientation",
            IssueKind::InwardFacing => "inward_facing",
            IssueKind::SeveralComponents => "several_components",
            IssueKind::BoundaryEdges => "boundary_edges",
            IssueKind::NeedleFaces => "needle_faces",
            IssueKind::NoFaces => "no_faces",
        }
    }
}

/// What [`repair`] does (or would do) about an issue.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Action {
    /// Fixed in the repaired mesh.
    Repaired,
    /// Left as is (harmless, informational, or its repair is switched off).
    Kept,
    /// Repair refuses the mesh because of it.
    Refused,
}

impl Action {
    /// Stable lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Action::Repaired => "repaired",
            Action::Kept => "kept",
            Action::Refused => "refused",
        }
    }
}

/// Where an issue occurs, in the input's numbering (at most [`MAX_EXAMPLES`] entries).
#[derive(Clone, Debug, PartialEq)]
pub enum Locations {
    /// Vertex indices.
    Vertices(Vec<u32>),
    /// Face indices.
    Faces(Vec<u32>),
    /// Edges as vertex pairs.
    Edges(Vec<[u32; 2]>),
    /// `[duplicate, kept]` vertex pairs.
    VertexPairs(Vec<[u32; 2]>),
    /// Vertex counts of the parts, largest first.
    ComponentSizes(Vec<usize>),
    /// Nothing to point at.
    None,
}

/// One problem found in a mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct Issue {
    /// What it is.
    pub kind: IssueKind,
    /// How many elements are affected (all of them, not just the examples).
    pub count: usize,
    /// The first few places.
    pub examples: Locations,
    /// What repair does about it.
    pub action: Action,
    /// One sentence for a person, naming the problem, where, and what happens.
    pub message: String,
}

/// Everything [`validate`] or [`repair`] found, in the order the policy handles it.
#[derive(Clone, Debug, PartialEq)]
pub struct ValidationReport {
    /// Vertices in the input.
    pub input_vertices: usize,
    /// Faces in the input.
    pub input_faces: usize,
    /// Vertices after repair (what repair would produce).
    pub output_vertices: usize,
    /// Faces after repair.
    pub output_faces: usize,
    /// Connected parts after repair.
    pub components: usize,
    /// `true` when, after repair, every edge has exactly two faces.
    pub closed: bool,
    /// The problems, in policy order.
    pub issues: Vec<Issue>,
}

impl ValidationReport {
    /// `true` when repair refuses this mesh.
    pub fn is_refused(&self) -> bool {
        self.issues.iter().any(|i| i.action == Action::Refused)
    }

    /// `true` when there is nothing at all to report.
    pub fn is_clean(&self) -> bool {
        self.issues.is_empty()
    }

    /// The issue of a kind, if present.
    pub fn issue(&self, kind: IssueKind) -> Option<&Issue> {
        self.issues.iter().find(|i| i.kind == kind)
    }

    /// The messages of the refusing issues, joined (empty when not refused).
    pub fn refusal_message(&self) -> String {
        self.issues
            .iter()
            .filter(|i| i.action == Action::Refused)
            .map(|i| i.message.as_str())
            .collect::<Vec<_>>()
            .join("; ")
    }
}

/// The result of [`repair`].
#[derive(Clone, Debug, PartialEq)]
pub struct Repaired {
    /// The cleaned mesh.
    pub mesh: TriMesh,
    /// For each input vertex, its index in `mesh` (`None` when dropped; a welded duplicate maps
    /// to the vertex it was welded onto).
    pub vertex_map: Vec<Option<u32>>,
    /// For each input face, its index in `mesh` (`None` when dropped).
    pub face_map: Vec<Option<u32>>,
    /// What was found and done.
    pub report: ValidationReport,
}

impl Repaired {
    /// Maps per-vertex values of the repaired mesh back to the input's numbering (`None` for
    /// dropped input vertices).
    pub fn to_input_vertices<T: Clone>(&self, values: &[T]) -> Vec<Option<T>> {
        self.vertex_map
            .iter()
            .map(|m| m.and_then(|i| values.get(i as usize).cloned()))
            .collect()
    }
}

/// Inspects `mesh` and reports every issue with what [`repair`] would do; changes nothing.
pub fn validate(mesh: &TriMesh, options: &RepairOptions) -> ValidationReport {
    analyse(mesh, options).report
}

/// Repairs `mesh` by the policy in the module docs, or refuses it with a message naming the
/// problems and the first few places.
pub fn repair(mesh: &TriMesh, options: &RepairOptions) -> Result<Repaired, MeshError> {
    let r = analyse(mesh, options);
    if r.report.is_refused() {
        return Err(MeshError::Invalid(r.report.refusal_message()));
    }
    Ok(r)
}

fn examples<T: Copy>(items: &[T]) -> Vec<T> {
    items.iter().take(MAX_EXAMPLES).copied().collect()
}

fn list<T: std::fmt::Display>(items: &[T], total: usize) -> String {
    let mut s = items
        .iter()
        .take(MAX_EXAMPLES)
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(", ");
    if total > MAX_EXAMPLES.min(items.len()) {
        s.push_str(", …");
    }
    s
}

fn list_edges(items: &[[u32; 2]], total: usize) -> String {
    let shown: Vec<String> = items
        .iter()
        .take(MAX_EXAMPLES)
        .map(|e| format!("{}–{}", e[0], e[1]))
        .collect();
    list(&shown, total)
}

fn plural(n: usize, one: &str, many: &str) -> String {
    if n == 1 {
        format!("1 {one}")
    } else {
        format!("{n} {many}")
    }
}

/// The edges `p1 − p0`, `p2 − p0` of a triangle divided by their largest absolute component, so
/// that products of them neither overflow (coordinates of 1e200) nor underflow, with the
/// differences taken before any rounding (halving is exact, and differences of nearby floats are
/// exact). `None` when the three corners coincide.
fn scaled_edges(p: [[f64; 3]; 3]) -> Option<([f64; 3], [f64; 3])> {
    let half = |q: [f64; 3], r: [f64; 3]| {
        [
            0.5 * q[0] - 0.5 * r[0],
            0.5 * q[1] - 0.5 * r[1],
            0.5 * q[2] - 0.5 * r[2],
        ]
    };
    let a = half(p[1], p[0]);
    let b = half(p[2], p[0]);
    let s = a.iter().chain(&b).fold(0.0f64, |m, c| m.max(c.abs()));
    if s == 0.0 || !s.is_finite() {
        return None;
    }
    Some((a.map(|c| c / s), b.map(|c| c / s)))
}

/// Area of a triangle relative to the square of its longest edge, `|e1 × e2| / (2 max|e|²)`
/// (0 for corners on a line or a point; at most √3/4 for an equilateral triangle). Scale-free.
fn relative_area(p: [[f64; 3]; 3]) -> f64 {
    let Some((a, b)) = scaled_edges(p) else {
        return 0.0;
    };
    let longest = dot(a, a).max(dot(b, b)).max(dot(sub(b, a), sub(b, a)));
    0.5 * norm(cross(a, b)) / longest
}

/// Smallest corner angle of a triangle, in degrees (0 for a degenerate one), in a scaled frame.
fn min_angle_degrees(p: [[f64; 3]; 3]) -> f64 {
    let Some((a, b)) = scaled_edges(p) else {
        return 0.0;
    };
    // The scaled triangle 0, a, b has the same angles.
    let q = [[0.0; 3], a, b];
    let mut best = f64::INFINITY;
    for i in 0..3 {
        let a = sub(q[(i + 1) % 3], q[i]);
        let b = sub(q[(i + 2) % 3], q[i]);
        let angle = norm(cross(a, b)).atan2(dot(a, b));
        best = best.min(angle);
    }
    if best.is_finite() {
        best.to_degrees()
    } else {
        0.0
    }
}

/// Sign of the volume enclosed by `faces`, computed about the centre of their vertices' bounding
/// box and in units of its half extent so that huge or tiny coordinates cannot overflow
/// (`Σ q0 · (q1 × q2)`; only the sign is meaningful).
fn volume_sign(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for f in faces {
        for &v in f {
            let p = positions[v as usize];
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    // Halves so that neither the centre nor the offsets overflow.
    let c: [f64; 3] = std::array::from_fn(|k| 0.5 * lo[k] + 0.5 * hi[k]);
    let half = |p: [f64; 3]| -> [f64; 3] { std::array::from_fn(|k| 0.5 * p[k] - 0.5 * c[k]) };
    let s = (0..3).fold(0.0f64, |m, k| m.max(0.5 * hi[k] - 0.5 * c[k]));
    if s == 0.0 || !s.is_finite() {
        return 0.0;
    }
    let q = |v: u32| half(positions[v as usize]).map(|x| x / s);
    faces
        .iter()
        .map(|f| dot(q(f[0]), cross(q(f[1]), q(f[2]))))
        .sum()
}
