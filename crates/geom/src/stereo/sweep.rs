//! Plane-sweep stereo in a reference camera (Collins 1996; Gallup et al. 2007), for pairs that
//! rectification cannot serve: a camera that walks forward, whose epipoles lie inside the
//! images, or two views turned so far apart that rectified rows would stretch them out of shape.
//!
//! The depth hypotheses are planes parallel to the reference image, evenly spaced in inverse
//! depth between the pair's near and far depth (as disparities are in a rectified pair), as
//! many as the longest epipolar segment between them has pixels. For every plane the source
//! image is warped into the reference camera through the plane's homography and compared with
//! the reference pixel by pixel; the costs are those of the rectified matcher
//! ([`super::sgm`]: absolute differences of the clipped Sobel derivatives and a quarter of the
//! intensities, summed over the block), in both image directions since epipolar lines run any
//! way here, and are aggregated by the same semi-global paths with the same penalties. Each
//! pixel takes the unique cheapest plane, refined by a parabola, then the 3×3 median and the
//! speckle filter as after rectified matching. The consistency of the two views' depths is
//! checked afterwards by the hierarchical cloud, as for rectified pairs.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use fewview_scene::{Camera, Image};

use super::pairs::StereoView;
use super::refine::{RefineOptions, grey};
use super::sgm::{self, DISP_SCALE, PARALLEL_VOLUME_BYTES, SgmParams, median3x3, speckle_filter};
use super::sweep_refine::{Rays, Textured, refine_inverse_depths};
use super::view_depth::{PairDepths, ViewDepth};
use crate::error::{GeomError, Result};

/// The most depth planes a sweep tests.
pub const MAX_PLANES: usize = 256;
/// The fewest depth planes a sweep tests.
pub const MIN_PLANES: usize = 16;

/// Depth hypotheses evenly spaced in inverse depth from the far plane (index 0) to the near one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Planes {
    pub near: f64,
    pub far: f64,
    pub count: usize,
}

impl Planes {
    /// The planes between `near` and `far` in `reference`'s camera for matching against
    /// `source`: one per pixel of the longest epipolar segment that depth range draws in the
    /// source image (over a grid of reference pixels), between [`MIN_PLANES`] and
    /// [`MAX_PLANES`].
    pub fn between(reference: &Camera, source: &Camera, near: f64, far: f64) -> Result<Self> {
        if !(near > 0.0 && near < far && far.is_finite()) {
            return Err(GeomError::invalid(
                "plane sweep",
                format!("depth range {near} to {far} is not 0 < near < far"),
            ));
        }
        let (w, h) = (reference.width() as f64, reference.height() as f64);
        let (sw, sh) = (source.width() as f64, source.height() as f64);
        let inside = |(u, v, _): (f64, f64, f64)| (0.0..sw).contains(&u) && (0.0..sh).contains(&v);
        // The epipolar segment of a reference pixel, walked in inverse depth: only the part in
        // front of the source camera and inside its image counts.
        const STEPS: usize = 64;
        let mut longest = 0.0f64;
        for j in 0..=12 {
            for i in 0..=16 {
                let (u, v) = (w * i as f64 / 16.0, h * j as f64 / 12.0);
                let mut length = 0.0;
                let mut previous: Option<(f64, f64, f64)> = None;
                for k in 0..=STEPS {
                    let rho = 1.0 / far + (1.0 / near - 1.0 / far) * k as f64 / STEPS as f64;
                    let seen = source
                        .project(&reference.unproject(u, v, 1.0 / rho))
                        .filter(|&p| inside(p));
                    if let (Some(a), Some(b)) = (previous, seen) {
                        length += (b.0 - a.0).hypot(b.1 - a.1);
                    }
                    previous = seen;
                }
                longest = longest.max(length);
            }
        }
        let count = (longest.ceil() as usize + 1).clamp(MIN_PLANES, MAX_PLANES);
        Ok(Self { near, far, count })
    }

    /// The inverse depth of (fractional) plane `k`.
    pub fn inverse_depth(&self, k: f64) -> f64 {
        let step = (1.0 / self.near - 1.0 / self.far) / (self.count - 1).max(1) as f64;
        1.0 / self.far + k * step
    }
}

