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
mod images;
mod params;
mod paths;
mod select;

use crate::error::{GeomError, Result};

pub use filter::{median3x3, speckle_filter};
pub use images::{Disparity, GrayOrRgb};
pub use params::{Border, DISP_SCALE, Paths, SgmParams};

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

/// Both disparity maps of a pair, computed side by side, or one after the other when a cost
/// volume is larger than [`PARALLEL_VOLUME_BYTES`] (the matcher holds three volumes at once).
pub fn match_both(
    left: &GrayOrRgb,
    right: &GrayOrRgb,
    params: &SgmParams,
) -> Result<(Disparity, Disparity)> {
    let volume = left.width * left.height * params.num_disparities * std::mem::size_of::<i16>();
    if volume > PARALLEL_VOLUME_BYTES {
        return Ok((
            match_left(left, right, params)?,
            match_right(left, right, params)?,
        ));
    }
    let (l, r) = rayon::join(
        || match_left(left, right, params),
        || match_right(left, right, params),
    );
    Ok((l?, r?))
}

/// The largest cost volume (bytes) two matchers build at once: above it, the two directions of
/// a pair run one after the other, so that a large pair needs half the memory.
pub const PARALLEL_VOLUME_BYTES: usize = 256 << 20;

/// A cost volume built outside the rectified matcher (`height × width × d` saturating `i16`,
/// hypothesis innermost; plane sweep, [`crate::stereo::sweep`]) aggregated along `params`'
/// paths with the penalties `params` gives images of `channels` channels: the same Eq. 13 as
/// the rectified matcher, with hypotheses in place of disparities.
pub(crate) fn aggregate_volume(
    cost: &[i16],
    (width, height, d): (usize, usize, usize),
    params: &SgmParams,
    channels: usize,
) -> Result<Vec<i16>> {
    let window = SgmParams {
        min_disparity: 0,
        num_disparities: d,
        border: Border::Partial,
        ..params.clone()
    };
    let p = window.resolve(channels)?;
    let layout = cost::Layout::new(width, &p)
        .ok_or_else(|| GeomError::invalid("cost volume", "no column to aggregate"))?;
    if cost.len() != height * layout.row_len() {
        return Err(GeomError::invalid(
            "cost volume",
            format!("{} values for {width}×{height}×{d}", cost.len()),
        ));
    }
    Ok(paths::aggregate(cost, height, &layout, &p))
}

/// The hypothesis a pixel's aggregated costs `sp` choose, in 1/[`DISP_SCALE`] steps (the
/// parabola through the minimum and its neighbours), as the rectified matcher chooses a
/// disparity; `None` when another hypothesis more than one step away comes within
/// `uniqueness_ratio` percent of its cost.
pub(crate) fn best_hypothesis(sp: &[i16], uniqueness_ratio: i32) -> Option<i32> {
    let (best, min) = select::arg_min(sp);
    select::is_unique(sp, best, min, uniqueness_ratio).then(|| select::sub_pixel(sp, best))
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
