//! Matching costs: the Birchfield–Tomasi pixel cost ("Depth discontinuities by pixel-to-pixel
//! stereo", 1999) on two image planes per channel, summed over a square block.
//!
//! Plane one is the horizontal Sobel derivative clipped to `±cap` and shifted by `cap` (a
//! prefilter that removes brightness offsets between the views); plane two is the raw intensity,
//! whose cost is divided by 4. As in OpenCV, the first and last column of every plane hold the
//! neutral value `cap`. The cost of left pixel `x` at disparity `d` is
//! `min(max(0, u − v⁺, v⁻ − u), max(0, v − u⁺, u⁻ − v))` with `u = left(x)`, `v = right(x − d)`
//! and `·⁻`, `·⁺` the smallest and largest of a pixel and its two half-pixel interpolants.

use rayon::prelude::*;

use super::images::GrayOrRgb;
use super::params::{Border, Resolved};

/// Which columns of the left image are matched and how the cost volume is laid out.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layout {
    /// Image width.
    pub width: usize,
    /// First matched column: every candidate `x − d` must fall inside the right image.
    pub x0: usize,
    /// Number of matched columns.
    pub columns: usize,
    /// Disparities per pixel.
    pub d: usize,
}

impl Layout {
    /// `None` when no column can be matched (the image is narrower than the disparity range).
    pub fn new(width: usize, p: &Resolved) -> Option<Self> {
        let max_d = p.min_d + p.d as i32;
        let (x0, x1) = match p.border {
            Border::OpenCv => (max_d.max(0) as i64, width as i64 + p.min_d.min(0) as i64),
            Border::Partial => (0, width as i64),
        };
        (x1 > x0).then(|| Self {
            width,
            x0: x0 as usize,
            columns: (x1 - x0) as usize,
            d: p.d,
        })
    }

    /// Values per image row of a cost volume.
    pub fn row_len(&self) -> usize {
        self.columns * self.d
    }
}

/// Rows per parallel task of [`block_costs`]: each band recomputes the `2r` rows around it.
const BAND: usize = 32;

/// The block-summed cost volume, `height × columns × d` values.
pub(crate) fn block_costs(
    left: &GrayOrRgb,
    right: &GrayOrRgb,
    layout: &Layout,
    p: &Resolved,
) -> Vec<i16> {
    let (h, n) = (left.height, layout.row_len());
    let r = p.half_block;
    let mut block = vec![0i16; h * n];
    block
        .par_chunks_mut(BAND * n)
        .enumerate()
        .for_each(|(b, out)| {
            // The rows this band's blocks reach, with the image's first and last row repeated.
            let (y0, y1) = (b * BAND, (b * BAND + BAND).min(h));
            let first = y0 as i64 - r as i64;
            let rows = y1 - y0 + 2 * r;
            let mut horizontal = vec![0i16; rows * n];
            for (k, row) in horizontal.chunks_mut(n).enumerate() {
                let y = (first + k as i64).clamp(0, h as i64 - 1) as usize;
                row_costs(left, right, y, layout, p, row);
            }
            for (k, o) in out.chunks_mut(n).enumerate() {
                for j in 0..=2 * r {
                    add_into(o, &horizontal[(k + j) * n..(k + j + 1) * n]);
                }
            }
        });
    block
}

/// The pixel costs of row `y`, summed over the block's columns, into `row`.
fn row_costs(
    left: &GrayOrRgb,
    right: &GrayOrRgb,
    y: usize,
    layout: &Layout,
    p: &Resolved,
    row: &mut [i16],
) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2")]
        fn avx2(
            l: &GrayOrRgb,
            r: &GrayOrRgb,
            y: usize,
            la: &Layout,
            p: &Resolved,
            row: &mut [i16],
        ) {
            let pixel = pixel_costs(l, r, y, la, p);
            box_sum_columns(&pixel, row, la, p.half_block);
        }
        if fewview_scene::cpu::avx2() {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { avx2(left, right, y, layout, p, row) };
        }
    }
    let pixel = pixel_costs(left, right, y, layout, p);
    box_sum_columns(&pixel, row, layout, p.half_block);
}

#[inline(always)]
fn add_into(acc: &mut [i16], v: &[i16]) {
    for (a, b) in acc.iter_mut().zip(v) {
        *a = a.wrapping_add(*b);
    }
}

#[inline(always)]
/// Sums each column's costs over `2r + 1` neighbouring columns, the border column repeated.
fn box_sum_columns(pixel: &[i16], out: &mut [i16], layout: &Layout, r: usize) {
    let (cols, d) = (layout.columns, layout.d);
    for x in 0..cols {
        let o = &mut out[x * d..(x + 1) * d];
        for k in 0..=2 * r {
            let xx = (x as i64 + k as i64 - r as i64).clamp(0, cols as i64 - 1) as usize;
            add_into(o, &pixel[xx * d..(xx + 1) * d]);
        }
    }
}

