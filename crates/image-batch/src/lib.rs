//! [`Images`]: a batch of `f32` images with one (grey) or three (RGB) channels, the value that
//! crosses the seam between the renderer (`raster-diff`, which produces images and takes
//! dL/dimages back) and the guidance (`csd`, which takes images and returns dL/dimages).
//!
//! It lives in its own dependency-free crate so that the guidance can name the renderer's type
//! without depending on the renderer (and so on meshes, `glam` and, with its `gpu` feature, `wgpu`).
//!
//! Layout: `(view, row, column, channel)` row-major, row 0 at the top, [`Images::channels`]
//! channels per pixel (1: grey, 3: RGB); rendered values are in `[0, 1]`, gradients are any finite
//! values. A gradient has the channel count of the images it belongs to. A grey image stands for
//! the RGB image whose three channels are its value ([`Images::to_rgb`]), so dL/d(grey) is the
//! sum of dL/d(channel) over the three channels.
//!
//! ```
//! use image_batch::Images;
//! let images = Images::new(2, 4, 3, vec![0.5; 2 * 4 * 3 * 3])?;
//! assert_eq!(images.view(1).len(), 4 * 3 * 3);
//! let grad = images.zeros_like();
//! assert!(grad.same_shape(&images));
//! let grey = Images::with_channels(2, 4, 3, 1, vec![0.5; 2 * 4 * 3])?;
//! assert_eq!(grey.to_rgb(), images);
//! # Ok::<(), image_batch::ImagesError>(())
//! ```

/// Channels per pixel of an RGB batch (the default, [`Images::new`]).
pub const CHANNELS: usize = 3;

/// Channels per pixel of a grey batch.
pub const GREY: usize = 1;

/// A batch of images, `(view, row, column, channel)` row-major, with 1 (grey) or 3 (RGB)
/// channels.
#[derive(Clone, Debug, PartialEq)]
pub struct Images {
    /// Number of views.
    pub count: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Image width in pixels.
    pub width: usize,
    /// Channels per pixel: [`GREY`] (1) or [`CHANNELS`] (3, RGB).
    pub channels: usize,
    /// `count * height * width * channels` values (RGB triples for an RGB batch, one grey value
    /// per pixel for a grey one).
    pub rgb: Vec<f32>,
}

/// An empty RGB batch.
impl Default for Images {
    fn default() -> Self {
        Self {
            count: 0,
            height: 0,
            width: 0,
            channels: CHANNELS,
            rgb: Vec::new(),
        }
    }
}

/// A batch whose sizes and values disagree.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ImagesError {
    /// `rgb` does not hold `count·height·width·channels` values.
    #[error("{count} images of {height}×{width}×{channels} need {expected} values, got {actual}")]
    WrongLength {
        /// Views.
        count: usize,
        /// Rows.
        height: usize,
        /// Columns.
        width: usize,
        /// Channels per pixel.
        channels: usize,
        /// `count·height·width·channels`.
        expected: usize,
        /// `rgb.len()`.
        actual: usize,
    },
    /// A channel count other than 1 (grey) or 3 (RGB).
    #[error("images have {0} channels per pixel; 1 (grey) or 3 (RGB) are supported")]
    Channels(usize),
    /// A gradient batch does not have the shape of the images it belongs to.
    #[error("gradient images are {}×{}×{}, the last render was {}×{}×{}", got.0, got.1, got.2, expected.0, expected.1, expected.2)]
    ShapeMismatch {
        /// (count, height, width) of the gradient.
        got: (usize, usize, usize),
        /// (count, height, width) of the render.
        expected: (usize, usize, usize),
    },
    /// A gradient batch has another channel count than the images it belongs to.
    #[error("gradient images have {got} channels per pixel, the last render had {expected}")]
    ChannelMismatch {
        /// Channels of the gradient.
        got: usize,
        /// Channels of the render.
        expected: usize,
    },
    /// A gradient batch has the right sizes but not the right number of values.
    #[error("gradient images have the wrong number of values")]
    GradientLength,
}

impl Images {
    /// An RGB batch from its sizes and values; an error when `rgb.len() != count·height·width·3`.
    pub fn new(
        count: usize,
        height: usize,
        width: usize,
        rgb: Vec<f32>,
    ) -> Result<Self, ImagesError> {
        Self::with_channels(count, height, width, CHANNELS, rgb)
    }

    /// A batch of `channels` channels per pixel (1: grey, 3: RGB) from its sizes and values; an
    /// error for another channel count or when `values.len() != count·height·width·channels`.
    pub fn with_channels(
        count: usize,
        height: usize,
        width: usize,
        channels: usize,
        values: Vec<f32>,
    ) -> Result<Self, ImagesError> {
        let images = Self {
            count,
            height,
            width,
            channels,
            rgb: values,
        };
        images.check()?;
        Ok(images)
    }

    /// Values per view, `height·width·channels`.
    pub fn view_len(&self) -> usize {
        self.height * self.width * self.channels
    }

    /// Whether this is a grey batch (one channel).
    pub fn is_grey(&self) -> bool {
        self.channels == GREY
    }

    /// Checks that the channel count is 1 or 3 and that `rgb` holds `count·height·width·channels`
    /// values.
    pub fn check(&self) -> Result<(), ImagesError> {
        if self.channels != GREY && self.channels != CHANNELS {
            return Err(ImagesError::Channels(self.channels));
        }
        let expected = self.count * self.view_len();
        if self.rgb.len() != expected {
            return Err(ImagesError::WrongLength {
                count: self.count,
                height: self.height,
                width: self.width,
                channels: self.channels,
                expected,
                actual: self.rgb.len(),
            });
        }
        Ok(())
    }

