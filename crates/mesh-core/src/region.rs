//! Regions of a mesh: which vertices a localized stylization may rotate (geometry only, no I/O).
//!
//! A region is a union of [`RegionSpec`]s, each written as a short string:
//!
//! | spec | selects |
//! |---|---|
//! | `box:x0,y0,z0,x1,y1,z1` | vertices inside the axis-aligned box (bounds included), **normalized side-2 frame** |
//! | `sphere:cx,cy,cz,r` | vertices with `|p − c| ≤ r`, normalized side-2 frame |
//! | `vertices:FILE` | the vertex indices listed in FILE (one 0-based index per line, `#` comments) |
//! | `part:NAME` | the faces of a named part of the input file (OBJ `o`/`g` group, `usemtl` material, glTF node or mesh) |
//! | `property:NAME OP VALUE` | a PLY per-vertex or per-face scalar property compared with VALUE (`==`, `!=`, `<`, `<=`, `>`, `>=`) |
//! | `not:SPEC` | the complement of SPEC |
//!
//! The **normalized side-2 frame** is the one every computation uses ([`crate::normalize::side2_cube`]):
//! the input's bounding box is centred at the origin and its longest side spans exactly `[−1, 1]`,
//! so `box:-1,-1,-1,0,1,1` is the half of the mesh with `x ≤ 0` (the other axes scaled by the same
//! factor, so they span at most `[−1, 1]`).
//!
//! **Faces to vertices.** A face-based selection (named parts, per-face properties) selects a
//! vertex when **any** of its faces is selected: every corner of a selected face may rotate, so
//! the selected faces deform as a whole and the boundary ring of the part is included.
//!
//! **Numbering.** Vertex files, named parts and properties refer to the **input file's** vertex and
//! face order (what a modelling tool shows). Repair may weld, drop or reorder vertices and faces
//! ([`crate::validate::Repaired`]); [`RegionInput`] carries its maps and a selection follows them:
//! a repaired vertex is selected when any input vertex merged into it is, a dropped vertex or face
//! drops out of the selection. Box and sphere specs are evaluated on the repaired, normalized
//! positions.
//!
//! **Feathering.** [`feather_weights`] turns a selection into per-vertex weights in `[0, 1]` that
//! ramp up over `K` rings *inside* the region (weight 0 outside): see its docs and `docs/method.md`.

use std::collections::VecDeque;
use std::fmt;
use std::path::PathBuf;

/// Errors of region parsing and selection; messages name the spec at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegionError {
    /// The spec string does not follow the grammar.
    #[error("region `{spec}`: {message}")]
    Parse {
        /// The spec as written.
        spec: String,
        /// What was expected.
        message: String,
    },
    /// A spec refers to something the mesh does not offer (a part name, a property, an index).
    #[error("region `{spec}`: {message}")]
    NotFound {
        /// The spec as written.
        spec: String,
        /// What is missing and what is available.
        message: String,
    },
    /// The union selects no vertex at all: a localized run would change nothing.
    #[error(
        "the region {specs} selects no vertex of the mesh (boxes and spheres are in the normalized side-2 frame: the mesh spans [-1, 1] along its longest side)"
    )]
    Empty {
        /// The specs, joined.
        specs: String,
    },
    /// A vertex-file spec reached selection without its indices being read.
    #[error(
        "region `{spec}`: the vertex file was not read (resolve it with RegionSpec::with_indices)"
    )]
    UnresolvedFile {
        /// The spec as written.
        spec: String,
    },
}

/// A comparison of a scalar property with a value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Comparison {
    /// `==`
    Eq,
    /// `!=`
    Ne,
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
}

impl Comparison {
    /// `lhs OP rhs`.
    pub fn holds(self, lhs: f64, rhs: f64) -> bool {
        match self {
            Comparison::Eq => lhs == rhs,
            Comparison::Ne => lhs != rhs,
            Comparison::Lt => lhs < rhs,
            Comparison::Le => lhs <= rhs,
            Comparison::Gt => lhs > rhs,
            Comparison::Ge => lhs >= rhs,
        }
    }

    fn symbol(self) -> &'static str {
        match self {
            Comparison::Eq => "==",
            Comparison::Ne => "!=",
            Comparison::Lt => "<",
            Comparison::Le => "<=",
            Comparison::Gt => ">",
            Comparison::Ge => ">=",
        }
    }
}

