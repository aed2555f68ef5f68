//! [`Images`]: a batch of `f32` RGB images, the value that crosses the seam between the renderer
//! (`raster-diff`, which produces images and takes dL/dimages back) and the guidance (`csd`, which
//! takes images and returns dL/dimages).
//!
//! It lives in its own dependency-free crate so that the guidance can name the renderer's type
//! without depending on the renderer (and so on meshes, `glam` and, with its `gpu` feature, `wgpu`).
//!
//! Layout: `(view, row, column, channel)` row-major, row 0 at the top, 3 channels; rendered values
//! are in `[0, 1]`, gradients are any finite values.
//!
//! ```
//! use image_batch::Images;
//! let images = Images::new(2, 4, 3, vec![0.5; 2 * 4 * 3 * 3])?;
//! assert_eq!(images.view(1).len(), 4 * 3 * 3);
//! let grad = images.zeros_like();
//! assert!(grad.same_shape(&images));
//! # Ok::<(), image_batch::ImagesError>(())
//! ```

/// Channels per pixel (RGB).
pub const CHANNELS: usize = 3;

/// A batch of RGB images, `(view, row, column, channel)` row-major.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Images {
    /// Number of views.
    pub count: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Image width in pixels.
    pub width: usize,
    /// `count * height * width * 3` values.
    pub rgb: Vec<f32>,
}

/// A batch whose sizes and values disagree.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ImagesError {
    /// `rgb` does not hold `count·height·width·3` values.
    #[error("{count} images of {height}×{width}×3 need {expected} values, got {actual}")]
    WrongLength {
        /// Views.
        count: usize,
        /// Rows.
        height: usize,
        /// Columns.
        width: usize,
        /// `count·height·width·3`.
        expected: usize,
        /// `rgb.len()`.
        actual: usize,
    },
    /// A gradient batch does not have the shape of the images it belongs to.
    #[error("gradient images are {}×{}×{}, the last render was {}×{}×{}", got.0, got.1, got.2, expected.0, expected.1, expected.2)]
    ShapeMismatch {
        /// (count, height, width) of the gradient.
        got: (usize, usize, usize),
        /// (count, height, width) of the render.
        expected: (usize, usize, usize),
    },
    /// A gradient batch has the right sizes but not the right number of values.
    #[error("gradient images have the wrong number of values")]
    GradientLength,
}

impl Images {
    /// A batch from its sizes and values; an error when `rgb.len() != count·height·width·3`.
    pub fn new(
        count: usize,
        height: usize,
        width: usize,
        rgb: Vec<f32>,
    ) -> Result<Self, ImagesError> {
        let images = Self {
            count,
            height,
            width,
            rgb,
        };
        images.check()?;
        Ok(images)
    }

    /// Checks that `rgb` holds `count·height·width·3` values.
    pub fn check(&self) -> Result<(), ImagesError> {
        let expected = self.count * self.height * self.width * CHANNELS;
        if self.rgb.len() != expected {
            return Err(ImagesError::WrongLength {
                count: self.count,
                height: self.height,
                width: self.width,
                expected,
                actual: self.rgb.len(),
            });
        }
        Ok(())
    }

    /// Zeros with the same sizes (e.g. a gradient buffer).
    pub fn zeros_like(&self) -> Self {
        Self {
            count: self.count,
            height: self.height,
            width: self.width,
            rgb: vec![0.0; self.count * self.height * self.width * CHANNELS],
        }
    }

    /// Whether `other` has the same count, height, width and number of values.
    pub fn same_shape(&self, other: &Images) -> bool {
        (self.count, self.height, self.width, self.rgb.len())
            == (other.count, other.height, other.width, other.rgb.len())
    }

    /// Values of one view, `(row, column, channel)`; empty when `index` is out of range.
    pub fn view(&self, index: usize) -> &[f32] {
        let n = self.height * self.width * CHANNELS;
        self.rgb.get(index * n..(index + 1) * n).unwrap_or(&[])
    }