    /// Zeros with the same sizes and channel count (e.g. a gradient buffer).
    pub fn zeros_like(&self) -> Self {
        Self {
            rgb: vec![0.0; self.count * self.view_len()],
            ..*self
        }
    }

    /// Whether `other` has the same count, height, width, channel count and number of values.
    pub fn same_shape(&self, other: &Images) -> bool {
        (
            self.count,
            self.height,
            self.width,
            self.channels,
            self.rgb.len(),
        ) == (
            other.count,
            other.height,
            other.width,
            other.channels,
            other.rgb.len(),
        )
    }

    /// Values of one view, `(row, column, channel)`; empty when `index` is out of range.
    pub fn view(&self, index: usize) -> &[f32] {
        let n = self.view_len();
        self.rgb.get(index * n..(index + 1) * n).unwrap_or(&[])
    }

    /// The RGB batch these images stand for: an RGB batch is returned as it is, a grey one with
    /// each value in all three channels.
    pub fn to_rgb(&self) -> Images {
        if self.channels == CHANNELS {
            return self.clone();
        }
        self.expanded()
    }

    /// [`Images::to_rgb`], consuming the batch (an RGB batch is moved, not copied).
    pub fn into_rgb(self) -> Images {
        if self.channels == CHANNELS {
            return self;
        }
        self.expanded()
    }

    /// Each value in all three channels.
    fn expanded(&self) -> Images {
        let mut rgb = Vec::with_capacity(self.rgb.len() * CHANNELS);
        for &v in &self.rgb {
            rgb.extend_from_slice(&[v; CHANNELS]);
        }
        Images {
            channels: CHANNELS,
            rgb,
            ..*self
        }
    }

    /// Checks that these gradient images have the shape of the images they belong to (`count`
    /// views of `height`×`width` with `channels` channels).
    pub fn check_gradient_shape(
        &self,
        count: usize,
        height: usize,
        width: usize,
        channels: usize,
    ) -> Result<(), ImagesError> {
        if (self.count, self.height, self.width) != (count, height, width) {
            return Err(ImagesError::ShapeMismatch {
                got: (self.count, self.height, self.width),
                expected: (count, height, width),
            });
        }
        if self.channels != channels {
            return Err(ImagesError::ChannelMismatch {
                got: self.channels,
                expected: channels,
            });
        }
        if self.rgb.len() != count * height * width * channels {
            return Err(ImagesError::GradientLength);
        }
        Ok(())
    }

    /// Per pixel, the sum of its channels in f64, `(view, row, column)`: of gradient images,
    /// dL/d(grey) for a render whose channels are one grey value (a grey batch's values widened).
    pub fn channel_sums(&self) -> Vec<f64> {
        channel_sums(&self.rgb, self.channels)
    }
}

/// Per pixel, the sum of its `channels` values in f64, added in channel order from the first
/// (`c0 + c1 + c2`; one channel: its value).
fn channel_sums(values: &[f32], channels: usize) -> Vec<f64> {
    values
        .chunks_exact(channels.max(1))
        .map(|c| {
            c[1..]
                .iter()
                .fold(f64::from(c[0]), |sum, &v| sum + f64::from(v))
        })
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
                channels: 3,
                expected: 24,
                actual: 12
            })
        );
        assert_eq!(
            e.map_err(|e| e.to_string()),
            Err("2 images of 2×2×3 need 24 values, got 12".into())
        );
        assert!(Images::with_channels(2, 2, 3, 1, vec![0.0; 12]).is_ok());
        assert_eq!(
            Images::with_channels(1, 2, 2, 2, vec![0.0; 8]),
            Err(ImagesError::Channels(2))
        );
        assert_eq!(Images::default().channels, CHANNELS);
    }

    #[test]
    fn grey_expands_to_rgb_and_channel_sums_check_the_shape() {
        let img = Images::with_channels(1, 1, 2, 1, vec![0.25, 0.5]).unwrap_or_default();
        let rgb = img.to_rgb();
        assert_eq!(rgb.rgb, vec![0.25, 0.25, 0.25, 0.5, 0.5, 0.5]);
        assert_eq!(
            (rgb.channels, rgb.count, rgb.height, rgb.width),
            (3, 1, 1, 2)
        );
        assert_eq!(img.clone().into_rgb(), rgb);
        assert_eq!(rgb.clone().into_rgb(), rgb);
        assert_eq!(rgb.channel_sums(), vec![0.75, 1.5]);
        assert_eq!(img.channel_sums(), vec![0.25, 0.5]);
        assert_eq!(rgb.check_gradient_shape(1, 1, 2, 3), Ok(()));
        assert_eq!(
            rgb.check_gradient_shape(1, 2, 1, 3)
                .map_err(|e| e.to_string()),
            Err("gradient images are 1×1×2, the last render was 1×2×1".into())
        );
        assert_eq!(
            img.check_gradient_shape(1, 1, 2, 3),
            Err(ImagesError::ChannelMismatch {
                got: 1,
                expected: 3
            })
        );
    }

    #[test]
    fn view_slices_and_zeros_like_keep_the_shape() {
        let img = Images::new(2, 1, 1, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap_or_default();
        assert_eq!(img.view(1), &[4.0, 5.0, 6.0]);
        assert!(img.view(2).is_empty());
        let z = img.zeros_like();
        assert!(z.same_shape(&img) && z.rgb.iter().all(|&v| v == 0.0));
        let grey = Images::with_channels(3, 1, 2, 1, vec![1.0; 6]).unwrap_or_default();
        assert_eq!(grey.view(2).len(), 2);
        assert!(!grey.same_shape(&img) && grey.zeros_like().same_shape(&grey));
    }
}