/// One region spec (see the module docs for the grammar).
#[derive(Clone, Debug, PartialEq)]
pub enum RegionSpec {
    /// Axis-aligned box `[lo, hi]` (bounds included) in the normalized side-2 frame.
    Box {
        /// Lower corner.
        lo: [f64; 3],
        /// Upper corner.
        hi: [f64; 3],
    },
    /// Ball `|p − centre| ≤ radius` in the normalized side-2 frame.
    Sphere {
        /// Centre.
        centre: [f64; 3],
        /// Radius (> 0).
        radius: f64,
    },
    /// A file of vertex indices, not read yet.
    VertexFile(PathBuf),
    /// Vertex indices (input numbering), e.g. a [`RegionSpec::VertexFile`] once read.
    Vertices {
        /// Where they came from (for messages and records).
        source: String,
        /// 0-based indices.
        indices: Vec<usize>,
    },
    /// A named part of the input file.
    Part(String),
    /// A scalar property compared with a value.
    Property {
        /// Property name.
        name: String,
        /// Comparison.
        op: Comparison,
        /// Right-hand side.
        value: f64,
    },
    /// The complement of a spec.
    Not(Box<RegionSpec>),
}

/// `spec` as an error quotes it: at most 200 characters, then `…`.
fn abbreviated(spec: &str) -> String {
    match spec.char_indices().nth(200) {
        Some((at, _)) => format!("{}…", &spec[..at]),
        None => spec.to_string(),
    }
}

/// The most `not:` a spec may nest ([`RegionSpec::parse`] refuses more).
pub const MAX_NOT_DEPTH: usize = 64;

fn fmt_num(x: f64) -> String {
    format!("{x}")
}

impl fmt::Display for RegionSpec {
    /// The canonical spec string (parses back to the same spec; a resolved vertex list prints as
    /// its source).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RegionSpec::Box { lo, hi } => {
                let v: Vec<String> = lo.iter().chain(hi).map(|&x| fmt_num(x)).collect();
                write!(f, "box:{}", v.join(","))
            }
            RegionSpec::Sphere { centre, radius } => {
                let v: Vec<String> = centre
                    .iter()
                    .chain(std::iter::once(radius))
                    .map(|&x| fmt_num(x))
                    .collect();
                write!(f, "sphere:{}", v.join(","))
            }
            RegionSpec::VertexFile(p) => write!(f, "vertices:{}", p.display()),
            RegionSpec::Vertices { source, .. } => write!(f, "vertices:{source}"),
            RegionSpec::Part(name) => write!(f, "part:{name}"),
            RegionSpec::Property { name, op, value } => {
                write!(f, "property:{name}{}{}", op.symbol(), fmt_num(*value))
            }
            RegionSpec::Not(inner) => write!(f, "not:{inner}"),
        }
    }
}

fn parse_numbers(
    spec: &str,
    body: &str,
    count: usize,
    what: &str,
) -> Result<Vec<f64>, RegionError> {
    let parts: Vec<&str> = body.split(',').map(str::trim).collect();
    if parts.len() != count {
        return Err(RegionError::Parse {
            spec: spec.to_string(),
            message: format!(
                "{what} needs {count} comma-separated numbers, found {}",
                parts.len()
            ),
        });
    }
    parts
        .iter()
        .map(|t| {
            t.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| RegionError::Parse {
                    spec: spec.to_string(),
                    message: format!("`{t}` is not a finite number"),
                })
        })
        .collect()
}

