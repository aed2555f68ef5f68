//! The pictures of a run directory, all rendered with the CPU renderer in orbit views (azimuth
//! 360°·k/N, elevation 20°, light at the camera):
//!
//! - `before_after.png`: the source (top row) and the result (bottom row) in the same views, the
//!   same camera distance (fitting the larger of the two bounding spheres) and the same crop — the
//!   union of every view's silhouette of both meshes, squared, with a 4 % margin — so the meshes
//!   fill their tiles and the two rows compare pixel for pixel;
//! - `turntable.png` and `turntable.gif` ([`filled_orbit`]): the result framed so that it fills
//!   its `size`×`size` tiles (one zoom and one crop for all views, so the animation does not pump),
//!   as a contact sheet and as a looping GIF ([`encode_gif`]);
//! - the helpers the previews, `eval` and the command line share: [`bounding_orbit`] and
//!   [`turntable`] (orbit views fitting a mesh's bounding sphere), [`tint_region`] (a localized
//!   run's region in [`REGION_TINT`]) and [`write_grid`] (a contact sheet of views as one PNG).

use std::io::Write;
use std::path::Path;

use crate::error::{Context, IoContext, Result, invalid};
use raster_diff::image::Encoding;
use raster_diff::{Images, Renderer};

/// Hundredths of a second each frame of `turntable.gif` is shown: 8 (36 frames turn once in
/// 2.9 s).
pub const GIF_FRAME_DELAY_CS: u16 = 8;

/// The most a [`filled_orbit`] zooms in (a mesh whose silhouettes fill less than a quarter of the
/// bounding-sphere framing is still shown whole, just not filling its tiles).
const MAX_ZOOM: f64 = 4.0;

/// Pixels [`filled_orbit`] renders at once (12 views of 512²): its views are rendered in chunks
/// of at most this many pixels, at least one view, so the renderer's buffers stay bounded however
/// long the orbit or large the zoomed render.
const ORBIT_CHUNK_PIXELS: usize = 12 * 512 * 512;

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
    write_png_atomic(path, &sheet)
}

/// Writes the first image of `images` as a PNG at `path`, atomically ([`rundir::durable`]).
pub fn write_png_atomic(path: &Path, images: &Images) -> Result<()> {
    rundir::durable::replace_with(path, |tmp| {
        let file = std::fs::File::create(tmp).io_context("cannot create", tmp)?;
        raster_diff::image::write_png(std::io::BufWriter::new(file), images, 0, Encoding::Direct)
            .with_context(|| format!("cannot write {}", path.display()))
    })
}

/// Writes a grid of images as one PNG.
pub fn write_grid(path: &Path, images: &Images) -> Result<()> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).io_context("cannot create", parent)?;
    }
    let columns = images.count.clamp(1, 4);
    let sheet = raster_diff::image::contact_sheet(images, columns.max(1));
    write_png_atomic(path, &sheet)
}

/// Tint of [`tint_region`] (a warm orange, multiplied into the shading).
pub const REGION_TINT: [f32; 3] = [1.0, 0.62, 0.3];

/// Tints, in place, the pixels whose visible triangle (`ids`, one per pixel as
/// `CpuRenderer::triangle_ids` returns them) has a corner in the region `free`.
pub fn tint_region(images: &mut Images, ids: &[u32], faces: &[[u32; 3]], free: &[bool]) {
    for (pixel, &t) in images.rgb.chunks_exact_mut(3).zip(ids) {
        let inside = faces.get(t as usize).is_some_and(|f| {
            f.iter()
                .any(|&v| free.get(v as usize).copied().unwrap_or(false))
        });
        if inside {
            for (c, k) in pixel.iter_mut().zip(REGION_TINT) {
                *c *= k;
            }
        }
    }
}

/// `n` orbit views (elevation 20°, azimuth 360°·k/n, looking at the origin, vertical field of view
/// `fov` degrees) from which the whole mesh is visible: with r the largest distance of a vertex
/// from the origin, a sphere of radius r subtends the field of view at distance r / sin(fov/2);
/// 10 % margin is added.
pub fn bounding_orbit(positions: &[[f64; 3]], n: usize, fov: f64) -> Vec<raster_diff::View> {
    let radius = positions
        .iter()
        .map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt())
        .filter(|r| r.is_finite())
        .fold(0.0_f64, f64::max)
        .max(1e-3);
    let half_fov = (fov.clamp(1.0, 179.0) * 0.5).to_radians();
    let distance = 1.1 * radius / half_fov.sin();
    raster_diff::orbit_views(n.max(1), 20.0, distance, fov)
}

