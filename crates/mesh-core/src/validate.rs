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

use std::collections::HashMap;

use crate::geometry::{cross, dot, norm, sub};
use crate::topology::{EdgeFaces, connected_components, orient_consistently};
use crate::{MeshError, TriMesh};

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

/// Runs the whole policy; refusing issues are recorded and the analysis continues without the
/// offending elements so that the report is as complete as possible.
fn analyse(mesh: &TriMesh, o: &RepairOptions) -> Repaired {
    let nv = mesh.positions.len();
    let nf = mesh.faces.len();
    let mut issues = Vec::new();
    // Working state in input numbering: `rep[v]` = the input vertex v is merged into (or None).
    let mut vertex_alive = vec![true; nv];
    let mut rep: Vec<u32> = (0..nv as u32).collect();
    let mut face_alive = vec![true; nf];

    // 1. Non-finite coordinates.
    let bad_vertices: Vec<u32> = (0..nv)
        .filter(|&v| mesh.positions[v].iter().any(|c| !c.is_finite()))
        .map(|v| v as u32)
        .collect();
    if !bad_vertices.is_empty() {
        let n = bad_vertices.len();
        let refuse = !o.drop_nonfinite_vertices;
        let what = plural(n, "vertex has", "vertices have");
        let message = format!(
            "{what} NaN or infinite coordinates (vertex {}); {}",
            list(&bad_vertices, n),
            if refuse {
                "fix or re-export the mesh from your modelling tool"
            } else {
                "they and the faces using them were removed"
            }
        );
        for &v in &bad_vertices {
            vertex_alive[v as usize] = false;
        }
        issues.push(Issue {
            kind: IssueKind::NonFiniteCoordinates,
            count: n,
            examples: Locations::Vertices(examples(&bad_vertices)),
            action: if refuse {
                Action::Refused
            } else {
                Action::Repaired
            },
            message,
        });
    }

    // 2. Out-of-range indices.
    let oor: Vec<u32> = (0..nf)
        .filter(|&f| mesh.faces[f].iter().any(|&v| v as usize >= nv))
        .map(|f| f as u32)
        .collect();
    if !oor.is_empty() {
        let n = oor.len();
        let refuse = !o.drop_out_of_range_faces;
        let first = mesh.faces[oor[0] as usize];
        let message = format!(
            "{} to vertices that do not exist (face {}; e.g. face {} uses {:?} but the mesh has only {} vertices); {}",
            plural(n, "face refers", "faces refer"),
            list(&oor, n),
            oor[0],
            first,
            nv,
            if refuse {
                "the file is probably damaged or truncated"
            } else {
                "those faces were removed"
            }
        );
        for &f in &oor {
            face_alive[f as usize] = false;
        }
        issues.push(Issue {
            kind: IssueKind::IndexOutOfRange,
            count: n,
            examples: Locations::Faces(examples(&oor)),
            action: if refuse {
                Action::Refused
            } else {
                Action::Repaired
            },
            message,
        });
    }
    // Faces touching a non-finite vertex go too.
    for f in 0..nf {
        if face_alive[f] && mesh.faces[f].iter().any(|&v| !vertex_alive[v as usize]) {
            face_alive[f] = false;
        }
    }

    // 3. Exact duplicate vertices.
    let key = |p: [f64; 3]| p.map(|c| if c == 0.0 { 0u64 } else { c.to_bits() });
    let mut first_at: HashMap<[u64; 3], u32> = HashMap::with_capacity(nv);
    let mut dup_pairs: Vec<[u32; 2]> = Vec::new();
    for v in 0..nv {
        if !vertex_alive[v] {
            continue;
        }
        let k = key(mesh.positions[v]);
        match first_at.get(&k) {
            Some(&kept) => dup_pairs.push([v as u32, kept]),
            None => {
                first_at.insert(k, v as u32);
            }
        }
    }
    // Weld a pair when it closes a crack: one of them is used by no face, or both lie on an open
    // border. Two vertices inside closed surface regions are distinct points that touch (welding
    // them would pinch the surface into a non-manifold vertex), unless `weld_touching_vertices`.
    let mut referenced = vec![false; nv];
    let mut on_border = vec![false; nv];
    {
        let live: Vec<[u32; 3]> = (0..nf)
            .filter(|&f| face_alive[f])
            .map(|f| mesh.faces[f])
            .collect();
        for f in &live {
            for &v in f {
                referenced[v as usize] = true;
            }
        }
        for [a, b] in EdgeFaces::new(&live).boundary_edges() {
            on_border[a as usize] = true;
            on_border[b as usize] = true;
        }
    }
    let (weld_pairs, touching): (Vec<[u32; 2]>, Vec<[u32; 2]>) =
        dup_pairs.iter().partition(|&&[d, kept]| {
            let (d, kept) = (d as usize, kept as usize);
            o.weld_touching_vertices
                || !referenced[d]
                || !referenced[kept]
                || (on_border[d] && on_border[kept])
        });
    let show_pairs = |pairs: &[[u32; 2]]| -> Vec<String> {
        pairs
            .iter()
            .take(MAX_EXAMPLES)
            .map(|p| format!("{} = {}", p[0], p[1]))
            .collect()
    };
    if !weld_pairs.is_empty() {
        let n = weld_pairs.len();
        if o.weld_exact_duplicates {
            for &[d, kept] in &weld_pairs {
                rep[d as usize] = kept;
            }
        }
        issues.push(Issue {
            kind: IssueKind::DuplicateVertices,
            count: n,
            examples: Locations::VertexPairs(examples(&weld_pairs)),
            action: if o.weld_exact_duplicates {
                Action::Repaired
            } else {
                Action::Kept
            },
            message: format!(
                "{} at exactly the same position as an earlier vertex ({}); {}",
                plural(n, "vertex sits", "vertices sit"),
                list(&show_pairs(&weld_pairs), n),
                if o.weld_exact_duplicates {
                    "they were welded, closing the cracks between the faces around them"
                } else {
                    "left unwelded: the surface has cracks there"
                }
            ),
        });
    }
    if !touching.is_empty() {
        let n = touching.len();
        issues.push(Issue {
            kind: IssueKind::TouchingVertices,
            count: n,
            examples: Locations::VertexPairs(examples(&touching)),
            action: Action::Kept,
            message: format!(
                "{} the same position as an earlier vertex but on a closed part of the surface ({}): the surface touches itself there; kept apart (welding would pinch it)",
                plural(n, "vertex has", "vertices have"),
                list(&show_pairs(&touching), n)
            ),
        });
    }
    let welded = |f: [u32; 3]| f.map(|v| rep[v as usize]);

    // 4. Repeated vertex in a face (after welding).
    let repeated: Vec<u32> = (0..nf)
        .filter(|&f| face_alive[f])
        .filter(|&f| {
            let t = welded(mesh.faces[f]);
            t[0] == t[1] || t[1] == t[2] || t[0] == t[2]
        })
        .map(|f| f as u32)
        .collect();
    if !repeated.is_empty() {
        let n = repeated.len();
        if o.drop_degenerate_faces {
            for &f in &repeated {
                face_alive[f as usize] = false;
            }
        }
        issues.push(Issue {
            kind: IssueKind::RepeatedVertexInFace,
            count: n,
            examples: Locations::Faces(examples(&repeated)),
            action: if o.drop_degenerate_faces {
                Action::Repaired
            } else {
                Action::Kept
            },
            message: format!(
                "{} the same vertex twice{} (face {}); {}",
                plural(n, "face uses", "faces use"),
                if o.weld_exact_duplicates && !weld_pairs.is_empty() {
                    " after welding"
                } else {
                    ""
                },
                list(&repeated, n),
                if o.drop_degenerate_faces {
                    "they were removed"
                } else {
                    "kept"
                }
            ),
        });
    }

    // 5. Zero-area faces: a test of each face's shape at its own scale, so neither far-away
    //    debris nor an unreferenced outlier changes which faces count as degenerate.
    let zero_area: Vec<u32> = (0..nf)
        .filter(|&f| face_alive[f])
        .filter(|&f| {
            let t = welded(mesh.faces[f]).map(|v| mesh.positions[v as usize]);
            relative_area(t) <= o.zero_area_tolerance
        })
        .map(|f| f as u32)
        .collect();
    if !zero_area.is_empty() {
        let n = zero_area.len();
        if o.drop_degenerate_faces {
            for &f in &zero_area {
                face_alive[f as usize] = false;
            }
        }
        issues.push(Issue {
            kind: IssueKind::ZeroAreaFaces,
            count: n,
            examples: Locations::Faces(examples(&zero_area)),
            action: if o.drop_degenerate_faces {
                Action::Repaired
            } else {
                Action::Kept
            },
            message: format!(
                "{} no area: corners on a line or a point (face {}); {}",
                plural(n, "face has", "faces have"),
                list(&zero_area, n),
                if o.drop_degenerate_faces {
                    "they were removed"
                } else {
                    "kept: the solver's cotangent weights blow up there"
                }
            ),
        });
    }

    // 6. Duplicate faces (same vertex set).
    let mut seen: std::collections::HashSet<[u32; 3]> =
        std::collections::HashSet::with_capacity(nf);
    let mut dup_faces: Vec<u32> = Vec::new();
    for f in 0..nf {
        if !face_alive[f] {
            continue;
        }
        let mut s = welded(mesh.faces[f]);
        s.sort_unstable();
        if !seen.insert(s) {
            dup_faces.push(f as u32);
        }
    }
    if !dup_faces.is_empty() {
        let n = dup_faces.len();
        if o.drop_duplicate_faces {
            for &f in &dup_faces {
                face_alive[f as usize] = false;
            }
        }
        issues.push(Issue {
            kind: IssueKind::DuplicateFaces,
            count: n,
            examples: Locations::Faces(examples(&dup_faces)),
            action: if o.drop_duplicate_faces {
                Action::Repaired
            } else {
                Action::Kept
            },
            message: format!(
                "{} the same three vertices as an earlier face (face {}); {}",
                plural(n, "face uses", "faces use"),
                list(&dup_faces, n),
                if o.drop_duplicate_faces {
                    "the copies were removed"
                } else {
                    "kept"
                }
            ),
        });
    }

    // 7. Unreferenced vertices (finite, not welded away, used by no surviving face).
    let mut used = vec![false; nv];
    for f in 0..nf {
        if face_alive[f] {
            for v in welded(mesh.faces[f]) {
                used[v as usize] = true;
            }
        }
    }
    let unreferenced: Vec<u32> = (0..nv)
        .filter(|&v| vertex_alive[v] && rep[v] as usize == v && !used[v])
        .map(|v| v as u32)
        .collect();
    if !unreferenced.is_empty() {
        let n = unreferenced.len();
        issues.push(Issue {
            kind: IssueKind::UnreferencedVertices,
            count: n,
            examples: Locations::Vertices(examples(&unreferenced)),
            action: if o.drop_unreferenced_vertices {
                Action::Repaired
            } else {
                Action::Kept
            },
            message: format!(
                "{} not used by any face (vertex {}); {}",
                plural(n, "vertex is", "vertices are"),
                list(&unreferenced, n),
                if o.drop_unreferenced_vertices {
                    "they were removed"
                } else {
                    "kept: each becomes a separate part"
                }
            ),
        });
    }

    // Compact: new vertex numbering in input order.
    let mut vertex_map: Vec<Option<u32>> = vec![None; nv];
    let mut positions = Vec::new();
    for v in 0..nv {
        let keep =
            vertex_alive[v] && rep[v] as usize == v && (used[v] || !o.drop_unreferenced_vertices);
        if keep {
            vertex_map[v] = Some(positions.len() as u32);
            positions.push(mesh.positions[v]);
        }
    }
    for v in 0..nv {
        if vertex_alive[v] && rep[v] as usize != v {
            vertex_map[v] = vertex_map[rep[v] as usize];
        }
    }
    // Surviving faces, in input numbering (welded) and in output numbering.
    let mut face_map: Vec<Option<u32>> = vec![None; nf];
    let mut kept_input: Vec<u32> = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::new();
    for f in 0..nf {
        if face_alive[f] {
            let t = welded(mesh.faces[f]);
            face_map[f] = Some(faces.len() as u32);
            kept_input.push(f as u32);
            faces.push(t.map(|v| vertex_map[v as usize].unwrap_or(0)));
        }
    }
    // Output → input vertex numbering, to report locations in the input's numbering.
    let mut to_input = vec![0u32; positions.len()];
    for v in 0..nv {
        if let Some(n) = vertex_map[v]
            && rep[v] as usize == v
        {
            to_input[n as usize] = v as u32;
        }
    }
    let edge_in = |e: [u32; 2]| e.map(|v| to_input[v as usize]);

    // 8. Non-manifold edges.
    let ef = EdgeFaces::new(&faces);
    let nm: Vec<[u32; 2]> = ef.non_manifold_edges().into_iter().map(edge_in).collect();
    if !nm.is_empty() {
        let n = nm.len();
        issues.push(Issue {
            kind: IssueKind::NonManifoldEdges,
            count: n,
            examples: Locations::Edges(examples(&nm)),
            action: if o.refuse_non_manifold {
                Action::Refused
            } else {
                Action::Kept
            },
            message: format!(
                "{} shared by more than two faces (edge {}); {}",
                plural(n, "edge is", "edges are"),
                list_edges(&nm, n),
                if o.refuse_non_manifold {
                    "separate the fins or overlapping sheets in your modelling tool"
                } else {
                    "kept: the deformation still works but may crease there"
                }
            ),
        });
    }

    // 9. Orientation.
    let bad_edges: Vec<[u32; 2]> = ef
        .inconsistently_oriented_edges()
        .into_iter()
        .map(edge_in)
        .collect();
    if !bad_edges.is_empty() {
        let n = bad_edges.len();
        let oriented = orient_consistently(&faces);
        let fixed = o.fix_orientation && oriented.orientable;
        if fixed {
            faces = oriented.faces;
        }
        let flipped_in: Vec<u32> = oriented
            .flipped
            .iter()
            .map(|&f| kept_input[f as usize])
            .collect();
        issues.push(Issue {
            kind: IssueKind::InconsistentOrientation,
            count: n,
            examples: Locations::Edges(examples(&bad_edges)),
            action: if fixed {
                Action::Repaired
            } else {
                Action::Kept
            },
            message: format!(
                "neighbouring faces disagree about which side is outside at {} (edge {}); {}",
                plural(n, "edge", "edges"),
                list_edges(&bad_edges, n),
                match (o.fix_orientation, oriented.orientable) {
                    (true, true) => format!(
                        "{} flipped to agree (face {})",
                        plural(flipped_in.len(), "face was", "faces were"),
                        list(&flipped_in, flipped_in.len())
                    ),
                    (true, false) => "the surface is one-sided (like a Möbius strip), so no \
                                      flip can fix it; kept as is, normals there will be wrong"
                        .to_string(),
                    (false, _) => "kept: normals there will be wrong".to_string(),
                }
            ),
        });
    }

    // 10. Components, and inward-facing closed parts.
    let (labels, count) = connected_components(positions.len(), &faces);
    let mut sizes = vec![0usize; count];
    for &l in &labels {
        sizes[l as usize] += 1;
    }
    let ef = EdgeFaces::new(&faces);
    // A part is closed when none of its edges is a boundary edge.
    let mut part_open = vec![false; count];
    for e in 0..ef.len() {
        if ef.uses_of(e).len() == 1 {
            part_open[labels[ef.edges[e][0] as usize] as usize] = true;
        }
    }
    if o.fix_orientation {
        let mut part_faces: Vec<Vec<[u32; 3]>> = vec![Vec::new(); count];
        for f in &faces {
            part_faces[labels[f[0] as usize] as usize].push(*f);
        }
        let inward: Vec<usize> = (0..count)
            .filter(|&c| !part_open[c] && volume_sign(&positions, &part_faces[c]) < 0.0)
            .collect();
        if !inward.is_empty() {
            let reps: Vec<u32> = inward
                .iter()
                .filter_map(|&c| labels.iter().position(|&l| l as usize == c))
                .map(|v| to_input[v])
                .collect();
            for f in faces.iter_mut() {
                if inward.contains(&(labels[f[0] as usize] as usize)) {
                    *f = [f[0], f[2], f[1]];
                }
            }
            issues.push(Issue {
                kind: IssueKind::InwardFacing,
                count: inward.len(),
                examples: Locations::Vertices(examples(&reps)),
                action: Action::Repaired,
                message: format!(
                    "{} inside out: all faces point inward (the part containing vertex {}); {}",
                    plural(inward.len(), "closed part is", "closed parts are"),
                    list(&reps, reps.len()),
                    "its faces were flipped"
                ),
            });
        }
    }
    if count > 1 {
        let mut sorted = sizes.clone();
        sorted.sort_unstable_by(|a, b| b.cmp(a));
        issues.push(Issue {
            kind: IssueKind::SeveralComponents,
            count,
            examples: Locations::ComponentSizes(examples(&sorted)),
            action: if o.refuse_several_components {
                Action::Refused
            } else {
                Action::Kept
            },
            message: format!(
                "the mesh has {count} separate parts (vertices per part: {}); {}",
                list(&sorted, count),
                if o.refuse_several_components {
                    "join them or keep one"
                } else {
                    "each part is deformed on its own and pinned at its first vertex"
                }
            ),
        });
    }
    let boundary: Vec<[u32; 2]> = ef.boundary_edges().into_iter().map(edge_in).collect();
    if !boundary.is_empty() {
        let n = boundary.len();
        issues.push(Issue {
            kind: IssueKind::BoundaryEdges,
            count: n,
            examples: Locations::Edges(examples(&boundary)),
            action: Action::Kept,
            message: format!(
                "the surface is open: {} only one face (edge {}); fine for deformation",
                plural(n, "edge has", "edges have"),
                list_edges(&boundary, n)
            ),
        });
    }

    // 11. Needle faces.
    let needles: Vec<u32> = faces
        .iter()
        .enumerate()
        .filter(|(_, f)| {
            min_angle_degrees(f.map(|v| positions[v as usize])) < o.needle_angle_degrees
        })
        .map(|(i, _)| kept_input[i])
        .collect();
    if !needles.is_empty() {
        let n = needles.len();
        issues.push(Issue {
            kind: IssueKind::NeedleFaces,
            count: n,
            examples: Locations::Faces(examples(&needles)),
            action: Action::Kept,
            message: format!(
                "{} very thin, with a corner under {}° (face {}); kept: they work, but \
                 remeshing to more even triangles gives smoother results",
                plural(n, "face is", "faces are"),
                o.needle_angle_degrees,
                list(&needles, n)
            ),
        });
    }

    // 12. Nothing left.
    if faces.is_empty() {
        issues.push(Issue {
            kind: IssueKind::NoFaces,
            count: 0,
            examples: Locations::None,
            action: Action::Refused,
            message: if nf == 0 {
                "the mesh has no triangles".to_string()
            } else {
                format!("none of the {nf} faces is usable after removing the broken ones")
            },
        });
    }

    let closed = !faces.is_empty() && boundary.is_empty();
    let report = ValidationReport {
        input_vertices: nv,
        input_faces: nf,
        output_vertices: positions.len(),
        output_faces: faces.len(),
        components: count,
        closed,
        issues,
    };
    Repaired {
        mesh: TriMesh { positions, faces },
        vertex_map,
        face_map,
        report,
    }
}
