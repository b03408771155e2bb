//! From aggregated costs to disparities: winner-takes-all, the uniqueness test, a parabola for
//! the sub-pixel position and the left–right consistency check, each as OpenCV's `StereoSGBM`.

use rayon::prelude::*;

use super::cost::Layout;
use super::params::{Border, DISP_SCALE, Resolved};

/// Writes the fixed-point disparity of every matched pixel into `out` (`width × height`, filled
/// with the invalid value beforehand).
pub(crate) fn disparities(s: &[i16], layout: &Layout, p: &Resolved, out: &mut [i16]) {
    let n = layout.row_len();
    out.par_chunks_mut(layout.width)
        .zip(s.par_chunks(n))
        .for_each(|(row, s_row)| select_row(s_row, layout, p, row));
}

/// The disparity each pixel of one row chooses, with the right image's choices for the check.
fn select_row(s: &[i16], layout: &Layout, p: &Resolved, out: &mut [i16]) {
    let (w, d) = (layout.width, layout.d);
    let invalid = ((p.min_d - 1) * DISP_SCALE) as i16;
    // For each right pixel: the lowest cost any left pixel matched it with, and that disparity.
    let mut right_cost = vec![i16::MAX; w];
    let mut right_disp = vec![invalid; w];
    let edges = claimable_columns(w, p);
    // Right to left, so that among equal costs the rightmost left pixel claims a right pixel.
    for i in (0..layout.columns).rev() {
        let sp = &s[i * d..(i + 1) * d];
        let (best, min) = arg_min(sp);
        if !is_unique(sp, best, min, p.uniqueness) {
            continue;
        }
        let x = layout.x0 + i;
        let xr = x as i64 - best as i64 - p.min_d as i64;
        if !(edges.0..edges.1).contains(&xr) {
            continue;
        }
        let xr = xr as usize;
        if right_cost[xr] > min {
            right_cost[xr] = min;
            right_disp[xr] = (best as i32 + p.min_d) as i16;
        }
        out[x] = (sub_pixel(sp, best) + p.min_d * DISP_SCALE) as i16;
    }
    left_right_check(out, &right_disp, layout, p, invalid);
}

/// The right image's columns a left pixel's match may land in. With `Border::Partial`, a match
/// whose block (with its Sobel neighbours) reaches past an edge of the right image that the
/// candidates can cross is dropped: near that edge, pixels whose true match lies outside the
/// right image have only wrong candidates, and no right pixel may claim them to fail the check
/// below. Positive disparities cross the left edge; negative ones (a rectification with
/// per-image principal points) cross the right edge. (OpenCV's columns never come this close.)
fn claimable_columns(w: usize, p: &Resolved) -> (i64, i64) {
    let w = w as i64;
    let inner = match p.border {
        Border::Partial => p.half_block as i64 + 1,
        Border::OpenCv => return (0, w),
    };
    let max_d = p.min_d as i64 + p.d as i64 - 1;
    let lo = if max_d > 0 { inner } else { 0 };
    let hi = if p.min_d < 0 { w - inner } else { w };
    (lo, hi)
}

/// The first disparity index of the smallest cost, and that cost.
#[inline]
pub(super) fn arg_min(sp: &[i16]) -> (usize, i16) {
    let mut best = (0, i16::MAX);
    for (k, &v) in sp.iter().enumerate() {
        if v < best.1 {
            best = (k, v);
        }
    }
    best
}

/// No disparity more than one away from `best` comes within `ratio` percent of its cost.
#[inline]
pub(super) fn is_unique(sp: &[i16], best: usize, min: i16, ratio: i32) -> bool {
    sp.iter()
        .enumerate()
        .all(|(k, &v)| best.abs_diff(k) <= 1 || v as i32 * (100 - ratio) >= min as i32 * 100)
}

/// `best` in 1/16 px, moved to the vertex of the parabola through its two neighbours' costs.
#[inline]
pub(super) fn sub_pixel(sp: &[i16], best: usize) -> i32 {
    let scaled = best as i32 * DISP_SCALE;
    if best == 0 || best + 1 >= sp.len() {
        return scaled;
    }
    let (a, b, c) = (sp[best - 1] as i32, sp[best] as i32, sp[best + 1] as i32);
    let denom2 = (a + c - 2 * b).max(1);
    // Integer division truncates towards zero, as the reference does.
    scaled + ((a - c) * DISP_SCALE + denom2) / (denom2 * 2)
}

/// Drops a left disparity when the right pixels at both its floor and its ceiling chose a
/// disparity that differs from it by more than `disp12_max_diff`.
fn left_right_check(out: &mut [i16], right: &[i16], layout: &Layout, p: &Resolved, invalid: i16) {
    let w = layout.width as i64;
    let disagrees = |xr: i64, d: i32| {
        (0..w).contains(&xr) && {
            let r = right[xr as usize] as i32;
            r >= p.min_d && (r - d).abs() > p.disp12_max_diff
        }
    };
    for x in layout.x0..layout.x0 + layout.columns {
        let d1 = out[x] as i32;
        if d1 == invalid as i32 {
            continue;
        }
        let (floor, ceil) = (d1 >> 4, (d1 + DISP_SCALE - 1) >> 4);
        if disagrees(x as i64 - floor as i64, floor) && disagrees(x as i64 - ceil as i64, ceil) {
            out[x] = invalid;
        }
    }
}