/// Renders `n` turntable views of a mesh on the CPU renderer, from [`bounding_orbit`].
pub fn turntable(
    renderer: &mut raster_diff::CpuRenderer,
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    n: usize,
    size: usize,
    fov: f64,
) -> Result<Images> {
    let views = bounding_orbit(positions, n, fov);
    renderer
        .render(positions, faces, &views, size, size)
        .map(Images::into_rgb)
        .context("turntable render")
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
            .map(Images::into_rgb)
            .context("before/after render")
    };
    let (src, res) = (render(source)?, render(result)?);
    let (x0, y0, side) = silhouette_square(&[&src, &res], size);
    let (src, res) = (
        crop(&src, size, x0, y0, side),
        crop(&res, size, x0, y0, side),
    );
    let mut tiles = src;
    tiles.count += res.count;
    tiles.rgb.extend_from_slice(&res.rgb);
    Ok(raster_diff::image::contact_sheet(&tiles, views))
}

/// The smallest and largest `[x, y]` of the non-background pixels of every view of `sets` (the
/// background is each set's top-left pixel's colour), `None` when every pixel is background.
fn silhouette_bounds(sets: &[&Images], size: usize) -> Option<([usize; 2], [usize; 2])> {
    let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
    for images in sets {
        let Some(bg) = images.rgb.get(..3) else {
            continue;
        };
        let bg = [bg[0], bg[1], bg[2]];
        for v in 0..images.count {
            for y in 0..size {
                for x in 0..size {
                    let i = ((v * size + y) * size + x) * 3;
                    let Some(px) = images.rgb.get(i..i + 3) else {
                        continue;
                    };
                    if px.iter().zip(bg).any(|(a, b)| (a - b).abs() > 1e-3) {
                        lo = [lo[0].min(x), lo[1].min(y)];
                        hi = [hi[0].max(x), hi[1].max(y)];
                    }
                }
            }
        }
    }
    (lo[0] <= hi[0]).then_some((lo, hi))
}

/// The square `(x0, y0, side)` holding every non-background pixel of every view (the background
/// is the top-left pixel's colour), with a 4 % margin, inside the `size`×`size` image.
fn silhouette_square(sets: &[&Images], size: usize) -> (usize, usize, usize) {
    let Some((lo, hi)) = silhouette_bounds(sets, size) else {
        return (0, 0, size);
    };
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]) + 1;
    let side = ((extent as f64 * 1.04).ceil() as usize).clamp(1, size);
    (
        window_start(lo[0], hi[0], side, size),
        window_start(lo[1], hi[1], side, size),
        side,
    )
}

/// Start of a window of `side` pixels centred on `lo..=hi`, kept inside `0..size`.
fn window_start(lo: usize, hi: usize, side: usize, size: usize) -> usize {
    let centre = (lo + hi).div_ceil(2);
    centre
        .saturating_sub(side / 2)
        .min(size.saturating_sub(side))
}

/// The `side`×`side` window at `(x0, y0)` of every view of `images` (`size`×`size` each).
fn crop(images: &Images, size: usize, x0: usize, y0: usize, side: usize) -> Images {
    let mut out = Images {
        count: images.count,
        height: side,
        width: side,
        channels: 3,
        rgb: Vec::with_capacity(images.count * side * side * 3),
    };
    for v in 0..images.count {
        for y in y0..y0 + side {
            let row = ((v * size + y) * size + x0) * 3;
            if let Some(r) = images.rgb.get(row..row + side * 3) {
                out.rgb.extend_from_slice(r);
            }
        }
    }
    out
}

