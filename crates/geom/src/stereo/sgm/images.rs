//! What the matcher reads and writes: 8-bit images and fixed-point disparity maps.

use super::params::DISP_SCALE;
use crate::error::{GeomError, Result};

/// An 8-bit image with 1 or 3 interleaved channels, row-major (the matcher's input).
#[derive(Clone, Copy, Debug)]
pub struct GrayOrRgb<'a> {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: &'a [u8],
}

impl<'a> GrayOrRgb<'a> {
    pub fn new(width: usize, height: usize, channels: usize, data: &'a [u8]) -> Result<Self> {
        if !matches!(channels, 1 | 3) {
            return Err(GeomError::invalid(
                "stereo image",
                format!("{channels} channels (expected 1 or 3)"),
            ));
        }
        if data.len() != width * height * channels {
            return Err(GeomError::invalid(
                "stereo image",
                format!("{} values for {width}×{height}×{channels}", data.len()),
            ));
        }
        Ok(Self {
            width,
            height,
            channels,
            data,
        })
    }

    pub(super) fn row(&self, y: usize) -> &'a [u8] {
        let n = self.width * self.channels;
        &self.data[y * n..(y + 1) * n]
    }
}

/// A disparity map in 1/16 px (`x_left − x_right`), `invalid` where no disparity was found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Disparity {
    pub width: usize,
    pub height: usize,
    /// Row-major fixed-point disparities, `DISP_SCALE` steps per pixel.
    pub fixed: Vec<i16>,
    /// The value marking "no disparity": `(min_disparity − 1)·DISP_SCALE`, as OpenCV.
    pub invalid: i16,
}

impl Disparity {
    /// The disparity at `(x, y)` in pixels, `None` where invalid.
    pub fn get(&self, x: usize, y: usize) -> Option<f32> {
        let v = self.fixed[y * self.width + x];
        (v != self.invalid).then(|| v as f32 / DISP_SCALE as f32)
    }

    /// Disparities in pixels, NaN where invalid.
    pub fn to_f32(&self) -> Vec<f32> {
        self.fixed
            .iter()
            .map(|&v| {
                if v == self.invalid {
                    f32::NAN
                } else {
                    v as f32 / DISP_SCALE as f32
                }
            })
            .collect()
    }

    /// The fraction of pixels with a disparity.
    pub fn valid_fraction(&self) -> f64 {
        let n = self.fixed.iter().filter(|&&v| v != self.invalid).count();
        n as f64 / self.fixed.len().max(1) as f64
    }

    /// The same map mirrored left–right (used to match right-to-left).
    pub(super) fn mirrored(&self) -> Self {
        let mut fixed = self.fixed.clone();
        for row in fixed.chunks_mut(self.width.max(1)) {
            row.reverse();
        }
        Self { fixed, ..*self }
    }
}
