//! Labelled picture sheets: the one piece behind `stylize apply --lambda A,B,…`'s comparison sheet
//! ([`crate::cmd::apply_grid`]) and `stylize batch`'s grid of its rows ([`crate::batch_grid`]).
//!
//! - [`Canvas`]: an RGB sheet (values in `[0, 1]`, row-major, white where nothing is drawn) with
//!   [`Canvas::paste`] (one view of an [`Images`] at a position, clipped), [`Canvas::fill`] and
//!   [`Canvas::draw_text`];
//! - text is drawn with the built-in 5×7 pixel font [`FONT`] (printable ASCII, `λ` and `…`), each
//!   font pixel a `scale`×`scale` square, glyphs 6 font pixels apart ([`label_mask`]); a character
//!   without a glyph is drawn as a blank; [`fit_text`] shortens a text to a width with `…`;
//! - [`resample`] crops a square of a picture and box-filters it to a tile's size (each tile pixel
//!   is the mean of the source pixels its footprint starts in, at least one), so a run's render
//!   becomes a tile without rendering again; [`read_png_region`] reads the part of a picture needed.

use std::path::Path;

use anyhow::{Context, bail};
use raster_diff::Images;

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
    ('=', [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00]),
    ('λ', [0x18, 0x04, 0x04, 0x0A, 0x0A, 0x11, 0x11]),
    ('…', [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x15]),
    (' ', [0x00; 7]),
    ('!', [0x04, 0x04, 0x04, 0x04, 0x04, 0x00, 0x04]),
    ('"', [0x0A, 0x0A, 0x00, 0x00, 0x00, 0x00, 0x00]),
    ('#', [0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A]),
    ('%', [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03]),
    ('&', [0x0C, 0x12, 0x14, 0x08, 0x15, 0x12, 0x0D]),
    ('\'', [0x04, 0x04, 0x00, 0x00, 0x00, 0x00, 0x00]),
    ('(', [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02]),
    (')', [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08]),
    ('*', [0x00, 0x04, 0x15, 0x0E, 0x15, 0x04, 0x00]),
    (',', [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08]),
    ('/', [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00]),
    (':', [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00]),
    (';', [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x04, 0x08]),
    ('<', [0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02]),
    ('>', [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08]),
    ('?', [0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04]),
    ('@', [0x0E, 0x11, 0x17, 0x15, 0x17, 0x10, 0x0F]),
    ('[', [0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E]),
    (']', [0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E]),
    ('_', [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F]),
    ('A', [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11]),
    ('B', [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E]),
    ('C', [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E]),
    ('D', [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C]),
    ('E', [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F]),
    ('F', [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10]),
    ('G', [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F]),
    ('H', [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11]),
    ('I', [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E]),
    ('J', [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C]),
    ('K', [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11]),
    ('L', [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F]),
    ('M', [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11]),
    ('N', [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11]),
    ('O', [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E]),
    ('P', [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10]),
    ('Q', [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D]),
    ('R', [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11]),
    ('S', [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E]),
    ('T', [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04]),
    ('U', [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E]),
    ('V', [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04]),
    ('W', [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A]),
    ('X', [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11]),
    ('Y', [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04]),
    ('Z', [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F]),
    ('a', [0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F]),
    ('b', [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E]),
    ('c', [0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E]),
    ('d', [0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F]),
    ('e', [0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E]),
    ('f', [0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08]),
    ('g', [0x00, 0x00, 0x0F, 0x11, 0x0F, 0x01, 0x0E]),
    ('h', [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11]),
    ('i', [0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E]),
    ('j', [0x02, 0x00, 0x06, 0x02, 0x02, 0x12, 0x0C]),
    ('k', [0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12]),
    ('l', [0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E]),
    ('m', [0x00, 0x00, 0x1A, 0x15, 0x15, 0x11, 0x11]),
    ('n', [0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11]),
    ('o', [0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E]),
    ('p', [0x00, 0x00, 0x1E, 0x11, 0x1E, 0x10, 0x10]),
    ('q', [0x00, 0x00, 0x0D, 0x13, 0x0F, 0x01, 0x01]),
    ('r', [0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10]),
    ('s', [0x00, 0x00, 0x0E, 0x10, 0x0E, 0x01, 0x1E]),
    ('t', [0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06]),
    ('u', [0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0D]),
    ('v', [0x00, 0x00, 0x11, 0x11, 0x11, 0x0A, 0x04]),
    ('w', [0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0A]),
    ('x', [0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11]),
    ('y', [0x00, 0x00, 0x11, 0x11, 0x0F, 0x01, 0x0E]),
    ('z', [0x00, 0x00, 0x1F, 0x02, 0x04, 0x08, 0x1F]),
];

