//! A dense two-view matcher that needs neither poses nor sparse seeds: coarse-to-fine
//! PatchMatch with affine patches from a global search at the coarsest level, affine
//! Lucas–Kanade at full resolution, forward–backward checks and match propagation. It stands
//! in for the learned dense matcher of the surface paper (PDC-Net) where SIFT finds too few seeds for
//! [`super::densify`] to grow from.
//!
//! **What.** Points of view `a` on a regular grid (spacing `spacing_px`, by default 1 % of the
//! long side; inside `a`'s mask when one is given) each get a correspondence in view `b` and
//! a confidence in `[0, 1]`. Only matches that pass the checks below are returned.
//!
//! **How.**
//! 1. *Pyramids.* Both grey images (Rec. 601 luminance) are halved (Gaussian blur, 2×2 box)
//!    until the long side is at most `coarsest_long_side`; masks are box-filtered alongside.
//! 2. *Global search* at the coarsest level. A subset of the grid points (at most
//!    `max_global_points`) is matched against every position of image `b` (inside `b`'s mask)
//!    by normalised cross-correlation (NCC) of `(2r+1)²` patches. Views tens of degrees apart
//!    see a surface rotated, scaled and foreshortened, so each template is tried under a small
//!    set of affine warps (`SEARCH_WARPS`: identity, ±15° rotations, scales 0.8 and 1.25,
//!    0.8/1.25 foreshortening along each axis). The level is small (≤ 64 px by default), so
//!    the exhaustive search costs about a billion multiply–adds. The remaining grid points
//!    start from their nearest searched point.
//! 3. *PatchMatch* (Barnes et al. 2009) refines the field of hypotheses — a position in `b`
//!    and a 2×2 affine map of patch offsets, as PatchMatch Stereo's slanted windows (Bleyer
//!    et al. 2011) — at every level, coarsest to finest: each point tries its neighbour's
//!    hypothesis carried over by the neighbour's affine map (propagation, in four sweeps:
//!    rows and columns, both ways; the lines run in parallel) and random perturbations of its
//!    own position and warp in a window halving from `coarse_search_fraction` of the long side
//!    (coarsest level) or 2 px (finer levels, after the field is doubled in resolution).
//! 4. *Sub-pixel fit.* At full resolution affine Lucas–Kanade with gain and bias
//!    ([`super::refine`], Baker & Matthews 2004) starts from each hypothesis; its windows
//!    must correlate (`min_ncc`) and `b` must fall inside `b`'s mask.
//! 5. *Consistency.* The whole search is run from `b` to `a` as well. A forward match `a → b`
//!    is kept when the backward field near `b` points back to within `max_field_disagreement`
//!    of `a` (an independent search agrees) and a backward Lucas–Kanade fit from there
//!    returns to within `max_forward_backward` of `a`; both are fractions of the long side.
//! 6. *Confidence* is the product of three factors in `[0, 1]`: the fitted windows' NCC
//!    rescaled from `min_ncc..1`; `exp(−e²)` of the forward–backward error `e` (the larger of
//!    the round trip and half the field disagreement, in units of `consistency_scale`); and
//!    the texture `λ / (λ + λ_med / 4)`, `λ` the smaller eigenvalue of the window's structure
//!    tensor (Shi & Tomasi 1994) and `λ_med` its median over the grid, so that flat and
//!    edge-like windows, whose fits are least determined, rank last.
//! 7. *Match propagation* (quasi-dense propagation, Lhuillier & Quan 2002): grid points next
//!    to accepted matches are tried from their best neighbour's match carried over by its
//!    fitted warp, in rounds; a point is accepted when its fit stays within
//!    `max_growth_shift` of that prediction and passes the checks of steps 4–5 (the backward
//!    fit starting from the point itself). This reaches points whose search went astray.
//!
//! All sizes are fractions of the image's long side or statistics of the matches, so the
//! same defaults hold from 320 × 240 to 1600 × 1200; the search's run time depends on the
//! number of grid points (about 10⁴ by default) more than on the resolution.
//!
//! **Limits.** The checks reject what two windows cannot tell apart, not what is consistent
//! and wrong: specular reflections that move with the viewpoint, and look-alike structure
//! between views so far apart (70°) that the true match is beyond the warps searched.

use fewview_geom::blend::gaussian_blur;
use fewview_scene::Image;
use nalgebra::{Matrix2, Vector2};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::refine::{Fit, Plane, WarpModel, Window, refine_one};
use crate::correspondence::{Match, MatchInput, luminance, mask_admits};

/// Options of [`dense_matches`]. Sizes are fractions of the long side of image `a` unless
/// their name says pixels.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DenseOptions {
    /// Spacing of the output grid of view `a` (pixels); `None`: 1 % of the long side.
    pub spacing_px: Option<f64>,
    /// The pyramid is halved until its long side is at most this (pixels).
    pub coarsest_long_side: usize,
    /// Half-size `r` of the `(2r+1)²` patches of the search (pixels of each level).
    pub patch_radius: usize,
    /// Most grid points matched by the exhaustive search at the coarsest level.
    pub max_global_points: usize,
    /// PatchMatch iterations (four sweeps each) at the coarsest level.
    pub coarse_iterations: usize,
    /// PatchMatch iterations at each finer level.
    pub fine_iterations: usize,
    /// Radius of the random search at the coarsest level, as a fraction of that level's long
    /// side.
    pub coarse_search_fraction: f64,
    /// Half-size of the Lucas–Kanade window; `None`: 2 % of the long side, 5–15 px.
    pub lk_half_window: Option<usize>,
    /// Gauss–Newton steps of each Lucas–Kanade fit.
    pub lk_iterations: usize,
    /// Blur σ before Lucas–Kanade as a fraction of the long side (at least 0.5 px).
    pub blur_fraction: f64,
    /// Least NCC of the fitted Lucas–Kanade windows.
    pub min_ncc: f64,
    /// Most distance between `a` and where the backward field points from `b` (fraction of
    /// the long side).
    pub max_field_disagreement: f64,
    /// Most distance between `a` and the backward Lucas–Kanade fit (fraction of the long
    /// side).
    pub max_forward_backward: f64,
    /// The forward–backward error (fraction of the long side) at which the confidence's
    /// consistency factor is `e⁻¹`; the field disagreement counts half. Separate from the
    /// acceptance thresholds so that loosening those does not flatten the ranking.
    pub consistency_scale: f64,
    /// Rounds of match propagation from the checked matches (0: none).
    pub growth_rounds: usize,
    /// Most distance between a propagated match and its neighbour's prediction (fraction of
    /// the long side).
    pub max_growth_shift: f64,
    /// Matches below this confidence are dropped.
    pub min_confidence: f32,
    /// Seed of the random search.
    pub seed: u64,
}

