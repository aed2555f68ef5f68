//! The comparison sheet of `stylize apply --lambda A,B,…` (several λ): `OUT_grid.png` beside the
//! meshes, one **column per λ** (in the order given) of [`GRID_VIEWS`] turntable views (rows,
//! azimuth 360°·k/N, elevation 20°, CPU renderer, [`TILE`]-pixel square tiles, the same bounding
//! framing for every column, so sizes compare), and under each column a white strip of
//! [`LABEL_HEIGHT`] pixels with its label `λ=<value>` in black, centred, drawn with the built-in
//! 5×7 pixel font ([`FONT`]) scaled ×[`GLYPH_SCALE`]. The drawing is [`crate::sheet`]'s, which
//! `stylize batch`'s grid ([`crate::batch_grid`]) shares.

use std::path::{Path, PathBuf};

use anyhow::Context;
use raster_diff::Images;

use crate::sheet::Canvas;

/// Views (rows) per column.
pub const GRID_VIEWS: usize = 3;
/// Tile side in pixels.
pub const TILE: usize = 192;
/// Height of the label strip under the tiles.
pub const LABEL_HEIGHT: usize = 32;
/// Pixels per font pixel.
pub const GLYPH_SCALE: usize = 3;
/// Vertical field of view of the tiles' camera (degrees).
pub const GRID_FOV_DEG: f64 = 40.0;

pub use crate::sheet::FONT;

/// The sheet's path for the meshes' `-o OUT.ext`: `OUT_grid.png`.
pub fn grid_path(output: &Path) -> anyhow::Result<PathBuf> {
    let stem = output
        .file_stem()
        .and_then(|s| s.to_str())
        .with_context(|| format!("output {} has no usable file name", output.display()))?;
    Ok(output.with_file_name(format!("{stem}_grid.png")))
}

/// A column's label.
pub fn label_text(lambda: f64) -> String {
    format!("λ={lambda}")
}

/// The label's ink: `(width, height, mask)` at [`GLYPH_SCALE`] ([`crate::sheet::label_mask`]).
pub fn label_mask(text: &str) -> (usize, usize, Vec<bool>) {
    crate::sheet::label_mask(text, GLYPH_SCALE)
}

/// Where a column's label starts: `(x, y)` of its mask's top-left corner in the sheet.
pub fn label_origin(column: usize, text: &str) -> (usize, usize) {
    let (w, h, _) = label_mask(text);
    (
        column * TILE + TILE.saturating_sub(w) / 2,
        GRID_VIEWS * TILE + LABEL_HEIGHT.saturating_sub(h) / 2,
    )
}

/// The tiles of one result: [`GRID_VIEWS`] RGB views of [`TILE`] pixels.
pub fn tiles(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> anyhow::Result<Images> {
    let mut renderer = raster_diff::CpuRenderer::default();
    Ok(stylize::run_pictures::turntable(
        &mut renderer,
        positions,
        faces,
        GRID_VIEWS,
        TILE,
        GRID_FOV_DEG,
    )?)
}

/// The sheet of the module docs for `(λ, tiles)` columns.
pub fn sheet(columns: &[(f64, Images)]) -> Images {
    let labelled: Vec<(String, &Images)> = columns
        .iter()
        .map(|(lambda, tiles)| (label_text(*lambda), tiles))
        .collect();
    sheet_labelled(&labelled)
}

/// The sheet for columns with their own labels (`s=1.5` for `apply --strength`).
pub fn sheet_labelled(columns: &[(String, &Images)]) -> Images {
    let width = columns.len() * TILE;
    let mut canvas = Canvas::new(width, GRID_VIEWS * TILE + LABEL_HEIGHT);
    for (j, (text, tiles)) in columns.iter().enumerate() {
        for v in 0..GRID_VIEWS.min(tiles.count) {
            canvas.paste(&crop(tiles, v), 0, j * TILE, v * TILE);
        }
        let (x0, y0) = label_origin(j, text);
        canvas.draw_text(text, GLYPH_SCALE, x0, y0, [0.0; 3]);
    }
    canvas.into_images()
}

/// View `v` of `tiles`, cut to at most [`TILE`]×[`TILE`] pixels (a tile never spills into its
/// neighbour).
fn crop(tiles: &Images, v: usize) -> Images {
    let (w, h) = (tiles.width.min(TILE), tiles.height.min(TILE));
    let c = tiles.channels;
    let view = tiles.view(v);
    let mut rgb = Vec::with_capacity(w * h * c);
    for y in 0..h {
        rgb.extend_from_slice(&view[y * tiles.width * c..(y * tiles.width + w) * c]);
    }
    Images {
        count: 1,
        height: h,
        width: w,
        channels: c,
        rgb,
    }
}

/// Writes the sheet to `path` (atomically).
pub fn write_sheet(path: &Path, columns: &[(f64, Images)]) -> anyhow::Result<()> {
    stylize::run_pictures::write_png_atomic(path, &sheet(columns))
        .with_context(|| format!("cannot write {}", path.display()))
}

/// [`write_sheet`] for labelled columns ([`sheet_labelled`]).
pub fn write_sheet_labelled(path: &Path, columns: &[(String, Images)]) -> anyhow::Result<()> {
    let refs: Vec<(String, &Images)> = columns.iter().map(|(t, i)| (t.clone(), i)).collect();
    stylize::run_pictures::write_png_atomic(path, &sheet_labelled(&refs))
        .with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_fit_their_strip_and_have_a_glyph_for_every_character_of_a_lambda() {
        for lambda in [0.0, 5.0, 8.5, 11.0, -0.25, 1e-7, 123456.0] {
            let text = label_text(lambda);
            for c in text.chars() {
                assert!(
                    FONT.iter().any(|(g, _)| *g == c),
                    "no glyph for {c:?} in {text}"
                );
            }
        }
        let (w, h, mask) = label_mask("λ=11");
        assert!(w <= TILE && h <= LABEL_HEIGHT);
        assert!(mask.iter().any(|&b| b));
    }
}
