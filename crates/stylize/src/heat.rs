//! `mesh_heat.glb`: the deformed mesh with per-vertex colours showing where and how much the
//! surface moved — a heat map of the displacement magnitude — for viewers that show vertex colours
//! (Blender, three.js, any glTF viewer).
//!
//! **Quantity.** `d_v = ‖p_v − (r_v − r̄)‖`: the result `p` (dARAP's `recenter_rescale` output,
//! vertex centroid at the origin, bounding-box diagonal that of the rest mesh) against the rest
//! mesh `r` moved to its own vertex centroid `r̄`, both in the normalized side-2 frame of
//! `deformation.npz` (so `d` is in units of that frame, where the mesh's longest side is 2).
//!
//! **Colours.** `t_v = d_v / d_max` (`d_max` the largest `d_v`; 0 everywhere when nothing moved)
//! through [`colormap`], a piecewise-linear map over five stops of viridis (dark blue → green →
//! yellow) in sRGB, stored as glTF `COLOR_0` in linear RGB ([`srgb_to_linear`]). `run.json`
//! records the scale: `heat.max_displacement` = `d_max`.

use std::path::Path;

use mesh_core::TriMesh;

/// Five stops of matplotlib's viridis at t = 0, ¼, ½, ¾, 1 (sRGB, 0–1).
pub const VIRIDIS_STOPS: [[f64; 3]; 5] = [
    [0.267, 0.005, 0.329],
    [0.230, 0.322, 0.546],
    [0.128, 0.567, 0.551],
    [0.369, 0.789, 0.383],
    [0.993, 0.906, 0.144],
];

/// The sRGB colour of `t` ∈ [0, 1] (clamped; NaN → 0): linear interpolation between the
/// [`VIRIDIS_STOPS`].
pub fn colormap(t: f64) -> [f64; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (VIRIDIS_STOPS.len() - 1) as f64;
    let i = (x.floor() as usize).min(VIRIDIS_STOPS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (VIRIDIS_STOPS[i], VIRIDIS_STOPS[i + 1]);
    [0, 1, 2].map(|k| a[k] + f * (b[k] - a[k]))
}

/// The sRGB transfer function inverted (IEC 61966-2-1): what glTF's linear `COLOR_0` holds.
pub fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// `d_v` of the module docs for a rest mesh and a result with the same vertices.
pub fn displacement(rest: &[[f64; 3]], result: &[[f64; 3]]) -> Vec<f64> {
    let n = rest.len().max(1) as f64;
    let mut c = [0.0; 3];
    for r in rest {
        for k in 0..3 {
            c[k] += r[k] / n;
        }
    }
    rest.iter()
        .zip(result)
        .map(|(r, p)| {
            let d = [0, 1, 2].map(|k| p[k] - (r[k] - c[k]));
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        })
        .collect()
}

/// The linear-RGB `COLOR_0` of each displacement, and the scale `d_max`.
pub fn heat_colors(displacement: &[f64]) -> (Vec<[f32; 3]>, f64) {
    let max = displacement
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .fold(0.0, f64::max);
    let colors = displacement
        .iter()
        .map(|&d| {
            let t = if max > 0.0 { d / max } else { 0.0 };
            colormap(t).map(|c| srgb_to_linear(c) as f32)
        })
        .collect();
    (colors, max)
}

/// Writes `written` (the result as the run's mesh files hold it, with `normals`) as a GLB whose
/// vertex colours are the heat map of the displacement of `result` from `rest` (both in the
/// normalized side-2 frame, the same vertex order as `written`); returns `d_max`. The colours do
/// not depend on the frame `written` is in.
pub fn write_heat_glb(
    path: &Path,
    rest: &[[f64; 3]],
    result: &[[f64; 3]],
    written: &TriMesh,
    normals: Option<&[[f64; 3]]>,
) -> Result<f64, mesh_core::MeshError> {
    if rest.len() != result.len() || result.len() != written.positions.len() {
        return Err(mesh_core::MeshError::Invalid(format!(
            "{}: rest mesh has {} vertices, result {}, written mesh {}",
            path.display(),
            rest.len(),
            result.len(),
            written.positions.len()
        )));
    }
    let (colors, max) = heat_colors(&displacement(rest, result));
    mesh_core::io::write_glb_with_colors(path, written, normals, Some(&colors))?;
    Ok(max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colormap_hits_its_stops_and_interpolates_between_them() {
        for (k, stop) in VIRIDIS_STOPS.iter().enumerate() {
            assert_eq!(colormap(k as f64 / 4.0), *stop);
        }
        let mid = colormap(0.125);
        for k in 0..3 {
            let want = 0.5 * (VIRIDIS_STOPS[0][k] + VIRIDIS_STOPS[1][k]);
            assert!((mid[k] - want).abs() < 1e-12);
        }
        assert_eq!(colormap(-1.0), VIRIDIS_STOPS[0]);
        assert_eq!(colormap(7.0), VIRIDIS_STOPS[4]);
        assert_eq!(colormap(f64::NAN), VIRIDIS_STOPS[0]);
    }

    #[test]
    fn displacement_is_measured_against_the_rest_mesh_at_its_centroid() {
        let rest = [[1.0, 0.0, 0.0], [3.0, 0.0, 0.0]]; // centroid (2, 0, 0)
        let result = [[-1.0, 0.0, 0.0], [1.0, 2.0, 0.0]];
        let d = displacement(&rest, &result);
        assert_eq!(d, vec![0.0, 2.0]);
        let (colors, max) = heat_colors(&d);
        assert_eq!(max, 2.0);
        assert_eq!(
            colors[0],
            VIRIDIS_STOPS[0].map(|c| srgb_to_linear(c) as f32)
        );
        assert_eq!(
            colors[1],
            VIRIDIS_STOPS[4].map(|c| srgb_to_linear(c) as f32)
        );
        let (still, zero) = heat_colors(&[0.0, 0.0]);
        assert_eq!(zero, 0.0);
        assert_eq!(still[1], still[0]);
    }
}