/// The depth maps of both views of a pair, each swept as the reference against the other (side
/// by side, or one after the other for large images, as rectified matching does).
pub fn sweep_pair(
    first: &StereoView,
    second: &StereoView,
    (near, far): (f64, f64),
    params: &SgmParams,
    refine: Option<&RefineOptions>,
) -> Result<PairDepths> {
    let volume = first.image.width * first.image.height * MAX_PLANES * std::mem::size_of::<i16>();
    let (a, b) = if volume > PARALLEL_VOLUME_BYTES {
        (
            sweep_view(first, second, (near, far), params, refine),
            sweep_view(second, first, (near, far), params, refine),
        )
    } else {
        rayon::join(
            || sweep_view(first, second, (near, far), params, refine),
            || sweep_view(second, first, (near, far), params, refine),
        )
    };
    let (mut a, mut b) = (a?, b?);
    let tolerance = 0.5 * params.disp12_max_diff.max(1) as f64;
    let a_agrees = agreeing(first.camera, &a, second.camera, &b, tolerance);
    let b_agrees = agreeing(second.camera, &b, first.camera, &a, tolerance);
    for (depth, agrees) in [(&mut a, a_agrees), (&mut b, b_agrees)] {
        for (v, ok) in depth.verified.iter_mut().zip(agrees) {
            *v &= ok;
        }
    }
    Ok(PairDepths {
        first: a,
        second: b,
    })
}

/// The left–right check of a sweep: a pixel of `a` agrees with `b` when the point its depth
/// places, seen by `b` and put back at `b`'s own depth there, lands within `tolerance` pixels
/// of it (OpenCV's `disp12MaxDiff`, in the image rather than along a rectified row).
fn agreeing(
    camera_a: &Camera,
    a: &ViewDepth,
    camera_b: &Camera,
    b: &ViewDepth,
    tolerance: f64,
) -> Vec<bool> {
    let (w, wb, hb) = (
        camera_a.width() as usize,
        camera_b.width() as usize,
        camera_b.height() as usize,
    );
    (0..a.depth.len())
        .into_par_iter()
        .map(|i| {
            let z = a.depth[i];
            if z <= 0.0 {
                return false;
            }
            let (u, v) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let Some((ub, vb, _)) = camera_b.project(&camera_a.unproject(u, v, z as f64)) else {
                return false;
            };
            if !(ub >= 0.0 && vb >= 0.0 && (ub as usize) < wb && (vb as usize) < hb) {
                return false;
            }
            let zb = b.depth[vb as usize * wb + ub as usize];
            if zb <= 0.0 {
                return false;
            }
            let back = camera_a
                .project(&camera_b.unproject(ub, vb, zb as f64))
                .is_some_and(|(ua, va, _)| (ua - u).hypot(va - v) <= tolerance);
            back && parallax_per_percent(camera_a, camera_b, (u, v), z as f64)
                >= MIN_PARALLAX_PX_PER_PERCENT
        })
        .collect()
}

/// The least parallax (pixels in the other view per 1 % of depth) a verified depth needs: near
/// the epipoles of a camera walking forward a point barely moves, so a pixel's matching error
/// there is many percent of depth.
pub const MIN_PARALLAX_PX_PER_PERCENT: f64 = 0.25;

/// How far the point at depth `z` through pixel `(u, v)` of `a` moves in `b` when its depth
/// changes by 1 %.
fn parallax_per_percent(a: &Camera, b: &Camera, (u, v): (f64, f64), z: f64) -> f64 {
    let seen = |z: f64| b.project(&a.unproject(u, v, z));
    match (seen(z * 1.005), seen(z / 1.005)) {
        (Some(p), Some(q)) => (p.0 - q.0).hypot(p.1 - q.1),
        _ => 0.0,
    }
}