impl Default for DenseOptions {
    fn default() -> Self {
        Self {
            spacing_px: None,
            coarsest_long_side: 64,
            patch_radius: 5,
            max_global_points: 1500,
            coarse_iterations: 4,
            fine_iterations: 2,
            coarse_search_fraction: 0.125,
            lk_half_window: None,
            lk_iterations: 20,
            blur_fraction: 0.7 / 800.0,
            min_ncc: 0.8,
            max_field_disagreement: 0.005,
            max_forward_backward: 0.0025,
            consistency_scale: 0.0025,
            growth_rounds: 100,
            max_growth_shift: 0.0075,
            min_confidence: 0.05,
            seed: 0,
        }
    }
}

/// The affine patch warps of the global search: identity, rotations by ±15°, isotropic scales
/// 0.8 and 1.25, and foreshortening by 0.8 and 1.25 along x and along y (column-major 2×2,
/// mapping offsets around `a` to offsets around `b`).
const SEARCH_WARPS: [[f64; 4]; 9] = [
    [1.0, 0.0, 0.0, 1.0],
    [0.965_925_8, 0.258_819, -0.258_819, 0.965_925_8],
    [0.965_925_8, -0.258_819, 0.258_819, 0.965_925_8],
    [0.8, 0.0, 0.0, 0.8],
    [1.25, 0.0, 0.0, 1.25],
    [0.8, 0.0, 0.0, 1.0],
    [1.25, 0.0, 0.0, 1.0],
    [1.0, 0.0, 0.0, 0.8],
    [1.0, 0.0, 0.0, 1.25],
];

/// Dense correspondences from `a` (view `view_a`) to `b` (view `view_b`) on a regular grid of
/// `a`; see the module docs. Deterministic for a given `options.seed`, whatever the number of
/// threads.
pub fn dense_matches(
    a: &MatchInput,
    b: &MatchInput,
    view_a: usize,
    view_b: usize,
    options: &DenseOptions,
) -> Vec<Match> {
    let sizes = Sizes::new(a.image, options);
    let levels = pyramid_levels(a.image, b.image, options.coarsest_long_side);
    let (pa, pb) = rayon::join(|| Pyramid::new(a, levels), || Pyramid::new(b, levels));
    let grid_a = Grid::new(a.image, a.mask, sizes.spacing, sizes.margin);
    let grid_b = Grid::new(b.image, b.mask, sizes.spacing, sizes.margin);
    let (forward, backward) = rayon::join(
        || search_field(&pa, &pb, &grid_a, options, options.seed),
        || search_field(&pb, &pa, &grid_b, options, options.seed ^ 0x5bd1_e995),
    );
    let (plane_a, plane_b) = rayon::join(
        || Plane::new(a.image, sizes.blur),
        || Plane::new(b.image, sizes.blur),
    );
    let check = Checker {
        a: &plane_a,
        b: &plane_b,
        mask_b: b.mask,
        window: Window::new(sizes.half_window),
        backward: (&grid_b, &backward),
        sizes: &sizes,
        options,
    };
    check.matches(&grid_a, &forward, (view_a, view_b))
}

/// The sizes that follow from the image size and the options.
struct Sizes {
    long: f64,
    spacing: f64,
    half_window: usize,
    margin: f64,
    blur: f32,
    max_field: f64,
    max_forward_backward: f64,
    consistency: f64,
}

impl Sizes {
    fn new(image: &Image, o: &DenseOptions) -> Self {
        let long = image.width.max(image.height) as f64;
        let half_window = o
            .lk_half_window
            .unwrap_or_else(|| (0.02 * long).round().clamp(5.0, 15.0) as usize);
        Self {
            long,
            spacing: o.spacing_px.unwrap_or(long / 100.0).max(1.0),
            half_window,
            margin: half_window as f64 + 1.0,
            blur: (o.blur_fraction * long).max(0.5) as f32,
            max_field: o.max_field_disagreement * long,
            max_forward_backward: o.max_forward_backward * long,
            consistency: (o.consistency_scale * long).max(f64::MIN_POSITIVE),
        }
    }
}

/// How many times both images are halved: until the longer of their long sides is at most
/// `coarsest` pixels.
fn pyramid_levels(a: &Image, b: &Image, coarsest: usize) -> usize {
    let mut long = a.width.max(a.height).max(b.width).max(b.height);
    let mut levels = 0;
    while long > coarsest.max(8) {
        long /= 2;
        levels += 1;
    }
    levels
}

/// Grey images and masks of one view, finest (the input) first, each level half the previous.
struct Pyramid {
    planes: Vec<Plane>,
    masks: Vec<Option<Image>>,
}

impl Pyramid {
    /// Each level is the previous one blurred (σ = 0.6 px) and 2×2-averaged, so that pixel
    /// `i` of level `l + 1` covers pixels `2i, 2i + 1` of level `l` and coordinates (pixel
    /// centres at half-integers) halve exactly.
    fn new(input: &MatchInput, levels: usize) -> Self {
        let im = input.image;
        let grey: Vec<f32> = (0..im.num_pixels())
            .map(|i| luminance(im.pixel(i % im.width, i / im.width)))
            .collect();
        let mut images = vec![Image::from_vec(im.width, im.height, 1, grey)];
        let mut masks = vec![input.mask.map(|m| m.channel(0))];
        for _ in 0..levels {
            let prev = images.last().expect("finest level");
            let blurred = gaussian_blur(&prev.data, prev.width, prev.height, 0.6);
            let next = Image::from_vec(prev.width, prev.height, 1, blurred).downscale(2);
            images.push(next);
            let mask = masks
                .last()
                .expect("finest mask")
                .as_ref()
                .map(|m| m.downscale(2));
            masks.push(mask);
        }
        Self {
            planes: images.iter().map(|i| Plane::new(i, 0.0)).collect(),
            masks,
        }
    }

    fn coarsest(&self) -> usize {
        self.planes.len() - 1
    }
}

/// A regular grid of points over an image (full-resolution pixels), row-major; `active`
/// points lie at least `margin` inside the image and inside its mask.
struct Grid {
    points: Vec<Vector2<f64>>,
    active: Vec<bool>,
    cols: usize,
    rows: usize,
    spacing: f64,
}

