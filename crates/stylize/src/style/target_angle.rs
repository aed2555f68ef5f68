//! How far a style asks the normals of a mesh to turn, measured once before a run: the
//! area-weighted mean angle between the rest face normals `n_f` and their targets `t_f`,
//!
//! ```text
//! θ̄ = Σ_f A_f · acos(n_f · t_f) / Σ_f A_f     (degrees)
//! ```
//!
//! The model-free objective `Σ_f A_f (1 − n_f·t_f)` can only move the mesh as far as the targets
//! differ from the normals it already has: with θ̄ of a few degrees the result is the input,
//! whatever λ and the number of iterations. This happens with an exemplar whose vertex normals
//! cover the sphere densely (a smooth or finely curved exemplar, e.g. the fandisk): every normal of
//! the input finds a near-copy of itself among them. A good exemplar has a few dominant normal
//! directions (flat faces meeting at creases: a cube, an octahedron, a low-poly mesh), so the
//! nearest of them is far from most input normals.

use super::alignment::face_cross;

/// Below this mean angle (degrees) between the input's normals and their targets the style barely
/// changes the input: 12° (a first choice; the tests check that the fandisk as exemplar on the bunny
/// falls below it and the cube and octahedron styles above).
pub const WEAK_TARGET_ANGLE_DEG: f64 = 12.0;

/// θ̄ of the module documentation, in degrees (0 for a mesh of zero area).
pub fn mean_target_angle_deg(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    targets: &[[f64; 3]],
) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (&f, &t) in faces.iter().zip(targets) {
        let n = face_cross(positions, f);
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if len <= 0.0 || !len.is_finite() {
            continue;
        }
        let cos = (n[0] * t[0] + n[1] * t[1] + n[2] * t[2]) / len;
        num += len * cos.clamp(-1.0, 1.0).acos();
        den += len;
    }
    if den > 0.0 {
        (num / den).to_degrees()
    } else {
        0.0
    }
}

/// The warning for a style whose targets are within [`WEAK_TARGET_ANGLE_DEG`] of the input's
/// normals on average (`None` otherwise). `style` names the style in the message.
pub fn weak_style_warning(
    style: &super::Style,
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    targets: &[[f64; 3]],
) -> Option<String> {
    let angle = mean_target_angle_deg(positions, faces, targets);
    if angle >= WEAK_TARGET_ANGLE_DEG {
        return None;
    }
    let advice = match style {
        super::Style::Exemplar { .. } => {
            "the exemplar's vertex normals already contain nearly every normal of the input, so the \
             result will look almost unchanged. Use an exemplar with a few dominant normal \
             directions (flat faces meeting at sharp creases, e.g. a low-poly or boxy mesh), or a \
             built-in style (--style cube, --style octahedron)"
        }
        _ => {
            "the input already has nearly this style's normals; the result will look almost unchanged"
        }
    };
    Some(format!(
        "style {}: the input's face normals are on average only {angle:.1}° from their targets \
         (below {WEAK_TARGET_ANGLE_DEG}°): {advice}",
        style.name()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::style::Style;

    fn fixture(name: &str) -> std::path::PathBuf {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/meshes")
            .join(name)
    }

    fn bunny() -> mesh_core::TriMesh {
        let mut m =
            mesh_core::io::read_mesh(fixture("bunny.obj")).unwrap_or_else(|e| panic!("{e}"));
        mesh_core::normalize::side2_cube(&mut m.positions);
        m
    }

    #[test]
    fn mean_angle_is_area_weighted_and_in_degrees() {
        // Two faces in the xy-plane (normal +z), areas 1/2 and 2; targets at 30° and 0°.
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [2.0, 0.0, 0.0],
            [0.0, 2.0, 0.0],
        ];
        let f = [[0, 1, 2], [0, 3, 4]];
        let s = 30f64.to_radians();
        let t = [[s.sin(), 0.0, s.cos()], [0.0, 0.0, 1.0]];
        let angle = mean_target_angle_deg(&p, &f, &t);
        assert!((angle - 30.0 * 0.5 / 2.5).abs() < 1e-9, "{angle}");
        assert_eq!(mean_target_angle_deg(&[[0.0; 3]; 3], &[[0, 1, 2]], &t), 0.0);
    }

    #[test]
    fn the_fandisk_as_exemplar_warns_and_faceted_styles_do_not() {
        let m = bunny();
        let angle = |style: &Style| {
            let t = style.face_targets(&m.positions, &m.faces);
            let warning = weak_style_warning(style, &m.positions, &m.faces, &t);
            (mean_target_angle_deg(&m.positions, &m.faces, &t), warning)
        };
        let spec = format!("exemplar:{}", fixture("fandisk.off").display());
        let fandisk = Style::parse(&spec).unwrap_or_else(|e| panic!("{e:#}"));
        let (a, w) = angle(&fandisk);
        println!("bunny, fandisk exemplar: {a:.2}°");
        let w = w.unwrap_or_else(|| panic!("no warning at {a}°"));
        assert!(w.contains("fandisk.off") && w.contains("exemplar"), "{w}");
        assert!(w.contains(&format!("{a:.1}°")), "{w}");
        for style in [Style::Cube, Style::Octahedron] {
            let (a, w) = angle(&style);
            println!("bunny, {}: {a:.2}°", style.name());
            assert!(w.is_none(), "{w:?}");
        }
        // A faceted exemplar: the regular octahedron (its vertex normals are ±e_i, the cube style).
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("octahedron.obj");
        mesh_core::io::write_mesh(&path, &mesh_core::shapes::octahedron(), None)
            .unwrap_or_else(|e| panic!("{e}"));
        let octa = Style::parse(&format!("exemplar:{}", path.display()))
            .unwrap_or_else(|e| panic!("{e:#}"));
        let (a, w) = angle(&octa);
        println!("bunny, octahedron exemplar: {a:.2}°");
        assert!(w.is_none(), "{w:?}");
    }
}