/// Font pixels from one glyph's left edge to the next one's (5 of glyph, 1 of space).
pub const ADVANCE: usize = 6;
/// Font pixels of a glyph's height.
pub const GLYPH_ROWS: usize = 7;

/// The width in pixels of `text` drawn at `scale` ([`label_mask`]'s width).
pub fn text_width(text: &str, scale: usize) -> usize {
    (text.chars().count() * ADVANCE).saturating_sub(1) * scale
}

/// `text` if it fits `max_width` pixels at `scale`, otherwise its longest prefix followed by `…`
/// that fits (just `…` when nothing more does). Leading and trailing blanks are dropped, and runs of
/// white space (new lines too) become one space.
pub fn fit_text(text: &str, max_width: usize, scale: usize) -> String {
    let text = text.split_whitespace().collect::<Vec<_>>().join(" ");
    if text_width(&text, scale) <= max_width {
        return text;
    }
    let chars: Vec<char> = text.chars().collect();
    let mut n = chars.len();
    while n > 0 {
        let candidate: String = chars[..n].iter().collect::<String>().trim_end().to_string() + "…";
        if text_width(&candidate, scale) <= max_width {
            return candidate;
        }
        n -= 1;
    }
    "…".to_string()
}

/// The ink of `text`: `(width, height, mask)` at `scale` pixels per font pixel, one font pixel of
/// space between glyphs; characters without a glyph are drawn as a blank.
pub fn label_mask(text: &str, scale: usize) -> (usize, usize, Vec<bool>) {
    let s = scale.max(1);
    let chars: Vec<char> = text.chars().collect();
    let width = text_width(text, s);
    let height = GLYPH_ROWS * s;
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
                            let x = (i * ADVANCE + col) * s + dx;
                            mask[(r * s + dy) * width + x] = true;
                        }
                    }
                }
            }
        }
    }
    (width, height, mask)
}

/// The left edge at which `text` at `scale` is centred in the span `[x0, x0 + span)` (at `x0`
/// when it is wider).
pub fn centred(x0: usize, span: usize, text: &str, scale: usize) -> usize {
    x0 + span.saturating_sub(text_width(text, scale)) / 2
}

/// An RGB sheet being drawn: `width`×`height` pixels, values in `[0, 1]`, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Canvas {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `height`×`width`×3 values.
    pub rgb: Vec<f32>,
}

impl Canvas {
    /// A white sheet.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            rgb: vec![1.0; width * height * 3],
        }
    }

    /// Sets pixel `(x, y)` (outside the sheet: nothing).
    pub fn set(&mut self, x: usize, y: usize, rgb: [f32; 3]) {
        if x < self.width && y < self.height {
            let i = (y * self.width + x) * 3;
            self.rgb[i..i + 3].copy_from_slice(&rgb);
        }
    }

    /// Fills the rectangle of `w`×`h` pixels at `(x0, y0)` (clipped to the sheet).
    pub fn fill(&mut self, x0: usize, y0: usize, w: usize, h: usize, rgb: [f32; 3]) {
        for y in y0..(y0 + h).min(self.height) {
            for x in x0..(x0 + w).min(self.width) {
                self.set(x, y, rgb);
            }
        }
    }

    /// Copies view `view` of `images` (grey or RGB) with its top-left corner at `(x0, y0)`, clipped
    /// to the sheet.
    pub fn paste(&mut self, images: &Images, view: usize, x0: usize, y0: usize) {
        if view >= images.count {
            return;
        }
        let pixels = images.view(view);
        let c = images.channels;
        for y in 0..images.height {
            for x in 0..images.width {
                let i = (y * images.width + x) * c;
                let rgb = if c >= 3 {
                    [pixels[i], pixels[i + 1], pixels[i + 2]]
                } else {
                    [pixels[i]; 3]
                };
                self.set(x0 + x, y0 + y, rgb);
            }
        }
    }

    /// Draws `text` in `rgb` at `scale` with its mask's top-left corner at `(x0, y0)` (clipped;
    /// the pixels between the glyphs keep what is under them).
    pub fn draw_text(&mut self, text: &str, scale: usize, x0: usize, y0: usize, rgb: [f32; 3]) {
        let (w, h, mask) = label_mask(text, scale);
        for y in 0..h {
            for x in 0..w {
                if mask[y * w + x] {
                    self.set(x0 + x, y0 + y, rgb);
                }
            }
        }
    }

    /// The sheet as a one-view RGB [`Images`].
    pub fn into_images(self) -> Images {
        Images {
            count: 1,
            height: self.height,
            width: self.width,
            channels: 3,
            rgb: self.rgb,
        }
    }

    /// Writes the sheet as a PNG at `path`, atomically.
    pub fn write_png(self, path: &Path) -> anyhow::Result<()> {
        stylize::run_pictures::write_png_atomic(path, &self.into_images())
            .with_context(|| format!("cannot write {}", path.display()))
    }
}

