//! File attributes that follow a remesh: the [`Parts`] of an input file (named face sets, PLY
//! per-face and per-vertex scalars) carried onto the remeshed mesh, so that `part:…` and
//! `property:…` region specs select the same parts of the surface after remeshing.
//!
//! - A **face** label (named part membership, face property) moves to every output face whose
//!   source face ([`super::Remeshed::source_faces`]: the input face its centroid projects onto)
//!   carried it.
//! - A **vertex** property takes the value of the input vertex nearest to the output vertex's
//!   closest point on the input surface (the nearest corner of the face that point lies on). Values are copied, never blended, so a label compared with `=`
//!   selects the same region; a continuous property is sampled at the nearest input vertex
//!   (at most half an input edge away).

use super::RemeshError;
use crate::bvh::Bvh;
use crate::region::{NamedPart, Parts, ScalarProperty};

/// The input a remesh started from, in the numbering of [`Parts`] (the file's) and of the mesh
/// the remesher saw (repaired): `vertex_map[i]` / `face_map[f]` give the repaired vertex / face of
/// file vertex `i` / file triangle `f` (`None`: dropped by the repair; empty slices: the identity).
#[derive(Clone, Copy, Debug)]
pub struct TransferSource<'a> {
    /// Positions of the mesh that was remeshed.
    pub positions: &'a [[f64; 3]],
    /// Faces of the mesh that was remeshed.
    pub faces: &'a [[u32; 3]],
    /// File vertex → remeshed-input vertex (empty: identity).
    pub vertex_map: &'a [Option<u32>],
    /// File triangle → remeshed-input face (empty: identity).
    pub face_map: &'a [Option<u32>],
}

impl TransferSource<'_> {
    /// For each face of the remeshed input, the first file triangle that maps to it.
    fn file_face_of(&self) -> Vec<Option<usize>> {
        let mut out = vec![None; self.faces.len()];
        if self.face_map.is_empty() {
            for (f, slot) in out.iter_mut().enumerate() {
                *slot = Some(f);
            }
        } else {
            for (f, g) in self.face_map.iter().enumerate() {
                if let Some(g) = g
                    && let Some(slot) = out.get_mut(*g as usize)
                    && slot.is_none()
                {
                    *slot = Some(f);
                }
            }
        }
        out
    }

    /// For each vertex of the remeshed input, the first file vertex that maps to it.
    fn file_vertex_of(&self) -> Vec<Option<usize>> {
        let mut out = vec![None; self.positions.len()];
        if self.vertex_map.is_empty() {
            for (v, slot) in out.iter_mut().enumerate() {
                *slot = Some(v);
            }
        } else {
            for (i, v) in self.vertex_map.iter().enumerate() {
                if let Some(v) = v
                    && let Some(slot) = out.get_mut(*v as usize)
                    && slot.is_none()
                {
                    *slot = Some(i);
                }
            }
        }
        out
    }
}