impl RegionSpec {
    /// Parses one spec (see the module docs). Whitespace around the spec is ignored.
    pub fn parse(spec: &str) -> Result<RegionSpec, RegionError> {
        let s = spec.trim();
        let err = |message: String| RegionError::Parse {
            spec: abbreviated(spec),
            message,
        };
        let (kind, body) = s.split_once(':').ok_or_else(|| {
            err(
                "expected KIND:…, with KIND one of box, sphere, vertices, part, property, not"
                    .into(),
            )
        })?;
        match kind.trim() {
            "not" => {
                // Counted in a loop, not by recursion: a spec of 15,000 `not:` must not overflow
                // the stack here, nor in what walks the nested specs later (drop included).
                let mut depth = 1usize;
                let mut rest = body;
                while let Some((k, b)) = rest.trim_start().split_once(':')
                    && k.trim() == "not"
                {
                    depth += 1;
                    if depth > MAX_NOT_DEPTH {
                        return Err(err(format!(
                            "more than {MAX_NOT_DEPTH} nested `not:` (two cancel out: write \
                             `not:` once or not at all)"
                        )));
                    }
                    rest = b;
                }
                let mut spec = RegionSpec::parse(rest).map_err(|e| match e {
                    RegionError::Parse { message, .. } => err(message),
                    other => other,
                })?;
                for _ in 0..depth {
                    spec = RegionSpec::Not(Box::new(spec));
                }
                Ok(spec)
            }
            "box" => {
                let v = parse_numbers(spec, body, 6, "a box")?;
                let lo = [v[0], v[1], v[2]];
                let hi = [v[3], v[4], v[5]];
                if (0..3).any(|k| lo[k] > hi[k]) {
                    return Err(err(format!(
                        "the first corner must be ≤ the second on every axis (got {lo:?} and {hi:?})"
                    )));
                }
                Ok(RegionSpec::Box { lo, hi })
            }
            "sphere" => {
                let v = parse_numbers(spec, body, 4, "a sphere")?;
                if v[3] <= 0.0 {
                    return Err(err(format!("the radius must be positive, got {}", v[3])));
                }
                Ok(RegionSpec::Sphere {
                    centre: [v[0], v[1], v[2]],
                    radius: v[3],
                })
            }
            "vertices" => {
                let path = body.trim();
                if path.is_empty() {
                    return Err(err("vertices: needs a file name".into()));
                }
                Ok(RegionSpec::VertexFile(PathBuf::from(path)))
            }
            "part" => {
                let name = body.trim();
                if name.is_empty() {
                    return Err(err(
                        "part: needs a part name (see `stylize mesh check --regions FILE`)".into(),
                    ));
                }
                Ok(RegionSpec::Part(name.to_string()))
            }
            "property" => {
                // Longest operators first so that `<=` is not read as `<`.
                for (sym, op) in [
                    ("==", Comparison::Eq),
                    ("!=", Comparison::Ne),
                    ("<=", Comparison::Le),
                    (">=", Comparison::Ge),
                    ("<", Comparison::Lt),
                    (">", Comparison::Gt),
                    ("=", Comparison::Eq),
                ] {
                    if let Some((name, value)) = body.split_once(sym) {
                        let name = name.trim();
                        let value = value.trim();
                        if name.is_empty() {
                            return Err(err(
                                "property: needs a property name before the operator".into()
                            ));
                        }
                        let value = value
                            .parse::<f64>()
                            .ok()
                            .filter(|x| !x.is_nan())
                            .ok_or_else(|| err(format!("`{value}` is not a number")))?;
                        return Ok(RegionSpec::Property {
                            name: name.to_string(),
                            op,
                            value,
                        });
                    }
                }
                Err(err(
                    "property: needs NAME OP VALUE with OP one of ==, !=, <, <=, >, >= (e.g. `property:label == 3`)"
                        .into(),
                ))
            }
            other => Err(err(format!(
                "unknown region kind `{other}` (expected box, sphere, vertices, part, property or not)"
            ))),
        }
    }

    /// Replaces every [`RegionSpec::VertexFile`] (also under `not:`) by the indices `read` returns
    /// for its path.
    pub fn with_indices<E>(
        self,
        read: &mut impl FnMut(&std::path::Path) -> Result<Vec<usize>, E>,
    ) -> Result<RegionSpec, E> {
        Ok(match self {
            RegionSpec::VertexFile(p) => RegionSpec::Vertices {
                source: p.display().to_string(),
                indices: read(&p)?,
            },
            RegionSpec::Not(inner) => RegionSpec::Not(Box::new(inner.with_indices(read)?)),
            other => other,
        })
    }

    /// The vertex files this spec names (for input bookkeeping).
    pub fn files(&self) -> Vec<PathBuf> {
        match self {
            RegionSpec::VertexFile(p) => vec![p.clone()],
            RegionSpec::Not(inner) => inner.files(),
            _ => Vec::new(),
        }
    }
}

/// Parses the text of a vertex-index file: one 0-based index per line; blank lines and lines
/// starting with `#` are ignored. Errors name the line.
pub fn parse_index_list(text: &str) -> Result<Vec<usize>, String> {
    let mut out = Vec::new();
    // A leading UTF-8 byte-order mark (Windows editors) is not part of the first index.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    for (lineno, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let v: usize = line
            .parse()
            .map_err(|_| format!("line {}: `{line}` is not a vertex index", lineno + 1))?;
        out.push(v);
    }
    Ok(out)
}

/// What kind of named part.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PartKind {
    /// OBJ `o` object.
    Object,
    /// OBJ `g` group.
    Group,
    /// OBJ `usemtl` material.
    Material,
    /// glTF node.
    Node,
    /// glTF mesh.
    Mesh,
}

impl PartKind {
    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            PartKind::Object => "object",
            PartKind::Group => "group",
            PartKind::Material => "material",
            PartKind::Node => "node",
            PartKind::Mesh => "mesh",
        }
    }
}

/// A named set of faces of the input file (triangulated face indices in file order).
#[derive(Clone, Debug, PartialEq)]
pub struct NamedPart {
    /// What the file calls it.
    pub kind: PartKind,
    /// Its name.
    pub name: String,
    /// Triangle indices (file order, after fan triangulation).
    pub faces: Vec<u32>,
}

/// A scalar per-vertex or per-face property (values in file order).
#[derive(Clone, Debug, PartialEq)]
pub struct ScalarProperty {
    /// Property name as in the file.
    pub name: String,
    /// One value per element.
    pub values: Vec<f64>,
}