/// The square of `side` pixels at `(x0, y0)` of view `view` of `images`, box-filtered to a
/// `size`×`size` RGB tile: tile pixel `(x, y)` is the mean of the source pixels `(i, j)` of the
/// square with `⌊x·side/size⌋ ≤ i < max(⌊(x+1)·side/size⌋, ⌊x·side/size⌋ + 1)` (likewise `j`), so
/// an integer downscale averages blocks and an integer upscale repeats pixels. Errors when the
/// square does not lie inside the picture.
pub fn resample(
    images: &Images,
    view: usize,
    (x0, y0, side): (usize, usize, usize),
    size: usize,
) -> anyhow::Result<Images> {
    if view >= images.count
        || side == 0
        || size == 0
        || x0 + side > images.width
        || y0 + side > images.height
    {
        bail!(
            "a {side}-pixel square at ({x0}, {y0}) of view {view} does not lie inside {} views of \
             {}×{} pixels",
            images.count,
            images.width,
            images.height
        );
    }
    let pixels = images.view(view);
    let c = images.channels;
    let span = |k: usize| {
        let a = k * side / size;
        (a, ((k + 1) * side / size).max(a + 1))
    };
    let mut rgb = Vec::with_capacity(size * size * 3);
    for y in 0..size {
        let (ya, yb) = span(y);
        for x in 0..size {
            let (xa, xb) = span(x);
            let mut sum = [0.0f64; 3];
            for j in ya..yb {
                for i in xa..xb {
                    let p = ((y0 + j) * images.width + x0 + i) * c;
                    for (k, s) in sum.iter_mut().enumerate() {
                        *s += f64::from(pixels[p + if c >= 3 { k } else { 0 }]);
                    }
                }
            }
            let n = ((yb - ya) * (xb - xa)) as f64;
            rgb.extend(sum.iter().map(|s| (s / n) as f32));
        }
    }
    Ok(Images {
        count: 1,
        height: size,
        width: size,
        channels: 3,
        rgb,
    })
}

/// The largest picture [`read_png_region`] reads, in pixels (a 16384² sheet; larger is refused
/// before any pixel buffer is made). A run's `before_after.png` is at most 64 × 1024 by 2 × 1024.
pub const MAX_PNG_PIXELS: u64 = 16384 * 16384;