/// One plane of an image row: the clipped x-Sobel of channel `c` (`raw = false`) or the raw
/// channel, with the neutral value in the first and last column.
fn plane(img: &GrayOrRgb, y: usize, c: usize, raw: bool, cap: i32) -> Vec<i16> {
    let (w, cn) = (img.width, img.channels);
    let row = img.row(y);
    let up = img.row(y.saturating_sub(1));
    let down = img.row((y + 1).min(img.height - 1));
    let mut out = vec![cap as i16; w];
    for x in 1..w.saturating_sub(1) {
        let at = |r: &[u8], xx: usize| r[xx * cn + c] as i32;
        out[x] = if raw {
            at(row, x) as i16
        } else {
            let g = 2 * (at(row, x + 1) - at(row, x - 1)) + at(up, x + 1) - at(up, x - 1)
                + at(down, x + 1)
                - at(down, x - 1);
            (g.clamp(-cap, cap) + cap) as i16
        };
    }
    out
}

/// The smallest and largest of each value and its two half-way interpolants.
fn half_pixel_range(v: &[i16]) -> (Vec<i16>, Vec<i16>) {
    let w = v.len();
    let mut lo = vec![0i16; w];
    let mut hi = vec![0i16; w];
    for x in 0..w {
        let c = v[x];
        let l = if x > 0 { (c + v[x - 1]) / 2 } else { c };
        let r = if x + 1 < w { (c + v[x + 1]) / 2 } else { c };
        lo[x] = c.min(l).min(r);
        hi[x] = c.max(l).max(r);
    }
    (lo, hi)
}

/// The pixel costs of row `y`, `columns × d` values.
#[inline(always)]
fn pixel_costs(
    left: &GrayOrRgb,
    right: &GrayOrRgb,
    y: usize,
    layout: &Layout,
    p: &Resolved,
) -> Vec<i16> {
    let (w, d) = (layout.width, layout.d);
    let mut cost = vec![0i16; layout.row_len()];
    for raw in [false, true] {
        let shift = if raw { 2 } else { 0 };
        for c in 0..left.channels {
            let u = plane(left, y, c, raw, p.cap);
            let mut v = plane(right, y, c, raw, p.cap);
            // Reversed, so that the candidates `x − d` of one pixel are contiguous and
            // increasing in `d`: right column `x − d` sits at `w − 1 − x + d`.
            v.reverse();
            let (v_lo, v_hi) = half_pixel_range(&v);
            let (u_lo, u_hi) = half_pixel_range(&u);
            // What a candidate outside the right image costs: the most this plane can add.
            let outside = if raw { 255 >> shift } else { 2 * p.cap as i16 };
            for i in 0..layout.columns {
                let x = layout.x0 + i;
                let k = w as i64 - 1 - x as i64 + p.min_d as i64;
                // Candidates `k + j` (j < d) inside the reversed row `0..w`.
                let first = (-k).clamp(0, d as i64) as usize;
                let end = (w as i64 - k).clamp(first as i64, d as i64) as usize;
                let cost = &mut cost[i * d..(i + 1) * d];
                if first < end {
                    let r = (k + first as i64) as usize..(k + end as i64) as usize;
                    accumulate_bt(
                        &mut cost[first..end],
                        (u[x], u_lo[x], u_hi[x]),
                        (&v[r.clone()], &v_lo[r.clone()], &v_hi[r]),
                        shift,
                    );
                }
                let (head, rest) = cost.split_at_mut(first);
                for c in head.iter_mut().chain(&mut rest[end - first..]) {
                    *c += outside;
                }
            }
        }
    }
    cost
}

/// Lanes of the fixed-width blocks of the inner loop (16 `i16` fill an AVX2 register).
const LANES: usize = 16;

/// Adds the Birchfield–Tomasi cost of one left value against `d` right candidates.
#[inline(always)]
fn accumulate_bt(
    cost: &mut [i16],
    (u, u_lo, u_hi): (i16, i16, i16),
    (v, v_lo, v_hi): (&[i16], &[i16], &[i16]),
    shift: u32,
) {
    let bt = |v: i16, lo: i16, hi: i16| {
        let left_in_right = (u - hi).max(lo - u).max(0);
        let right_in_left = (v - u_hi).max(u_lo - v).max(0);
        left_in_right.min(right_in_left) >> shift
    };
    let d = cost.len();
    let blocks = d / LANES;
    for b in 0..blocks {
        let i = b * LANES;
        let c: &mut [i16; LANES] = (&mut cost[i..i + LANES]).try_into().unwrap();
        let vv: &[i16; LANES] = v[i..i + LANES].try_into().unwrap();
        let lo: &[i16; LANES] = v_lo[i..i + LANES].try_into().unwrap();
        let hi: &[i16; LANES] = v_hi[i..i + LANES].try_into().unwrap();
        for k in 0..LANES {
            c[k] += bt(vv[k], lo[k], hi[k]);
        }
    }
    for i in blocks * LANES..d {
        cost[i] += bt(v[i], v_lo[i], v_hi[i]);
    }
}