/// The depth map of `reference` matched against `source` over the depths `near..far` (of the
/// pair; the planes are set in the reference camera), each depth refined between the planes
/// where the window allows when `refine` is given ([`super::sweep_refine`]).
pub fn sweep_view(
    reference: &StereoView,
    source: &StereoView,
    (near, far): (f64, f64),
    params: &SgmParams,
    refine: Option<&RefineOptions>,
) -> Result<ViewDepth> {
    let name = || format!("views {} and {}", reference.name, source.name);
    let planes = Planes::between(reference.camera, source.camera, near, far)
        .map_err(|e| GeomError::invalid(name(), e.to_string()))?;
    // The clip the rectified matcher resolves its `pre_filter_cap` to.
    let cap = (params.pre_filter_cap.max(15) | 1) as f32;
    let r = Grey::new(reference.image);
    let s = Grey::new(source.image);
    let warp = Warp::new(reference.camera, source.camera);
    let (w, h, d) = (r.width, r.height, planes.count);
    let cost = cost_volume(&r, &s, &warp, &planes, (params.block_size / 2, cap));
    // Two derivative planes and the intensities weigh about as much as two colour channels of
    // the rectified matcher's cost, so its penalties are taken for two channels.
    let aggregated = sgm::aggregate_volume(&cost, (w, h, d), params, 2)
        .map_err(|e| GeomError::invalid(name(), e.to_string()))?;
    drop(cost);
    let invalid = -DISP_SCALE as i16;
    let mut steps: Vec<i16> = aggregated
        .par_chunks(d)
        .map(|sp| sgm::best_hypothesis(sp, params.uniqueness_ratio).map_or(invalid, |k| k as i16))
        .collect();
    median3x3(&mut steps, w, h);
    if params.speckle_window_size > 0 {
        speckle_filter(
            &mut steps,
            w,
            h,
            invalid,
            params.speckle_window_size,
            params.speckle_range * DISP_SCALE,
        );
    }
    // A choice on the first or last plane may lie beyond the range: depth, but not verified.
    let last = ((d - 1) as i32 * DISP_SCALE) as i16;
    let mut rho: Vec<f64> = steps
        .iter()
        .map(|&k| {
            if k <= 0 {
                f64::NAN
            } else {
                planes.inverse_depth(k as f64 / DISP_SCALE as f64)
            }
        })
        .collect();
    let verified: Vec<bool> = steps.iter().map(|&k| k > 0 && k < last).collect();
    if let Some(options) = refine {
        refine_view(reference, source, &mut rho, options);
    }
    let depth = rho
        .iter()
        .map(|&r| if r > 0.0 { (1.0 / r) as f32 } else { 0.0 })
        .collect();
    Ok(ViewDepth { depth, verified })
}

/// [`refine_inverse_depths`] of `reference`'s inverse depths against `source`.
fn refine_view(
    reference: &StereoView,
    source: &StereoView,
    rho: &mut [f64],
    options: &RefineOptions,
) -> Vec<bool> {
    let textured = |image: &Image| Textured::new(grey(image), image.width, image.height);
    let warp = Warp::new(reference.camera, source.camera);
    let w = reference.image.width;
    let rays: Vec<Vector3<f64>> = (0..rho.len())
        .map(|i| warp.rays * Vector3::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, 1.0))
        .collect();
    let rays = Rays {
        rays: &rays,
        shift: warp.shift,
    };
    refine_inverse_depths(
        &textured(reference.image),
        &textured(source.image),
        &rays,
        rho,
        options,
    )
}

/// An image's intensities (0–255, the mean of its colour channels), as the matcher compares
/// them.
struct Grey {
    width: usize,
    height: usize,
    values: Vec<f32>,
}

impl Grey {
    fn new(image: &Image) -> Self {
        let c = image.channels.max(1);
        let values = image
            .data
            .chunks(c)
            .map(|p| {
                let v = if c >= 3 {
                    (p[0] + p[1] + p[2]) / 3.0
                } else {
                    p[0]
                };
                (v.clamp(0.0, 1.0) * 255.0).round()
            })
            .collect();
        Self {
            width: image.width,
            height: image.height,
            values,
        }
    }

