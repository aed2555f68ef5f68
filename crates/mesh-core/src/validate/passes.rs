//! The passes of [`analyse`], one public function each (re-exported by the parent module, whose
//! docs list them and state the two numberings).

use std::collections::{HashMap, HashSet};

use super::{
    Action, Issue, IssueKind, Locations, MAX_EXAMPLES, RepairOptions, Repaired, ValidationReport,
    examples, list, list_edges, min_angle_degrees, plural, relative_area, volume_sign,
};
use crate::TriMesh;
use crate::topology::{EdgeFaces, connected_components, orient_consistently};

/// The state of passes 1–7, in the input mesh's numbering.
#[derive(Clone, Debug)]
pub struct InputPass<'a> {
    /// The mesh being analysed (never modified).
    pub mesh: &'a TriMesh,
    /// `vertex_alive[v]`: input vertex `v` is kept (false once found non-finite).
    pub vertex_alive: Vec<bool>,
    /// `rep[v]`: the input vertex that `v` is welded onto (`v` itself when not welded).
    pub rep: Vec<u32>,
    /// `face_alive[f]`: input face `f` is kept.
    pub face_alive: Vec<bool>,
    /// Issues found so far, in policy order.
    pub issues: Vec<Issue>,
}

impl<'a> InputPass<'a> {
    /// Every vertex alive, nothing welded, no issues; every face alive except those with a vertex
    /// index out of range (reported by [`drop_out_of_range_faces`], but never alive, so that any
    /// pass can be called alone on any mesh without indexing out of bounds).
    pub fn new(mesh: &'a TriMesh) -> Self {
        let nv = mesh.positions.len();
        Self {
            mesh,
            vertex_alive: vec![true; nv],
            rep: (0..nv as u32).collect(),
            face_alive: mesh
                .faces
                .iter()
                .map(|f| f.iter().all(|&v| (v as usize) < nv))
                .collect(),
            issues: Vec::new(),
        }
    }

    /// Face `f` with every corner replaced by the vertex it is welded onto.
    fn welded(&self, f: usize) -> [u32; 3] {
        self.mesh.faces[f].map(|v| self.rep[v as usize])
    }

    /// Vertices used by a surviving face, after welding.
    fn used_vertices(&self) -> Vec<bool> {
        let mut used = vec![false; self.mesh.positions.len()];
        for f in 0..self.mesh.faces.len() {
            if self.face_alive[f] {
                for v in self.welded(f) {
                    used[v as usize] = true;
                }
            }
        }
        used
    }

    /// The common tail of passes 4–6: when `faces` is not empty, marks them dead if `drop` and
    /// records one issue of `kind` whose message `describe(count, listed faces)` writes.
    fn drop_faces(
        &mut self,
        faces: &[u32],
        kind: IssueKind,
        drop: bool,
        describe: impl FnOnce(usize, String) -> String,
    ) {
        if faces.is_empty() {
            return;
        }
        let n = faces.len();
        if drop {
            for &f in faces {
                self.face_alive[f as usize] = false;
            }
        }
        self.issues.push(Issue {
            kind,
            count: n,
            examples: Locations::Faces(examples(faces)),
            action: action(drop),
            message: describe(n, list(faces, n)),
        });
    }
}

/// The state of passes 8–12: the compacted mesh in the output numbering plus the maps back to the
/// input (issues name input vertices and faces).
#[derive(Clone, Debug)]
pub struct OutputPass {
    /// The mesh as repair returns it (passes 9 and 10 may still flip faces).
    pub mesh: TriMesh,
    /// Input vertex → output vertex (`None` when dropped; a welded vertex maps to its target).
    pub vertex_map: Vec<Option<u32>>,
    /// Input face → output face (`None` when dropped).
    pub face_map: Vec<Option<u32>>,
    /// Output vertex → the input vertex it comes from.
    pub to_input: Vec<u32>,
    /// Output face → the input face it comes from.
    pub kept_input: Vec<u32>,
    /// Faces in the input (for pass 12's message and the report).
    pub input_faces: usize,
    /// Issues found so far, in policy order.
    pub issues: Vec<Issue>,
}