/// The parts a mesh file offers, beside its [`crate::TriMesh`], in the file's numbering.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Parts {
    /// Named face sets (OBJ groups/objects/materials, glTF nodes/meshes).
    pub named: Vec<NamedPart>,
    /// Per-vertex scalar properties (PLY).
    pub vertex_properties: Vec<ScalarProperty>,
    /// Per-face scalar properties (PLY), one value per **triangle** (a polygon's value is repeated
    /// on each of its fan triangles).
    pub face_properties: Vec<ScalarProperty>,
}

impl Parts {
    /// Whether the file offers nothing.
    pub fn is_empty(&self) -> bool {
        self.named.is_empty()
            && self.vertex_properties.is_empty()
            && self.face_properties.is_empty()
    }

    /// The names on offer, for messages.
    fn offered(&self) -> String {
        let mut names: Vec<String> = self
            .named
            .iter()
            .map(|p| format!("{} `{}`", p.kind.name(), p.name))
            .collect();
        names.extend(
            self.vertex_properties
                .iter()
                .map(|p| format!("vertex property `{}`", p.name)),
        );
        names.extend(
            self.face_properties
                .iter()
                .map(|p| format!("face property `{}`", p.name)),
        );
        if names.is_empty() {
            "the file offers no named parts or properties".into()
        } else {
            format!("the file offers {}", names.join(", "))
        }
    }
}

/// Everything a selection is evaluated against: the repaired mesh (positions in the normalized
/// side-2 frame) and the maps from the input file's numbering to it.
#[derive(Clone, Copy, Debug)]
pub struct RegionInput<'a> {
    /// Repaired, normalized positions.
    pub positions: &'a [[f64; 3]],
    /// Repaired faces.
    pub faces: &'a [[u32; 3]],
    /// Input vertex → repaired vertex (`None`: dropped). Empty: the identity (a mesh that was
    /// not repaired, [`RegionInput::unrepaired`]).
    pub vertex_map: &'a [Option<u32>],
    /// Input triangle → repaired face (`None`: dropped). Empty: the identity.
    pub face_map: &'a [Option<u32>],
    /// Parts of the input file.
    pub parts: &'a Parts,
}

impl<'a> RegionInput<'a> {
    /// A mesh used as it is (no repair: both maps the identity), e.g. the rest mesh of a saved
    /// deformation.
    pub fn unrepaired(positions: &'a [[f64; 3]], faces: &'a [[u32; 3]], parts: &'a Parts) -> Self {
        Self {
            positions,
            faces,
            vertex_map: &[],
            face_map: &[],
            parts,
        }
    }

    /// Vertices of the input file (before repair).
    fn input_vertices(&self) -> usize {
        if self.vertex_map.is_empty() {
            self.positions.len()
        } else {
            self.vertex_map.len()
        }
    }

    /// The repaired vertex of input vertex `i`: `None` when `i` is out of range, `Some(None)` when
    /// the repair dropped it.
    fn repaired_vertex(&self, i: usize) -> Option<Option<u32>> {
        if self.vertex_map.is_empty() {
            (i < self.positions.len()).then(|| u32::try_from(i).ok())
        } else {
            self.vertex_map.get(i).copied()
        }
    }

    /// The repaired face of input triangle `f` (`None`: dropped or out of range).
    fn repaired_face(&self, f: usize) -> Option<u32> {
        if self.face_map.is_empty() {
            (f < self.faces.len())
                .then(|| u32::try_from(f).ok())
                .flatten()
        } else {
            self.face_map.get(f).copied().flatten()
        }
    }
}

/// A resolved region: `free[v]` for each vertex of the repaired mesh, and notes for the user.
#[derive(Clone, Debug, PartialEq)]
pub struct Region {
    /// Vertices that may rotate.
    pub free: Vec<bool>,
    /// Warnings (a spec that selects nothing, a region that covers the whole mesh).
    pub warnings: Vec<String>,
}

impl Region {
    /// Number of selected vertices.
    pub fn count(&self) -> usize {
        self.free.iter().filter(|&&f| f).count()
    }

    /// Whether every vertex is selected (the run is not localized at all).
    pub fn is_everything(&self) -> bool {
        self.free.iter().all(|&f| f)
    }
}

/// Vertices (repaired numbering) of the selected input faces, by the "any face" rule.
fn vertices_of_faces(
    input: &RegionInput<'_>,
    selected_faces: impl Iterator<Item = usize>,
) -> Vec<bool> {
    let mut out = vec![false; input.positions.len()];
    for f in selected_faces {
        if let Some(g) = input.repaired_face(f)
            && let Some(face) = input.faces.get(g as usize)
        {
            for &v in face {
                if let Some(slot) = out.get_mut(v as usize) {
                    *slot = true;
                }
            }
        }
    }
    out
}

