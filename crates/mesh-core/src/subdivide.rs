//! Midpoint (1 → 4) subdivision.

use std::collections::HashMap;

use crate::TriMesh;

/// Splits every triangle into four at its edge midpoints; neighbouring faces share the midpoint
/// vertex of their common edge, so a closed manifold stays closed and manifold.
///
/// New vertices are appended after the old ones (old indices are kept), in order of first use while
/// walking the faces and their edges `(0,1), (1,2), (2,0)`. Face `[a, b, c]` with midpoints
/// `ab, bc, ca` becomes `[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]` (orientation kept).
/// V' = V + E, F' = 4F. Faces must index into `mesh.positions`.
pub fn midpoint(mesh: &TriMesh) -> TriMesh {
    let mut positions = mesh.positions.clone();
    let mut midpoints: HashMap<(u32, u32), u32> = HashMap::with_capacity(mesh.faces.len() * 3 / 2);
    let mut faces = Vec::with_capacity(mesh.faces.len() * 4);
    let mut mid = |a: u32, b: u32, positions: &mut Vec<[f64; 3]>| -> u32 {
        let key = if a < b { (a, b) } else { (b, a) };
        *midpoints.entry(key).or_insert_with(|| {
            let (pa, pb) = (positions[a as usize], positions[b as usize]);
            positions.push([
                0.5 * (pa[0] + pb[0]),
                0.5 * (pa[1] + pb[1]),
                0.5 * (pa[2] + pb[2]),
            ]);
            (positions.len() - 1) as u32
        })
    };
    for &[a, b, c] in &mesh.faces {
        let ab = mid(a, b, &mut positions);
        let bc = mid(b, c, &mut positions);
        let ca = mid(c, a, &mut positions);
        faces.push([a, ab, ca]);
        faces.push([ab, b, bc]);
        faces.push([ca, bc, c]);
        faces.push([ab, bc, ca]);
    }
    TriMesh { positions, faces }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{signed_volume, surface_area};
    use crate::topology::EdgeFaces;

    fn tet() -> TriMesh {
        crate::shapes::tetrahedron()
    }

    #[test]
    fn counts_follow_v_plus_e_and_four_f_and_mesh_stays_closed() {
        let m = midpoint(&tet());
        assert_eq!(m.num_vertices(), 4 + 6);
        assert_eq!(m.num_faces(), 16);
        let ef = EdgeFaces::new(&m.faces);
        assert!(ef.boundary_edges().is_empty());
        assert!(ef.inconsistently_oriented_edges().is_empty());
        let m2 = midpoint(&m);
        assert_eq!(m2.num_vertices(), 10 + ef.len());
        assert_eq!(m2.num_faces(), 64);
    }

    #[test]
    fn flat_subdivision_preserves_area_and_volume() {
        let t = tet();
        let m = midpoint(&t);
        assert!(
            (surface_area(&m.positions, &m.faces) - surface_area(&t.positions, &t.faces)).abs()
                < 1e-14
        );
        assert!((signed_volume(&m.positions, &m.faces) - 1.0 / 6.0).abs() < 1e-15);
        assert_eq!(
            &m.positions[..4],
            &t.positions[..],
            "old vertices keep their indices"
        );
    }
}