impl Grid {
    fn new(image: &Image, mask: Option<&Image>, spacing: f64, margin: f64) -> Self {
        let (w, h) = (image.width as f64, image.height as f64);
        let cols = ((w / spacing).floor() as usize).max(1);
        let rows = ((h / spacing).floor() as usize).max(1);
        let mut points = Vec::with_capacity(cols * rows);
        let mut active = Vec::with_capacity(cols * rows);
        for j in 0..rows {
            for i in 0..cols {
                let p = Vector2::new(spacing * (i as f64 + 0.5), spacing * (j as f64 + 0.5));
                let inside =
                    p.x >= margin && p.y >= margin && p.x <= w - margin && p.y <= h - margin;
                points.push(p);
                active.push(inside && mask_admits(mask, p, 0.5));
            }
        }
        Self {
            points,
            active,
            cols,
            rows,
            spacing,
        }
    }

    /// The (up to eight) grid neighbours of point `i`.
    fn neighbours(&self, i: usize) -> Vec<usize> {
        let (x, y) = ((i % self.cols) as isize, (i / self.cols) as isize);
        let mut out = Vec::with_capacity(8);
        for dy in -1..=1 {
            for dx in -1..=1 {
                let (u, v) = (x + dx, y + dy);
                let inside =
                    u >= 0 && v >= 0 && (u as usize) < self.cols && (v as usize) < self.rows;
                if (dx, dy) != (0, 0) && inside {
                    out.push(v as usize * self.cols + u as usize);
                }
            }
        }
        out
    }

    /// The lines of the four PatchMatch sweeps: rows left to right, rows right to left,
    /// columns top to bottom, columns bottom to top.
    fn sweep_lines(&self) -> [Vec<Vec<usize>>; 4] {
        let rows: Vec<Vec<usize>> = (0..self.rows)
            .map(|j| (0..self.cols).map(|i| j * self.cols + i).collect())
            .collect();
        let cols: Vec<Vec<usize>> = (0..self.cols)
            .map(|i| (0..self.rows).map(|j| j * self.cols + i).collect())
            .collect();
        let reversed = |lines: &[Vec<usize>]| -> Vec<Vec<usize>> {
            lines
                .iter()
                .map(|l| l.iter().rev().copied().collect())
                .collect()
        };
        let (rows_back, cols_back) = (reversed(&rows), reversed(&cols));
        [rows, rows_back, cols, cols_back]
    }
}

/// One hypothesis of PatchMatch: the point's position in image `b` and the affine map of patch
/// offsets around the point to offsets around that position (both in pixels of the current
/// level), with its cost `1 − NCC`.
#[derive(Clone, Copy, Debug)]
struct Hypothesis {
    b: Vector2<f64>,
    warp: Matrix2<f64>,
    cost: f64,
}

/// A deterministic stream of uniform numbers (SplitMix64, Steele et al. 2014), seeded per
/// point, level and sweep so that results do not depend on the threads' schedule.
struct SplitMix(u64);

impl SplitMix {
    fn new(keys: &[u64]) -> Self {
        let mut s = Self(0x853c_49e6_748f_ea9b);
        for &k in keys {
            s.0 ^= k;
            s.0 = s.next_u64();
        }
        s
    }

    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `[−1, 1)`.
    fn symmetric(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// The whole coarse-to-fine search from `a` to `b` for the points of `grid`: one hypothesis
/// per active point (full-resolution pixels), `None` where none was found.
fn search_field(
    a: &Pyramid,
    b: &Pyramid,
    grid: &Grid,
    o: &DenseOptions,
    seed: u64,
) -> Vec<Option<Hypothesis>> {
    let top = a.coarsest();
    let lines = grid.sweep_lines();
    let mut field: Vec<Option<Hypothesis>> = Vec::new();
    for level in (0..=top).rev() {
        let ctx = LevelContext::new(a, b, grid, level, o.patch_radius);
        let (iterations, radius) = if level == top {
            field = ctx.global_search(o.max_global_points);
            let long = ctx.b.width.max(ctx.b.height) as f64;
            (o.coarse_iterations, o.coarse_search_fraction * long)
        } else {
            ctx.rescore_doubled(&mut field);
            (o.fine_iterations, 2.0)
        };
        for iteration in 0..iterations {
            for (direction, line_set) in lines.iter().enumerate() {
                let keys = [seed, level as u64, iteration as u64, direction as u64];
                ctx.sweep(&mut field, line_set, radius, &keys);
            }
        }
    }
    field
}

/// What the search needs at one level of the pyramids.
struct LevelContext<'a> {
    a: &'a Plane,
    b: &'a Plane,
    mask_b: Option<&'a Image>,
    grid: &'a Grid,
    /// Grid points in this level's pixels.
    points: Vec<Vector2<f64>>,
    /// Patch offsets (pixels of this level).
    offsets: Vec<Vector2<f64>>,
    /// Zero-mean, unit-norm patches of `a` around each point; `None` where flat or inactive.
    templates: Vec<Option<Vec<f32>>>,
}

/// Patches with a variance below this (grey levels in `[0, 1]`) are flat.
const FLAT_VARIANCE: f64 = 1e-7;

impl<'a> LevelContext<'a> {
    fn new(a: &'a Pyramid, b: &'a Pyramid, grid: &'a Grid, level: usize, radius: usize) -> Self {
        let scale = 0.5f64.powi(level as i32);
        let r = radius as isize;
        let offsets: Vec<Vector2<f64>> = (-r..=r)
            .flat_map(|dy| (-r..=r).map(move |dx| Vector2::new(dx as f64, dy as f64)))
            .collect();
        let plane_a = &a.planes[level];
        let points: Vec<Vector2<f64>> = grid.points.iter().map(|p| p * scale).collect();
        let templates = points
            .par_iter()
            .zip(&grid.active)
            .map(|(p, &active)| {
                let values = offsets
                    .iter()
                    .map(|d| plane_a.sample(&plane_a.value, p.x + d.x, p.y + d.y));
                active.then(|| normalised(values, offsets.len())).flatten()
            })
            .collect();
        Self {
            a: plane_a,
            b: &b.planes[level],
            mask_b: b.masks[level].as_ref(),
            grid,
            points,
            offsets,
            templates,
        }
    }

