//! Plain geometric quantities over slices: face areas, signed volume, bounding box.
//!
//! Faces are CCW `u32` triples; indices must be in range (see [`crate::validate`]), otherwise these
//! functions panic on the out-of-range index like any slice access.

/// `a − b`.
#[inline]
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Cross product `a × b`.
#[inline]
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Dot product `a · b`.
#[inline]
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Euclidean length `|a|`.
#[inline]
pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Unnormalized face normal `N_f = (p1 − p0) × (p2 − p0)`; its length is twice the face area and it
/// points outward for a CCW face.
#[inline]
pub fn face_cross(positions: &[[f64; 3]], face: [u32; 3]) -> [f64; 3] {
    let p0 = positions[face[0] as usize];
    let p1 = positions[face[1] as usize];
    let p2 = positions[face[2] as usize];
    cross(sub(p1, p0), sub(p2, p0))
}

/// Area of every face, `|N_f| / 2` (same units² as the positions). Always ≥ 0.
pub fn face_areas(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Vec<f64> {
    faces
        .iter()
        .map(|&f| 0.5 * norm(face_cross(positions, f)))
        .collect()
}

/// Total surface area `Σ_f area_f`.
pub fn surface_area(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> f64 {
    face_areas(positions, faces).iter().sum()
}

/// Signed volume enclosed by the surface, by the divergence theorem: `Σ_f p0 · (p1 × p2) / 6`.
///
/// Positive for a closed mesh with outward (CCW) faces, negative if every face is flipped; for an
/// open mesh the value depends on the origin.
pub fn signed_volume(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> f64 {
    faces
        .iter()
        .map(|f| {
            let p0 = positions[f[0] as usize];
            let p1 = positions[f[1] as usize];
            let p2 = positions[f[2] as usize];
            dot(p0, cross(p1, p2))
        })
        .sum::<f64>()
        / 6.0
}

/// Axis-aligned bounding box `(min, max)` of the positions, per axis.
///
/// An empty slice gives `([0; 3], [0; 3])`. NaN coordinates are ignored (`f64::min`/`max` semantics);
/// a slice of only NaN coordinates gives `(+∞, −∞)` on that axis.
pub fn bbox(positions: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    if positions.is_empty() {
        return ([0.0; 3], [0.0; 3]);
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// Length of the bounding-box diagonal `|max − min|` (0 for an empty slice).
pub fn bbox_diagonal(positions: &[[f64; 3]]) -> f64 {
    let (lo, hi) = bbox(positions);
    norm(sub(hi, lo))
}

/// Mean of the positions (the centroid of the vertices, not of the surface); `[0; 3]` when empty.
pub fn vertex_centroid(positions: &[[f64; 3]]) -> [f64; 3] {
    if positions.is_empty() {
        return [0.0; 3];
    }
    let mut c = [0.0; 3];
    for p in positions {
        for k in 0..3 {
            c[k] += p[k];
        }
    }
    let n = positions.len() as f64;
    [c[0] / n, c[1] / n, c[2] / n]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit corner tetrahedron of [`crate::shapes::tetrahedron`] (outward CCW faces).
    fn tet() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let m = crate::shapes::tetrahedron();
        (m.positions, m.faces)
    }

    #[test]
    fn tetrahedron_volume_is_one_sixth_and_flips_sign_with_orientation() {
        let (p, f) = tet();
        assert!((signed_volume(&p, &f) - 1.0 / 6.0).abs() < 1e-15);
        let flipped: Vec<[u32; 3]> = f.iter().map(|t| [t[0], t[2], t[1]]).collect();
        assert!((signed_volume(&p, &flipped) + 1.0 / 6.0).abs() < 1e-15);
        // Translation invariance for a closed surface.
        let moved: Vec<[f64; 3]> = p
            .iter()
            .map(|q| [q[0] + 3.0, q[1] - 2.0, q[2] + 0.5])
            .collect();
        assert!((signed_volume(&moved, &f) - 1.0 / 6.0).abs() < 1e-13);
    }

    #[test]
    fn tetrahedron_face_areas_match_closed_form() {
        let (p, f) = tet();
        let a = face_areas(&p, &f);
        assert!((a[0] - 0.5).abs() < 1e-15);
        assert!((a[1] - 0.5).abs() < 1e-15);
        assert!((a[2] - 0.5).abs() < 1e-15);
        // Equilateral face with side √2: area = √3/4 · 2.
        assert!((a[3] - 3f64.sqrt() / 2.0).abs() < 1e-15);
    }

    #[test]
    fn bbox_and_diagonal_of_unit_cube_corners() {
        let (p, _) = tet();
        let (lo, hi) = bbox(&p);
        assert_eq!(lo, [0.0; 3]);
        assert_eq!(hi, [1.0; 3]);
        assert!((bbox_diagonal(&p) - 3f64.sqrt()).abs() < 1e-15);
        assert_eq!(bbox_diagonal(&[]), 0.0);
    }
}