/// `views` orbit views of a mesh (CPU renderer, elevation 20°, light at the camera, looking at
/// the origin), `size`×`size` pixels each, framed so the mesh fills the tiles.
///
/// The camera first fits the bounding sphere (distance 1.1·r / sin(fov/2), as
/// [`turntable`]); a probe render at ≤ 128 pixels measures the union of the views'
/// silhouettes, and the views are rendered again at `zoom·size` pixels (zoom = probe size /
/// (silhouette side + 2 probe pixels), at most 4) and cropped to the `size`×`size` window centred
/// on the silhouettes — one zoom and one window for all views. Should the silhouettes still not
/// fit the window, the resolution is lowered until they do (down to the unzoomed render). With
/// `free`, the pixels of faces touching the region are tinted ([`tint_region`]).
///
/// Every pass renders the views in chunks of at most [`ORBIT_CHUNK_PIXELS`] pixels and keeps only
/// the silhouette bounds, or the cropped tiles, of each chunk: memory grows with `views·size²`,
/// not with the zoomed renders (the final resolution is rendered twice, for the bounds and for the
/// tiles).
pub fn filled_orbit(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    views: usize,
    size: usize,
    fov_deg: f64,
    free: Option<&[bool]>,
) -> Result<Images> {
    let size = size.max(1);
    let orbit = bounding_orbit(positions, views, fov_deg);
    let mut renderer = raster_diff::CpuRenderer::default();
    // Renders the orbit at `side` pixels a chunk of views at a time (`ORBIT_CHUNK_PIXELS`),
    // handing each chunk (with its triangle ids) to `each`.
    let mut chunks =
        |side: usize, each: &mut dyn FnMut(Images, Option<Vec<u32>>) -> Result<()>| -> Result<()> {
            let per_chunk = (ORBIT_CHUNK_PIXELS / (side * side)).max(1);
            for chunk in orbit.chunks(per_chunk) {
                let images = renderer
                    .render(positions, faces, chunk, side, side)
                    .map(Images::into_rgb)
                    .context("turntable render")?;
                each(images, renderer.triangle_ids())?;
            }
            Ok(())
        };
    // The union of the views' silhouettes at `side` pixels.
    let mut bounds_at = |side: usize| -> Result<Option<([usize; 2], [usize; 2])>> {
        let mut union: Option<([usize; 2], [usize; 2])> = None;
        chunks(side, &mut |images, _| {
            if let Some((lo, hi)) = silhouette_bounds(&[&images], side) {
                union = Some(match union {
                    Some((l, h)) => (
                        [l[0].min(lo[0]), l[1].min(lo[1])],
                        [h[0].max(hi[0]), h[1].max(hi[1])],
                    ),
                    None => (lo, hi),
                });
            }
            Ok(())
        })?;
        Ok(union)
    };
    let probe_size = size.min(128);
    let zoom = match bounds_at(probe_size)? {
        Some((lo, hi)) => {
            let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]) + 1 + 2;
            (probe_size as f64 / extent as f64).clamp(1.0, MAX_ZOOM)
        }
        None => 1.0,
    };
    let mut big = ((size as f64 * zoom).floor() as usize).max(size);
    let bounds = loop {
        let bounds = bounds_at(big)?;
        let extent = bounds.map_or(0, |(lo, hi)| (hi[0] - lo[0]).max(hi[1] - lo[1]) + 1);
        if extent <= size || big == size {
            break bounds;
        }
        big = (big * size / extent).max(size);
    };
    let (x0, y0) = match bounds {
        Some((lo, hi)) => (
            window_start(lo[0], hi[0], size, big),
            window_start(lo[1], hi[1], size, big),
        ),
        None => ((big - size) / 2, (big - size) / 2),
    };
    let mut out = Images {
        count: 0,
        height: size,
        width: size,
        channels: 3,
        rgb: Vec::with_capacity(orbit.len() * size * size * 3),
    };
    chunks(big, &mut |mut images, ids| {
        if let (Some(free), Some(ids)) = (free, ids) {
            tint_region(&mut images, &ids, faces, free);
        }
        let cropped = crop(&images, big, x0, y0, size);
        out.count += cropped.count;
        out.rgb.extend_from_slice(&cropped.rgb);
        Ok(())
    })?;
    Ok(out)
}

/// Writes `turntable.gif` (see [`encode_gif`]) atomically.
pub fn write_turntable_gif(path: &Path, frames: &Images, delay_cs: u16) -> Result<()> {
    rundir::durable::replace_with(path, |tmp| {
        let file = std::fs::File::create(tmp).io_context("cannot create", tmp)?;
        encode_gif(
            std::io::BufWriter::new(file),
            frames,
            delay_cs,
            Encoding::Direct,
        )
        .with_context(|| format!("cannot write {}", path.display()))
    })
}

