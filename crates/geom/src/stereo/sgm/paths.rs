//! Cost aggregation along straight paths (Hirschmüller 2008, Eq. 13):
//! `L_r(p, d) = C(p, d) + min(L_r(p−r, d), L_r(p−r, d±1) + P1, min_k L_r(p−r, k) + P2)
//! − min_k L_r(p−r, k)`, summed over the paths into `S(p, d)`.
//!
//! The horizontal paths run row by row in parallel; then the paths from the row above (and, with
//! eight paths, beside them those from the row below) run down (up) the image, each row
//! vectorised over columns and disparities. Outside the image a path starts from zero costs.
//! Values are saturating `i16`, as OpenCV keeps them: every `L_r ≥ 0`, so the saturated sum does
//! not depend on the order of the additions.

use rayon::prelude::*;

use super::cost::Layout;
use super::params::{Paths, Resolved};

/// Sentinel of the padded path rows: no disparity below 0 or above `d − 1`.
const OUTSIDE: i16 = i16::MAX;

/// `S`, the aggregated cost volume (`height × columns × d`).
pub(crate) fn aggregate(c: &[i16], height: usize, layout: &Layout, p: &Resolved) -> Vec<i16> {
    let n = layout.row_len();
    // The horizontal paths first, every row in parallel; then the paths from above into the same
    // sums, beside those from below into their own.
    let mut s = horizontal(c, layout, p);
    let up = match p.paths {
        Paths::Eight => {
            let (_, up) = rayon::join(
                || vertical(c, height, layout, p, Direction::Down, &mut s),
                || {
                    let mut up = vec![0i16; c.len()];
                    vertical(c, height, layout, p, Direction::Up, &mut up);
                    up
                },
            );
            Some(up)
        }
        Paths::Five => {
            vertical(c, height, layout, p, Direction::Down, &mut s);
            None
        }
    };
    if let Some(up) = up {
        s.par_chunks_mut(n)
            .zip(up.par_chunks(n))
            .for_each(|(row, u)| saturating_add_into(row, u));
    }
    s
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Direction {
    Down,
    Up,
}

#[inline(always)]
fn saturating_add_into(acc: &mut [i16], v: &[i16]) {
    for (a, b) in acc.iter_mut().zip(v) {
        *a = a.saturating_add(*b);
    }
}

/// A padded path row of one pixel: `d + 2` values, the first and last [`OUTSIDE`].
fn zero_padded(d: usize) -> Vec<i16> {
    let mut v = vec![0i16; d + 2];
    v[0] = OUTSIDE;
    v[d + 1] = OUTSIDE;
    v
}

/// Lanes of the fixed-width blocks the inner loops work on (16 `i16` fill an AVX2 register).
const LANES: usize = 16;

/// One step of Eq. 13: `out = cost + min(prev(d), prev(d±1) + P1, prev_min + P2) − prev_min`
/// (both `prev` and `out` padded), `acc += out`; returns `min_d out`.
#[inline(always)]
fn step(
    cost: &[i16],
    prev: &[i16],
    prev_min: i16,
    p1: i16,
    p2: i16,
    out: &mut [i16],
    acc: &mut [i16],
) -> i16 {
    let d = cost.len();
    let jump = prev_min.saturating_add(p2);
    let mut mins = [OUTSIDE; LANES];
    let blocks = d / LANES;
    for b in 0..blocks {
        let i = b * LANES;
        let c: &[i16; LANES] = cost[i..i + LANES].try_into().unwrap();
        let below: &[i16; LANES] = prev[i..i + LANES].try_into().unwrap();
        let same: &[i16; LANES] = prev[i + 1..i + 1 + LANES].try_into().unwrap();
        let above: &[i16; LANES] = prev[i + 2..i + 2 + LANES].try_into().unwrap();
        let o: &mut [i16; LANES] = (&mut out[i + 1..i + 1 + LANES]).try_into().unwrap();
        let a: &mut [i16; LANES] = (&mut acc[i..i + LANES]).try_into().unwrap();
        for k in 0..LANES {
            let best = same[k]
                .min(below[k].saturating_add(p1))
                .min(above[k].saturating_add(p1))
                .min(jump);
            let l = c[k].saturating_add(best - prev_min);
            o[k] = l;
            a[k] = a[k].saturating_add(l);
            mins[k] = mins[k].min(l);
        }
    }
    let mut min = mins.into_iter().min().unwrap_or(OUTSIDE);
    for i in blocks * LANES..d {
        let best = prev[i + 1]
            .min(prev[i].saturating_add(p1))
            .min(prev[i + 2].saturating_add(p1))
            .min(jump);
        let l = cost[i].saturating_add(best - prev_min);
        out[i + 1] = l;
        acc[i] = acc[i].saturating_add(l);
        min = min.min(l);
    }
    min
}

/// Left-to-right plus right-to-left, every row on its own.
fn horizontal(c: &[i16], layout: &Layout, p: &Resolved) -> Vec<i16> {
    let n = layout.row_len();
    let mut s = vec![0i16; c.len()];
    s.par_chunks_mut(n)
        .zip(c.par_chunks(n))
        .for_each(|(s_row, c_row)| dispatch_row(c_row, s_row, layout, p));
    s
}

fn dispatch_row(c: &[i16], s: &mut [i16], layout: &Layout, p: &Resolved) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2")]
        fn avx2(c: &[i16], s: &mut [i16], layout: &Layout, p: &Resolved) {
            horizontal_row(c, s, layout, p);
        }
        if fewview_scene::cpu::avx2() {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { avx2(c, s, layout, p) };
        }
    }
    horizontal_row(c, s, layout, p);
}

