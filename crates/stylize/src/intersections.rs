//! Self-intersections of a result against its source: the figures `mesh check`, `eval`, `apply`,
//! the end of a run and the viewer report (issue 41), on [`mesh_core::intersect`].
//!
//! The definitions (what counts as two faces intersecting, adjacent faces included) are those of
//! [`mesh_core::intersect`]; see `docs/self_intersections.md`. A **new** pair is a pair of faces
//! that intersect in the result and not in the source (pairs, not counts: a source that already
//! intersects itself, as the cow fixture does, only reports what the deformation added). The
//! source and the result must have the same faces in the same order.

use mesh_core::TriMesh;
use mesh_core::intersect::{SelfIntersectionChecker, SelfIntersections, new_pairs};
use serde::Serialize;

use crate::error::{Error, Result};

/// The self-intersection figures of one result against its source.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct IntersectionFigures {
    /// Intersecting face pairs of the source.
    pub source_pairs: usize,
    /// Faces of the source in at least one intersecting pair.
    pub source_faces: usize,
    /// Intersecting face pairs of the result.
    pub pairs: usize,
    /// Faces of the result in at least one intersecting pair.
    pub faces: usize,
    /// Pairs of the result that the source does not have.
    pub new_pairs: usize,
    /// Faces in at least one new pair.
    pub new_faces: usize,
}

impl IntersectionFigures {
    /// One sentence for a warning when the result has new intersecting pairs (None otherwise):
    /// `12 new self-intersecting face pairs (20 faces) that the source does not have`.
    pub fn warning(&self) -> Option<String> {
        (self.new_pairs > 0).then(|| {
            format!(
                "{} new self-intersecting face pair{} ({} face{}) that the source does not have \
                 (the source has {} pair{})",
                self.new_pairs,
                plural(self.new_pairs),
                self.new_faces,
                plural(self.new_faces),
                self.source_pairs,
                plural(self.source_pairs)
            )
        })
    }

    /// Short form for a sanity line: `self-intersections: 4 pairs (6 faces), 0 new`.
    pub fn summary(&self) -> String {
        format!(
            "self-intersections: {} pair{} ({} face{}), {} new",
            self.pairs,
            plural(self.pairs),
            self.faces,
            plural(self.faces),
            self.new_pairs
        )
    }
}

fn plural(n: usize) -> &'static str {
    if n == 1 { "" } else { "s" }
}

/// One checked result: the figures and the faces of the new pairs (sorted, for highlighting).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CheckedResult {
    /// The figures.
    pub figures: IntersectionFigures,
    /// The result's intersecting faces (sorted).
    pub faces: Vec<u32>,
    /// Faces in at least one new pair (sorted).
    pub new_faces: Vec<u32>,
}

/// A source mesh checked once, and a checker (the source's BVH, refitted) for its deformations:
/// for callers that check many results of one source (several λ, a slider, a search).
#[derive(Clone, Debug)]
pub struct SourceIntersections {
    checker: SelfIntersectionChecker,
    source: SelfIntersections,
    vertices: usize,
}

impl SourceIntersections {
    /// Checks `source`. Refuses a mesh without faces, an out-of-range index and a non-finite
    /// vertex used by a face.
    pub fn new(source: &TriMesh) -> Result<Self> {
        let checker = SelfIntersectionChecker::new(&source.positions, &source.faces)
            .map_err(|e| Error::Invalid(format!("{e} (source mesh)")))?;
        let source_result = checker.check();
        Ok(Self {
            checker,
            source: source_result,
            vertices: source.positions.len(),
        })
    }

    /// Checks on `threads` threads ([`SelfIntersectionChecker::set_threads`]; a speed setting:
    /// the figures do not depend on it).
    pub fn set_threads(&mut self, threads: usize) {
        self.checker.set_threads(threads);
    }

    /// The source's own self-intersections.
    pub fn source(&self) -> &SelfIntersections {
        &self.source
    }

