//! The comparison sheet of `stylize apply --lambda A,B,…` (several λ): `OUT_grid.png` beside the
//! meshes, one **column per λ** (in the order given) of [`GRID_VIEWS`] turntable views (rows,
//! azimuth 360°·k/N, elevation 20°, CPU renderer, [`TILE`]-pixel square tiles, the same bounding
//! framing for every column, so sizes compare), and under each column a white strip of
//! [`LABEL_HEIGHT`] pixels with its label `λ=<value>` in black, centred, drawn with the built-in
//! 5×7 pixel font ([`FONT`]) scaled ×[`GLYPH_SCALE`].

use std::path::{Path, PathBuf};

use anyhow::Context;
use raster_diff::Images;

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

/// 5×7 glyphs: seven rows, the five low bits of each a pixel (bit 4 leftmost).
pub const FONT: &[(char, [u8; 7])] = &[
    ('0', [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E]),
    ('1', [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E]),
    ('2', [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F]),
    ('3', [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E]),
    ('4', [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02]),
    ('5', [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E]),
    ('6', [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E]),
    ('7', [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08]),
    ('8', [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E]),
    ('9', [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C]),
    ('.', [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C]),
    ('-', [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00]),
    ('+', [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00]),
    ('e', [0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E]),
    ('=', [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00]),
    ('λ', [0x18, 0x04, 0x04, 0x0A, 0x0A, 0x11, 0x11]),
];

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

/// The label's ink: `(width, height, mask)` at [`GLYPH_SCALE`], one pixel of space between
/// glyphs; characters without a glyph are drawn as a blank.
pub fn label_mask(text: &str) -> (usize, usize, Vec<bool>) {
    let s = GLYPH_SCALE;
    let chars: Vec<char> = text.chars().collect();
    let width = (chars.len() * 6).saturating_sub(1) * s;
    let height = 7 * s;
    let mut mask = vec![false; width * height];
    for (i, c) in chars.iter().enumerate() {
        let Some((_, rows)) = FONT.iter().find(|(g, _)| g == c) else {
            continue;
        };
        for (r, bits) in rows.iter().enumerate() {
            for col in 0..5 {
                if bits & (0x10 >> col) != 0 {
                    for dy in 0..s {
                        for dx in 0..s {
                            let x = (i * 6 + col) * s + dx;
                            mask[(r * s + dy) * width + x] = true;
                        }
                    }
                }
            }
        }
    }
    (width, height, mask)
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
    let width = columns.len() * TILE;
    let height = GRID_VIEWS * TILE + LABEL_HEIGHT;
    let mut rgb = vec![1.0f32; width * height * 3];
    for (j, (lambda, tiles)) in columns.iter().enumerate() {
        for v in 0..GRID_VIEWS.min(tiles.count) {
            let view = tiles.view(v);
            for y in 0..TILE.min(tiles.height) {
                for x in 0..TILE.min(tiles.width) {
                    let src = (y * tiles.width + x) * 3;
                    let dst = ((v * TILE + y) * width + j * TILE + x) * 3;
                    rgb[dst..dst + 3].copy_from_slice(&view[src..src + 3]);
                }
            }
        }
        let text = label_text(*lambda);
        let (w, h, mask) = label_mask(&text);
        let (x0, y0) = label_origin(j, &text);
        for y in 0..h {
            for x in 0..w.min(width - x0) {
                if mask[y * w + x] {
                    let dst = ((y0 + y) * width + x0 + x) * 3;
                    rgb[dst..dst + 3].copy_from_slice(&[0.0; 3]);
                }
            }
        }
    }
    Images {
        count: 1,
        height,
        width,
        channels: 3,
        rgb,
    }
}

/// Writes the sheet to `path` (atomically).
pub fn write_sheet(path: &Path, columns: &[(f64, Images)]) -> anyhow::Result<()> {
    stylize::run_pictures::write_png_atomic(path, &sheet(columns))
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
