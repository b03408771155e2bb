//! Semi-Global Matching on a rectified pair (Hirschmüller 2008), block-matching variant as
//! OpenCV's `StereoSGBM` computes it, so that its parameters mean the same here and its output
//! can serve as the reference (the fusion paper §2 uses a learned model, UniMatch, whose weights cannot
//! be fetched here; see [`crate::stereo::source`] for plugging one in).
//!
//! The stages, each in its own module:
//! 1. `cost`: the Birchfield–Tomasi sampling-insensitive pixel cost on an x-Sobel image clipped
//!    to `±pre_filter_cap`, plus the same cost on the raw intensities divided by 4, summed over
//!    channels and over a `block_size²` window;
//! 2. `paths`: the costs aggregated along 5 (or 8) straight paths with penalties `P1` for a
//!    disparity change of one and `P2` for larger jumps (Hirschmüller's Eq. 13);
//! 3. `select`: winner-takes-all with the uniqueness ratio, a parabola through the three
//!    aggregated costs around the minimum for sub-pixel disparity, and the left–right check
//!    against the disparity each right pixel would choose;
//! 4. `filter`: a 3×3 median and the speckle filter (small connected regions are dropped).
//!
//! Disparities are `x_left − x_right` in pixels and are kept in OpenCV's fixed point (1/16 px,
//! `i16`), costs as saturating `i16`, so that an image pair gives the same map as OpenCV's.
//! Columns left of `min_disparity + num_disparities` cannot see every candidate in the right
//! image: OpenCV leaves them invalid ([`Border::OpenCv`]); by default ([`Border::Partial`]) they
//! are matched against the candidates inside the right image, which keeps the left band of a
//! wide-baseline pair (otherwise the results are the same).

mod cost;
mod filter;
mod paths;
mod select;

use crate::error::{GeomError, Result};

pub use filter::{median3x3, speckle_filter};

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

    fn row(&self, y: usize) -> &'a [u8] {
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
    fn mirrored(&self) -> Self {
        let mut fixed = self.fixed.clone();
        for row in fixed.chunks_mut(self.width.max(1)) {
            row.reverse();
        }
        Self { fixed, ..*self }
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

    fn resolve(&self, channels: usize) -> Result<Resolved> {
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

/// The disparity of every left pixel: `left(x, y)` matches `right(x − d, y)`.
pub fn match_left(left: &GrayOrRgb, right: &GrayOrRgb, params: &SgmParams) -> Result<Disparity> {
    if (left.width, left.height, left.channels) != (right.width, right.height, right.channels) {
        return Err(GeomError::invalid(
            "stereo pair",
            format!(
                "left image is {}×{}×{}, right {}×{}×{}",
                left.width, left.height, left.channels, right.width, right.height, right.channels
            ),
        ));
    }
    let p = params.resolve(left.channels)?;
    let invalid = ((p.min_d - 1) * DISP_SCALE) as i16;
    let (w, h) = (left.width, left.height);
    let mut fixed = vec![invalid; w * h];
    if let Some(layout) = cost::Layout::new(w, &p) {
        let c = cost::block_costs(left, right, &layout, &p);
        let s = paths::aggregate(&c, h, &layout, &p);
        select::disparities(&s, &layout, &p, &mut fixed);
    }
    median3x3(&mut fixed, w, h);
    if params.speckle_window_size > 0 {
        speckle_filter(
            &mut fixed,
            w,
            h,
            invalid,
            params.speckle_window_size,
            params.speckle_range * DISP_SCALE,
        );
    }
    Ok(Disparity {
        width: w,
        height: h,
        fixed,
        invalid,
    })
}

/// The disparity of every right pixel, `right(x, y)` matches `left(x + d, y)`: the pair mirrored
/// left–right and swapped, matched with [`match_left`], and mirrored back.
pub fn match_right(left: &GrayOrRgb, right: &GrayOrRgb, params: &SgmParams) -> Result<Disparity> {
    let (ml, mr) = (mirror(right), mirror(left));
    let ml = GrayOrRgb {
        data: &ml,
        ..*right
    };
    let mr = GrayOrRgb { data: &mr, ..*left };
    Ok(match_left(&ml, &mr, params)?.mirrored())
}

/// Both disparity maps of a pair, computed side by side.
pub fn match_both(
    left: &GrayOrRgb,
    right: &GrayOrRgb,
    params: &SgmParams,
) -> Result<(Disparity, Disparity)> {
    let (l, r) = rayon::join(
        || match_left(left, right, params),
        || match_right(left, right, params),
    );
    Ok((l?, r?))
}

fn mirror(img: &GrayOrRgb) -> Vec<u8> {
    let cn = img.channels;
    let mut out = Vec::with_capacity(img.data.len());
    for y in 0..img.height {
        let row = img.row(y);
        for x in (0..img.width).rev() {
            out.extend_from_slice(&row[x * cn..(x + 1) * cn]);
        }
    }
    out
}

#[cfg(test)]
mod tests;