    /// `1 − NCC` of point `i`'s template against image `b` sampled at `b + W·d`; infinite
    /// where the centre leaves the image or `b`'s mask, or the warp is implausible.
    fn cost(&self, i: usize, b: Vector2<f64>, warp: &Matrix2<f64>) -> f64 {
        let Some(t) = &self.templates[i] else {
            return f64::INFINITY;
        };
        if !self.b.inside(b.x, b.y) || !mask_admits(self.mask_b, b, 0.25) || !plausible(warp) {
            return f64::INFINITY;
        }
        let (mut st, mut s, mut ss) = (0.0f64, 0.0f64, 0.0f64);
        for (d, &tk) in self.offsets.iter().zip(t) {
            let x = b + warp * d;
            let v = self.b.sample(&self.b.value, x.x, x.y);
            st += tk as f64 * v;
            s += v;
            ss += v * v;
        }
        let n = self.offsets.len() as f64;
        let var = ss - s * s / n;
        if var <= FLAT_VARIANCE * n {
            return 1.0;
        }
        1.0 - st / var.sqrt()
    }

    /// `h` carried from point `from` to point `to` by its affine map.
    fn propagate(&self, h: &Hypothesis, from: usize, to: usize) -> (Vector2<f64>, Matrix2<f64>) {
        let d = self.points[to] - self.points[from];
        (h.b + h.warp * d, h.warp)
    }
}

/// Whether a patch warp keeps its orientation and scales by 0.4–2.5 at most (the Frobenius
/// norm and determinant bound the singular values).
fn plausible(w: &Matrix2<f64>) -> bool {
    let det = w.determinant();
    det > 0.16 && det < 6.25 && w.norm_squared() < 2.0 * 6.25
}

/// The samples minus their mean, scaled to unit norm (as `f32`, padded with zeros to a multiple
/// of 8 for [`dot`]); `None` when flat.
fn normalised(values: impl Iterator<Item = f64>, n: usize) -> Option<Vec<f32>> {
    let v: Vec<f64> = values.collect();
    let mean = v.iter().sum::<f64>() / n as f64;
    let ss: f64 = v.iter().map(|x| (x - mean) * (x - mean)).sum();
    if ss <= FLAT_VARIANCE * n as f64 {
        return None;
    }
    let inv = 1.0 / ss.sqrt();
    let mut out: Vec<f32> = v.iter().map(|x| ((x - mean) * inv) as f32).collect();
    out.resize(n.div_ceil(8) * 8, 0.0);
    Some(out)
}

/// Dot product of two equally long vectors whose length is a multiple of 8, in eight lanes
/// so that it vectorises.
fn dot(x: &[f32], y: &[f32]) -> f32 {
    let mut lanes = [0.0f32; 8];
    for (cx, cy) in x.chunks_exact(8).zip(y.chunks_exact(8)) {
        for k in 0..8 {
            lanes[k] += cx[k] * cy[k];
        }
    }
    lanes.iter().sum()
}

impl LevelContext<'_> {
    /// The exhaustive search at the coarsest level (module docs, step 2): the searched points
    /// (a sub-grid of at most `max_points` active points) get the best NCC over every
    /// position of `b` and every [`SEARCH_WARPS`] entry; the other active points start from
    /// the nearest searched point's hypothesis.
    fn global_search(&self, max_points: usize) -> Vec<Option<Hypothesis>> {
        let positions = self.search_positions();
        let grid = self.grid;
        let active = grid.active.iter().filter(|a| **a).count();
        let stride = ((active as f64 / max_points.max(1) as f64).sqrt().ceil() as usize).max(1);
        let searched: Vec<usize> = (0..grid.points.len())
            .filter(|&i| (i % grid.cols) % stride == stride / 2)
            .filter(|&i| (i / grid.cols) % stride == stride / 2)
            .filter(|&i| self.templates[i].is_some())
            .collect();
        let found: Vec<(usize, Hypothesis)> = searched
            .par_iter()
            .filter_map(|&i| Some((i, self.best_position(i, &positions)?)))
            .collect();
        (0..grid.points.len())
            .into_par_iter()
            .map(|i| {
                if !grid.active[i] {
                    return None;
                }
                let (j, h) = found.iter().min_by(|x, y| {
                    let dx = (grid.points[x.0] - grid.points[i]).norm_squared();
                    let dy = (grid.points[y.0] - grid.points[i]).norm_squared();
                    dx.total_cmp(&dy)
                })?;
                let (b, warp) = self.propagate(h, *j, i);
                Some(Hypothesis {
                    b,
                    warp,
                    cost: self.cost(i, b, &warp),
                })
            })
            .collect()
    }

    /// Every pixel centre of `b` whose axis-aligned patch lies inside the image (and whose
    /// centre inside `b`'s mask), with that patch normalised; flat patches are left out.
    fn search_positions(&self) -> Vec<(Vector2<f64>, Vec<f32>)> {
        let r = ((self.offsets.len() as f64).sqrt() as usize) / 2;
        let (w, h) = (self.b.width, self.b.height);
        let n = self.offsets.len();
        (r..h.saturating_sub(r))
            .into_par_iter()
            .flat_map_iter(|y| {
                (r..w.saturating_sub(r)).filter_map(move |x| {
                    let centre = Vector2::new(x as f64 + 0.5, y as f64 + 0.5);
                    if !mask_admits(self.mask_b, centre, 0.25) {
                        return None;
                    }
                    let values = self.offsets.iter().map(|d| {
                        let (px, py) = (x as isize + d.x as isize, y as isize + d.y as isize);
                        self.b.value[py as usize * w + px as usize] as f64
                    });
                    Some((centre, normalised(values, n)?))
                })
            })
            .collect()
    }

    /// The best hypothesis of point `i` over `positions` and [`SEARCH_WARPS`]: the template
    /// is resampled through each warp's inverse (so that it lines up with `b`'s axis-aligned
    /// patches) and correlated with every position.
    fn best_position(
        &self,
        i: usize,
        positions: &[(Vector2<f64>, Vec<f32>)],
    ) -> Option<Hypothesis> {
        let p = self.points[i];
        let n = self.offsets.len();
        let mut best: Option<Hypothesis> = None;
        for w in SEARCH_WARPS {
            let warp = Matrix2::new(w[0], w[2], w[1], w[3]);
            let inverse = warp.try_inverse()?;
            let values = self.offsets.iter().map(|d| {
                let x = p + inverse * d;
                self.a.sample(&self.a.value, x.x, x.y)
            });
            let Some(template) = normalised(values, n) else {
                continue;
            };
            for (centre, patch) in positions {
                let cost = 1.0 - dot(&template, patch) as f64;
                if best.is_none_or(|h| cost < h.cost) {
                    best = Some(Hypothesis {
                        b: *centre,
                        warp,
                        cost,
                    });
                }
            }
        }
        best
    }