/// Encodes the views of `frames` as a looping animated GIF, one frame per view, each shown
/// `delay_cs` hundredths of a second. Bytes are `raster_diff::image::to_byte` of the values (as in
/// the PNGs). When every pixel of every frame is grey (r = g = b, the untinted renderer's shading)
/// the file has one global palette of the 256 greys and the frames are exact; otherwise (a tinted
/// region) each frame is quantized to its own 256-colour palette (NeuQuant, `gif`'s
/// `Frame::from_rgb_speed` at speed 10).
pub fn encode_gif<W: Write>(
    writer: W,
    frames: &Images,
    delay_cs: u16,
    encoding: Encoding,
) -> Result<()> {
    let (Ok(width), Ok(height)) = (u16::try_from(frames.width), u16::try_from(frames.height))
    else {
        invalid!(
            "{}×{} frames are too large for a GIF (65535 pixels at most per side)",
            frames.width,
            frames.height
        );
    };
    if frames.count == 0 || width == 0 || height == 0 {
        invalid!("a GIF needs at least one non-empty frame");
    }
    let bytes = (0..frames.count)
        .map(|i| raster_diff::image::view_bytes(frames, i, encoding))
        .collect::<Result<Vec<_>, _>>()
        .context("GIF frames")?;
    let grey = bytes
        .iter()
        .all(|f| f.chunks_exact(3).all(|p| p[0] == p[1] && p[1] == p[2]));
    let palette: Vec<u8> = if grey {
        (0..=255u8).flat_map(|v| [v, v, v]).collect()
    } else {
        Vec::new()
    };
    let mut encoder = gif::Encoder::new(writer, width, height, &palette)
        .map_err(crate::Error::external)
        .context("GIF header")?;
    encoder
        .set_repeat(gif::Repeat::Infinite)
        .map_err(crate::Error::external)
        .context("GIF loop extension")?;
    for rgb in &bytes {
        let mut frame = if grey {
            let indices: Vec<u8> = rgb.chunks_exact(3).map(|p| p[0]).collect();
            gif::Frame::from_indexed_pixels(width, height, indices, None)
        } else {
            gif::Frame::from_rgb_speed(width, height, rgb, 10)
        };
        frame.delay = delay_cs;
        encoder
            .write_frame(&frame)
            .map_err(crate::Error::external)
            .context("GIF frame")?;
    }
    let mut writer = encoder
        .into_inner()
        .map_err(crate::Error::external)
        .context("GIF trailer")?;
    writer
        .flush()
        .map_err(crate::Error::external)
        .context("GIF flush")?;
    Ok(())
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

    fn bunny() -> mesh_core::TriMesh {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/meshes/bunny.obj");
        let mut m = mesh_core::io::read_mesh(&path).unwrap_or_else(|e| panic!("{e}"));
        mesh_core::normalize::side2_cube(&mut m.positions);
        m
    }

    /// Fraction of the pixels of frame `rgba` (RGBA8) that differ from its top-left pixel, and the
    /// larger side of their bounding box as a fraction of the frame's `size`.
    fn coverage(rgba: &[u8], size: usize) -> (f64, f64) {
        let bg = [rgba[0], rgba[1], rgba[2]];
        let (mut n, mut lo, mut hi) = (0usize, [usize::MAX; 2], [0usize; 2]);
        for (i, p) in rgba.chunks_exact(4).enumerate() {
            if p[..3] != bg {
                n += 1;
                let (x, y) = (i % size, i / size);
                lo = [lo[0].min(x), lo[1].min(y)];
                hi = [hi[0].max(x), hi[1].max(y)];
            }
        }
        let extent = if n == 0 {
            0
        } else {
            (hi[0] - lo[0]).max(hi[1] - lo[1]) + 1
        };
        (n as f64 / (size * size) as f64, extent as f64 / size as f64)
    }

    fn decode(bytes: &[u8]) -> (u16, u16, gif::Repeat, Vec<(u16, Vec<u8>)>) {
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::RGBA);
        let mut decoder = options
            .read_info(std::io::Cursor::new(bytes))
            .unwrap_or_else(|e| panic!("the GIF does not decode: {e}"));
        let mut frames = Vec::new();
        while let Some(frame) = decoder
            .read_next_frame()
            .unwrap_or_else(|e| panic!("frame: {e}"))
        {
            frames.push((frame.delay, frame.buffer.to_vec()));
        }
        (decoder.width(), decoder.height(), decoder.repeat(), frames)
    }

    #[test]
    fn filled_orbit_fills_its_tiles_more_than_the_bounding_sphere_framing() {
        let m = bunny();
        let size = 64;
        let filled = filled_orbit(&m.positions, &m.faces, 4, size, 60.0, None)
            .unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!((filled.count, filled.height, filled.width), (4, size, size));
        let plain = turntable(
            &mut raster_diff::CpuRenderer::default(),
            &m.positions,
            &m.faces,
            4,
            size,
            60.0,
        )
        .unwrap_or_else(|e| panic!("{e:#}"));
        let extent = |images: &Images| {
            let (lo, hi) = silhouette_bounds(&[images], size).unwrap_or(([0; 2], [0; 2]));
            (hi[0] - lo[0]).max(hi[1] - lo[1]) + 1
        };
        let (e_filled, e_plain) = (extent(&filled), extent(&plain));
        assert!(e_filled <= size, "{e_filled}");
        assert!(
            e_filled as f64 >= 0.85 * size as f64,
            "the bunny spans {e_filled} of {size} pixels"
        );
        assert!(e_filled > e_plain, "{e_filled} vs {e_plain}");
    }

    #[test]
    fn turntable_gif_decodes_loops_and_shows_the_turning_mesh() {
        let m = bunny();
        let (views, size) = (12, 48);
        let frames = filled_orbit(&m.positions, &m.faces, views, size, 60.0, None)
            .unwrap_or_else(|e| panic!("{e:#}"));
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let path = dir.path().join("turntable.gif");
        write_turntable_gif(&path, &frames, GIF_FRAME_DELAY_CS).unwrap_or_else(|e| panic!("{e:#}"));
        let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{e}"));
        let (w, h, repeat, decoded) = decode(&bytes);
        assert_eq!((w as usize, h as usize), (size, size));
        assert_eq!(repeat, gif::Repeat::Infinite);
        assert_eq!(decoded.len(), views);
        for (k, (delay, rgba)) in decoded.iter().enumerate() {
            assert_eq!(*delay, GIF_FRAME_DELAY_CS);
            assert_eq!(rgba.len(), size * size * 4);
            // Grey frames are exact: the decoded bytes are the rendered ones.
            let expected = raster_diff::image::view_bytes(&frames, k, Encoding::Direct)
                .unwrap_or_else(|e| panic!("{e}"));
            let got: Vec<u8> = rgba
                .chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect();
            assert!(got == expected, "frame {k} differs from its render");
            let (share, extent) = coverage(rgba, size);
            assert!(share > 0.2 && share < 0.95, "frame {k}: {share}");
            assert!(extent > 0.8, "frame {k}: {extent}");
        }
        for k in 1..views {
            assert!(
                decoded[k].1 != decoded[k - 1].1,
                "frames {} and {k} are equal",
                k - 1
            );
        }
    }

    #[test]
    fn tinted_frames_are_quantized_to_colour_and_still_decode() {
        let m = bunny();
        let free: Vec<bool> = m.positions.iter().map(|p| p[1] > 0.0).collect();
        let frames = filled_orbit(&m.positions, &m.faces, 3, 40, 60.0, Some(free.as_slice()))
            .unwrap_or_else(|e| panic!("{e:#}"));
        let mut bytes = Vec::new();
        encode_gif(&mut bytes, &frames, 5, Encoding::Direct).unwrap_or_else(|e| panic!("{e:#}"));
        let (_, _, _, decoded) = decode(&bytes);
        assert_eq!(decoded.len(), 3);
        // The tint (r > b) survives the quantization.
        let warm = decoded[0]
            .1
            .chunks_exact(4)
            .filter(|p| i32::from(p[0]) - i32::from(p[2]) > 40)
            .count();
        assert!(warm > 40, "{warm} tinted pixels");
    }

    #[test]
    fn gif_of_nothing_or_oversized_frames_is_an_error() {
        let empty = Images {
            count: 0,
            height: 4,
            width: 4,
            channels: 3,
            rgb: Vec::new(),
        };
        assert!(encode_gif(Vec::new(), &empty, 5, Encoding::Direct).is_err());
        let huge = Images {
            count: 1,
            height: 70_000,
            width: 1,
            channels: 3,
            rgb: Vec::new(),
        };
        let e = encode_gif(Vec::new(), &huge, 5, Encoding::Direct)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("too large"), "{e}");
    }
}