    /// The intensity at continuous pixel position `(u, v)` (pixel centres at half-integers),
    /// bilinearly; NaN outside the image.
    fn sample(&self, u: f32, v: f32) -> f32 {
        let (x, y) = (u - 0.5, v - 0.5);
        if !(x >= 0.0 && y >= 0.0) {
            return f32::NAN;
        }
        let (x0, y0) = (x as usize, y as usize);
        if x0 + 1 >= self.width || y0 + 1 >= self.height {
            return f32::NAN;
        }
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let i = y0 * self.width + x0;
        let (a, b) = (self.values[i], self.values[i + 1]);
        let (c, d) = (self.values[i + self.width], self.values[i + self.width + 1]);
        let top = a + fx * (b - a);
        let bottom = c + fx * (d - c);
        top + fy * (bottom - top)
    }
}

/// The matcher's planes of one pixel from the 3×3 intensities around it (row by row): the
/// intensity and its x and y Sobel derivatives clipped to `±cap` and shifted by `cap`, as the
/// rectified matcher prefilters its images.
fn prefiltered(n: [f32; 9], cap: f32) -> [f32; 3] {
    let dx = (n[2] + 2.0 * n[5] + n[8]) - (n[0] + 2.0 * n[3] + n[6]);
    let dy = (n[6] + 2.0 * n[7] + n[8]) - (n[0] + 2.0 * n[1] + n[2]);
    [n[4], dx.clamp(-cap, cap) + cap, dy.clamp(-cap, cap) + cap]
}

/// Row `y` of `rows` (row-major, `w` wide, `h` rows, edges repeated) as prefiltered planes; a
/// pixel whose neighbourhood holds a NaN (outside the warped source) is `None`.
fn prefiltered_row(
    rows: &[f32],
    w: usize,
    h: usize,
    y: usize,
    cap: f32,
    out: &mut [Option<[f32; 3]>],
) {
    for (x, o) in out.iter_mut().enumerate() {
        let mut n = [0.0f32; 9];
        for (k, v) in n.iter_mut().enumerate() {
            let xx = (x as i64 + k as i64 % 3 - 1).clamp(0, w as i64 - 1) as usize;
            let yy = (y as i64 + k as i64 / 3 - 1).clamp(0, h as i64 - 1) as usize;
            *v = rows[yy * w + xx];
        }
        *o = n.iter().all(|v| v.is_finite()).then(|| prefiltered(n, cap));
    }
}

/// Reference pixel → source pixel through a plane of inverse depth `ρ`: the source point is
/// `K_s (R K_r⁻¹ p + ρ t)` up to scale, with `(R, t)` the reference-to-source motion.
struct Warp {
    /// `K_s R K_r⁻¹`.
    rays: Matrix3<f64>,
    /// `K_s t`.
    shift: Vector3<f64>,
}

impl Warp {
    fn new(reference: &Camera, source: &Camera) -> Self {
        let (rr, tr) = (
            reference.world_to_camera.rotation,
            reference.world_to_camera.translation,
        );
        let (rs, ts) = (
            source.world_to_camera.rotation,
            source.world_to_camera.translation,
        );
        let r = rs * rr.transpose();
        let t = ts - r * tr;
        let k = |c: &Camera| {
            let i = c.intrinsics;
            Matrix3::new(i.fx, 0.0, i.cx, 0.0, i.fy, i.cy, 0.0, 0.0, 1.0)
        };
        let k_r_inv = k(reference).try_inverse().unwrap_or_else(Matrix3::identity);
        Self {
            rays: k(source) * r * k_r_inv,
            shift: k(source) * t,
        }
    }
}

/// The cost of a pixel whose plane point falls outside the source image or behind it: the most
/// a pixel can cost (as candidates outside the right image in the rectified matcher).
fn outside_cost(cap: f32) -> i16 {
    (2.0 * 2.0 * cap + 255.0 / 4.0) as i16
}

/// Rows per parallel task of [`cost_volume`]: each band warps and prefilters the rows around it
/// again.
const BAND: usize = 16;