    /// Doubles the hypotheses of the previous (coarser) level into this level's pixels and
    /// scores them here.
    fn rescore_doubled(&self, field: &mut [Option<Hypothesis>]) {
        field.par_iter_mut().enumerate().for_each(|(i, h)| {
            if let Some(h) = h {
                h.b *= 2.0;
                h.cost = self.cost(i, h.b, &h.warp);
            }
        });
    }

    /// One PatchMatch sweep along every line of `lines` (lines in parallel): each active point
    /// tries the previous active point's hypothesis propagated to it, then a random search
    /// around its own in windows of `radius`, `radius / 2`, … down to half a pixel, with
    /// affine perturbations that shrink alongside.
    fn sweep(
        &self,
        field: &mut [Option<Hypothesis>],
        lines: &[Vec<usize>],
        radius: f64,
        keys: &[u64],
    ) {
        let updates: Vec<Vec<(usize, Hypothesis)>> = lines
            .par_iter()
            .map(|line| {
                let mut out = Vec::with_capacity(line.len());
                let mut previous: Option<(usize, Hypothesis)> = None;
                for &i in line {
                    let Some(mut h) = field[i] else {
                        continue;
                    };
                    if let Some((j, hj)) = previous {
                        let (b, warp) = self.propagate(&hj, j, i);
                        self.try_candidate(i, &mut h, b, warp);
                    }
                    let mut keys = keys.to_vec();
                    keys.push(i as u64);
                    self.random_search(i, &mut h, radius, &mut SplitMix::new(&keys));
                    out.push((i, h));
                    previous = Some((i, h));
                }
                out
            })
            .collect();
        for (i, h) in updates.into_iter().flatten() {
            field[i] = Some(h);
        }
    }

    /// Replaces `h` by `(b, warp)` when that costs less.
    fn try_candidate(&self, i: usize, h: &mut Hypothesis, b: Vector2<f64>, warp: Matrix2<f64>) {
        let cost = self.cost(i, b, &warp);
        if cost < h.cost {
            *h = Hypothesis { b, warp, cost };
        }
    }

    /// PatchMatch's random search around `h` (see [`Self::sweep`]); the warp's entries move by
    /// up to 0.2 at the largest radius.
    fn random_search(&self, i: usize, h: &mut Hypothesis, radius: f64, rng: &mut SplitMix) {
        let mut r = radius;
        while r >= 0.5 {
            let b = h.b + Vector2::new(rng.symmetric(), rng.symmetric()) * r;
            let k = 0.2 * r / radius;
            let dw = Matrix2::new(
                rng.symmetric(),
                rng.symmetric(),
                rng.symmetric(),
                rng.symmetric(),
            ) * k;
            self.try_candidate(i, h, b, h.warp + dw);
            r *= 0.5;
        }
    }
}

/// The full-resolution fit and checks of the forward field, and the growth from the matches
/// that pass them (module docs, steps 4–7).
struct Checker<'a> {
    a: &'a Plane,
    b: &'a Plane,
    mask_b: Option<&'a Image>,
    window: Window,
    /// The grid of `b` and the backward field found on it.
    backward: (&'a Grid, &'a [Option<Hypothesis>]),
    sizes: &'a Sizes,
    options: &'a DenseOptions,
}

/// A forward match that passed the checks.
#[derive(Clone, Copy)]
struct Checked {
    b: Vector2<f64>,
    /// The fitted affine map of window offsets around `a` to offsets around `b`.
    warp: Matrix2<f64>,
    ncc: f64,
    /// Forward–backward error in units of `consistency_scale` (the larger of the round trip
    /// and half the field disagreement).
    error: f64,
}