/// Selection of one spec on the repaired mesh.
fn select_one(spec: &RegionSpec, input: &RegionInput<'_>) -> Result<Vec<bool>, RegionError> {
    let n = input.positions.len();
    let label = spec.to_string();
    Ok(match spec {
        RegionSpec::Box { lo, hi } => input
            .positions
            .iter()
            .map(|p| (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]))
            .collect(),
        RegionSpec::Sphere { centre, radius } => input
            .positions
            .iter()
            .map(|p| {
                let d2: f64 = (0..3).map(|k| (p[k] - centre[k]).powi(2)).sum();
                d2 <= radius * radius
            })
            .collect(),
        RegionSpec::VertexFile(_) => return Err(RegionError::UnresolvedFile { spec: label }),
        RegionSpec::Vertices { indices, .. } => {
            let mut out = vec![false; n];
            for &i in indices {
                let mapped = input
                    .repaired_vertex(i)
                    .ok_or_else(|| RegionError::NotFound {
                        spec: label.clone(),
                        message: format!(
                            "vertex {i} is out of range (the file has {} vertices)",
                            input.input_vertices()
                        ),
                    })?;
                if let Some(m) = mapped
                    && let Some(slot) = out.get_mut(m as usize)
                {
                    *slot = true;
                }
            }
            out
        }
        RegionSpec::Part(name) => {
            let matching: Vec<&NamedPart> = input
                .parts
                .named
                .iter()
                .filter(|p| &p.name == name)
                .collect();
            if matching.is_empty() {
                return Err(RegionError::NotFound {
                    spec: label,
                    message: format!("no part named `{name}`: {}", input.parts.offered()),
                });
            }
            vertices_of_faces(
                input,
                matching
                    .iter()
                    .flat_map(|p| p.faces.iter().map(|&f| f as usize)),
            )
        }
        RegionSpec::Property { name, op, value } => {
            if let Some(p) = input
                .parts
                .vertex_properties
                .iter()
                .find(|p| &p.name == name)
            {
                let mut out = vec![false; n];
                for (i, &x) in p.values.iter().enumerate() {
                    if op.holds(x, *value)
                        && let Some(Some(m)) = input.repaired_vertex(i)
                        && let Some(slot) = out.get_mut(m as usize)
                    {
                        *slot = true;
                    }
                }
                out
            } else if let Some(p) = input.parts.face_properties.iter().find(|p| &p.name == name) {
                vertices_of_faces(
                    input,
                    p.values
                        .iter()
                        .enumerate()
                        .filter(|(_, x)| op.holds(**x, *value))
                        .map(|(i, _)| i),
                )
            } else {
                return Err(RegionError::NotFound {
                    spec: label,
                    message: format!("no property named `{name}`: {}", input.parts.offered()),
                });
            }
        }
        RegionSpec::Not(inner) => select_one(inner, input)?.iter().map(|&b| !b).collect(),
    })
}

/// The vertices one spec selects on the repaired mesh (no emptiness check; see [`select`]).
pub fn select_vertices(
    spec: &RegionSpec,
    input: &RegionInput<'_>,
) -> Result<Vec<bool>, RegionError> {
    select_one(spec, input)
}

/// The union of `specs` on the repaired mesh.
///
/// Errors: a spec that does not parse or names a missing part/property/vertex, or a union that
/// selects **no** vertex ([`RegionError::Empty`]). A spec that selects nothing by itself and a
/// union that selects **every** vertex (nothing stays fixed) are returned as warnings.
pub fn select(specs: &[RegionSpec], input: &RegionInput<'_>) -> Result<Region, RegionError> {
    let mut free = vec![false; input.positions.len()];
    let mut warnings = Vec::new();
    for spec in specs {
        let one = select_one(spec, input)?;
        if !one.iter().any(|&b| b) {
            warnings.push(format!("region `{spec}` selects no vertex"));
        }
        for (f, s) in free.iter_mut().zip(one) {
            *f |= s;
        }
    }
    let joined = || {
        specs
            .iter()
            .map(|s| format!("`{s}`"))
            .collect::<Vec<_>>()
            .join(" ∪ ")
    };
    if !free.iter().any(|&b| b) {
        return Err(RegionError::Empty { specs: joined() });
    }
    if free.iter().all(|&b| b) {
        warnings.push(format!(
            "the region {} covers every vertex: the run is not localized",
            joined()
        ));
    }
    Ok(Region { free, warnings })
}