    /// Checks the source's faces at `positions` (one per source vertex) against the source.
    /// Refuses another vertex count and a non-finite coordinate (a result that blew up).
    pub fn check(&mut self, positions: &[[f64; 3]]) -> Result<CheckedResult> {
        if positions.len() != self.vertices {
            return Err(Error::Invalid(format!(
                "self-intersection check: the result has {} vertices and the source {}",
                positions.len(),
                self.vertices
            )));
        }
        let result = self
            .checker
            .check_moved(positions)
            .map_err(|e| Error::Invalid(format!("{e} (result mesh)")))?;
        let new = new_pairs(&self.source, &result).map_err(|e| Error::Invalid(e.to_string()))?;
        let mut new_faces: Vec<u32> = new.iter().flat_map(|&(a, b)| [a, b]).collect();
        new_faces.sort_unstable();
        new_faces.dedup();
        Ok(CheckedResult {
            figures: IntersectionFigures {
                source_pairs: self.source.pairs.len(),
                source_faces: self.source.faces.len(),
                pairs: result.pairs.len(),
                faces: result.faces.len(),
                new_pairs: new.len(),
                new_faces: new_faces.len(),
            },
            faces: result.faces,
            new_faces,
        })
    }
}

/// The figures of `result` against `source` (same faces in the same order, checked here).
pub fn compare(source: &TriMesh, result: &TriMesh) -> Result<IntersectionFigures> {
    if source.faces != result.faces {
        return Err(Error::Invalid(format!(
            "self-intersection check: the source and the result have different faces ({} and {}); \
             new intersections need the same connectivity",
            source.faces.len(),
            result.faces.len()
        )));
    }
    Ok(SourceIntersections::new(source)?
        .check(&result.positions)?
        .figures)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok<T>(r: Result<T>) -> T {
        r.unwrap_or_else(|e| panic!("{e}"))
    }

    fn refused<T>(r: Result<T>) -> String {
        match r {
            Ok(_) => panic!("accepted"),
            Err(e) => e.to_string(),
        }
    }

    /// Two unit squares (two triangles each) stacked at z = 0 and z = `dz`, not sharing vertices.
    fn two_sheets(dz: f64) -> TriMesh {
        let mut positions = Vec::new();
        for z in [0.0, dz] {
            positions.extend([[0.0, 0.0, z], [1.0, 0.0, z], [1.0, 1.0, z], [0.0, 1.0, z]]);
        }
        TriMesh::new(positions, vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    }

    #[test]
    fn new_pairs_are_those_the_source_does_not_have() {
        let apart = two_sheets(1.0);
        let touching = two_sheets(0.0);
        let f = ok(compare(&apart, &touching));
        assert_eq!(f.source_pairs, 0);
        assert!(f.pairs > 0 && f.new_pairs == f.pairs, "{f:?}");
        assert_eq!(f.faces, 4);
        assert_eq!(f.new_faces, 4);
        assert!(
            f.warning()
                .unwrap_or_default()
                .contains("new self-intersecting")
        );
        // The other way round nothing is new: the source already had every pair.
        let back = ok(compare(&touching, &apart));
        assert_eq!(back.new_pairs, 0);
        assert_eq!(back.source_pairs, f.pairs);
        assert!(back.warning().is_none());
        let same = ok(compare(&touching, &touching));
        assert_eq!((same.pairs, same.new_pairs), (f.pairs, 0));
    }

    #[test]
    fn checker_refuses_bad_results() {
        let mut s = ok(SourceIntersections::new(&two_sheets(1.0)));
        let mut p = two_sheets(1.0).positions;
        p[5][1] = f64::NAN;
        let e = refused(s.check(&p));
        assert!(e.contains("result mesh"), "{e}");
        assert!(refused(s.check(&p[..3])).contains("vertices"));
        // The checker is still usable after a refusal.
        let crossing = ok(s.check(&two_sheets(0.0).positions));
        assert!(crossing.figures.new_pairs > 0);
        let empty = TriMesh::new(vec![[0.0; 3]], vec![]);
        assert!(SourceIntersections::new(&empty).is_err());
        let other = TriMesh::new(two_sheets(1.0).positions, vec![[0, 1, 2]]);
        assert!(compare(&two_sheets(1.0), &other).is_err());
    }
}