impl Checker<'_> {
    fn matches(
        &self,
        grid: &Grid,
        forward: &[Option<Hypothesis>],
        views: (usize, usize),
    ) -> Vec<Match> {
        let tensor = structure_planes(self.a);
        let textures: Vec<Option<f64>> = grid
            .points
            .par_iter()
            .zip(&grid.active)
            .map(|(p, &active)| active.then(|| self.corner_strength(&tensor, *p)))
            .collect();
        let median = median(textures.iter().flatten().copied().collect()).unwrap_or(0.0);
        let mut accepted: Vec<Option<Checked>> = (0..grid.points.len())
            .into_par_iter()
            .map(|i| self.check(grid.points[i], &forward[i]?))
            .collect();
        self.grow(grid, &mut accepted);
        accepted
            .iter()
            .enumerate()
            .filter_map(|(i, c)| {
                let c = c.as_ref()?;
                let confidence = self.confidence(c, textures[i]?, median);
                let a = grid.points[i];
                (confidence >= self.options.min_confidence).then(|| Match {
                    view_a: views.0,
                    view_b: views.1,
                    a: [a.x as f32, a.y as f32],
                    b: [c.b.x as f32, c.b.y as f32],
                    confidence,
                    b_covariance: None,
                })
            })
            .collect()
    }

    /// Lucas–Kanade from `start` with the warp `warp` at point `p` of `a`; the fit when its
    /// windows correlate (`min_ncc`) and it lands inside `b`'s mask.
    fn fit(&self, p: Vector2<f64>, start: Vector2<f64>, warp: Matrix2<f64>) -> Option<Fit> {
        let o = self.options;
        let fit = refine_one(
            self.a,
            self.b,
            p,
            start,
            warp,
            &self.window,
            o.lk_iterations,
            WarpModel::Affine,
        )?;
        (fit.ncc >= o.min_ncc && mask_admits(self.mask_b, fit.b, 0.5)).then_some(fit)
    }

    /// The distance from `p` of the backward Lucas–Kanade fit of `fit.b` started at `back`;
    /// `None` when it fails or exceeds `max_forward_backward`.
    fn round_trip(&self, p: Vector2<f64>, fit: &Fit, back: Vector2<f64>) -> Option<f64> {
        let back_fit = refine_one(
            self.b,
            self.a,
            fit.b,
            back,
            fit.warp.try_inverse()?,
            &self.window,
            self.options.lk_iterations,
            WarpModel::Affine,
        )?;
        let d = (back_fit.b - p).norm();
        (d <= self.sizes.max_forward_backward).then_some(d)
    }

    /// A searched hypothesis: the fit, then the independent backward field must point back to
    /// near `p` and the backward fit from there return to `p` (module docs, step 5).
    fn check(&self, p: Vector2<f64>, h: &Hypothesis) -> Option<Checked> {
        let fit = self.fit(p, h.b, h.warp)?;
        let (back, disagreement) = self.backward_prediction(fit.b, p)?;
        if disagreement > self.sizes.max_field {
            return None;
        }
        let round_trip = self.round_trip(p, &fit, back)?;
        Some(Checked {
            b: fit.b,
            warp: fit.warp,
            ncc: fit.ncc,
            error: (0.5 * disagreement).max(round_trip) / self.sizes.consistency,
        })
    }

    /// Match propagation from the accepted matches (module docs, step 7): in rounds, every
    /// active grid point next to an accepted one (8-neighbourhood) that gained such a
    /// neighbour in the previous round is tried from the best neighbour's match carried over
    /// by its fitted warp. It is accepted when the fit stays within `max_growth_shift` of that
    /// prediction, its windows correlate, and the backward fit returns to it.
    fn grow(&self, grid: &Grid, accepted: &mut [Option<Checked>]) {
        let max_shift = self.options.max_growth_shift * self.sizes.long;
        let mut fresh: Vec<bool> = accepted.iter().map(Option::is_some).collect();
        for _ in 0..self.options.growth_rounds {
            let found: Vec<(usize, Checked)> = (0..grid.points.len())
                .into_par_iter()
                .filter(|&i| grid.active[i] && accepted[i].is_none())
                .filter_map(|i| {
                    let neighbours = grid.neighbours(i);
                    if !neighbours.iter().any(|&j| fresh[j]) {
                        return None;
                    }
                    let (j, n) = neighbours
                        .iter()
                        .filter_map(|&j| Some((j, accepted[j]?)))
                        .max_by(|x, y| (x.1.ncc - x.1.error).total_cmp(&(y.1.ncc - y.1.error)))?;
                    let p = grid.points[i];
                    let predicted = n.b + n.warp * (p - grid.points[j]);
                    let fit = self.fit(p, predicted, n.warp)?;
                    if (fit.b - predicted).norm() > max_shift {
                        return None;
                    }
                    let round_trip = self.round_trip(p, &fit, p)?;
                    let error = round_trip / self.sizes.consistency;
                    let (b, warp, ncc) = (fit.b, fit.warp, fit.ncc);
                    Some((
                        i,
                        Checked {
                            b,
                            warp,
                            ncc,
                            error,
                        },
                    ))
                })
                .collect();
            if found.is_empty() {
                break;
            }
            fresh.iter_mut().for_each(|f| *f = false);
            for (i, c) in found {
                accepted[i] = Some(c);
                fresh[i] = true;
            }
        }
    }

    /// Where the backward field sends `q` (a point of `b`): of the (up to four) grid points
    /// of `b` around `q`, the prediction of the one whose hypothesis, carried to `q` by its
    /// affine map, lands nearest `p`; with that distance.
    fn backward_prediction(&self, q: Vector2<f64>, p: Vector2<f64>) -> Option<(Vector2<f64>, f64)> {
        let (grid, field) = self.backward;
        let u = (q.x / grid.spacing - 0.5).floor();
        let v = (q.y / grid.spacing - 0.5).floor();
        let mut best: Option<(Vector2<f64>, f64)> = None;
        for (du, dv) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            let (i, j) = (u + du, v + dv);
            if i < 0.0 || j < 0.0 || i as usize >= grid.cols || j as usize >= grid.rows {
                continue;
            }
            let k = j as usize * grid.cols + i as usize;
            let Some(h) = field[k] else {
                continue;
            };
            let predicted = h.b + h.warp * (q - grid.points[k]);
            let d = (predicted - p).norm();
            if best.is_none_or(|(_, bd)| d < bd) {
                best = Some((predicted, d));
            }
        }
        best
    }

    /// The smaller eigenvalue of the window-weighted structure tensor around `p` (Shi &
    /// Tomasi 1994): large only where the window is textured in every direction, so that a
    /// fit pins `b` down along both axes (an edge fixes it across the edge only).
    fn corner_strength(&self, tensor: &[Vec<f32>; 3], p: Vector2<f64>) -> f64 {
        let w = &self.window;
        let mut m = [0.0f64; 3];
        for (d, &wd) in w.offsets.iter().zip(&w.weights) {
            for (mk, plane) in m.iter_mut().zip(tensor) {
                *mk += wd * self.a.sample(plane, p.x + d.x, p.y + d.y);
            }
        }
        let total: f64 = w.weights.iter().sum();
        let [xx, xy, yy] = m.map(|v| v / total);
        let half_trace = 0.5 * (xx + yy);
        let spread = (0.25 * (xx - yy) * (xx - yy) + xy * xy).sqrt();
        (half_trace - spread).max(0.0)
    }

    /// The confidence of a checked match (module docs, step 6) whose window has the gradient
    /// energy `texture`.
    fn confidence(&self, c: &Checked, texture: f64, median_texture: f64) -> f32 {
        let min = self.options.min_ncc;
        let ncc = ((c.ncc - min) / (1.0 - min).max(1e-9)).clamp(0.0, 1.0);
        let consistency = (-c.error * c.error).exp();
        let texture = texture / (texture + 0.25 * median_texture).max(f64::MIN_POSITIVE);
        (ncc * consistency * texture).clamp(0.0, 1.0) as f32
    }
}

/// The structure-tensor planes `(g_x², g_x·g_y, g_y²)` of a plane's (blurred) values, by
/// central differences.
fn structure_planes(plane: &Plane) -> [Vec<f32>; 3] {
    let (w, h) = (plane.width, plane.height);
    let v = &plane.value;
    let products: Vec<[f32; 3]> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let gx = (v[y * w + (x + 1).min(w - 1)] - v[y * w + x.saturating_sub(1)]) * 0.5;
            let gy = (v[(y + 1).min(h - 1) * w + x] - v[y.saturating_sub(1) * w + x]) * 0.5;
            [gx * gx, gx * gy, gy * gy]
        })
        .collect();
    [0, 1, 2].map(|k| products.iter().map(|p| p[k]).collect())
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*m)
}

#[cfg(test)]
mod tests {
    use fewview_scene::{Camera, Intrinsics};
    use nalgebra::{Matrix3, Vector3};

    use super::*;

