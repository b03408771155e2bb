//! The matcher's parameters, as OpenCV's `StereoSGBM` names them, and their form resolved for
//! one image pair.

use crate::error::{GeomError, Result};

/// Sub-pixel steps per pixel of the fixed-point disparities (OpenCV's `DISP_SCALE`).
pub const DISP_SCALE: i32 = 16;

/// How many straight paths aggregate the costs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Paths {
    /// Left-to-right, right-to-left and the three from the row above (OpenCV's `MODE_SGBM`).
    #[default]
    Five,
    /// The five plus the three from the row below (OpenCV's `MODE_HH`).
    Eight,
}

/// Which left columns are matched.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Border {
    /// Every column; candidates `x − d` that fall outside the right image cost the most a pixel
    /// can cost, so a pixel near the left edge chooses among the candidates it can see. With a
    /// wide disparity range (wide baselines) OpenCV's rule loses a large band of the image.
    #[default]
    Partial,
    /// Only the columns whose every candidate lies inside the right image, as OpenCV does: the
    /// columns left of `min_disparity + num_disparities` stay invalid.
    OpenCv,
}

/// Parameters of the matcher, named and defaulted as OpenCV's `StereoSGBM`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SgmParams {
    /// Smallest disparity searched (pixels).
    pub min_disparity: i32,
    /// Number of disparities searched, `min_disparity .. min_disparity + num_disparities`.
    pub num_disparities: usize,
    /// Side of the square window the pixel costs are summed over (odd).
    pub block_size: usize,
    /// Penalty for a disparity change of one pixel between neighbours; `None`: `8·cn·block_size²`.
    pub p1: Option<i32>,
    /// Penalty for larger changes; `None`: `32·cn·block_size²`.
    pub p2: Option<i32>,
    /// Clip of the x-Sobel prefilter.
    pub pre_filter_cap: i32,
    /// Percent by which the best cost must beat every other disparity further than one pixel away.
    pub uniqueness_ratio: i32,
    /// Largest difference (integer pixels) allowed by the left–right check.
    pub disp12_max_diff: i32,
    /// Connected regions of at most this many pixels are dropped (0: no speckle filter).
    pub speckle_window_size: usize,
    /// Largest disparity step (pixels) inside one connected region.
    pub speckle_range: i32,
    pub paths: Paths,
    pub border: Border,
}

impl Default for SgmParams {
    fn default() -> Self {
        Self {
            min_disparity: 0,
            num_disparities: 64,
            block_size: 5,
            p1: None,
            p2: None,
            pre_filter_cap: 63,
            uniqueness_ratio: 10,
            disp12_max_diff: 1,
            speckle_window_size: 100,
            speckle_range: 2,
            paths: Paths::Five,
            border: Border::Partial,
        }
    }
}

/// Parameters resolved for one image pair: penalties filled in and checked against the 16-bit
/// cost range.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Resolved {
    pub min_d: i32,
    /// Number of disparities.
    pub d: usize,
    pub half_block: usize,
    pub p1: i16,
    pub p2: i16,
    pub cap: i32,
    pub uniqueness: i32,
    pub disp12_max_diff: i32,
    pub paths: Paths,
    pub border: Border,
}

impl SgmParams {
    /// `P1` and `P2` for images of `channels` channels.
    pub fn penalties(&self, channels: usize) -> (i32, i32) {
        let area = (channels * self.block_size * self.block_size) as i32;
        let p1 = self.p1.unwrap_or(8 * area);
        let p2 = self.p2.unwrap_or(32 * area).max(p1 + 1);
        (p1, p2)
    }

    pub(super) fn resolve(&self, channels: usize) -> Result<Resolved> {
        let bad = |m: String| Err(GeomError::invalid("stereo parameters", m));
        if self.num_disparities < 2 || self.num_disparities > 1024 {
            return bad(format!(
                "{} disparities (expected 2 to 1024)",
                self.num_disparities
            ));
        }
        if self.block_size.is_multiple_of(2) || self.block_size > 11 {
            return bad(format!(
                "block size {} (expected odd, 1 to 11)",
                self.block_size
            ));
        }
        if !(1..=63).contains(&self.pre_filter_cap) {
            return bad(format!(
                "pre-filter cap {} (expected 1 to 63)",
                self.pre_filter_cap
            ));
        }
        if !(0..100).contains(&self.uniqueness_ratio) {
            return bad(format!(
                "uniqueness ratio {} (expected 0 to 99)",
                self.uniqueness_ratio
            ));
        }
        let (p1, p2) = self.penalties(channels);
        // The largest windowed cost: each channel adds at most 2·cap (Sobel) + 255/4 (raw).
        let cap = self.pre_filter_cap.max(15) | 1;
        let window = (channels * self.block_size * self.block_size) as i64;
        let largest = window * (2 * cap as i64 + 63) + p2 as i64;
        if p1 <= 0 || largest > i16::MAX as i64 {
            return bad(format!(
                "P1 {p1}, P2 {p2} with a {0}×{0} block of {channels} channels overflow the \
                 16-bit costs (largest {largest}); use a smaller block or penalties",
                self.block_size
            ));
        }
        let max_d = self.min_disparity as i64 + self.num_disparities as i64;
        if self.min_disparity < -1000 || max_d * DISP_SCALE as i64 >= i16::MAX as i64 {
            return bad(format!(
                "disparities {} to {max_d} do not fit 1/16-pixel 16-bit values",
                self.min_disparity
            ));
        }
        Ok(Resolved {
            min_d: self.min_disparity,
            d: self.num_disparities,
            half_block: self.block_size / 2,
            p1: p1 as i16,
            p2: p2 as i16,
            cap,
            uniqueness: self.uniqueness_ratio,
            disp12_max_diff: self.disp12_max_diff.max(1),
            paths: self.paths,
            border: self.border,
        })
    }
}