/// The block-summed cost volume, `height × width × planes` values. For each plane the source's
/// intensities are warped into the reference camera and prefiltered there, so that a surface
/// at the plane's depth looks alike in both, whatever the change of scale between the views
/// (a camera walking forward magnifies what it approaches).
fn cost_volume(
    reference: &Grey,
    source: &Grey,
    warp: &Warp,
    planes: &Planes,
    (half_block, cap): (usize, f32),
) -> Vec<i16> {
    let (w, h, d) = (reference.width, reference.height, planes.count);
    let n = w * d;
    let worst = outside_cost(cap);
    let rays: Vec<Vector3<f32>> = (0..w * h)
        .map(|i| {
            let p = warp.rays * Vector3::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5, 1.0);
            p.map(|v| v as f32)
        })
        .collect();
    let shift = warp.shift.map(|v| v as f32);
    let mut volume = vec![0i16; h * n];
    volume
        .par_chunks_mut(BAND * n)
        .enumerate()
        .for_each(|(band, out)| {
            let (y0, y1) = (band * BAND, (band * BAND + BAND).min(h));
            // Rows of the block sums, and one more on each side for the derivatives.
            let first = y0 as i64 - half_block as i64;
            let rows = y1 - y0 + 2 * half_block;
            let clamp_row = |y: i64| y.clamp(0, h as i64 - 1) as usize;
            let mut reference_rows = vec![None; (rows + 2) * w];
            let window: Vec<f32> = (0..rows + 2)
                .flat_map(|k| {
                    let y = clamp_row(first - 1 + k as i64);
                    reference.values[y * w..(y + 1) * w].iter().copied()
                })
                .collect();
            for k in 0..rows {
                prefiltered_row(
                    &window,
                    w,
                    rows + 2,
                    k + 1,
                    cap,
                    &mut reference_rows[k * w..(k + 1) * w],
                );
            }
            let mut summed = vec![0i16; rows * n];
            let mut warped = vec![0.0f32; (rows + 2) * w];
            let mut planes_row = vec![None; w];
            let mut pixel = vec![0i16; w];
            for (k, &rho) in planes_inverse(planes).iter().enumerate() {
                for (j, row) in warped.chunks_mut(w).enumerate() {
                    let y = clamp_row(first - 1 + j as i64);
                    for (x, v) in row.iter_mut().enumerate() {
                        let q = rays[y * w + x] + shift * rho;
                        *v = if q.z > 1e-6 {
                            source.sample(q.x / q.z, q.y / q.z)
                        } else {
                            f32::NAN
                        };
                    }
                }
                for j in 0..rows {
                    prefiltered_row(&warped, w, rows + 2, j + 1, cap, &mut planes_row);
                    let r = &reference_rows[j * w..(j + 1) * w];
                    for ((c, s), r) in pixel.iter_mut().zip(&planes_row).zip(r) {
                        *c = match (s, r) {
                            (Some(s), Some(r)) => ((s[1] - r[1]).abs()
                                + (s[2] - r[2]).abs()
                                + 0.25 * (s[0] - r[0]).abs())
                            .round() as i16,
                            _ => worst,
                        };
                    }
                    box_sum_plane(&pixel, &mut summed[j * n..(j + 1) * n], d, k, half_block);
                }
            }
            for (j, o) in out.chunks_mut(n).enumerate() {
                for k in 0..=2 * half_block {
                    for (a, b) in o.iter_mut().zip(&summed[(j + k) * n..(j + k + 1) * n]) {
                        *a += *b;
                    }
                }
            }
        });
    volume
}

/// The inverse depth of every plane, far to near.
fn planes_inverse(planes: &Planes) -> Vec<f32> {
    (0..planes.count)
        .map(|k| planes.inverse_depth(k as f64) as f32)
        .collect()
}

/// One plane's pixel costs of a row (`pixel`, `width` values) summed over `2r + 1` columns (the
/// edge columns repeated) into entry `k` of each pixel of `out` (`width × planes`).
fn box_sum_plane(pixel: &[i16], out: &mut [i16], d: usize, k: usize, r: usize) {
    let w = pixel.len();
    for x in 0..w {
        let mut sum = 0i16;
        for dx in 0..=2 * r {
            let xs = (x as i64 + dx as i64 - r as i64).clamp(0, w as i64 - 1) as usize;
            sum += pixel[xs];
        }
        out[x * d + k] = sum;
    }
}