/// Per-vertex rotation weights for a feathered region.
///
/// `d_v` is the number of edges from `v` to the nearest vertex **outside** the region (0 outside,
/// 1 on the region's boundary ring, …); the weight is `w_v = min(1, d_v / (rings + 1))`. So
/// `rings = 0` gives the hard mask (1 inside, 0 outside) and `rings = K` ramps `1/(K+1), 2/(K+1), …`
/// over the first `K` rings inside the region. Weights are 0 everywhere outside: feathering never
/// lets a vertex outside the region rotate. Vertices of a connected part with no outside vertex
/// get weight 1.
///
/// # Panics
/// If `free.len()` differs from the number of vertices the faces need (a programming error).
pub fn feather_weights(free: &[bool], faces: &[[u32; 3]], rings: usize) -> Vec<f64> {
    let n = free.len();
    let mut adjacency: Vec<Vec<u32>> = vec![Vec::new(); n];
    for f in faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            if a != b && (a as usize) < n && (b as usize) < n {
                adjacency[a as usize].push(b);
                adjacency[b as usize].push(a);
            }
        }
    }
    let mut distance = vec![usize::MAX; n];
    let mut queue = VecDeque::new();
    for (v, &f) in free.iter().enumerate() {
        if !f {
            distance[v] = 0;
            queue.push_back(v);
        }
    }
    while let Some(v) = queue.pop_front() {
        let d = distance[v];
        if d > rings {
            continue;
        }
        for &u in &adjacency[v] {
            let u = u as usize;
            if distance[u] == usize::MAX {
                distance[u] = d + 1;
                queue.push_back(u);
            }
        }
    }
    let denominator = (rings + 1) as f64;
    distance
        .iter()
        .map(|&d| {
            if d == usize::MAX {
                1.0
            } else {
                (d as f64 / denominator).min(1.0)
            }
        })
        .collect()
}