    /// RGB images from grey values laid out `(view, row, column)`: each grey value fills all three
    /// channels (the reference shading is grey: kd is the same in every channel).
    pub fn from_grey(count: usize, height: usize, width: usize, grey: &[f64]) -> Self {
        let mut rgb = vec![0.0; grey.len() * CHANNELS];
        grey_to_rgb(grey, &mut rgb);
        Self {
            count,
            height,
            width,
            rgb,
        }
    }

    /// dL/d(grey) from these dL/d(RGB) images, checked against the shape of the render they belong
    /// to (`count` views of `height`×`width`). All three channels carry the same grey value, so
    /// dL/d(grey) is the channel sum, summed in f64.
    pub fn grey_gradient(
        &self,
        count: usize,
        height: usize,
        width: usize,
    ) -> Result<Vec<f64>, ImagesError> {
        self.check_gradient_shape(count, height, width)?;
        Ok(grey_sums(&self.rgb))
    }

    /// Checks that these dL/d(RGB) images have the shape of the render they belong to (`count`
    /// views of `height`×`width`), as [`Images::grey_gradient`] does.
    pub fn check_gradient_shape(
        &self,
        count: usize,
        height: usize,
        width: usize,
    ) -> Result<(), ImagesError> {
        if (self.count, self.height, self.width) != (count, height, width) {
            return Err(ImagesError::ShapeMismatch {
                got: (self.count, self.height, self.width),
                expected: (count, height, width),
            });
        }
        if self.rgb.len() != count * height * width * CHANNELS {
            return Err(ImagesError::GradientLength);
        }
        Ok(())
    }

    /// dL/d(grey) of view `index` alone, `(row, column)`: the part of
    /// [`Images::grey_gradient`] that belongs to that view (empty when `index` is out of range).
    pub fn view_grey_gradient(&self, index: usize) -> Vec<f64> {
        grey_sums(self.view(index))
    }
}

/// Writes grey values into RGB pixels, `rgb[3i + c] = grey[i] as f32` for every channel `c`
/// (what [`Images::from_grey`] does, for a caller that owns the destination, e.g. one view's
/// slice of a batch filled in parallel). Stops at the shorter of the two.
pub fn grey_to_rgb(grey: &[f64], rgb: &mut [f32]) {
    for (&g, px) in grey.iter().zip(rgb.chunks_exact_mut(CHANNELS)) {
        px.fill(g as f32);
    }
}

/// Per pixel, the sum of its three channels in f64.
fn grey_sums(rgb: &[f32]) -> Vec<f64> {
    rgb.chunks_exact(CHANNELS)
        .map(|c| f64::from(c[0]) + f64::from(c[1]) + f64::from(c[2]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_checks_the_value_count() {
        assert!(Images::new(1, 2, 2, vec![0.0; 12]).is_ok());
        let e = Images::new(2, 2, 2, vec![0.0; 12]);
        assert_eq!(
            e,
            Err(ImagesError::WrongLength {
                count: 2,
                height: 2,
                width: 2,
                expected: 24,
                actual: 12
            })
        );
    }

    #[test]
    fn grey_round_trip_sums_channels_and_checks_shape() {
        let img = Images::from_grey(1, 1, 2, &[0.25, 0.5]);
        assert_eq!(img.rgb, vec![0.25, 0.25, 0.25, 0.5, 0.5, 0.5]);
        assert_eq!(img.grey_gradient(1, 1, 2), Ok(vec![0.75, 1.5]));
        let e = img.grey_gradient(1, 2, 1);
        assert_eq!(
            e.map_err(|e| e.to_string()),
            Err("gradient images are 1×1×2, the last render was 1×2×1".into())
        );
    }

    #[test]
    fn view_slices_and_zeros_like_keep_the_shape() {
        let img = Images::new(2, 1, 1, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap_or_default();
        assert_eq!(img.view(1), &[4.0, 5.0, 6.0]);
        assert!(img.view(2).is_empty());
        let z = img.zeros_like();
        assert!(z.same_shape(&img) && z.rgb.iter().all(|&v| v == 0.0));
    }
}