    /// A uniform number in `[0, 1)` for an integer lattice point.
    fn lattice(i: i64, j: i64, k: i64, seed: u64) -> f64 {
        let mut s = SplitMix::new(&[seed, i as u64, j as u64, k as u64]);
        (s.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Smooth value noise (trilinear with a smoothstep) of three octaves, the coarsest of
    /// period `period`, in `[0, 1]`.
    fn noise(p: Vector3<f64>, period: f64, seed: u64) -> f64 {
        let mut total = 0.0;
        for (octave, amplitude) in [(1.0, 0.5), (2.0, 0.3), (4.0, 0.2)] {
            let q = p * (octave / period);
            let base = q.map(f64::floor);
            let f = (q - base).map(|t| t * t * (3.0 - 2.0 * t));
            let mut v = 0.0;
            for corner in 0..8 {
                let c = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
                let w: f64 = (0..3)
                    .map(|k| if c[k] == 1 { f[k] } else { 1.0 - f[k] })
                    .product();
                let at = |k: usize| base[k] as i64 + c[k] as i64;
                v += w * lattice(at(0), at(1), at(2), seed ^ octave as u64);
            }
            total += amplitude * v;
        }
        total
    }

    /// A grey image whose pixel `(x, y)` (centre at half-integers) is `f(centre)`.
    fn render(w: usize, h: usize, f: impl Fn(Vector2<f64>) -> f64 + Sync) -> Image {
        let data = (0..w * h)
            .into_par_iter()
            .map(|i| f(Vector2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5)) as f32)
            .collect();
        Image::from_vec(w, h, 1, data)
    }

    fn texture_2d(p: Vector2<f64>, seed: u64) -> f64 {
        noise(Vector3::new(p.x, p.y, 0.37), 32.0, seed)
    }

    fn apply(h: &Matrix3<f64>, p: Vector2<f64>) -> Vector2<f64> {
        let q = h * Vector3::new(p.x, p.y, 1.0);
        Vector2::new(q.x / q.z, q.y / q.z)
    }

    fn unmasked(image: &Image) -> MatchInput<'_> {
        MatchInput { image, mask: None }
    }

    fn error(m: &Match, truth: impl Fn(Vector2<f64>) -> Vector2<f64>) -> f64 {
        let a = Vector2::new(m.a[0] as f64, m.a[1] as f64);
        (Vector2::new(m.b[0] as f64, m.b[1] as f64) - truth(a)).norm()
    }

    /// The fraction of matches within `px` of the truth.
    fn within(errors: &[f64], px: f64) -> f64 {
        errors.iter().filter(|e| **e < px).count() as f64 / errors.len().max(1) as f64
    }