impl OutputPass {
    fn edge_in(&self, e: [u32; 2]) -> [u32; 2] {
        e.map(|v| self.to_input[v as usize])
    }
}

fn action(repaired: bool) -> Action {
    if repaired {
        Action::Repaired
    } else {
        Action::Kept
    }
}

fn refused_or(refuse: bool, otherwise: Action) -> Action {
    if refuse { Action::Refused } else { otherwise }
}

/// Pass 1: vertices with a NaN or infinite coordinate. They are marked dead, and so is every face
/// that uses one (faces with an out-of-range index are left to pass 2). Refused unless
/// `drop_nonfinite_vertices`.
pub fn drop_nonfinite_vertices(s: &mut InputPass, o: &RepairOptions) {
    let (mesh, nv) = (s.mesh, s.mesh.positions.len());
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
            s.vertex_alive[v as usize] = false;
        }
        s.issues.push(Issue {
            kind: IssueKind::NonFiniteCoordinates,
            count: n,
            examples: Locations::Vertices(examples(&bad_vertices)),
            action: refused_or(refuse, Action::Repaired),
            message,
        });
    }
    // Faces touching a non-finite vertex go too.
    for (f, face) in mesh.faces.iter().enumerate() {
        if s.face_alive[f]
            && face
                .iter()
                .any(|&v| (v as usize) < nv && !s.vertex_alive[v as usize])
        {
            s.face_alive[f] = false;
        }
    }
}

/// Pass 2: faces with a vertex index ≥ the number of vertices (a damaged or truncated file).
/// Marked dead; refused unless `drop_out_of_range_faces`.
pub fn drop_out_of_range_faces(s: &mut InputPass, o: &RepairOptions) {
    let (mesh, nv) = (s.mesh, s.mesh.positions.len());
    let oor: Vec<u32> = (0..mesh.faces.len())
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
            s.face_alive[f as usize] = false;
        }
        s.issues.push(Issue {
            kind: IssueKind::IndexOutOfRange,
            count: n,
            examples: Locations::Faces(examples(&oor)),
            action: refused_or(refuse, Action::Repaired),
            message,
        });
    }
}