/// Reads the rectangle `region(width, height) = (x0, y0, w, h)` of a non-interlaced 8-bit (or
/// 16-bit, reduced to 8) grey, grey+alpha, RGB, RGBA or palette PNG as one RGB view with values
/// `byte / 255` (alpha dropped). The picture is decoded row by row and only the rectangle is kept,
/// so memory is one row plus the rectangle however wide the picture.
pub fn read_png_region(
    path: &Path,
    region: impl FnOnce(usize, usize) -> anyhow::Result<(usize, usize, usize, usize)>,
) -> anyhow::Result<Images> {
    let file =
        std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let unreadable = || format!("{} is not a readable PNG", path.display());
    let mut reader = decoder.read_info().with_context(unreadable)?;
    let (width, height, interlaced) = {
        let info = reader.info();
        (info.width, info.height, info.interlaced)
    };
    if u64::from(width) * u64::from(height) > MAX_PNG_PIXELS {
        bail!(
            "{} is {width}×{height} pixels, more than the {MAX_PNG_PIXELS} read here",
            path.display()
        );
    }
    if interlaced {
        bail!("{}: an interlaced PNG (not read here)", path.display());
    }
    let (width, height) = (width as usize, height as usize);
    let (x0, y0, w, h) = region(width, height)?;
    if x0 + w > width || y0 + h > height {
        bail!(
            "{}: the {w}×{h} rectangle at ({x0}, {y0}) does not lie inside its {width}×{height} \
             pixels",
            path.display()
        );
    }
    let channels = match reader.output_color_type().0 {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Indexed => bail!("{}: an unexpanded palette image", path.display()),
    };
    let mut rgb = Vec::with_capacity(w * h * 3);
    for y in 0..y0 + h {
        let row = reader
            .next_row()
            .with_context(unreadable)?
            .with_context(|| format!("{}: fewer rows than its header says", path.display()))?;
        if y < y0 {
            continue;
        }
        let data = row.data();
        let wanted = data
            .get(x0 * channels..(x0 + w) * channels)
            .with_context(|| format!("{}: a row shorter than its header says", path.display()))?;
        for px in wanted.chunks_exact(channels) {
            let v = |k: usize| f32::from(px[k]) / 255.0;
            if channels >= 3 {
                rgb.extend([v(0), v(1), v(2)]);
            } else {
                rgb.extend([v(0); 3]);
            }
        }
    }
    Ok(Images {
        count: 1,
        height: h,
        width: w,
        channels: 3,
        rgb,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_printable_ascii_character_has_a_glyph_and_glyphs_are_distinct() {
        for c in (0x20u8..0x7f).map(char::from) {
            if "$\\^`{|}~".contains(c) {
                continue;
            }
            assert!(FONT.iter().any(|(g, _)| *g == c), "no glyph for {c:?}");
        }
        for (i, (a, ga)) in FONT.iter().enumerate() {
            for (b, gb) in &FONT[i + 1..] {
                assert_ne!(a, b, "{a:?} twice");
                assert!(ga != gb || *a == ' ', "{a:?} and {b:?} look the same");
            }
        }
    }

    #[test]
    fn fit_text_shortens_with_an_ellipsis_to_the_width() {
        assert_eq!(fit_text("  a  cube\n", 100, 1), "a cube");
        let long = "a bunny made of lego bricks";
        let fitted = fit_text(long, 12 * 6 * 2, 2);
        assert!(text_width(&fitted, 2) <= 12 * 6 * 2, "{fitted}");
        assert_eq!(fitted, "a bunny mad…");
        assert_eq!(fit_text("abc", 1, 2), "…");
    }

    #[test]
    fn resample_averages_blocks_and_repeats_pixels() {
        // 4×4 picture, values = x + 4y (grey → RGB).
        let grey: Vec<f32> = (0..16).map(|v| v as f32).collect();
        let img = Images {
            count: 1,
            height: 4,
            width: 4,
            channels: 1,
            rgb: grey,
        };
        let down = resample(&img, 0, (0, 0, 4), 2).unwrap_or_else(|e| panic!("{e:#}"));
        // Block (0,0): 0, 1, 4, 5 → 2.5.
        assert_eq!(down.rgb[..3], [2.5; 3]);
        assert_eq!(down.rgb[9..12], [(10.0 + 11.0 + 14.0 + 15.0) / 4.0; 3]);
        let up = resample(&img, 0, (2, 2, 2), 4).unwrap_or_else(|e| panic!("{e:#}"));
        // The square's top-left pixel (value 10) fills the tile's top-left 2×2 block.
        for (x, y) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            assert_eq!(up.rgb[(y * 4 + x) * 3], 10.0);
        }
        assert_eq!(up.rgb[(3 * 4 + 3) * 3], 15.0);
        assert!(resample(&img, 0, (1, 0, 4), 2).is_err());
    }

    #[test]
    fn read_png_region_keeps_the_rectangle_asked_for() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("p.png");
        // 5×3 RGB picture, red = x·50, green = y·100, blue = 7.
        let mut canvas = Canvas::new(5, 3);
        for y in 0..3 {
            for x in 0..5 {
                canvas.set(
                    x,
                    y,
                    [
                        x as f32 * 50.0 / 255.0,
                        y as f32 * 100.0 / 255.0,
                        7.0 / 255.0,
                    ],
                );
            }
        }
        canvas.write_png(&path).unwrap_or_else(|e| panic!("{e:#}"));
        let part = read_png_region(&path, |w, h| {
            assert_eq!((w, h), (5, 3));
            Ok((1, 1, 3, 2))
        })
        .unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!((part.width, part.height), (3, 2));
        let bytes: Vec<u8> = part.rgb.iter().map(|v| (v * 255.0).round() as u8).collect();
        assert_eq!(&bytes[..6], &[50, 100, 7, 100, 100, 7]);
        assert_eq!(&bytes[15..18], &[150, 200, 7]);
        assert!(read_png_region(&path, |_, _| Ok((3, 0, 3, 1))).is_err());
        std::fs::write(&path, b"not a png").unwrap_or_else(|e| panic!("{e}"));
        assert!(read_png_region(&path, |w, h| Ok((0, 0, w, h))).is_err());
    }
}