    /// Image `b` shows image `a` through a homography: rotated by 18°, scaled by 1.1 and in
    /// perspective (the local scale varies by ±7 % across the image), with gain 0.9 and bias
    /// 0.05. All returned matches are scored (the returned set is what callers use): at least
    /// 90 % lie within 1 px of the homography's prediction, they cover most of the overlap,
    /// and the few off by more than 2 px have a lower mean confidence than those within 1 px.
    #[test]
    fn recovers_a_homography_with_rotation_scale_and_perspective() {
        let (w, h) = (320, 240);
        let (s, c) = 18f64.to_radians().sin_cos();
        let centre = Matrix3::new(1.0, 0.0, -160.0, 0.0, 1.0, -120.0, 0.0, 0.0, 1.0);
        let similarity = Matrix3::new(1.1 * c, -1.1 * s, 0.0, 1.1 * s, 1.1 * c, 0.0, 0.0, 0.0, 1.0);
        let perspective = Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 4e-4, 1e-4, 1.0);
        let back = Matrix3::new(1.0, 0.0, 168.0, 0.0, 1.0, 114.0, 0.0, 0.0, 1.0);
        let hom = back * similarity * perspective * centre;
        let inv = hom.try_inverse().unwrap();
        let a = render(w, h, |p| texture_2d(p, 7));
        let b = render(w, h, |p| 0.9 * texture_2d(apply(&inv, p), 7) + 0.05);
        let start = std::time::Instant::now();
        let matches = dense_matches(&unmasked(&a), &unmasked(&b), 0, 1, &DenseOptions::default());
        let seconds = start.elapsed().as_secs_f64();
        let errors: Vec<f64> = matches
            .iter()
            .map(|m| error(m, |p| apply(&hom, p)))
            .collect();
        let visible = Grid::new(&a, None, 3.2, 8.0)
            .points
            .iter()
            .filter(|p| {
                let q = apply(&hom, **p);
                p.x > 8.0
                    && p.y > 8.0
                    && p.x < 312.0
                    && p.y < 232.0
                    && q.x > 8.0
                    && q.y > 8.0
                    && q.x < 312.0
                    && q.y < 232.0
            })
            .count();
        let mean_confidence = |lo: f64, hi: f64| {
            let c: Vec<f64> = matches
                .iter()
                .zip(&errors)
                .filter(|(_, e)| **e >= lo && **e < hi)
                .map(|(m, _)| m.confidence as f64)
                .collect();
            (c.iter().sum::<f64>() / c.len().max(1) as f64, c.len())
        };
        let (good, n_good) = mean_confidence(0.0, 1.0);
        let (bad, n_bad) = mean_confidence(2.0, f64::INFINITY);
        eprintln!(
            "homography: {} matches of {visible} visible grid points, {:.1} % < 1 px, \
             {:.1} % < 0.5 px; confidence {good:.3} (n={n_good}) < 1 px, {bad:.3} (n={n_bad}) \
             > 2 px; {seconds:.1} s",
            matches.len(),
            100.0 * within(&errors, 1.0),
            100.0 * within(&errors, 0.5),
        );
        assert!(within(&errors, 1.0) >= 0.9);
        assert!(matches.len() as f64 >= 0.5 * visible as f64);
        assert!(n_bad == 0 || bad < good, "{bad} vs {good}");
        assert!(matches.iter().all(|m| (0.0..=1.0).contains(&m.confidence)));
    }

    /// With the consistency checks loosened to the whole image and no confidence floor, the
    /// points of `a` that leave image `b` come back as wrong matches: the confidence ranks
    /// them last (their mean is below that of the correct ones and most of them lie in the
    /// bottom fifth of the confidences).
    #[test]
    fn confidence_ranks_wrong_matches_last() {
        let (w, h) = (320, 240);
        let shift = Vector2::new(70.0, 25.0);
        let a = render(w, h, |p| texture_2d(p, 3));
        let b = render(w, h, |p| texture_2d(p - shift, 3));
        let options = DenseOptions {
            max_field_disagreement: 1.0,
            max_forward_backward: 1.0,
            min_ncc: 0.3,
            min_confidence: 0.0,
            ..Default::default()
        };
        let matches = dense_matches(&unmasked(&a), &unmasked(&b), 0, 1, &options);
        let errors: Vec<f64> = matches.iter().map(|m| error(m, |p| p + shift)).collect();
        let mut confidences: Vec<f32> = matches.iter().map(|m| m.confidence).collect();
        confidences.sort_by(f32::total_cmp);
        let fifth = confidences[confidences.len() / 5];
        let wrong: Vec<f32> = matches
            .iter()
            .zip(&errors)
            .filter(|(_, e)| **e > 2.0)
            .map(|(m, _)| m.confidence)
            .collect();
        let right: Vec<f32> = matches
            .iter()
            .zip(&errors)
            .filter(|(_, e)| **e < 1.0)
            .map(|(m, _)| m.confidence)
            .collect();
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len().max(1) as f32;
        let low = wrong.iter().filter(|c| **c <= fifth).count();
        eprintln!(
            "ranking: {} matches, {} wrong (mean confidence {:.3}, {low} in the bottom fifth), \
             {} right (mean {:.3})",
            matches.len(),
            wrong.len(),
            mean(&wrong),
            right.len(),
            mean(&right)
        );
        assert!(
            wrong.len() >= 20,
            "too few wrong matches to rank: {}",
            wrong.len()
        );
        assert!(mean(&wrong) < 0.5 * mean(&right));
        assert!(low as f64 >= 0.7 * wrong.len() as f64);
    }

    /// Two unrelated textures share nothing: fewer than 5 % of the grid points come back.
    #[test]
    fn unrelated_images_give_few_matches() {
        let a = render(320, 240, |p| texture_2d(p, 11));
        let b = render(320, 240, |p| texture_2d(p, 12));
        let matches = dense_matches(&unmasked(&a), &unmasked(&b), 0, 1, &DenseOptions::default());
        let sizes = Sizes::new(&a, &DenseOptions::default());
        let grid = Grid::new(&a, None, sizes.spacing, sizes.margin);
        let points = grid.active.iter().filter(|x| **x).count();
        eprintln!(
            "unrelated: {} matches of {points} grid points",
            matches.len()
        );
        assert!((matches.len() as f64) < 0.05 * points as f64);
    }

    /// A corner of two textured planes (floor `z = 0` and wall `y = 1`) by ray casting; the
    /// texture is a function of the 3D point, so both views see the same surface.
    struct Corner;

    impl Corner {
        /// The first surface point along the ray from `origin` in direction `dir`.
        fn hit(&self, origin: Vector3<f64>, dir: Vector3<f64>) -> Option<Vector3<f64>> {
            let floor = (dir.z < 0.0).then(|| -origin.z / dir.z);
            let wall = (dir.y > 0.0).then(|| (1.0 - origin.y) / dir.y);
            let t = [floor, wall]
                .into_iter()
                .flatten()
                .filter(|t| *t > 0.0)
                .filter(|t| {
                    let p = origin + dir * *t;
                    p.z >= -1e-9 && p.y <= 1.0 + 1e-9
                })
                .fold(f64::INFINITY, f64::min);
            t.is_finite().then(|| origin + dir * t)
        }

        fn shade(&self, camera: &Camera, p: Vector2<f64>) -> f64 {
            let (o, d) = camera.ray(p.x, p.y);
            self.hit(o, d).map_or(0.0, |x| noise(x, 0.3, 21))
        }

        /// Where pixel `p` of `from` is seen in `to`, when that surface point is visible there.
        fn correspondence(
            &self,
            from: &Camera,
            to: &Camera,
            p: Vector2<f64>,
        ) -> Option<Vector2<f64>> {
            let (o, d) = from.ray(p.x, p.y);
            let x = self.hit(o, d)?;
            let (u, v, _) = to.project(&x)?;
            let (o2, d2) = to.ray(u, v);
            let seen = self.hit(o2, d2)?;
            let inside = u > 0.0 && v > 0.0 && u < to.width() as f64 && v < to.height() as f64;
            ((seen - x).norm() < 1e-6 && inside).then_some(Vector2::new(u, v))
        }
    }

    /// Two pinhole cameras 25° apart around a concave corner of two textured planes: at least
    /// 90 % of the returned matches (all at points both views see) lie within 1 px of the
    /// true correspondence, and they cover most of the grid points both views see.
    #[test]
    fn matches_a_rendered_corner_seen_25_degrees_apart() {
        let (w, h) = (320u32, 240u32);
        let k = Intrinsics::centered(300.0, w, h);
        let target = Vector3::new(0.0, 0.4, 0.3);
        let camera = |deg: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            let eye = target + Vector3::new(2.6 * s, -2.6 * c, 1.2);
            Camera::look_at(k, eye, target, Vector3::z())
        };
        let (ca, cb) = (camera(-12.5), camera(12.5));
        let scene = Corner;
        let a = render(w as usize, h as usize, |p| scene.shade(&ca, p));
        let b = render(w as usize, h as usize, |p| 0.85 * scene.shade(&cb, p) + 0.1);
        let start = std::time::Instant::now();
        let matches = dense_matches(&unmasked(&a), &unmasked(&b), 0, 1, &DenseOptions::default());
        let seconds = start.elapsed().as_secs_f64();
        let errors: Vec<f64> = matches
            .iter()
            .map(|m| {
                let p = Vector2::new(m.a[0] as f64, m.a[1] as f64);
                scene
                    .correspondence(&ca, &cb, p)
                    .map_or(f64::INFINITY, |q| {
                        (Vector2::new(m.b[0] as f64, m.b[1] as f64) - q).norm()
                    })
            })
            .collect();
        let sizes = Sizes::new(&a, &DenseOptions::default());
        let grid = Grid::new(&a, None, sizes.spacing, sizes.margin);
        let covisible = grid
            .points
            .iter()
            .zip(&grid.active)
            .filter(|(p, active)| **active && scene.correspondence(&ca, &cb, **p).is_some())
            .count();
        eprintln!(
            "corner: {} matches of {covisible} covisible grid points, {:.1} % < 1 px, \
             {:.1} % < 0.5 px, {seconds:.1} s",
            matches.len(),
            100.0 * within(&errors, 1.0),
            100.0 * within(&errors, 0.5),
        );
        assert!(within(&errors, 1.0) >= 0.9);
        assert!(matches.len() as f64 >= 0.5 * covisible as f64);
    }
}
