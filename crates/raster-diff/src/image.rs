//! Image output: PNG files and contact sheets, of grey or RGB batches (a grey batch is written as
//! RGB with three equal channels).
//!
//! Colour: the renderer's values are written **as they are** — 8-bit sRGB-tagged PNG with
//! byte = round(255 · clamp(v, 0, 1)), no transfer curve applied. Those are the pixels the
//! guidance model sees (the reference feeds its render straight to the diffusion model, which
//! treats it as an ordinary sRGB image), so the files show what was optimized.
//! [`Encoding::SrgbFromLinear`] applies the sRGB OETF first, for viewing the shading as linear light.

use std::io::Write;

use crate::{Images, RenderError};

/// How values become bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Encoding {
    /// byte = round(255 · clamp(v, 0, 1)) (what the guidance sees).
    #[default]
    Direct,
    /// Treat v as linear light and apply the sRGB transfer function first.
    SrgbFromLinear,
}

/// The sRGB OETF (IEC 61966-2-1).
pub fn linear_to_srgb(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// 8-bit value of one channel.
pub fn to_byte(v: f32, encoding: Encoding) -> u8 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    let v = match encoding {
        Encoding::Direct => v,
        Encoding::SrgbFromLinear => linear_to_srgb(v),
    };
    (v * 255.0).round() as u8
}

/// RGB8 bytes of view `index` (a grey view's byte in all three channels).
pub fn view_bytes(
    images: &Images,
    index: usize,
    encoding: Encoding,
) -> Result<Vec<u8>, RenderError> {
    let n = images.view_len();
    if index >= images.count || images.rgb.len() < (index + 1) * n {
        return Err(RenderError::InvalidInput(format!(
            "no view {index} in {} images",
            images.count
        )));
    }
    let values = &images.rgb[index * n..(index + 1) * n];
    Ok(if images.is_grey() {
        values
            .iter()
            .flat_map(|&v| [to_byte(v, encoding); 3])
            .collect()
    } else {
        values.iter().map(|&v| to_byte(v, encoding)).collect()
    })
}

/// Encodes view `index` as an 8-bit RGB PNG (sRGB chunk set) into `writer`; a grey view is
/// written as RGB with three equal channels.
pub fn write_png<W: Write>(
    writer: W,
    images: &Images,
    index: usize,
    encoding: Encoding,
) -> Result<(), RenderError> {
    let bytes = view_bytes(images, index, encoding)?;
    let (w, h) = (u32::try_from(images.width), u32::try_from(images.height));
    let (Ok(w), Ok(h)) = (w, h) else {
        return Err(RenderError::InvalidInput("image too large for PNG".into()));
    };
    let mut enc = png::Encoder::new(writer, w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    let io = |e: png::EncodingError| RenderError::InvalidInput(format!("PNG encoding failed: {e}"));
    let mut wr = enc.write_header().map_err(io)?;
    wr.write_image_data(&bytes).map_err(io)?;
    wr.finish().map_err(io)
}

/// Lays the views out in a grid of `columns` columns (row-major, view 0 top-left) on white; the
/// sheet has the images' channel count.
pub fn contact_sheet(images: &Images, columns: usize) -> Images {
    let columns = columns.clamp(1, images.count.max(1));
    let rows = images.count.div_ceil(columns);
    let (h, w, c) = (images.height, images.width, images.channels);
    let (sh, sw) = (rows * h, columns * w);
    let mut values = vec![1.0f32; sh * sw * c];
    for v in 0..images.count {
        let (r0, c0) = ((v / columns) * h, (v % columns) * w);
        for y in 0..h {
            let src = (v * h + y) * w * c;
            let dst = ((r0 + y) * sw + c0) * c;
            if let (Some(s), Some(d)) = (
                images.rgb.get(src..src + w * c),
                values.get_mut(dst..dst + w * c),
            ) {
                d.copy_from_slice(s);
            }
        }
    }
    Images {
        count: 1,
        height: sh,
        width: sw,
        channels: c,
        rgb: values,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contact_sheet_places_views_row_major_on_white() {
        // Three 1×2 views, values 0.1, 0.2, 0.3; two columns → 2×4 sheet, last cell white.
        let rgb = [0.1f32, 0.2, 0.3].iter().flat_map(|&v| [v; 6]).collect();
        let imgs = Images {
            count: 3,
            height: 1,
            width: 2,
            channels: 3,
            rgb,
        };
        let sheet = contact_sheet(&imgs, 2);
        assert_eq!((sheet.count, sheet.height, sheet.width), (1, 2, 4));
        let px = |y: usize, x: usize| sheet.rgb[(y * 4 + x) * 3];
        assert_eq!(
            [px(0, 0), px(0, 1), px(0, 2), px(0, 3)],
            [0.1, 0.1, 0.2, 0.2]
        );
        assert_eq!(
            [px(1, 0), px(1, 1), px(1, 2), px(1, 3)],
            [0.3, 0.3, 1.0, 1.0]
        );
    }

    #[test]
    fn png_round_trips_direct_bytes() {
        let rgb = vec![0.0f32, 0.5, 1.0, 2.0, -1.0, f32::NAN];
        let imgs = Images {
            count: 1,
            height: 1,
            width: 2,
            channels: 3,
            rgb,
        };
        let mut buf = Vec::new();
        write_png(&mut buf, &imgs, 0, Encoding::Direct).expect("encode");
        let dec = png::Decoder::new(std::io::Cursor::new(buf));
        let mut reader = dec.read_info().expect("header");
        let mut out = vec![0u8; reader.output_buffer_size()];
        let info = reader.next_frame(&mut out).expect("frame");
        assert_eq!((info.width, info.height), (2, 1));
        assert_eq!(&out[..6], &[0, 128, 255, 255, 0, 0]);
        assert!(write_png(Vec::new(), &imgs, 1, Encoding::Direct).is_err());
    }

    #[test]
    fn a_grey_batch_gives_the_sheet_and_png_bytes_of_its_rgb_expansion() {
        let grey = Images::with_channels(3, 2, 2, 1, (0..12).map(|v| v as f32 / 11.0).collect())
            .expect("grey batch");
        let sheet = contact_sheet(&grey, 2);
        assert_eq!(sheet.channels, 1);
        assert_eq!(sheet.to_rgb(), contact_sheet(&grey.to_rgb(), 2));
        let png = |images: &Images| {
            let mut buf = Vec::new();
            write_png(&mut buf, images, 0, Encoding::Direct).expect("encode");
            buf
        };
        assert_eq!(png(&sheet), png(&sheet.to_rgb()));
        for v in 0..3 {
            assert_eq!(
                view_bytes(&grey, v, Encoding::SrgbFromLinear).expect("bytes"),
                view_bytes(&grey.to_rgb(), v, Encoding::SrgbFromLinear).expect("bytes")
            );
        }
        assert!(view_bytes(&grey, 3, Encoding::Direct).is_err());
    }

    #[test]
    fn srgb_transfer_matches_known_values() {
        assert_eq!(to_byte(0.0, Encoding::SrgbFromLinear), 0);
        assert_eq!(to_byte(1.0, Encoding::SrgbFromLinear), 255);
        // Linear 0.214 is sRGB ≈ 0.5 (code value 128 ± 1).
        assert!((to_byte(0.214, Encoding::SrgbFromLinear) as i32 - 128).abs() <= 1);
    }
}