/// Pass 3: vertices at bitwise the same position (−0 = +0) as an earlier live vertex. A pair is
/// welded (`rep[duplicate] = first`, when `weld_exact_duplicates`) when it closes a crack: one of
/// the two is used by no live face, or both lie on an open border, or `weld_touching_vertices`.
/// Other pairs are two closed regions touching at a point: reported and kept apart. Expects
/// passes 1–2 to have removed faces with out-of-range indices.
pub fn weld_duplicate_vertices(s: &mut InputPass, o: &RepairOptions) {
    let mesh = s.mesh;
    let (nv, nf) = (mesh.positions.len(), mesh.faces.len());
    let key = |p: [f64; 3]| p.map(|c| if c == 0.0 { 0u64 } else { c.to_bits() });
    let mut first_at: HashMap<[u64; 3], u32> = HashMap::with_capacity(nv);
    let mut dup_pairs: Vec<[u32; 2]> = Vec::new();
    for v in 0..nv {
        if !s.vertex_alive[v] {
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
            .filter(|&f| s.face_alive[f])
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
                s.rep[d as usize] = kept;
            }
        }
        s.issues.push(Issue {
            kind: IssueKind::DuplicateVertices,
            count: n,
            examples: Locations::VertexPairs(examples(&weld_pairs)),
            action: action(o.weld_exact_duplicates),
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
        s.issues.push(Issue {
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
}

/// Pass 4: live faces that use one vertex twice after welding (`rep`). Dropped when
/// `drop_degenerate_faces`, else kept and reported.
pub fn drop_repeated_vertex_faces(s: &mut InputPass, o: &RepairOptions) {
    let nf = s.mesh.faces.len();
    let repeated: Vec<u32> = (0..nf)
        .filter(|&f| s.face_alive[f])
        .filter(|&f| {
            let t = s.welded(f);
            t[0] == t[1] || t[1] == t[2] || t[0] == t[2]
        })
        .map(|f| f as u32)
        .collect();
    // Pass 3 welds only under `weld_exact_duplicates`, so "something was welded" is exactly that
    // option with a non-empty weld list.
    let welded_any = s.rep.iter().enumerate().any(|(v, &r)| r as usize != v);
    let drop = o.drop_degenerate_faces;
    s.drop_faces(
        &repeated,
        IssueKind::RepeatedVertexInFace,
        drop,
        |n, listed| {
            format!(
                "{} the same vertex twice{} (face {listed}); {}",
                plural(n, "face uses", "faces use"),
                if welded_any { " after welding" } else { "" },
                if drop { "they were removed" } else { "kept" }
            )
        },
    );
}

/// Pass 5: live faces whose area is at most `zero_area_tolerance` × (their own longest edge)² —
/// corners on a line or a point. A test of each face's shape at its own scale, so neither far-away
/// debris nor an unreferenced outlier changes which faces count as degenerate. Dropped when
/// `drop_degenerate_faces`.
pub fn drop_zero_area_faces(s: &mut InputPass, o: &RepairOptions) {
    let mesh = s.mesh;
    let zero_area: Vec<u32> = (0..mesh.faces.len())
        .filter(|&f| s.face_alive[f])
        .filter(|&f| {
            let t = s.welded(f).map(|v| mesh.positions[v as usize]);
            relative_area(t) <= o.zero_area_tolerance
        })
        .map(|f| f as u32)
        .collect();
    let drop = o.drop_degenerate_faces;
    s.drop_faces(&zero_area, IssueKind::ZeroAreaFaces, drop, |n, listed| {
        format!(
            "{} no area: corners on a line or a point (face {listed}); {}",
            plural(n, "face has", "faces have"),
            if drop {
                "they were removed"
            } else {
                "kept: the solver's cotangent weights blow up there"
            }
        )
    });
}

/// Pass 6: live faces with the same vertex set (any order, after welding) as an earlier live
/// face. All but the first are dropped when `drop_duplicate_faces`.
pub fn drop_duplicate_faces(s: &mut InputPass, o: &RepairOptions) {
    let nf = s.mesh.faces.len();
    let mut seen: HashSet<[u32; 3]> = HashSet::with_capacity(nf);
    let mut dup_faces: Vec<u32> = Vec::new();
    for f in 0..nf {
        if !s.face_alive[f] {
            continue;
        }
        let mut t = s.welded(f);
        t.sort_unstable();
        if !seen.insert(t) {
            dup_faces.push(f as u32);
        }
    }
    let drop = o.drop_duplicate_faces;
    s.drop_faces(&dup_faces, IssueKind::DuplicateFaces, drop, |n, listed| {
        format!(
            "{} the same three vertices as an earlier face (face {listed}); {}",
            plural(n, "face uses", "faces use"),
            if drop {
                "the copies were removed"
            } else {
                "kept"
            }
        )
    });
}

/// Pass 7: finite vertices, not welded away, that no live face uses. Only reported here; [`compact`]
/// leaves them out when `drop_unreferenced_vertices`.
pub fn report_unreferenced_vertices(s: &mut InputPass, o: &RepairOptions) {
    let used = s.used_vertices();
    let unreferenced: Vec<u32> = (0..s.mesh.positions.len())
        .filter(|&v| s.vertex_alive[v] && s.rep[v] as usize == v && !used[v])
        .map(|v| v as u32)
        .collect();
    if !unreferenced.is_empty() {
        let n = unreferenced.len();
        s.issues.push(Issue {
            kind: IssueKind::UnreferencedVertices,
            count: n,
            examples: Locations::Vertices(examples(&unreferenced)),
            action: action(o.drop_unreferenced_vertices),
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
}

/// Between passes 7 and 8: keeps the live, unwelded vertices (those no face uses only without
/// `drop_unreferenced_vertices`) and the live faces, both in input order, with welded corners;
/// builds the maps between the numberings. Records no issue.
pub fn compact(s: InputPass, o: &RepairOptions) -> OutputPass {
    let mesh = s.mesh;
    let (nv, nf) = (mesh.positions.len(), mesh.faces.len());
    let used = s.used_vertices();
    // New vertex numbering in input order.
    let mut vertex_map: Vec<Option<u32>> = vec![None; nv];
    let mut positions = Vec::new();
    for v in 0..nv {
        let keep = s.vertex_alive[v]
            && s.rep[v] as usize == v
            && (used[v] || !o.drop_unreferenced_vertices);
        if keep {
            vertex_map[v] = Some(positions.len() as u32);
            positions.push(mesh.positions[v]);
        }
    }
    for v in 0..nv {
        if s.vertex_alive[v] && s.rep[v] as usize != v {
            vertex_map[v] = vertex_map[s.rep[v] as usize];
        }
    }
    // Surviving faces, in input numbering (welded) and in output numbering.
    let mut face_map: Vec<Option<u32>> = vec![None; nf];
    let mut kept_input: Vec<u32> = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::new();
    for f in 0..nf {
        if s.face_alive[f] {
            let t = s.welded(f);
            face_map[f] = Some(faces.len() as u32);
            kept_input.push(f as u32);
            faces.push(t.map(|v| vertex_map[v as usize].unwrap_or(0)));
        }
    }
    // Output → input vertex numbering, to report locations in the input's numbering.
    let mut to_input = vec![0u32; positions.len()];
    for v in 0..nv {
        if let Some(n) = vertex_map[v]
            && s.rep[v] as usize == v
        {
            to_input[n as usize] = v as u32;
        }
    }
    OutputPass {
        mesh: TriMesh { positions, faces },
        vertex_map,
        face_map,
        to_input,
        kept_input,
        input_faces: nf,
        issues: s.issues,
    }
}

/// Pass 8: edges shared by more than two faces (fins, overlapping sheets). Kept and reported,
/// refused when `refuse_non_manifold`.
pub fn report_non_manifold_edges(s: &mut OutputPass, o: &RepairOptions) {
    let ef = EdgeFaces::new(&s.mesh.faces);
    let nm: Vec<[u32; 2]> = ef
        .non_manifold_edges()
        .into_iter()
        .map(|e| s.edge_in(e))
        .collect();
    if !nm.is_empty() {
        let n = nm.len();
        s.issues.push(Issue {
            kind: IssueKind::NonManifoldEdges,
            count: n,
            examples: Locations::Edges(examples(&nm)),
            action: refused_or(o.refuse_non_manifold, Action::Kept),
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
}

/// Pass 9: edges whose two faces traverse it in the same direction (neighbours disagreeing about
/// the outside). With `fix_orientation` and an orientable surface, faces are flipped
/// ([`orient_consistently`]: per part, the part's first face keeps its winding); a one-sided
/// surface is reported and kept.
pub fn fix_inconsistent_orientation(s: &mut OutputPass, o: &RepairOptions) {
    let bad_edges: Vec<[u32; 2]> = EdgeFaces::new(&s.mesh.faces)
        .inconsistently_oriented_edges()
        .into_iter()
        .map(|e| s.edge_in(e))
        .collect();
    if !bad_edges.is_empty() {
        let n = bad_edges.len();
        let oriented = orient_consistently(&s.mesh.faces);
        let fixed = o.fix_orientation && oriented.orientable;
        let flipped_in: Vec<u32> = oriented
            .flipped
            .iter()
            .map(|&f| s.kept_input[f as usize])
            .collect();
        if fixed {
            s.mesh.faces = oriented.faces;
        }
        s.issues.push(Issue {
            kind: IssueKind::InconsistentOrientation,
            count: n,
            examples: Locations::Edges(examples(&bad_edges)),
            action: action(fixed),
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
}

/// Pass 10a: closed connected parts (no boundary edge) with negative enclosed volume — inside
/// out. With `fix_orientation`, every face of such a part is flipped (`[a, b, c] → [a, c, b]`);
/// without it nothing is checked. Expects consistently oriented parts (pass 9).
pub fn orient_closed_parts_outward(s: &mut OutputPass, o: &RepairOptions) {
    if !o.fix_orientation {
        return;
    }
    let (positions, faces) = (&s.mesh.positions, &mut s.mesh.faces);
    let (labels, count) = connected_components(positions.len(), faces);
    let ef = EdgeFaces::new(faces);
    // A part is closed when none of its edges is a boundary edge.
    let mut part_open = vec![false; count];
    for e in 0..ef.len() {
        if ef.uses_of(e).len() == 1 {
            part_open[labels[ef.edges[e][0] as usize] as usize] = true;
        }
    }
    let mut part_faces: Vec<Vec<[u32; 3]>> = vec![Vec::new(); count];
    for f in faces.iter() {
        part_faces[labels[f[0] as usize] as usize].push(*f);
    }
    let inward: Vec<usize> = (0..count)
        .filter(|&c| !part_open[c] && volume_sign(positions, &part_faces[c]) < 0.0)
        .collect();
    if !inward.is_empty() {
        let reps: Vec<u32> = inward
            .iter()
            .filter_map(|&c| labels.iter().position(|&l| l as usize == c))
            .map(|v| s.to_input[v])
            .collect();
        for f in faces.iter_mut() {
            if inward.contains(&(labels[f[0] as usize] as usize)) {
                *f = [f[0], f[2], f[1]];
            }
        }
        s.issues.push(Issue {
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

/// Pass 10b: several connected parts (vertices joined by faces; an unused kept vertex is a part of
/// its own). Kept and reported with the part sizes, largest first; refused when
/// `refuse_several_components`. Returns the number of parts.
pub fn report_components(s: &mut OutputPass, o: &RepairOptions) -> usize {
    let (labels, count) = connected_components(s.mesh.positions.len(), &s.mesh.faces);
    if count > 1 {
        let mut sorted = vec![0usize; count];
        for &l in &labels {
            sorted[l as usize] += 1;
        }
        sorted.sort_unstable_by(|a, b| b.cmp(a));
        s.issues.push(Issue {
            kind: IssueKind::SeveralComponents,
            count,
            examples: Locations::ComponentSizes(examples(&sorted)),
            action: refused_or(o.refuse_several_components, Action::Kept),
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
    count
}

/// Pass 10c: edges with one face only (holes, open borders). Informational (kept). Returns `true`
/// when there is none.
pub fn report_boundary_edges(s: &mut OutputPass) -> bool {
    let boundary: Vec<[u32; 2]> = EdgeFaces::new(&s.mesh.faces)
        .boundary_edges()
        .into_iter()
        .map(|e| s.edge_in(e))
        .collect();
    if !boundary.is_empty() {
        let n = boundary.len();
        s.issues.push(Issue {
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
    boundary.is_empty()
}

/// Pass 11: faces whose smallest corner angle is below `needle_angle_degrees`. Informational
/// (kept: they work, but remeshing gives smoother results).
pub fn report_needle_faces(s: &mut OutputPass, o: &RepairOptions) {
    let positions = &s.mesh.positions;
    let needles: Vec<u32> = s
        .mesh
        .faces
        .iter()
        .enumerate()
        .filter(|(_, f)| {
            min_angle_degrees(f.map(|v| positions[v as usize])) < o.needle_angle_degrees
        })
        .map(|(i, _)| s.kept_input[i])
        .collect();
    if !needles.is_empty() {
        let n = needles.len();
        s.issues.push(Issue {
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
}

/// Pass 12: no face left (an empty input, or every face removed by the passes before). Refused.
pub fn refuse_empty(s: &mut OutputPass) {
    if s.mesh.faces.is_empty() {
        let nf = s.input_faces;
        s.issues.push(Issue {
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
}

/// Runs the whole policy: passes 1–7, [`compact`], passes 8–12. Refusing issues are recorded and
/// the analysis continues without the offending elements so that the report is as complete as
/// possible ([`super::repair`] then refuses).
pub fn analyse(mesh: &TriMesh, o: &RepairOptions) -> Repaired {
    let mut s = InputPass::new(mesh);
    drop_nonfinite_vertices(&mut s, o); // 1
    drop_out_of_range_faces(&mut s, o); // 2
    weld_duplicate_vertices(&mut s, o); // 3
    drop_repeated_vertex_faces(&mut s, o); // 4
    drop_zero_area_faces(&mut s, o); // 5
    drop_duplicate_faces(&mut s, o); // 6
    report_unreferenced_vertices(&mut s, o); // 7
    let mut s = compact(s, o);
    report_non_manifold_edges(&mut s, o); // 8
    fix_inconsistent_orientation(&mut s, o); // 9
    orient_closed_parts_outward(&mut s, o); // 10
    let components = report_components(&mut s, o);
    let no_boundary = report_boundary_edges(&mut s);
    report_needle_faces(&mut s, o); // 11
    refuse_empty(&mut s); // 12
    let report = ValidationReport {
        input_vertices: mesh.positions.len(),
        input_faces: mesh.faces.len(),
        output_vertices: s.mesh.positions.len(),
        output_faces: s.mesh.faces.len(),
        components,
        closed: !s.mesh.faces.is_empty() && no_boundary,
        issues: s.issues,
    };
    Repaired {
        mesh: s.mesh,
        vertex_map: s.vertex_map,
        face_map: s.face_map,
        report,
    }
}

/// Each pass called alone on a small mesh built to trigger it.
#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{octahedron, tetrahedron};

    fn opts() -> RepairOptions {
        RepairOptions::default()
    }

    fn kinds(issues: &[Issue]) -> Vec<IssueKind> {
        issues.iter().map(|i| i.kind).collect()
    }

    /// Runs the input passes alone: nothing done, then `compact`.
    fn output_of(m: &TriMesh) -> OutputPass {
        compact(InputPass::new(m), &opts())
    }

    #[test]
    fn nonfinite_vertices_die_with_their_faces_and_are_refused_by_default() {
        let mut m = tetrahedron();
        m.positions[3][1] = f64::NAN;
        let mut s = InputPass::new(&m);
        drop_nonfinite_vertices(&mut s, &opts());
        assert_eq!(kinds(&s.issues), [IssueKind::NonFiniteCoordinates]);
        assert_eq!(s.issues[0].action, Action::Refused);
        assert_eq!(s.vertex_alive, [true, true, true, false]);
        assert_eq!(s.face_alive, [true, false, false, false]);
    }

    #[test]
    fn out_of_range_faces_die_and_the_message_names_the_vertex_count() {
        let mut m = tetrahedron();
        m.faces[2] = [0, 9, 2];
        let mut s = InputPass::new(&m);
        drop_out_of_range_faces(
            &mut s,
            &RepairOptions {
                drop_out_of_range_faces: true,
                ..opts()
            },
        );
        assert_eq!(s.issues[0].kind, IssueKind::IndexOutOfRange);
        assert_eq!(s.issues[0].action, Action::Repaired);
        assert!(
            s.issues[0].message.contains("only 4 vertices"),
            "{}",
            s.issues[0].message
        );
        assert_eq!(s.face_alive, [true, true, false, true]);
    }

    #[test]
    fn every_pass_alone_survives_out_of_range_faces() {
        // Each pass called on its own, without pass 2 first: no panic, and the damaged face
        // never reaches the output.
        let mut m = tetrahedron();
        m.faces[1] = [0, 9, 2];
        m.faces.push([7, 8, 9]);
        let input_passes: [fn(&mut InputPass, &RepairOptions); 6] = [
            drop_nonfinite_vertices,
            weld_duplicate_vertices,
            drop_repeated_vertex_faces,
            drop_zero_area_faces,
            drop_duplicate_faces,
            report_unreferenced_vertices,
        ];
        for pass in input_passes {
            let mut s = InputPass::new(&m);
            pass(&mut s, &opts());
            let out = compact(s, &opts());
            assert!(
                out.mesh
                    .faces
                    .iter()
                    .flatten()
                    .all(|&v| (v as usize) < out.mesh.positions.len())
            );
            assert_eq!(out.face_map[1], None);
            assert_eq!(out.face_map[4], None);
        }
        assert!(!InputPass::new(&m).face_alive[1]);
    }

    #[test]
    fn touching_closed_vertices_are_kept_apart_unless_asked() {
        // Two tetrahedra sharing a corner position: both copies are used on closed surfaces.
        let mut m = tetrahedron();
        let mut t = tetrahedron();
        for p in &mut t.positions {
            *p = [-p[0], -p[1], -p[2]];
        }
        m.positions.extend(&t.positions);
        m.faces
            .extend(t.faces.iter().map(|f| [f[0] + 4, f[2] + 4, f[1] + 4]));
        let mut s = InputPass::new(&m);
        weld_duplicate_vertices(&mut s, &opts());
        assert_eq!(kinds(&s.issues), [IssueKind::TouchingVertices]);
        assert_eq!(s.rep[4], 4);
        let mut s = InputPass::new(&m);
        weld_duplicate_vertices(
            &mut s,
            &RepairOptions {
                weld_touching_vertices: true,
                ..opts()
            },
        );
        assert_eq!(kinds(&s.issues), [IssueKind::DuplicateVertices]);
        assert_eq!(s.rep[4], 0);
    }

    #[test]
    fn repeated_vertex_faces_are_dropped_and_say_after_welding_only_when_welded() {
        let mut m = tetrahedron();
        m.faces.push([0, 1, 1]);
        let mut s = InputPass::new(&m);
        drop_repeated_vertex_faces(&mut s, &opts());
        assert_eq!(kinds(&s.issues), [IssueKind::RepeatedVertexInFace]);
        assert!(!s.issues[0].message.contains("after welding"));
        assert!(!s.face_alive[4]);
        // Face [0, 1, 4] with vertex 4 welded onto 1.
        let mut m = tetrahedron();
        m.positions.push(m.positions[1]);
        m.faces.push([0, 1, 4]);
        let mut s = InputPass::new(&m);
        s.rep[4] = 1;
        drop_repeated_vertex_faces(&mut s, &opts());
        assert!(
            s.issues[0].message.contains("after welding"),
            "{}",
            s.issues[0].message
        );
    }

    #[test]
    fn zero_area_faces_are_kept_when_degenerate_dropping_is_off() {
        let mut m = tetrahedron();
        m.positions.push([0.5, 0.0, 0.0]); // on the edge 0–1
        m.faces.push([0, 1, 4]);
        let mut s = InputPass::new(&m);
        drop_zero_area_faces(
            &mut s,
            &RepairOptions {
                drop_degenerate_faces: false,
                ..opts()
            },
        );
        assert_eq!(kinds(&s.issues), [IssueKind::ZeroAreaFaces]);
        assert_eq!(s.issues[0].action, Action::Kept);
        assert!(s.face_alive[4]);
        let mut s = InputPass::new(&m);
        drop_zero_area_faces(&mut s, &opts());
        assert!(!s.face_alive[4]);
    }

    #[test]
    fn duplicate_faces_keep_the_first_in_any_vertex_order() {
        let mut m = tetrahedron();
        m.faces.push([2, 1, 0]);
        let mut s = InputPass::new(&m);
        drop_duplicate_faces(&mut s, &opts());
        assert_eq!(kinds(&s.issues), [IssueKind::DuplicateFaces]);
        assert_eq!(s.issues[0].examples, Locations::Faces(vec![4]));
        assert_eq!(s.face_alive, [true, true, true, true, false]);
    }

    #[test]
    fn unreferenced_vertices_are_reported_and_compact_drops_them() {
        let mut m = tetrahedron();
        m.positions.insert(0, [5.0, 5.0, 5.0]);
        for f in &mut m.faces {
            *f = f.map(|v| v + 1);
        }
        let mut s = InputPass::new(&m);
        report_unreferenced_vertices(&mut s, &opts());
        assert_eq!(s.issues[0].examples, Locations::Vertices(vec![0]));
        let out = compact(s, &opts());
        assert_eq!(out.mesh, tetrahedron());
        assert_eq!(out.vertex_map, [None, Some(0), Some(1), Some(2), Some(3)]);
        assert_eq!(out.to_input, [1, 2, 3, 4]);
        assert_eq!(out.kept_input, [0, 1, 2, 3]);
        assert_eq!(kinds(&out.issues), [IssueKind::UnreferencedVertices]);
    }

    #[test]
    fn compact_welds_corners_and_maps_welded_vertices_to_their_target() {
        let mut m = tetrahedron();
        m.positions.push(m.positions[3]);
        m.faces[3] = [1, 2, 4];
        let mut s = InputPass::new(&m);
        s.rep[4] = 3;
        s.face_alive[0] = false;
        let out = compact(s, &opts());
        assert_eq!(out.mesh.positions.len(), 4);
        assert_eq!(out.mesh.faces[2], [1, 2, 3]);
        assert_eq!(out.vertex_map[4], Some(3));
        assert_eq!(out.face_map, [None, Some(0), Some(1), Some(2)]);
        assert!(out.issues.is_empty());
    }

    #[test]
    fn a_fin_is_a_non_manifold_edge_refused_on_request() {
        let mut m = tetrahedron();
        m.positions.push([1.0, 1.0, -1.0]);
        m.faces.push([0, 1, 4]);
        let mut s = output_of(&m);
        report_non_manifold_edges(
            &mut s,
            &RepairOptions {
                refuse_non_manifold: true,
                ..opts()
            },
        );
        assert_eq!(kinds(&s.issues), [IssueKind::NonManifoldEdges]);
        assert_eq!(s.issues[0].action, Action::Refused);
    }

    #[test]
    fn one_flipped_face_is_flipped_back() {
        let mut m = octahedron();
        m.faces[5] = [m.faces[5][0], m.faces[5][2], m.faces[5][1]];
        let mut s = output_of(&m);
        fix_inconsistent_orientation(&mut s, &opts());
        assert_eq!(kinds(&s.issues), [IssueKind::InconsistentOrientation]);
        assert!(
            s.issues[0].message.contains("face 5"),
            "{}",
            s.issues[0].message
        );
        assert_eq!(s.mesh, octahedron());
    }

    #[test]
    fn an_inside_out_closed_part_is_flipped_only_with_fix_orientation() {
        let mut m = octahedron();
        for f in &mut m.faces {
            *f = [f[0], f[2], f[1]];
        }
        let mut s = output_of(&m);
        orient_closed_parts_outward(
            &mut s,
            &RepairOptions {
                fix_orientation: false,
                ..opts()
            },
        );
        assert!(s.issues.is_empty());
        orient_closed_parts_outward(&mut s, &opts());
        assert_eq!(kinds(&s.issues), [IssueKind::InwardFacing]);
        assert_eq!(s.mesh, octahedron());
    }

    #[test]
    fn components_are_counted_and_sized_largest_first() {
        let mut m = tetrahedron();
        let o = octahedron();
        m.positions
            .extend(o.positions.iter().map(|p| p.map(|c| c + 5.0)));
        m.faces.extend(o.faces.iter().map(|f| f.map(|v| v + 4)));
        let mut s = output_of(&m);
        assert_eq!(report_components(&mut s, &opts()), 2);
        assert_eq!(s.issues[0].examples, Locations::ComponentSizes(vec![6, 4]));
        let mut s = output_of(&tetrahedron());
        assert_eq!(report_components(&mut s, &opts()), 1);
        assert!(s.issues.is_empty());
    }

    #[test]
    fn boundary_edges_of_an_open_surface_are_reported() {
        let mut m = tetrahedron();
        m.faces.pop();
        let mut s = output_of(&m);
        assert!(!report_boundary_edges(&mut s));
        assert_eq!(kinds(&s.issues), [IssueKind::BoundaryEdges]);
        assert_eq!(s.issues[0].count, 3);
        let mut s = output_of(&tetrahedron());
        assert!(report_boundary_edges(&mut s));
        assert!(s.issues.is_empty());
    }

    #[test]
    fn needle_faces_name_the_input_face() {
        let mut m = tetrahedron();
        m.positions.push([0.5, 1e-3, 0.0]);
        m.faces.insert(0, [0, 1, 4]); // a corner of about 0.11° at vertex 0
        let mut s = output_of(&m);
        report_needle_faces(&mut s, &opts());
        assert_eq!(kinds(&s.issues), [IssueKind::NeedleFaces]);
        assert_eq!(s.issues[0].examples, Locations::Faces(vec![0]));
    }

    #[test]
    fn an_empty_result_is_refused_with_the_input_face_count() {
        let mut s = output_of(&TriMesh::default());
        refuse_empty(&mut s);
        assert_eq!(s.issues[0].message, "the mesh has no triangles");
        let tet = tetrahedron();
        let mut s = InputPass::new(&tet);
        s.face_alive = vec![false; 4];
        let mut s = compact(s, &opts());
        refuse_empty(&mut s);
        assert_eq!(s.issues[0].action, Action::Refused);
        assert!(s.issues[0].message.contains("none of the 4 faces"));
    }
}
