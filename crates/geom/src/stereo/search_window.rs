//! The disparity search of a rectified pair as a window that starts at any disparity.
//!
//! The matcher keeps disparities in OpenCV's 16-bit fixed point (1/16 px), so it searches only
//! absolute disparities below 2,048 px. A rectification whose two images keep their own
//! principal points (per-image canvases, [`super::rectify`]) can put a pair's disparities in
//! the thousands. Matching `left'(x) = left(x + s)` against `right` turns the disparity `d`
//! into `d − s` and leaves every cost as it was (the same right column is compared), so the
//! window `s .. s + count` is searched as `0 .. count` and `s` is added back afterwards, in
//! floating point.

use super::sgm::{self, DISP_SCALE, GrayOrRgb, SgmParams};
use crate::error::{GeomError, Result};

/// The first disparity the window search starts from: the range's own first disparity when the
/// absolute range cannot be held by the matcher's fixed point, else 0 (no shift, so that pairs
/// with ordinary disparities match exactly as OpenCV's `StereoSGBM`).
pub fn window_start(params: &SgmParams) -> i32 {
    let last = params.min_disparity as i64 + params.num_disparities as i64;
    let fits = params.min_disparity >= -1000 && last * (DISP_SCALE as i64) < i16::MAX as i64;
    if fits { 0 } else { params.min_disparity }
}

/// Disparity maps of both rectified images (row-major, `width × height`, pixels, NaN where
/// none), searched over `params`' range from `shift` on ([`window_start`]). `left` and `right`
/// are interleaved 8-bit images of the same size with `channels` channels.
pub fn match_window(
    left: &[u8],
    right: &[u8],
    (width, height, channels): (usize, usize, usize),
    params: &SgmParams,
    shift: i32,
) -> Result<(Vec<f32>, Vec<f32>)> {
    if shift == 0 {
        let lg = GrayOrRgb::new(width, height, channels, left)?;
        let rg = GrayOrRgb::new(width, height, channels, right)?;
        let (ld, rd) = sgm::match_both(&lg, &rg, params)?;
        return Ok((ld.to_f32(), rd.to_f32()));
    }
    let inner = width as i64 - shift as i64;
    if inner < 2 {
        return Err(GeomError::invalid(
            "stereo pair",
            format!("no column of the {width}-pixel images can match at disparity {shift} or more"),
        ));
    }
    let inner = inner as usize;
    let l = columns(left, width, height, channels, shift as i64, inner);
    let r = columns(right, width, height, channels, 0, inner);
    let lg = GrayOrRgb::new(inner, height, channels, &l)?;
    let rg = GrayOrRgb::new(inner, height, channels, &r)?;
    let window = SgmParams {
        min_disparity: params.min_disparity - shift,
        ..params.clone()
    };
    let (ld, rd) = sgm::match_both(&lg, &rg, &window)?;
    let (ld, rd) = (ld.to_f32(), rd.to_f32());
    let mut lf = vec![f32::NAN; width * height];
    let mut rf = vec![f32::NAN; width * height];
    for y in 0..height {
        for x in 0..inner {
            // left'(x) is left(x + shift); right'(x) is right(x).
            let xl = x as i64 + shift as i64;
            if (0..width as i64).contains(&xl) {
                lf[y * width + xl as usize] = ld[y * inner + x] + shift as f32;
            }
            if x < width {
                rf[y * width + x] = rd[y * inner + x] + shift as f32;
            }
        }
    }
    Ok((lf, rf))
}

/// The columns `from .. from + count` of an interleaved image (zero outside it).
fn columns(
    data: &[u8],
    width: usize,
    height: usize,
    channels: usize,
    from: i64,
    count: usize,
) -> Vec<u8> {
    let mut out = vec![0u8; count * height * channels];
    for y in 0..height {
        for x in 0..count {
            let src = from + x as i64;
            if (0..width as i64).contains(&src) {
                let (s, d) = (
                    (y * width + src as usize) * channels,
                    (y * count + x) * channels,
                );
                out[d..d + channels].copy_from_slice(&data[s..s + channels]);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random-dot pair whose right image is the left one moved by `d` columns.
    fn shifted_dots(width: usize, height: usize, d: usize) -> (Vec<u8>, Vec<u8>) {
        let dot = |x: usize, y: usize| ((x * 7919 + y * 104_729) % 251) as u8;
        let left: Vec<u8> = (0..width * height)
            .map(|i| dot(i % width, i / width))
            .collect();
        // right(x) = left(x + d): every left pixel x matches right x − d.
        let right: Vec<u8> = (0..width * height)
            .map(|i| dot(i % width + d, i / width))
            .collect();
        (left, right)
    }

    /// A shift of 4,500 px, beyond the matcher's fixed point, is found by the window search;
    /// a shift the fixed point holds is searched in place, and the window finds it too.
    #[test]
    fn disparities_beyond_the_fixed_point_are_found_in_a_window() {
        let h = 24;
        // Exact in most places, within half a pixel nearly everywhere (the matcher errs by a
        // pixel or two at the image edges, and its parabola wobbles there).
        let all_at = |m: &[f32], d: f32| {
            let found: Vec<f32> = m.iter().copied().filter(|v| v.is_finite()).collect();
            let exact = found.iter().filter(|&&v| v == d).count();
            let close = found.iter().filter(|&&v| (v - d).abs() < 0.5).count();
            exact * 10 >= found.len() * 9 && close * 100 >= found.len() * 98
        };
        let valid = |m: &[f32]| m.iter().filter(|v| v.is_finite()).count();
        let (w, true_d) = (4700, 4500);
        let (left, right) = shifted_dots(w, h, true_d);
        let params = SgmParams {
            min_disparity: 4490,
            num_disparities: 32,
            ..SgmParams::default()
        };
        let shift = window_start(&params);
        assert_eq!(shift, 4490);
        let (lf, rf) = match_window(&left, &right, (w, h, 1), &params, shift).unwrap();
        // The left pixels from x = 4,500 on see their match.
        assert!(valid(&lf) > 150 * h, "{} left pixels", valid(&lf));
        assert!(valid(&rf) > 150 * h, "{} right pixels", valid(&rf));
        assert!(all_at(&lf, true_d as f32) && all_at(&rf, true_d as f32));
        // Disparities the fixed point holds: no window, and the window gives the same answer.
        let (left, right) = shifted_dots(200, h, 20);
        let params = SgmParams {
            min_disparity: 16,
            num_disparities: 16,
            ..SgmParams::default()
        };
        assert_eq!(window_start(&params), 0);
        for shift in [0, 16] {
            let (lf, rf) = match_window(&left, &right, (200, h, 1), &params, shift).unwrap();
            assert!(all_at(&lf, 20.0) && all_at(&rf, 20.0), "shift {shift}");
            assert!(
                valid(&lf) > 150 * h && valid(&rf) > 150 * h,
                "shift {shift}: {} and {} pixels",
                valid(&lf),
                valid(&rf)
            );
        }
    }
}
