//! `before_after.png` of a run: the source (top row) and the result (bottom row) in the same orbit
//! views (azimuth 360°·k/N, elevation 20°, CPU renderer), the same camera distance (fitting the
//! larger of the two bounding spheres) and the same crop — the union of every view's silhouette of
//! both meshes, squared, with a 4 % margin — so the meshes fill their tiles and the two rows compare
//! pixel for pixel.

use std::path::Path;

use crate::error::{Context, IoContext, Result};
use raster_diff::{Images, Renderer};

/// Renders and writes the before/after sheet (see the module documentation); `views` columns.
pub fn write_before_after(
    path: &Path,
    source: &[[f64; 3]],
    result: &[[f64; 3]],
    faces: &[[u32; 3]],
    views: usize,
    size: usize,
    fov_deg: f64,
) -> Result<()> {
    let sheet = before_after(source, result, faces, views, size, fov_deg)?;
    crate::durable::replace_with(path, |tmp| {
        let file = std::fs::File::create(tmp).io_context("cannot create", tmp)?;
        raster_diff::image::write_png(
            std::io::BufWriter::new(file),
            &sheet,
            0,
            raster_diff::image::Encoding::Direct,
        )
        .with_context(|| format!("cannot write {}", path.display()))
    })
}

/// The sheet as one image: 2 rows (source, result) × `views` columns of square tiles.
pub fn before_after(
    source: &[[f64; 3]],
    result: &[[f64; 3]],
    faces: &[[u32; 3]],
    views: usize,
    size: usize,
    fov_deg: f64,
) -> Result<Images> {
    let views = views.max(1);
    let radius = source
        .iter()
        .chain(result)
        .map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt())
        .filter(|r| r.is_finite())
        .fold(0.0_f64, f64::max)
        .max(1e-3);
    let half_fov = (fov_deg.clamp(1.0, 179.0) * 0.5).to_radians();
    let orbit = raster_diff::orbit_views(views, 20.0, 1.05 * radius / half_fov.sin(), fov_deg);
    let mut renderer = raster_diff::CpuRenderer::default();
    let mut render = |p: &[[f64; 3]]| {
        renderer
            .render(p, faces, &orbit, size, size)
            .context("before/after render")
    };
    let (src, res) = (render(source)?, render(result)?);
    let (x0, y0, side) = silhouette_square(&[&src, &res], size);
    let mut tiles = Images {
        count: 2 * views,
        height: side,
        width: side,
        rgb: Vec::with_capacity(2 * views * side * side * 3),
    };
    for images in [&src, &res] {
        for v in 0..views {
            for y in y0..y0 + side {
                let row = ((v * size + y) * size + x0) * 3;
                tiles
                    .rgb
                    .extend_from_slice(&images.rgb[row..row + side * 3]);
            }
        }
    }
    Ok(raster_diff::image::contact_sheet(&tiles, views))
}

/// The square `(x0, y0, side)` holding every non-background pixel of every view (the background
/// is the top-left pixel's colour), with a 4 % margin, inside the `size`×`size` image.
fn silhouette_square(sets: &[&Images], size: usize) -> (usize, usize, usize) {
    let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
    for images in sets {
        let bg = [images.rgb[0], images.rgb[1], images.rgb[2]];
        for v in 0..images.count {
            for y in 0..size {
                for x in 0..size {
                    let i = ((v * size + y) * size + x) * 3;
                    let px = &images.rgb[i..i + 3];
                    if px.iter().zip(bg).any(|(a, b)| (a - b).abs() > 1e-3) {
                        lo = [lo[0].min(x), lo[1].min(y)];
                        hi = [hi[0].max(x), hi[1].max(y)];
                    }
                }
            }
        }
    }
    if lo[0] > hi[0] {
        return (0, 0, size);
    }
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]) + 1;
    let side = ((extent as f64 * 1.04).ceil() as usize).clamp(1, size);
    let start = |lo: usize, hi: usize| {
        let centre = (lo + hi).div_ceil(2);
        centre.saturating_sub(side / 2).min(size - side)
    };
    (start(lo[0], hi[0]), start(lo[1], hi[1]), side)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sheet_has_two_rows_of_tiles_filled_by_the_mesh() {
        let octa = mesh_core::shapes::octahedron();
        let bigger: Vec<[f64; 3]> = octa.positions.iter().map(|p| p.map(|c| 1.3 * c)).collect();
        let sheet = before_after(&octa.positions, &bigger, &octa.faces, 4, 96, 60.0)
            .unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(sheet.count, 1);
        let side = sheet.height / 2;
        assert_eq!(sheet.width, 4 * side);
        assert!(
            side < 96,
            "the crop did not tighten the 96-pixel renders: {side}"
        );
        // The larger (result) row's silhouette spans nearly its whole tile; the source's is
        // smaller by the scale factor, in the same framing.
        let span = |row: usize| {
            let (mut lo, mut hi) = (usize::MAX, 0);
            for y in row * side..(row + 1) * side {
                for x in 0..side {
                    let i = (y * sheet.width + x) * 3;
                    if sheet.rgb[i..i + 3]
                        .iter()
                        .any(|&c| (c - sheet.rgb[0]).abs() > 1e-3)
                    {
                        lo = lo.min(x);
                        hi = hi.max(x);
                    }
                }
            }
            (hi + 1).saturating_sub(lo)
        };
        let (top, bottom) = (span(0), span(1));
        assert!(bottom as f64 > 0.85 * side as f64, "{bottom} of {side}");
        let ratio = bottom as f64 / top as f64;
        assert!((ratio - 1.3).abs() < 0.15, "{top} vs {bottom}");
    }
}