/// Vertices of the region's boundary: selected vertices with a neighbour outside (ring 1).
pub fn boundary_vertices(free: &[bool], faces: &[[u32; 3]]) -> Vec<usize> {
    let w = feather_weights(free, faces, 0);
    let mut on = vec![false; free.len()];
    for f in faces {
        let inside = f
            .iter()
            .filter(|&&v| w.get(v as usize).is_some_and(|&x| x > 0.0))
            .count();
        if inside > 0 && inside < 3 {
            for &v in f {
                if free.get(v as usize).copied().unwrap_or(false) {
                    on[v as usize] = true;
                }
            }
        }
    }
    (0..free.len()).filter(|&v| on[v]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn identity_maps(nv: usize, nf: usize) -> (Vec<Option<u32>>, Vec<Option<u32>>) {
        (
            (0..nv as u32).map(Some).collect(),
            (0..nf as u32).map(Some).collect(),
        )
    }

    /// A strip of 4 quads along x: vertices (i, 0) and (i, 1) for i = 0..=4, x in [-1, 1].
    fn strip() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        for i in 0..=4 {
            let x = -1.0 + 0.5 * i as f64;
            p.push([x, 0.0, 0.0]);
            p.push([x, 0.5, 0.0]);
        }
        let mut f = Vec::new();
        for i in 0..4u32 {
            let (a, b, c, d) = (2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1);
            f.push([a, b, c]);
            f.push([a, c, d]);
        }
        (p, f)
    }

    #[test]
    fn parse_round_trips_every_kind() {
        for s in [
            "box:-1,-1,-1,0,1,1",
            "sphere:0,0.5,0,0.25",
            "vertices:head.txt",
            "part:seat",
            "property:label==3",
            "property:quality>0.5",
            "property:q<=-1",
            "not:box:0,0,0,1,1,1",
            "not:not:part:legs",
        ] {
            let spec = RegionSpec::parse(s).expect("ok");
            assert_eq!(spec.to_string(), s);
            assert_eq!(RegionSpec::parse(&spec.to_string()).expect("ok"), spec);
        }
        assert_eq!(
            RegionSpec::parse("property: label == 3").expect("ok"),
            RegionSpec::Property {
                name: "label".into(),
                op: Comparison::Eq,
                value: 3.0
            }
        );
    }

    #[test]
    fn deeply_nested_not_is_refused_without_recursion() {
        let ok = format!("{}part:legs", "not:".repeat(MAX_NOT_DEPTH));
        let spec = RegionSpec::parse(&ok).expect("the deepest allowed nesting parses");
        assert_eq!(spec.to_string(), ok);
        // 15,000 levels used to overflow the stack: now a parse error, found in a loop.
        for n in [MAX_NOT_DEPTH + 1, 15_000, 1_000_000] {
            let deep = format!("{}box:0,0,0,1,1,1", " not :".repeat(n));
            let e = RegionSpec::parse(&deep).expect_err("too deep");
            assert!(e.to_string().contains("nested `not:`"), "{n}: {e}");
            assert!(
                e.to_string().len() < 400,
                "the message quotes an abbreviated spec"
            );
        }
    }

    #[test]
    fn parse_errors_name_the_spec_and_the_problem() {
        for (s, needle) in [
            ("cube", "expected KIND"),
            ("box:1,2,3", "6 comma-separated"),
            ("box:0,0,0,-1,1,1", "≤ the second"),
            ("box:0,0,0,nan,1,1", "not a finite number"),
            ("sphere:0,0,0,0", "radius must be positive"),
            ("sphere:0,0,0,x", "`x` is not a finite number"),
            ("part:", "needs a part name"),
            ("property:label", "NAME OP VALUE"),
            ("property:==3", "property name"),
            ("property:label==three", "`three` is not a number"),
            ("ellipsoid:1", "unknown region kind `ellipsoid`"),
            ("not:box:1", "6 comma-separated"),
        ] {
            let e = RegionSpec::parse(s).expect_err("an error").to_string();
            assert!(e.contains(s.trim()) && e.contains(needle), "{s}: {e}");
        }
    }

    #[test]
    fn box_sphere_not_and_union_select_the_right_vertices() {
        let (p, f) = strip();
        let parts = Parts::default();
        let input = RegionInput::unrepaired(&p, &f, &parts);
        let left = RegionSpec::parse("box:-1,-1,-1,-0.5,1,1").expect("ok");
        let r = select(std::slice::from_ref(&left), &input).expect("ok");
        assert_eq!(
            r.free,
            [
                true, true, true, true, false, false, false, false, false, false
            ]
        );
        let not_left = RegionSpec::Not(Box::new(left.clone()));
        let r = select(std::slice::from_ref(&not_left), &input).expect("ok");
        assert_eq!(r.count(), 6);
        let r = select(&[left, not_left], &input).expect("ok");
        assert!(r.is_everything());
        assert!(r.warnings.iter().any(|w| w.contains("covers every vertex")));
        let ball = RegionSpec::parse("sphere:1,0,0,0.1").expect("ok");
        let r = select(&[ball], &input).expect("ok");
        assert_eq!(r.count(), 1);
        assert!(r.free[8]);
    }

    #[test]
    fn an_empty_union_is_an_error_and_an_empty_member_a_warning() {
        let (p, f) = strip();
        let parts = Parts::default();
        let input = RegionInput::unrepaired(&p, &f, &parts);
        let far = RegionSpec::parse("sphere:5,5,5,1").expect("ok");
        let e = select(std::slice::from_ref(&far), &input).expect_err("an error");
        assert!(matches!(e, RegionError::Empty { .. }), "{e}");
        assert!(e.to_string().contains("sphere:5,5,5,1"));
        let r = select(
            &[far, RegionSpec::parse("sphere:1,0,0,0.1").expect("ok")],
            &input,
        )
        .expect("ok");
        assert!(r.warnings.iter().any(|w| w.contains("sphere:5,5,5,1")));
    }

    #[test]
    fn unrepaired_input_selects_as_explicit_identity_maps_do() {
        let (p, f) = strip();
        let (vm, fm) = identity_maps(p.len(), f.len());
        let parts = Parts {
            named: vec![NamedPart {
                kind: PartKind::Group,
                name: "first".into(),
                faces: vec![0, 1, 99],
            }],
            vertex_properties: vec![ScalarProperty {
                name: "label".into(),
                values: vec![0., 0., 0., 0., 0., 0., 0., 0., 0., 3.],
            }],
            face_properties: Vec::new(),
        };
        let explicit = RegionInput {
            positions: &p,
            faces: &f,
            vertex_map: &vm,
            face_map: &fm,
            parts: &parts,
        };
        let unrepaired = RegionInput::unrepaired(&p, &f, &parts);
        for spec in ["part:first", "property:label>1", "not:part:first"] {
            let spec = RegionSpec::parse(spec).expect("parses");
            assert_eq!(
                select(std::slice::from_ref(&spec), &unrepaired).expect("selects"),
                select(std::slice::from_ref(&spec), &explicit).expect("selects"),
                "{spec}"
            );
        }
        let vertices = RegionSpec::Vertices {
            source: "test".into(),
            indices: vec![3, 10],
        };
        let message = |input: &RegionInput<'_>| {
            select(std::slice::from_ref(&vertices), input)
                .expect_err("vertex 10 is out of range")
                .to_string()
        };
        assert_eq!(message(&unrepaired), message(&explicit));
        assert!(message(&unrepaired).contains("10 vertices"));
    }

    #[test]
    fn parts_and_properties_follow_the_repair_maps() {
        let (p, f) = strip();
        // Input: 11 vertices (vertex 10 is a duplicate of vertex 4 welded onto it) and 9 faces
        // (face 8 was degenerate and dropped).
        let mut vm: Vec<Option<u32>> = (0..10u32).map(Some).collect();
        vm.push(Some(4));
        let mut fm: Vec<Option<u32>> = (0..8u32).map(Some).collect();
        fm.push(None);
        let parts = Parts {
            named: vec![
                NamedPart {
                    kind: PartKind::Group,
                    name: "first".into(),
                    faces: vec![0, 1],
                },
                NamedPart {
                    kind: PartKind::Material,
                    name: "dropped".into(),
                    faces: vec![8],
                },
            ],
            vertex_properties: vec![ScalarProperty {
                name: "label".into(),
                values: vec![0., 0., 0., 0., 0., 0., 0., 0., 0., 0., 3.],
            }],
            face_properties: vec![ScalarProperty {
                name: "quality".into(),
                values: vec![0., 0., 0., 0., 0., 0., 0., 0.9, 0.9],
            }],
        };
        let input = RegionInput {
            positions: &p,
            faces: &f,
            vertex_map: &vm,
            face_map: &fm,
            parts: &parts,
        };
        // Faces 0 and 1 are the first quad: vertices 0, 1, 2, 3 (any-face rule).
        let r = select(&[RegionSpec::Part("first".into())], &input).expect("ok");
        assert_eq!(
            (0..10).filter(|&v| r.free[v]).collect::<Vec<_>>(),
            [0, 1, 2, 3]
        );
        // The welded input vertex 10 carries label 3: its repaired vertex 4 is selected.
        let r = select(
            &[RegionSpec::parse("property:label==3").expect("ok")],
            &input,
        )
        .expect("ok");
        assert_eq!((0..10).filter(|&v| r.free[v]).collect::<Vec<_>>(), [4]);
        // Face 7 (kept) is selected; face 8 (dropped) contributes nothing.
        let r = select(
            &[RegionSpec::parse("property:quality>0.5").expect("ok")],
            &input,
        )
        .expect("ok");
        let f7 = f[7];
        assert_eq!(r.count(), 3);
        assert!(f7.iter().all(|&v| r.free[v as usize]));
        // A part whose faces were all dropped selects nothing: an error, not a silent no-op.
        let e = select(&[RegionSpec::Part("dropped".into())], &input).expect_err("an error");
        assert!(matches!(e, RegionError::Empty { .. }));
        // Missing names list what is on offer.
        let e = select(&[RegionSpec::Part("seat".into())], &input)
            .expect_err("an error")
            .to_string();
        assert!(
            e.contains("no part named `seat`") && e.contains("group `first`"),
            "{e}"
        );
        let e = select(&[RegionSpec::parse("property:foo>1").expect("ok")], &input)
            .expect_err("an error");
        assert!(e.to_string().contains("vertex property `label`"), "{e}");
        // Vertex lists follow the maps and refuse out-of-range indices.
        let r = select(
            &[RegionSpec::Vertices {
                source: "x".into(),
                indices: vec![10],
            }],
            &input,
        )
        .expect("ok");
        assert_eq!((0..10).filter(|&v| r.free[v]).collect::<Vec<_>>(), [4]);
        let e = select(
            &[RegionSpec::Vertices {
                source: "x".into(),
                indices: vec![11],
            }],
            &input,
        )
        .expect_err("an error");
        assert!(e.to_string().contains("vertex 11 is out of range"), "{e}");
        let e = select(&[RegionSpec::VertexFile("a.txt".into())], &input).expect_err("an error");
        assert!(matches!(e, RegionError::UnresolvedFile { .. }));
    }

    #[test]
    fn index_lists_parse_and_report_the_line() {
        assert_eq!(parse_index_list("# head\n3\n\n 7 \n").expect("ok"), [3, 7]);
        assert_eq!(parse_index_list("\u{feff}3\n7\n").expect("a BOM"), [3, 7]);
        let e = parse_index_list("1\n-2\n").expect_err("an error");
        assert!(e.contains("line 2") && e.contains("-2"), "{e}");
    }

    #[test]
    fn feather_weights_ramp_over_k_rings_inside_and_are_zero_outside() {
        let (_, f) = strip();
        // Columns 0..=4 (two vertices each); the region is columns 1..=4.
        let free: Vec<bool> = (0..10).map(|v| v >= 2).collect();
        let hard = feather_weights(&free, &f, 0);
        for v in 0..10 {
            assert_eq!(hard[v], if free[v] { 1.0 } else { 0.0 });
        }
        let w = feather_weights(&free, &f, 2);
        // Column 1 is one edge from column 0, column 2 two edges, column 3+ saturate.
        let column = |c: usize| (w[2 * c], w[2 * c + 1]);
        assert_eq!(column(0), (0.0, 0.0));
        assert_eq!(column(1), (1.0 / 3.0, 1.0 / 3.0));
        assert_eq!(column(2), (2.0 / 3.0, 2.0 / 3.0));
        assert_eq!(column(3), (1.0, 1.0));
        assert_eq!(column(4), (1.0, 1.0));
        // No outside vertex: everything free.
        assert!(
            feather_weights(&[true; 10], &f, 3)
                .iter()
                .all(|&x| x == 1.0)
        );
        assert_eq!(boundary_vertices(&free, &f), [2, 3]);
    }
}
