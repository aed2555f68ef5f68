//! CLIP image preprocessing: PIL's bicubic resize on float planes, then per-channel normalization.

use std::borrow::Cow;

use crate::OnnxError;

/// Per output index: the first input index and the normalized weights of PIL's `Image.BICUBIC`
/// (`precompute_coeffs`: pixel centres at +0.5, kernel widened by the scale factor when reducing,
/// weights renormalized at the borders). This is exactly csd's antialiased Keys cubic (a = −0.5), the
/// kernel the guidance resizes with, so the two share one implementation.
fn resample_coefficients(input: usize, output: usize) -> Result<Vec<csd::resize::Taps>, OnnxError> {
    csd::Resize1d::cubic_antialias(input, output)
        .map(|r| r.rows().to_vec())
        .map_err(|e| OnnxError::Shape {
            model: "bicubic resize".into(),
            message: e.to_string(),
        })
}

/// Resizes one image `(row, column, channel)` with `channels` interleaved channels from
/// `height × width` to `out_height × out_width` with PIL's `Image.BICUBIC` on float planes: the
/// horizontal pass first (into an f32 intermediate), then the vertical one, each a normalized
/// bicubic kernel widened by the scale factor when reducing. Values are not clamped (bicubic can
/// overshoot slightly, as PIL's float mode does). Errors when a size is zero or `image` does not
/// hold `height · width · channels` values.
pub fn resize_bicubic(
    image: &[f32],
    height: usize,
    width: usize,
    channels: usize,
    out_height: usize,
    out_width: usize,
) -> Result<Vec<f32>, OnnxError> {
    if [height, width, channels, out_height, out_width].contains(&0)
        || image.len() != height * width * channels
    {
        return Err(OnnxError::Shape {
            model: "bicubic resize".into(),
            message: format!(
                "{} values for a {height}×{width}×{channels} image resized to {out_height}×{out_width} \
                 (sizes must be positive and the value count height·width·channels)",
                image.len()
            ),
        });
    }
    let horizontal = resample_coefficients(width, out_width)?;
    let mut tmp = vec![0.0f32; height * out_width * channels];
    for r in 0..height {
        for (
            o,
            csd::resize::Taps {
                start: lo,
                weights: w,
            },
        ) in horizontal.iter().enumerate()
        {
            for c in 0..channels {
                let s: f64 = w
                    .iter()
                    .enumerate()
                    .map(|(k, wk)| wk * f64::from(image[(r * width + lo + k) * channels + c]))
                    .sum();
                tmp[(r * out_width + o) * channels + c] = s as f32;
            }
        }
    }
    let vertical = resample_coefficients(height, out_height)?;
    let mut out = vec![0.0f32; out_height * out_width * channels];
    for (
        o,
        csd::resize::Taps {
            start: lo,
            weights: w,
        },
    ) in vertical.iter().enumerate()
    {
        for col in 0..out_width {
            for c in 0..channels {
                let s: f64 = w
                    .iter()
                    .enumerate()
                    .map(|(k, wk)| wk * f64::from(tmp[((lo + k) * out_width + col) * channels + c]))
                    .sum();
                out[(o * out_width + col) * channels + c] = s as f32;
            }
        }
    }
    Ok(out)
}

/// CLIP preprocessing of `count` square RGB images `(image, row, column, channel)` of side `side`,
/// values in `[0, 1]`: bicubic resize to `size` (skipped when `side == size`), then
/// `(x − mean) / std`, returned as `pixel_values` `(image, channel, row, column)`. Errors when
/// `rgb` does not hold `count · side² · 3` values or a size is zero.
pub fn preprocess(
    rgb: &[f32],
    count: usize,
    side: usize,
    size: usize,
    mean: [f32; 3],
    std: [f32; 3],
) -> Result<Vec<f32>, OnnxError> {
    let per = side * side * 3;
    if side == 0 || size == 0 || rgb.len() != count * per {
        return Err(OnnxError::Shape {
            model: "CLIP preprocessing".into(),
            message: format!(
                "{} values for {count} RGB images of side {side} (need count·side²·3 = {}), target size {size}",
                rgb.len(),
                count * per
            ),
        });
    }
    let mut out = Vec::with_capacity(count * 3 * size * size);
    for n in 0..count {
        let img = &rgb[n * per..(n + 1) * per];
        let resized: Cow<'_, [f32]> = if side == size {
            Cow::Borrowed(img)
        } else {
            Cow::Owned(resize_bicubic(img, side, side, 3, size, size)?)
        };
        for c in 0..3 {
            out.extend(resized.chunks_exact(3).map(|px| (px[c] - mean[c]) / std[c]));
        }
    }
    Ok(out)
}

/// `a·b / (|a| |b|)` in f64; 0 when either vector is zero. Slices of different lengths are compared
/// over the shorter one (callers compare embeddings of one model, which have equal lengths).
pub fn cosine_similarity(a: &[f32], b: &[f32]) -> f64 {
    let (mut ab, mut aa, mut bb) = (0.0f64, 0.0f64, 0.0f64);
    for (&x, &y) in a.iter().zip(b) {
        let (x, y) = (f64::from(x), f64::from(y));
        ab += x * y;
        aa += x * x;
        bb += y * y;
    }
    if aa == 0.0 || bb == 0.0 {
        return 0.0;
    }
    (ab / (aa.sqrt() * bb.sqrt())).clamp(-1.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resize_preserves_constants_and_identity() {
        let img: Vec<f32> = (0..5 * 5 * 3).map(|i| (i % 7) as f32 / 7.0).collect();
        assert_eq!(resize_bicubic(&img, 5, 5, 3, 5, 5).ok(), Some(img));
        let flat = vec![0.25f32; 48 * 48 * 3];
        let small = resize_bicubic(&flat, 48, 48, 3, 7, 7).expect("resize");
        assert!(small.iter().all(|v| (v - 0.25).abs() < 1e-6));
        let big = resize_bicubic(&flat, 48, 48, 3, 100, 100).expect("resize");
        assert!(resize_bicubic(&flat, 48, 48, 3, 0, 7).is_err());
        assert!(resize_bicubic(&flat, 47, 48, 3, 7, 7).is_err());
        assert!(big.iter().all(|v| (v - 0.25).abs() < 1e-6));
    }

    #[test]
    fn downscaling_is_antialiased() {
        // A one-pixel checkerboard averages to its mean when reduced 4×; point sampling would alias.
        let side = 32;
        let img: Vec<f32> = (0..side * side)
            .flat_map(|k| {
                let v = ((k / side + k % side) % 2) as f32;
                [v; 3]
            })
            .collect();
        let small = resize_bicubic(&img, side, side, 3, 8, 8).expect("resize");
        assert!(
            small.iter().all(|v| (v - 0.5).abs() < 0.02),
            "{:?}",
            &small[..6]
        );
    }

    #[test]
    fn cosine_similarity_is_scale_invariant_and_bounded() {
        let a = [1.0f32, 2.0, 3.0];
        let b = [2.0f32, 4.0, 6.0];
        assert!((cosine_similarity(&a, &b) - 1.0).abs() < 1e-12);
        assert!((cosine_similarity(&a, &[-1.0, -2.0, -3.0]) + 1.0).abs() < 1e-12);
        assert!(cosine_similarity(&[1.0, 0.0], &[0.0, 1.0]).abs() < 1e-12);
        assert_eq!(cosine_similarity(&[0.0, 0.0], &[1.0, 1.0]), 0.0);
    }
}