#[inline(always)]
fn horizontal_row(c: &[i16], s: &mut [i16], layout: &Layout, p: &Resolved) {
    let d = layout.d;
    let (mut prev, mut cur) = (zero_padded(d), zero_padded(d));
    for order in [false, true] {
        prev.fill(0);
        prev[0] = OUTSIDE;
        prev[d + 1] = OUTSIDE;
        let mut prev_min = 0;
        for k in 0..layout.columns {
            let x = if order { layout.columns - 1 - k } else { k };
            let r = x * d..(x + 1) * d;
            prev_min = step(
                &c[r.clone()],
                &prev,
                prev_min,
                p.p1,
                p.p2,
                &mut cur,
                &mut s[r],
            );
            std::mem::swap(&mut prev, &mut cur);
        }
    }
}

/// The three paths from the row above (`Down`) or below (`Up`): from the pixel straight above
/// and the two diagonal neighbours.
/// Adds the three paths' costs into `s`.
fn vertical(
    c: &[i16],
    height: usize,
    layout: &Layout,
    p: &Resolved,
    dir: Direction,
    s: &mut [i16],
) {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2")]
        fn avx2(c: &[i16], h: usize, l: &Layout, p: &Resolved, dir: Direction, s: &mut [i16]) {
            vertical_paths(c, h, l, p, dir, s);
        }
        if fewview_scene::cpu::avx2() {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { avx2(c, height, layout, p, dir, s) };
        }
    }
    vertical_paths(c, height, layout, p, dir, s);
}

/// Path rows of one image row for the three vertical directions: `columns × (d + 2)` padded
/// values per direction and each pixel's minimum.
struct PathRows {
    values: [Vec<i16>; 3],
    mins: [Vec<i16>; 3],
}

impl PathRows {
    fn zeros(layout: &Layout) -> Self {
        let row: Vec<i16> = (0..layout.columns)
            .flat_map(|_| zero_padded(layout.d))
            .collect();
        let mins = vec![0i16; layout.columns];
        Self {
            values: [row.clone(), row.clone(), row],
            mins: [mins.clone(), mins.clone(), mins],
        }
    }
}

#[inline(always)]
fn vertical_paths(
    c: &[i16],
    height: usize,
    layout: &Layout,
    p: &Resolved,
    dir: Direction,
    s: &mut [i16],
) {
    let (n, d, cols) = (layout.row_len(), layout.d, layout.columns);
    let stride = d + 2;
    let (mut prev, mut cur) = (PathRows::zeros(layout), PathRows::zeros(layout));
    let border = zero_padded(d);
    for k in 0..height {
        let y = if dir == Direction::Down {
            k
        } else {
            height - 1 - k
        };
        let (c_row, s_row) = (&c[y * n..(y + 1) * n], &mut s[y * n..(y + 1) * n]);
        for x in 0..cols {
            let cost = &c_row[x * d..(x + 1) * d];
            let acc = &mut s_row[x * d..(x + 1) * d];
            // 0: straight, 1: from column x − 1, 2: from column x + 1.
            for (r, source) in [Some(x), x.checked_sub(1), (x + 1 < cols).then_some(x + 1)]
                .into_iter()
                .enumerate()
            {
                let (from, from_min) = match source {
                    Some(sx) => (
                        &prev.values[r][sx * stride..(sx + 1) * stride],
                        prev.mins[r][sx],
                    ),
                    None => (&border[..], 0),
                };
                let out = &mut cur.values[r][x * stride..(x + 1) * stride];
                cur.mins[r][x] = step(cost, from, from_min, p.p1, p.p2, out, acc);
            }
        }
        std::mem::swap(&mut prev, &mut cur);
    }
}