/// `parts` (file numbering of `source`) carried onto the remeshed mesh `(positions, faces)` whose
/// `source_faces[o]` is the face of `source` output face `o` came from. The result is in the
/// remeshed numbering (use it with identity maps). A vertex property value of a file vertex the
/// repair dropped, or a face label of a dropped triangle, is lost as it is without remeshing; an
/// output element whose source has no file element gets NaN (selected by no comparison).
///
/// Errors: `source_faces` not one per output face or out of range, and what [`Bvh::new`]
/// refuses on the source (out-of-range indices, non-finite vertices).
pub fn transfer_parts(
    parts: &Parts,
    source: &TransferSource<'_>,
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    source_faces: &[u32],
) -> Result<Parts, RemeshError> {
    if source_faces.len() != faces.len() {
        return Err(RemeshError::Transfer(format!(
            "{} source faces for {} faces",
            source_faces.len(),
            faces.len()
        )));
    }
    if let Some(&s) = source_faces
        .iter()
        .find(|&&s| s as usize >= source.faces.len())
    {
        return Err(RemeshError::Transfer(format!(
            "source face {s} is out of range (the input has {} faces)",
            source.faces.len()
        )));
    }
    let file_face = source.file_face_of();
    let named = parts
        .named
        .iter()
        .map(|p| {
            let mut member = vec![false; source.faces.len()];
            for &f in &p.faces {
                let g = if source.face_map.is_empty() {
                    Some(f)
                } else {
                    source.face_map.get(f as usize).copied().flatten()
                };
                if let Some(slot) = g.and_then(|g| member.get_mut(g as usize)) {
                    *slot = true;
                }
            }
            NamedPart {
                kind: p.kind,
                name: p.name.clone(),
                faces: (0..faces.len() as u32)
                    .filter(|&o| member[source_faces[o as usize] as usize])
                    .collect(),
            }
        })
        .collect();
    let face_properties = parts
        .face_properties
        .iter()
        .map(|p| ScalarProperty {
            name: p.name.clone(),
            values: source_faces
                .iter()
                .map(|&s| {
                    file_face[s as usize]
                        .and_then(|f| p.values.get(f).copied())
                        .unwrap_or(f64::NAN)
                })
                .collect(),
        })
        .collect();
    let vertex_properties = if parts.vertex_properties.is_empty() {
        Vec::new()
    } else {
        let file_vertex = source.file_vertex_of();
        let bvh = Bvh::new(source.positions, source.faces)?;
        // The nearest input vertex of each output vertex's closest point.
        let nearest: Vec<Option<usize>> = positions
            .iter()
            .map(|&p| {
                bvh.closest_point(p).and_then(|c| {
                    let face = source.faces[c.face as usize];
                    let d2 = |v: u32| {
                        let q = crate::geometry::sub(source.positions[v as usize], c.point);
                        crate::geometry::dot(q, q)
                    };
                    let mut k = 0;
                    for j in 1..3 {
                        if d2(face[j]) < d2(face[k]) {
                            k = j;
                        }
                    }
                    file_vertex[face[k] as usize]
                })
            })
            .collect();
        parts
            .vertex_properties
            .iter()
            .map(|p| ScalarProperty {
                name: p.name.clone(),
                values: nearest
                    .iter()
                    .map(|i| i.and_then(|i| p.values.get(i).copied()).unwrap_or(f64::NAN))
                    .collect(),
            })
            .collect()
    };
    Ok(Parts {
        named,
        vertex_properties,
        face_properties,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::region::{Comparison, PartKind, RegionInput, RegionSpec, select_vertices};
    use crate::remesh::{RemeshOptions, remesh};

    /// A flat 8×4 grid of unit squares on [0, 8] × [0, 4], two triangles per square; the left half
    /// (x < 4) is part `left`, face property `side` is 0 left and 1 right, vertex property `x`.
    fn halves() -> (Vec<[f64; 3]>, Vec<[u32; 3]>, Parts) {
        let (nx, ny) = (8u32, 4u32);
        let mut p = Vec::new();
        for j in 0..=ny {
            for i in 0..=nx {
                p.push([f64::from(i), f64::from(j), 0.0]);
            }
        }
        let id = |i: u32, j: u32| j * (nx + 1) + i;
        let (mut f, mut left, mut side) = (Vec::new(), Vec::new(), Vec::new());
        for j in 0..ny {
            for i in 0..nx {
                for t in [
                    [id(i, j), id(i + 1, j), id(i + 1, j + 1)],
                    [id(i, j), id(i + 1, j + 1), id(i, j + 1)],
                ] {
                    if i < nx / 2 {
                        left.push(f.len() as u32);
                    }
                    side.push(if i < nx / 2 { 0.0 } else { 1.0 });
                    f.push(t);
                }
            }
        }
        let xs = p.iter().map(|q| q[0]).collect();
        let parts = Parts {
            named: vec![NamedPart {
                kind: PartKind::Group,
                name: "left".into(),
                faces: left,
            }],
            vertex_properties: vec![ScalarProperty {
                name: "x".into(),
                values: xs,
            }],
            face_properties: vec![ScalarProperty {
                name: "side".into(),
                values: side,
            }],
        };
        (p, f, parts)
    }

    #[test]
    fn labels_follow_the_faces_they_came_from() {
        let (p, f, parts) = halves();
        let out = remesh(&p, &f, &RemeshOptions::new(0.45)).unwrap_or_else(|e| panic!("{e}"));
        assert!(out.faces.len() > 2 * f.len(), "the grid was refined");
        let source = TransferSource {
            positions: &p,
            faces: &f,
            vertex_map: &[],
            face_map: &[],
        };
        let moved = transfer_parts(
            &parts,
            &source,
            &out.positions,
            &out.faces,
            &out.source_faces,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let centroid_x = |o: usize| {
            out.faces[o]
                .iter()
                .map(|&v| out.positions[v as usize][0])
                .sum::<f64>()
                / 3.0
        };
        // Every face of part `left` lies left of x = 4 (up to the faces that straddle it), and
        // every face left of x = 3.5 is in it.
        let left: std::collections::HashSet<u32> = moved.named[0].faces.iter().copied().collect();
        for o in 0..out.faces.len() {
            let x = centroid_x(o);
            if x < 3.5 {
                assert!(
                    left.contains(&(o as u32)),
                    "face {o} at x {x} lost its part"
                );
            }
            if x > 4.5 {
                assert!(
                    !left.contains(&(o as u32)),
                    "face {o} at x {x} wrongly in `left`"
                );
            }
            let side = moved.face_properties[0].values[o];
            assert!(
                side == 0.0 || side == 1.0,
                "face values are copied, not blended"
            );
            assert_eq!(side == 0.0, left.contains(&(o as u32)));
        }
        // Vertex values are copied from the nearest input vertex: within half a diagonal.
        for (v, q) in out.positions.iter().enumerate() {
            let x = moved.vertex_properties[0].values[v];
            assert_eq!(x, x.round(), "an input value");
            assert!(
                (x - q[0]).abs() <= 0.5 + 1e-9,
                "vertex {v} at x {} got {x}",
                q[0]
            );
        }
        // The same specs select the same side of the surface on both meshes.
        let before = RegionInput::unrepaired(&p, &f, &parts);
        let after = RegionInput::unrepaired(&out.positions, &out.faces, &moved);
        for spec in [
            RegionSpec::Part("left".into()),
            RegionSpec::Property {
                name: "side".into(),
                op: Comparison::Eq,
                value: 1.0,
            },
            RegionSpec::Property {
                name: "x".into(),
                op: Comparison::Le,
                value: 2.0,
            },
        ] {
            let share = |input: &RegionInput<'_>, pos: &[[f64; 3]]| {
                let sel = select_vertices(&spec, input).unwrap_or_else(|e| panic!("{e}"));
                let xs: Vec<f64> = pos
                    .iter()
                    .zip(&sel)
                    .filter(|(_, s)| **s)
                    .map(|(q, _)| q[0])
                    .collect();
                (
                    xs.iter().copied().fold(f64::INFINITY, f64::min),
                    xs.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                )
            };
            let (lo0, hi0) = share(&before, &p);
            let (lo1, hi1) = share(&after, &out.positions);
            assert!(
                (lo0 - lo1).abs() <= 0.5 && (hi0 - hi1).abs() <= 0.5,
                "{spec}: x range {lo0}..{hi0} before, {lo1}..{hi1} after"
            );
        }
    }

    #[test]
    fn repair_maps_are_followed_and_bad_sources_refused() {
        let (p, f, parts) = halves();
        // Pretend the repair dropped file triangle 0 and renumbered the rest down by one.
        let face_map: Vec<Option<u32>> = (0..f.len())
            .map(|i| (i > 0).then(|| i as u32 - 1))
            .collect();
        let repaired_faces: Vec<[u32; 3]> = f[1..].to_vec();
        let source = TransferSource {
            positions: &p,
            faces: &repaired_faces,
            vertex_map: &[],
            face_map: &face_map,
        };
        // A trivial "remesh": the repaired mesh itself.
        let src: Vec<u32> = (0..repaired_faces.len() as u32).collect();
        let moved = transfer_parts(&parts, &source, &p, &repaired_faces, &src)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            moved.face_properties[0].values,
            parts.face_properties[0].values[1..]
        );
        let expect: Vec<u32> = parts.named[0].faces[1..].iter().map(|f| f - 1).collect();
        assert_eq!(moved.named[0].faces, expect);
        assert!(matches!(
            transfer_parts(&parts, &source, &p, &repaired_faces, &src[1..]),
            Err(RemeshError::Transfer(_))
        ));
        let mut bad = src.clone();
        bad[0] = 10_000;
        let e = transfer_parts(&parts, &source, &p, &repaired_faces, &bad)
            .err()
            .unwrap_or_else(|| panic!("expected an error"));
        assert!(e.to_string().contains("10000"), "{e}");
    }
}
