//! Calibrated rectification of a stereo pair (Fusiello, Trucco, Verri 2000, "A compact algorithm
//! for rectification of stereo pairs"), with the common optical axis taken as the average of the
//! two original axes (as Bouguet's variant does) so that both views turn as little as possible.
//!
//! Both rectified cameras keep their original centres, share one rotation, one focal length,
//! one row of principal points and one image size, and see the second centre at `+x`:
//! corresponding points lie on the same image row and their disparity `x_left − x_right` is
//! `f·B / z + offset`, where `offset = cx_left − cx_right`. The offset is 0 (one shared set of
//! intrinsics) unless the two views turn so far towards each other that one canvas cannot hold
//! both images; then each rectified image is centred on its own original (OpenCV's
//! `stereoRectify` without `CALIB_ZERO_DISPARITY` does the same), and disparities near the
//! cameras' meeting point are near 0 or negative. Each original view maps to its rectified view
//! by the homography `K_r R_r R_oᵀ K_o⁻¹`.
//!
//! All pixel coordinates are continuous, with pixel `(i, j)` centred at `(i + 0.5, j + 0.5)`, as
//! [`Camera::project`] uses.

use fewview_scene::{Camera, Image, Intrinsics, Se3};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use crate::error::{GeomError, Result};

/// Which view of the pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The first camera given to [`Rectification::new`].
    Left,
    /// The second camera given to [`Rectification::new`].
    Right,
}

impl Side {
    fn name(self) -> &'static str {
        match self {
            Side::Left => "left",
            Side::Right => "right",
        }
    }
}

/// A rectified image and which of its pixels saw the original image.
#[derive(Clone, Debug, PartialEq)]
pub struct RectifiedImage {
    /// Same channel count as the original; 0 where `inside` is false.
    pub image: Image,
    /// Per rectified pixel (row-major): whether its source position lies on the original image.
    pub inside: Vec<bool>,
}

/// The rectifying transforms of a calibrated stereo pair.
#[derive(Clone, Debug)]
pub struct Rectification {
    /// Intrinsics of the left rectified image: `fx = fy = f` and the canvas size, both shared
    /// with the right one, which differs only in `cx` (by [`Self::offset`]).
    pub intrinsics: Intrinsics,
    /// The rectified first camera: the common rotation, the first original centre.
    pub left: Camera,
    /// The rectified second camera: the common rotation, the second original centre, at
    /// `(baseline, 0, 0)` in the left rectified camera's frame.
    pub right: Camera,
    /// Distance between the two centres (scene units).
    pub baseline: f64,
    /// `cx_left − cx_right` (rectified pixels): the disparity of a point at infinity.
    pub offset: f64,
    first: Camera,
    second: Camera,
    left_maps: SideMaps,
    right_maps: SideMaps,
}

/// The pixel maps of one side between its original and rectified image.
#[derive(Clone, Debug)]
struct SideMaps {
    /// Original pixel → rectified pixel (homogeneous): `K_r R_r R_oᵀ K_o⁻¹`.
    to_rect: Matrix3<f64>,
    /// Rectified pixel → original pixel (homogeneous): `K_o R_o R_rᵀ K_r⁻¹`.
    from_rect: Matrix3<f64>,
}

/// How far from orthonormal a camera rotation may be before it is refused.
const ROTATION_TOLERANCE: f64 = 1e-3;
/// Baselines below this fraction of the scene's distance scale count as no baseline.
const MIN_RELATIVE_BASELINE: f64 = 1e-9;
/// Above this `|cos|` between baseline and mean optical axis the epipoles lie inside the images
/// and no pair of parallel image planes contains the baseline usefully.
const MAX_AXIS_BASELINE_COS: f64 = 0.99;

impl Rectification {
    /// The rectification of `first` (left) and `second` (right).
    ///
    /// The common rotation has its x axis along the baseline `c2 − c1`, its z axis as close as
    /// possible to the mean optical axis, and y completing a right-handed frame. The focal length
    /// is the mean of both cameras' `fx` and `fy`; the shared principal point puts the mid-point of
    /// the two rectified original image centres at the centre of the rectified image. If the
    /// second camera sits to the left of the first, the rectified images are upside down (the
    /// common x axis must point from first to second); swap the views to keep them upright.
    pub fn new(first: &Camera, second: &Camera) -> Result<Self> {
        check_camera(first, "first")?;
        check_camera(second, "second")?;
        let (c1, c2) = (first.center(), second.center());
        let baseline_vec = c2 - c1;
        let baseline = baseline_vec.norm();
        let scale = 1f64.max(c1.norm()).max(c2.norm());
        if !(baseline >= MIN_RELATIVE_BASELINE * scale) {
            return Err(GeomError::invalid(
                "stereo views",
                format!(
                    "the two cameras are at the same place (baseline {baseline:.1e}): stereo needs a baseline"
                ),
            ));
        }
        let rotation = common_rotation(first, second, &(baseline_vec / baseline))?;
        let f = (first.intrinsics.fx
            + first.intrinsics.fy
            + second.intrinsics.fx
            + second.intrinsics.fy)
            / 4.0;
        principal_point(f, &rotation, first, second)?;
        let canvas = canvas(f, &rotation, first, second);
        let intrinsics = Intrinsics {
            fx: f,
            fy: f,
            cx: canvas.cx[0],
            cy: canvas.cy,
            width: canvas.width,
            height: canvas.height,
        };
        let right_intrinsics = Intrinsics {
            cx: canvas.cx[1],
            ..intrinsics
        };
        let left = Camera::new(intrinsics, Se3::new(rotation, -(rotation * c1)));
        let right = Camera::new(right_intrinsics, Se3::new(rotation, -(rotation * c2)));
        let left_maps = SideMaps::new(first, &left);
        let right_maps = SideMaps::new(second, &right);
        Ok(Self {
            intrinsics,
            left,
            right,
            baseline,
            offset: canvas.cx[0] - canvas.cx[1],
            first: first.clone(),
            second: second.clone(),
            left_maps,
            right_maps,
        })
    }

    /// The original camera of `side`.
    pub fn original(&self, side: Side) -> &Camera {
        match side {
            Side::Left => &self.first,
            Side::Right => &self.second,
        }
    }

    /// The rectified camera of `side`.
    pub fn rectified(&self, side: Side) -> &Camera {
        match side {
            Side::Left => &self.left,
            Side::Right => &self.right,
        }
    }

    fn maps(&self, side: Side) -> &SideMaps {
        match side {
            Side::Left => &self.left_maps,
            Side::Right => &self.right_maps,
        }
    }

    /// `f·B`: disparity times rectified depth.
    fn focal_baseline(&self) -> f64 {
        self.intrinsics.fx * self.baseline
    }

    /// Rectified z-depth of a disparity `d` (rectified pixels): `f·B / (d − offset)`.
    pub fn disparity_to_depth(&self, d: f64) -> f64 {
        self.focal_baseline() / (d - self.offset)
    }

    /// Disparity (rectified pixels) of a point at rectified z-depth `z`: `f·B / z + offset`.
    pub fn depth_to_disparity(&self, z: f64) -> f64 {
        self.focal_baseline() / z + self.offset
    }

    /// Whether `d` is a disparity of a point in front of the cameras (finite, above the offset).
    fn in_front(&self, d: f32) -> Option<f64> {
        (d.is_finite() && d as f64 > self.offset).then_some(d as f64)
    }

    /// Original pixel coordinates `(u, v)` of `side` → rectified pixel coordinates. `NaN` when the
    /// ray through `(u, v)` points behind the rectified camera.
    pub fn to_rectified(&self, side: Side, u: f64, v: f64) -> (f64, f64) {
        apply_homography(&self.maps(side).to_rect, u, v)
    }

    /// Rectified pixel coordinates `(u, v)` of `side` → original pixel coordinates; the inverse of
    /// [`Self::to_rectified`]. `NaN` when the ray points behind the original camera.
    pub fn from_rectified(&self, side: Side, u: f64, v: f64) -> (f64, f64) {
        apply_homography(&self.maps(side).from_rect, u, v)
    }

    /// The rectified image of `side`: every rectified pixel centre mapped back into `image` and
    /// sampled bilinearly. A pixel is inside when its source lies on the original image's area
    /// `[0, w] × [0, h]` (the outer half pixel is clamped to the edge pixels); outside pixels are 0.
    ///
    /// An `image` whose size differs from the camera's is taken as the same camera imaged at that
    /// size (as [`Intrinsics::resized`]).
    pub fn rectify_image(&self, side: Side, image: &Image) -> RectifiedImage {
        let (w, h) = self.rectified_size();
        let ch = image.channels;
        let k = &self.original(side).intrinsics;
        let sx = image.width as f64 / k.width.max(1) as f64;
        let sy = image.height as f64 / k.height.max(1) as f64;
        let mut out = Image::new(w, h, ch);
        let mut inside = vec![false; w * h];
        if w == 0 || ch == 0 {
            return RectifiedImage { image: out, inside };
        }
        out.data
            .par_chunks_mut(w * ch)
            .zip(inside.par_chunks_mut(w))
            .enumerate()
            .for_each(|(j, (row, row_inside))| {
                for i in 0..w {
                    let (u, v) = self.from_rectified(side, i as f64 + 0.5, j as f64 + 0.5);
                    let (x, y) = (u * sx, v * sy);
                    let on_image =
                        x >= 0.0 && y >= 0.0 && x <= image.width as f64 && y <= image.height as f64;
                    if on_image && image.width > 0 && image.height > 0 {
                        row_inside[i] = true;
                        sample_bilinear(image, x, y, &mut row[i * ch..(i + 1) * ch]);
                    }
                }
            });
        RectifiedImage { image: out, inside }
    }

    /// The z-depth map of the original camera of `side` (its image size, 0 where unknown) from
    /// `disparity`, a disparity map of that side's rectified image (rectified size, row-major,
    /// `x_left − x_right`; values not finite or `≤ offset` mean no disparity).
    ///
    /// Each original pixel centre is mapped into the rectified image, where the disparity is
    /// interpolated bilinearly when the four surrounding pixels are valid and within one pixel of
    /// each other, else taken from the nearest pixel. The depth then follows from triangulation
    /// along the rectified ray.
    pub fn depth_from_disparity(&self, side: Side, disparity: &[f32]) -> Result<Vec<f32>> {
        let (rw, rh) = self.rectified_size();
        check_len(
            disparity.len(),
            rw,
            rh,
            &format!("{} disparity map", side.name()),
        )?;
        let k = &self.original(side).intrinsics;
        let (w, h) = (k.width as usize, k.height as usize);
        let as_disparity = |d: f32| self.in_front(d);
        let mut out = vec![0f32; w * h];
        if w == 0 {
            return Ok(out);
        }
        out.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
            for i in 0..w {
                let (pu, pv) = (i as f64 + 0.5, j as f64 + 0.5);
                let (qu, qv) = self.to_rectified(side, pu, pv);
                let Some(d) = sample_map(disparity, rw, rh, qu, qv, as_disparity) else {
                    continue;
                };
                let z = self.disparity_to_depth(d) * self.depth_scale_to_original(side, qu, qv);
                if z.is_finite() && z > 0.0 {
                    row[i] = z as f32;
                }
            }
        });
        Ok(out)
    }

    /// The disparity map of the rectified image of `side` (rectified size, `NaN` where unknown)
    /// from `depth`, a z-depth map of that side's original camera (its image size, values not
    /// finite or `≤ 0` mean no depth). The inverse of [`Self::depth_from_disparity`].
    ///
    /// Each rectified pixel centre is mapped into the original image, where the inverse depth is
    /// interpolated bilinearly when the four surrounding pixels are valid and agree to within one
    /// pixel of disparity, else taken from the nearest pixel.
    pub fn disparity_from_depth(&self, side: Side, depth: &[f32]) -> Result<Vec<f32>> {
        let k = &self.original(side).intrinsics;
        let (w, h) = (k.width as usize, k.height as usize);
        check_len(depth.len(), w, h, &format!("{} depth map", side.name()))?;
        let (rw, rh) = self.rectified_size();
        let fb = self.focal_baseline();
        // Inverse depth in disparity units, so that "agree" means the same as for disparities.
        let as_disparity = |z: f32| (z.is_finite() && z > 0.0).then(|| fb / z as f64);
        let mut out = vec![f32::NAN; rw * rh];
        if rw == 0 {
            return Ok(out);
        }
        out.par_chunks_mut(rw).enumerate().for_each(|(j, row)| {
            for i in 0..rw {
                let (qu, qv) = (i as f64 + 0.5, j as f64 + 0.5);
                let (pu, pv) = self.from_rectified(side, qu, qv);
                let Some(inv) = sample_map(depth, w, h, pu, pv, as_disparity) else {
                    continue;
                };
                let z_rect = fb / inv / self.depth_scale_to_original(side, qu, qv);
                let d = self.depth_to_disparity(z_rect);
                if z_rect.is_finite() && z_rect > 0.0 && d.is_finite() {
                    row[i] = d as f32;
                }
            }
        });
        Ok(out)
    }

    /// The rectified image size `(width, height)`.
    fn rectified_size(&self) -> (usize, usize) {
        (
            self.intrinsics.width as usize,
            self.intrinsics.height as usize,
        )
    }

    /// `z_original / z_rectified` of the point seen at rectified pixel `(u, v)` of `side`: both
    /// cameras share their centre, so a point on the ray only changes the scale of its depth.
    fn depth_scale_to_original(&self, side: Side, u: f64, v: f64) -> f64 {
        let orig = self.original(side).world_to_camera.rotation;
        let rect = self.rectified(side).world_to_camera.rotation;
        let k = &self.rectified(side).intrinsics;
        let ray = Vector3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
        (orig * rect.transpose() * ray).z
    }
}

impl SideMaps {
    fn new(original: &Camera, rectified: &Camera) -> Self {
        let (ko, kr) = (&original.intrinsics, &rectified.intrinsics);
        let ro = original.world_to_camera.rotation;
        let rr = rectified.world_to_camera.rotation;
        Self {
            to_rect: kr.matrix() * rr * ro.transpose() * inverse_k(ko),
            from_rect: ko.matrix() * ro * rr.transpose() * inverse_k(kr),
        }
    }
}

/// `K⁻¹` in closed form (finite positive focal lengths are checked beforehand).
fn inverse_k(k: &Intrinsics) -> Matrix3<f64> {
    Matrix3::new(
        1.0 / k.fx,
        0.0,
        -k.cx / k.fx,
        0.0,
        1.0 / k.fy,
        -k.cy / k.fy,
        0.0,
        0.0,
        1.0,
    )
}

/// `H [u, v, 1]ᵀ` dehomogenised; `NaN` unless the homogeneous scale is positive (in front).
fn apply_homography(hm: &Matrix3<f64>, u: f64, v: f64) -> (f64, f64) {
    let p = hm * Vector3::new(u, v, 1.0);
    if p.z > 0.0 {
        (p.x / p.z, p.y / p.z)
    } else {
        (f64::NAN, f64::NAN)
    }
}

/// Refuses a camera with non-finite values, non-positive focal lengths, an empty image or a
/// rotation that is not orthonormal.
fn check_camera(camera: &Camera, which: &str) -> Result<()> {
    if !camera.is_finite() {
        return Err(GeomError::invalid(
            "stereo views",
            format!(
                "the {which} camera has a non-finite pose or intrinsics (or a focal length ≤ 0)"
            ),
        ));
    }
    let k = &camera.intrinsics;
    if k.width == 0 || k.height == 0 {
        return Err(GeomError::invalid(
            "stereo views",
            format!(
                "the {which} camera has an empty image ({}×{})",
                k.width, k.height
            ),
        ));
    }
    let r = camera.world_to_camera.rotation;
    let off = (r * r.transpose() - Matrix3::identity()).abs().max();
    if off > ROTATION_TOLERANCE {
        return Err(GeomError::invalid(
            "stereo views",
            format!("the {which} camera's rotation is not orthonormal (R·Rᵀ − I up to {off:.1e})"),
        ));
    }
    Ok(())
}

/// The common world-to-camera rotation (rows x, y, z): x along the unit baseline `x`, z the mean
/// optical axis made orthogonal to x, y = z × x. Refuses opposite optical axes and baselines
/// (nearly) along the mean axis.
fn common_rotation(first: &Camera, second: &Camera, x: &Vector3<f64>) -> Result<Matrix3<f64>> {
    let sum = first.forward() + second.forward();
    if !(sum.norm() > 1e-6) {
        return Err(GeomError::invalid(
            "stereo views",
            "the two cameras look in opposite directions: they share no view to rectify",
        ));
    }
    let mean_axis = sum.normalize();
    let cos = x.dot(&mean_axis);
    if !(cos.abs() <= MAX_AXIS_BASELINE_COS) {
        return Err(GeomError::invalid(
            "stereo views",
            format!(
                "the baseline is almost along the optical axis (cos {cos:.3}): the epipoles lie inside the images and rectification is degenerate"
            ),
        ));
    }
    let y = mean_axis.cross(x).normalize();
    let z = x.cross(&y);
    Ok(Matrix3::from_rows(&[
        x.transpose(),
        y.transpose(),
        z.transpose(),
    ]))
}

/// The shared principal point that puts the mid-point of both original image centres, seen by
/// the rectified cameras, at the centre of the rectified image (the first view's size).
fn principal_point(
    f: f64,
    rotation: &Matrix3<f64>,
    first: &Camera,
    second: &Camera,
) -> Result<(f64, f64)> {
    let mut mid = (0.0, 0.0);
    for (camera, which) in [(first, "first"), (second, "second")] {
        let k = &camera.intrinsics;
        let centre = Vector3::new(k.width as f64 / 2.0, k.height as f64 / 2.0, 1.0);
        let ray = rotation * camera.world_to_camera.rotation.transpose() * inverse_k(k) * centre;
        if !(ray.z > 0.0) {
            return Err(GeomError::invalid(
                "stereo views",
                format!(
                    "the {which} camera's image centre lies behind the common rectified view: the cameras turn too far apart"
                ),
            ));
        }
        mid.0 += 0.5 * f * ray.x / ray.z;
        mid.1 += 0.5 * f * ray.y / ray.z;
    }
    let k = &first.intrinsics;
    Ok((k.width as f64 / 2.0 - mid.0, k.height as f64 / 2.0 - mid.1))
}

/// The largest rectified canvas, per axis, relative to the first image.
const MAX_CANVAS_SCALE: f64 = 2.0;
/// Pixels added around the rectified canvas on every side.
const CANVAS_MARGIN: f64 = 2.0;

/// The rectified images' size and principal points.
struct Canvas {
    /// `cx` of the left and the right rectified image.
    cx: [f64; 2],
    cy: f64,
    width: u32,
    height: u32,
}

/// The rectified image: the bounding box of both original images mapped into the common frame
/// (so that a pair whose baseline runs diagonally across the images, and whose rectified images
/// therefore turn, loses no part of either image), at most [`MAX_CANVAS_SCALE`] times the first
/// image per axis around the box's centre, with a margin of [`CANVAS_MARGIN`] pixels so that
/// every original pixel centre has rectified neighbours on all sides. When the two images lie
/// so far apart along the rows that the clipped joint canvas would keep less than
/// [`MIN_KEPT_WIDTH`] of either image (cameras turned far towards each other), each rectified
/// image is instead centred on its own image's box: one width, one row of principal points,
/// two `cx`.
fn canvas(f: f64, rotation: &Matrix3<f64>, first: &Camera, second: &Camera) -> Canvas {
    let boxes = [first, second].map(|c| image_box(f, rotation, c));
    let joint = |a: usize| {
        (
            boxes[0].lo[a].min(boxes[1].lo[a]),
            boxes[0].hi[a].max(boxes[1].hi[a]),
        )
    };
    let k = &first.intrinsics;
    let (width_limit, height_limit) = (
        MAX_CANVAS_SCALE * k.width as f64,
        MAX_CANVAS_SCALE * k.height as f64,
    );
    let (height, cy) = fit(joint(1), height_limit);
    let (x_lo, x_hi) = joint(0);
    let (width, cx) = if keeps_most(&boxes, (x_lo, x_hi), width_limit) {
        let (width, cx) = fit((x_lo, x_hi), width_limit);
        (width, [cx, cx])
    } else {
        let widest = boxes.iter().map(|b| b.hi[0] - b.lo[0]).fold(0.0, f64::max);
        let (width, _) = fit((0.0, widest), width_limit);
        let centre = |b: &ImageBox| 0.5 * (b.lo[0] + b.hi[0]);
        (width, boxes.each_ref().map(|b| 0.5 * width - centre(b)))
    };
    Canvas {
        cx,
        cy,
        width: width as u32,
        height: height as u32,
    }
}

/// The least fraction of each image's rectified width a shared canvas must keep.
///
/// Pairs that clip a little (DTU's 40° pairs lose their outer image borders) keep the shared
/// canvas, the standard form; on DTU's wide triplets the per-image canvas gave the stereo start
/// more floaters (docs/experiments.md).
const MIN_KEPT_WIDTH: f64 = 0.5;

/// Whether the middle `limit` pixels of the joint span `(lo, hi)` keep at least
/// [`MIN_KEPT_WIDTH`] of each image's box.
fn keeps_most(boxes: &[ImageBox; 2], (lo, hi): (f64, f64), limit: f64) -> bool {
    let centre = 0.5 * (lo + hi);
    let (c_lo, c_hi) = (centre - 0.5 * limit, centre + 0.5 * limit);
    boxes.iter().all(|b| {
        let kept = (b.hi[0].min(c_hi) - b.lo[0].max(c_lo)).max(0.0);
        kept >= MIN_KEPT_WIDTH * (b.hi[0] - b.lo[0])
    })
}

/// The canvas extent (with its margin) and principal point that hold the span `(lo, hi)` of one
/// axis, or its middle `limit` pixels.
fn fit((lo, hi): (f64, f64), limit: f64) -> (f64, f64) {
    let extent = ((hi - lo).min(limit) + 2.0 * CANVAS_MARGIN).ceil();
    (extent, 0.5 * extent - 0.5 * (lo + hi))
}

/// The bounding box of an image's corners seen by a camera of focal length `f` and rotation
/// `rotation` at the same centre (corners behind it left out).
struct ImageBox {
    lo: [f64; 2],
    hi: [f64; 2],
}

fn image_box(f: f64, rotation: &Matrix3<f64>, camera: &Camera) -> ImageBox {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    let k = &camera.intrinsics;
    let to_common = rotation * camera.world_to_camera.rotation.transpose() * inverse_k(k);
    for (u, v) in [
        (0.0, 0.0),
        (k.width as f64, 0.0),
        (0.0, k.height as f64),
        (k.width as f64, k.height as f64),
    ] {
        let ray = to_common * Vector3::new(u, v, 1.0);
        if ray.z <= 0.0 {
            continue;
        }
        let p = [f * ray.x / ray.z, f * ray.y / ray.z];
        for a in 0..2 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    ImageBox { lo, hi }
}

/// Refuses a per-pixel map whose length is not `w × h`.
fn check_len(len: usize, w: usize, h: usize, what: &str) -> Result<()> {
    if len != w * h {
        return Err(GeomError::invalid(
            what,
            format!("{len} values, but the image is {w}×{h} = {} pixels", w * h),
        ));
    }
    Ok(())
}

/// `values` (a `w × h` row-major map) at continuous pixel coordinates `(u, v)`, each raw value
/// turned into a disparity-like quantity by `convert` (`None`: no value).
///
/// Bilinear over the 2×2 pixel centres around `(u, v)` when all four are valid and span at most
/// one unit. Where that block is incomplete (at a hole, or in the half-pixel band along the image
/// border), another complete, agreeing block that holds the containing pixel is extended linearly,
/// by at most half a pixel: exact for the affine disparity of a plane, where the containing
/// pixel's value alone would be off by up to half a pixel's gradient. Failing that, the containing
/// pixel's value; else `None`.
fn sample_map(
    values: &[f32],
    w: usize,
    h: usize,
    u: f64,
    v: f64,
    convert: impl Fn(f32) -> Option<f64>,
) -> Option<f64> {
    if !(u >= 0.0 && v >= 0.0 && u < w as f64 && v < h as f64) {
        return None;
    }
    let (ni, nj) = (u.floor() as usize, v.floor() as usize);
    if w >= 2 && h >= 2 {
        // Blocks (by top-left pixel) that hold the containing pixel, nearest first.
        let mut blocks = [(0usize, 0usize); 4];
        let mut count = 0;
        for oj in [nj.saturating_sub(1), nj.min(h - 2)] {
            for oi in [ni.saturating_sub(1), ni.min(w - 2)] {
                if !blocks[..count].contains(&(oi, oj)) {
                    blocks[count] = (oi, oj);
                    count += 1;
                }
            }
        }
        let off_centre = |&(oi, oj): &(usize, usize)| {
            (oi as f64 + 1.0 - u).abs().max((oj as f64 + 1.0 - v).abs())
        };
        blocks[..count].sort_by(|a, b| off_centre(a).total_cmp(&off_centre(b)));
        for &(oi, oj) in &blocks[..count] {
            if let Some(value) = block_bilinear(values, w, oi, oj, u, v, &convert) {
                return Some(value);
            }
        }
    }
    convert(values[nj * w + ni])
}

/// Bilinear interpolation (or linear extension) at `(u, v)` of the 2×2 block whose top-left
/// pixel is `(oi, oj)`; `None` unless all four values are valid and span at most one unit.
fn block_bilinear(
    values: &[f32],
    w: usize,
    oi: usize,
    oj: usize,
    u: f64,
    v: f64,
    convert: &impl Fn(f32) -> Option<f64>,
) -> Option<f64> {
    let at = |di: usize, dj: usize| convert(values[(oj + dj) * w + oi + di]);
    let (a, b, c, d) = (at(0, 0)?, at(1, 0)?, at(0, 1)?, at(1, 1)?);
    let lo = a.min(b).min(c).min(d);
    let hi = a.max(b).max(c).max(d);
    if !(hi - lo <= 1.0) {
        return None;
    }
    let (tx, ty) = (u - 0.5 - oi as f64, v - 0.5 - oj as f64);
    let top = a + (b - a) * tx;
    let bottom = c + (d - c) * tx;
    Some(top + (bottom - top) * ty)
}

/// Bilinear sample of every channel of `image` at continuous pixel coordinates `(x, y)`, clamping
/// to the edge pixels; writes into `out` (one value per channel).
fn sample_bilinear(image: &Image, x: f64, y: f64, out: &mut [f32]) {
    let max_x = (image.width - 1) as f64;
    let max_y = (image.height - 1) as f64;
    let fx = (x - 0.5).clamp(0.0, max_x);
    let fy = (y - 0.5).clamp(0.0, max_y);
    let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
    let (x1, y1) = (
        (x0 + 1).min(image.width - 1),
        (y0 + 1).min(image.height - 1),
    );
    let (tx, ty) = ((fx - x0 as f64) as f32, (fy - y0 as f64) as f32);
    for (c, o) in out.iter_mut().enumerate() {
        let top = image.get(x0, y0, c) * (1.0 - tx) + image.get(x1, y0, c) * tx;
        let bottom = image.get(x0, y1, c) * (1.0 - tx) + image.get(x1, y1, c) * tx;
        *o = top * (1.0 - ty) + bottom * ty;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;
    use rand::{RngExt, SeedableRng};

    const DEG: f64 = std::f64::consts::PI / 180.0;
    const W: u32 = 320;
    const H: u32 = 240;

    /// A camera at `centre` looking along world +z, turned by (roll about z, pitch about x, yaw
    /// about y) in degrees.
    fn camera(k: Intrinsics, centre: Vector3<f64>, roll: f64, pitch: f64, yaw: f64) -> Camera {
        let r = Rotation3::from_euler_angles(pitch * DEG, yaw * DEG, roll * DEG).into_inner();
        Camera::new(k, Se3::new(r, -(r * centre)))
    }

    /// A general pair: different focal lengths, principal points, rotations (with roll) and a
    /// baseline with small y and z components.
    fn pair() -> (Camera, Camera) {
        let k1 = Intrinsics {
            fx: 400.0,
            fy: 402.0,
            cx: 161.0,
            cy: 118.5,
            width: W,
            height: H,
        };
        let k2 = Intrinsics {
            fx: 420.0,
            fy: 418.0,
            cx: 158.0,
            cy: 121.0,
            width: W,
            height: H,
        };
        let first = camera(k1, Vector3::new(0.0, 0.0, 0.0), 1.5, -1.0, 1.0);
        let second = camera(k2, Vector3::new(0.5, 0.03, 0.04), -1.0, 1.2, -1.5);
        (first, second)
    }

    /// Two narrow cameras (about 15° across) 60° apart on a ring of radius 3 around the point
    /// `(0.2, 0, 4)`, both looking at it: one canvas cannot hold both images side by side.
    fn converged_pair() -> (Camera, Camera) {
        converged_pair_at(30.0)
    }

    /// Two cameras 3 units from a point, each turned `degrees` towards it from straight ahead.
    fn converged_pair_at(degrees: f64) -> (Camera, Camera) {
        let k = Intrinsics {
            fx: 1200.0,
            fy: 1200.0,
            cx: 160.0,
            cy: 120.0,
            width: W,
            height: H,
        };
        let target = Vector3::new(0.2, 0.0, 4.0);
        let look_at = |degrees: f64| {
            let a = degrees * DEG;
            let centre = target + 3.0 * Vector3::new(a.sin(), 0.05, -a.cos());
            let z = (target - centre).normalize();
            let x = Vector3::y().cross(&z).normalize();
            let r = Matrix3::from_rows(&[x.transpose(), z.cross(&x).transpose(), z.transpose()]);
            Camera::new(k, Se3::new(r, -(r * centre)))
        };
        (look_at(-degrees), look_at(degrees))
    }

    /// A slanted plane `n·X = offset` in front of the pair.
    struct Plane {
        n: Vector3<f64>,
        offset: f64,
    }

    impl Plane {
        fn new() -> Self {
            let n = Vector3::new(0.25, -0.15, 1.0).normalize();
            Self {
                n,
                offset: n.dot(&Vector3::new(0.2, 0.0, 4.0)),
            }
        }

        /// The point of the ray `origin + s·dir` on the plane (`s > 0`).
        fn hit(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> Option<Vector3<f64>> {
            let s = (self.offset - self.n.dot(origin)) / self.n.dot(dir);
            (s > 0.0).then(|| origin + dir * s)
        }

        /// A smooth RGB texture in plane coordinates.
        fn texture(&self, p: &Vector3<f64>) -> [f32; 3] {
            let e1 = self.n.cross(&Vector3::y()).normalize();
            let e2 = self.n.cross(&e1);
            let (a, b) = (p.dot(&e1), p.dot(&e2));
            [
                (0.5 + 0.3 * (a * 9.0).sin() * (b * 7.0).cos()) as f32,
                (0.5 + 0.4 * (a * 5.0 + b * 11.0).sin()) as f32,
                (0.5 + 0.25 * (b * 13.0).cos()) as f32,
            ]
        }
    }

    /// The plane point seen at pixel centre `(i, j)` of `camera`.
    fn plane_point(camera: &Camera, plane: &Plane, i: usize, j: usize) -> Option<Vector3<f64>> {
        let (o, d) = camera.ray(i as f64 + 0.5, j as f64 + 0.5);
        plane.hit(&o, &d)
    }

    /// Exact z-depth of the plane at every pixel centre of `camera` (0 where missed).
    fn exact_depth(camera: &Camera, plane: &Plane) -> Vec<f32> {
        let (w, h) = (camera.width() as usize, camera.height() as usize);
        let mut out = vec![0f32; w * h];
        for j in 0..h {
            for i in 0..w {
                if let Some(p) = plane_point(camera, plane, i, j) {
                    out[j * w + i] = camera.world_to_camera.transform_point(&p).z as f32;
                }
            }
        }
        out
    }

    /// Exact disparity of the plane at every rectified pixel centre of `side` (NaN where missed).
    fn exact_disparity(rect: &Rectification, side: Side, plane: &Plane) -> Vec<f32> {
        let camera = rect.rectified(side);
        let depth = exact_depth(camera, plane);
        depth
            .iter()
            .map(|&z| {
                if z > 0.0 {
                    rect.depth_to_disparity(z as f64) as f32
                } else {
                    f32::NAN
                }
            })
            .collect()
    }

    /// Point-sampled render of the textured plane into `camera`.
    fn render(camera: &Camera, plane: &Plane) -> Image {
        let (w, h) = (camera.width() as usize, camera.height() as usize);
        let mut img = Image::new(w, h, 3);
        for j in 0..h {
            for i in 0..w {
                if let Some(p) = plane_point(camera, plane, i, j) {
                    for (c, v) in plane.texture(&p).iter().enumerate() {
                        img.set(i, j, c, *v);
                    }
                }
            }
        }
        img
    }

    /// Largest relative error over pixels where `got` has a depth; also the fraction of those.
    fn compare_depths(got: &[f32], want: &[f32]) -> (f64, f64) {
        let mut worst = 0f64;
        let mut count = 0usize;
        for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
            // The four corner pixels are left out: there the sampler would have to extend a
            // block by half a pixel along both axes at once, and it falls back to the nearest
            // pixel (2e-4 off on the test plane).
            let (x, y) = (i % W as usize, i / W as usize);
            let corner = (x == 0 || x + 1 == W as usize) && (y == 0 || y + 1 == H as usize);
            if g > 0.0 && !corner {
                count += 1;
                worst = worst.max(((g - w) as f64 / w as f64).abs());
            }
        }
        (worst, count as f64 / got.len() as f64)
    }

    #[test]
    fn corresponding_points_share_a_rectified_row() {
        for (first, second) in [pair(), converged_pair()] {
            points_share_a_row(&first, &second);
        }
    }

    fn points_share_a_row(first: &Camera, second: &Camera) {
        let rect = Rectification::new(first, second).unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let (mut worst_row, mut worst_disp, mut worst_round) = (0f64, 0f64, 0f64);
        let mut n = 0;
        while n < 200 {
            let (u, v) = (
                rng.random::<f64>() * W as f64,
                rng.random::<f64>() * H as f64,
            );
            let z = 2.0 + 6.0 * rng.random::<f64>();
            let p = first.unproject(u, v, z);
            let Some((u2, v2, _)) = second.project(&p) else {
                continue;
            };
            if !(0.0..W as f64).contains(&u2) || !(0.0..H as f64).contains(&v2) {
                continue;
            }
            n += 1;
            let (ul, vl) = rect.to_rectified(Side::Left, u, v);
            let (ur, vr) = rect.to_rectified(Side::Right, u2, v2);
            worst_row = worst_row.max((vl - vr).abs());
            let z_rect = rect.left.world_to_camera.transform_point(&p).z;
            let want = rect.depth_to_disparity(z_rect);
            worst_disp = worst_disp.max(((ul - ur) - want).abs() / (want - rect.offset));
            for (side, (a, b), (x, y)) in [
                (Side::Left, (u, v), (ul, vl)),
                (Side::Right, (u2, v2), (ur, vr)),
            ] {
                let (ba, bb) = rect.from_rectified(side, x, y);
                worst_round = worst_round.max((ba - a).abs().max((bb - b).abs()));
            }
        }
        eprintln!(
            "max row error {worst_row:.2e} px, max disparity rel. error {worst_disp:.2e}, max round trip {worst_round:.2e} px"
        );
        assert!(worst_row < 0.05, "row error {worst_row}");
        assert!(worst_disp < 1e-6, "disparity error {worst_disp}");
        assert!(worst_round < 1e-9, "round trip {worst_round}");
    }

    #[test]
    fn depth_round_trips_through_rectified_disparity() {
        depth_round_trips(pair(), 1e-4);
        // Its geometric disparities (about 1,400 px) change by more than one unit from pixel to
        // pixel on the slanted plane, where the sampler takes the nearest pixel instead of
        // interpolating: up to half a pixel's change of depth.
        depth_round_trips(converged_pair(), 1e-3);
    }

    fn depth_round_trips((first, second): (Camera, Camera), tolerance: f64) {
        let rect = Rectification::new(&first, &second).unwrap();
        let plane = Plane::new();
        for side in [Side::Left, Side::Right] {
            let want = exact_depth(rect.original(side), &plane);
            let disparity = exact_disparity(&rect, side, &plane);
            let depth = rect.depth_from_disparity(side, &disparity).unwrap();
            let (err, frac) = compare_depths(&depth, &want);
            eprintln!("{side:?}: disparity → depth max rel. error {err:.2e}, coverage {frac:.3}");
            assert!(err < 1e-4, "{side:?} error {err}");
            assert!(frac > 0.8, "{side:?} coverage {frac}");

            let back = rect.disparity_from_depth(side, &want).unwrap();
            let (mut disp_err, mut disp_count) = (0f64, 0usize);
            for (&b, &e) in back.iter().zip(&disparity) {
                if b.is_finite() {
                    disp_count += 1;
                    disp_err = disp_err.max(((b - e) as f64 / (e as f64 - rect.offset)).abs());
                }
            }
            let again = rect.depth_from_disparity(side, &back).unwrap();
            let (err2, frac2) = compare_depths(&again, &want);
            eprintln!(
                "{side:?}: depth → disparity max rel. error {disp_err:.2e} ({disp_count} px), \
                 round trip max rel. error {err2:.2e}, coverage {frac2:.3}"
            );
            assert!(disp_err < tolerance, "{side:?} disparity error {disp_err}");
            // The canvas holds both images, so a part of it lies outside this one.
            assert!(disp_count as f64 > 0.6 * back.len() as f64);
            assert!(err2 < tolerance, "{side:?} round-trip error {err2}");
            assert!(frac2 > 0.8, "{side:?} round-trip coverage {frac2}");
        }
    }

    #[test]
    fn rectified_images_match_rendering_in_the_rectified_camera() {
        for (first, second) in [pair(), converged_pair()] {
            rectified_images_match_rendering(&first, &second);
        }
    }

    fn rectified_images_match_rendering(first: &Camera, second: &Camera) {
        let rect = Rectification::new(first, second).unwrap();
        let plane = Plane::new();
        for side in [Side::Left, Side::Right] {
            let original = render(rect.original(side), &plane);
            let direct = render(rect.rectified(side), &plane);
            let got = rect.rectify_image(side, &original);
            assert_eq!(got.image.channels, 3);
            let (mut sum, mut count) = (0f64, 0usize);
            for (p, &inside) in got.inside.iter().enumerate() {
                if inside {
                    count += 1;
                    for c in 0..3 {
                        sum += (got.image.data[p * 3 + c] - direct.data[p * 3 + c]).abs() as f64;
                    }
                } else {
                    let w = got.image.width;
                    assert!(got.image.pixel(p % w, p / w) == [0.0; 3]);
                }
            }
            let mean = sum / (3 * count.max(1)) as f64;
            let frac = count as f64 / got.inside.len() as f64;
            eprintln!("{side:?}: mean abs difference {mean:.2e}, inside {frac:.3}");
            assert!(mean < 0.01, "{side:?} mean difference {mean}");
            // The canvas holds both images, so a part of it lies outside this one.
            assert!(frac > 0.6, "{side:?} inside {frac}");
        }
    }

    #[test]
    fn disparity_steps_and_holes_are_respected() {
        let valid = |d: f32| (d.is_finite() && d > 0.0).then_some(d as f64);
        // A 4×3 map: disparity 10 in the two left columns, 30 in the right ones.
        let step = [10f32, 10.0, 30.0, 30.0].repeat(3);
        // Across the step: the containing pixel's value, never a mix.
        assert_eq!(sample_map(&step, 4, 3, 1.9, 1.5, valid), Some(10.0));
        assert_eq!(sample_map(&step, 4, 3, 2.1, 1.5, valid), Some(30.0));
        assert_eq!(sample_map(&step, 4, 3, 4.0, 1.0, valid), None);
        assert_eq!(sample_map(&step, 4, 3, f64::NAN, 1.0, valid), None);

        // A ramp along x (value 5 + 0.25·(u − 0.5)) with a hole at pixel (1, 0).
        let mut ramp: Vec<f32> = (0..12).map(|p| 5.0 + 0.25 * (p % 4) as f32).collect();
        ramp[1] = f32::NAN;
        let exact = |u: f64| 5.0 + 0.25 * (u - 0.5);
        // Inside the hole: nothing; next to it, a complete block is extended.
        assert_eq!(sample_map(&ramp, 4, 3, 1.5, 0.5, valid), None);
        let got = sample_map(&ramp, 4, 3, 1.25, 1.25, valid).unwrap();
        assert!((got - exact(1.25)).abs() < 1e-12, "{got}");
        // In the half-pixel band along the border, the outermost block is extended.
        let got = sample_map(&ramp, 4, 3, 3.9, 2.9, valid).unwrap();
        assert!((got - exact(3.9)).abs() < 1e-12, "{got}");
        // A pixel whose every block holds the hole falls back to its own value.
        assert_eq!(sample_map(&ramp, 4, 3, 0.3, 0.3, valid), Some(5.0));
    }

    #[test]
    fn the_second_camera_sits_at_plus_x() {
        let (first, second) = pair();
        let rect = Rectification::new(&first, &second).unwrap();
        let c = rect
            .left
            .world_to_camera
            .transform_point(&rect.right.center());
        assert!(
            (c - Vector3::new(rect.baseline, 0.0, 0.0)).norm() < 1e-9,
            "{c}"
        );
        assert!((rect.baseline - (second.center() - first.center()).norm()).abs() < 1e-12);
        let (rl, rr) = (
            rect.left.world_to_camera.rotation,
            rect.right.world_to_camera.rotation,
        );
        assert_eq!(rl, rr);
        assert!((rl * rl.transpose() - Matrix3::identity()).norm() < 1e-12);
        assert!((rl.determinant() - 1.0).abs() < 1e-12);
        assert!((rect.left.center() - first.center()).norm() < 1e-12);
        assert!((rect.right.center() - second.center()).norm() < 1e-12);
        // The rectified axis is the mean original axis, turned just enough to be orthogonal to
        // the baseline.
        let x = (second.center() - first.center()).normalize();
        let mean = (first.forward() + second.forward()).normalize();
        let want = (mean - x * x.dot(&mean)).normalize();
        assert!((rect.left.forward() - want).norm() < 1e-12);
        for original in [&first, &second] {
            let angle = original.forward().dot(&rect.left.forward()).acos() / DEG;
            assert!(angle < 8.0, "rectified axis turned {angle}°");
        }
        let k = rect.intrinsics;
        assert_eq!(k.fx, k.fy);
        assert!((k.fx - (400.0 + 402.0 + 420.0 + 418.0) / 4.0).abs() < 1e-12);
        // The canvas holds both images (turned by a few degrees) and no more than twice either.
        assert!(k.width >= W && k.height >= H && k.width <= 2 * W && k.height <= 2 * H);
    }

    #[test]
    fn views_turned_towards_each_other_are_each_centred_on_their_canvas() {
        let (first, second) = converged_pair();
        let rect = Rectification::new(&first, &second).unwrap();
        let (kl, kr) = (rect.left.intrinsics, rect.right.intrinsics);
        assert_eq!((kl.fx, kl.fy, kl.cy), (kr.fx, kr.fy, kr.cy));
        assert_eq!((kl.width, kl.height), (kr.width, kr.height));
        assert!(kl.width <= 2 * W && kl.height <= 2 * H, "{kl:?}");
        // Each original image centre lands near its rectified image's centre.
        for side in [Side::Left, Side::Right] {
            let (u, v) = rect.to_rectified(side, W as f64 / 2.0, H as f64 / 2.0);
            let k = rect.rectified(side).intrinsics;
            let (du, dv) = (u - k.width as f64 / 2.0, v - k.height as f64 / 2.0);
            assert!(
                du.abs() < 0.1 * W as f64 && dv.abs() < 0.1 * H as f64,
                "{side:?}: {du}, {dv}"
            );
        }
        // The point both cameras look at sits near zero disparity; points at infinity at the
        // offset, which is large and negative (the right image turned to the left).
        let z = rect
            .left
            .world_to_camera
            .transform_point(&Vector3::new(0.2, 0.0, 4.0))
            .z;
        let at_target = rect.depth_to_disparity(z);
        assert!(at_target.abs() < 0.2 * W as f64, "{at_target}");
        assert!(rect.offset < -(W as f64), "offset {}", rect.offset);
        assert!((rect.disparity_to_depth(at_target) - z).abs() < 1e-9 * z);
        // The shared canvas of a pair that fits keeps one principal point.
        let (a, b) = pair();
        assert_eq!(Rectification::new(&a, &b).unwrap().offset, 0.0);
    }

    /// Turned 10° each, the joint box exceeds twice the image width but the clipped canvas
    /// keeps most of both images: one shared canvas, clipped, and no offset.
    #[test]
    fn views_turned_a_little_share_one_clipped_canvas() {
        let (first, second) = converged_pair_at(10.0);
        let f = first.intrinsics.fx;
        let joint = W as f64 + 2.0 * f * 10f64.to_radians().tan();
        assert!(joint > 2.0 * W as f64, "the pair must clip: {joint}");
        let rect = Rectification::new(&first, &second).unwrap();
        assert_eq!(rect.offset, 0.0);
        assert_eq!(rect.left.intrinsics, rect.right.intrinsics);
        let width = rect.left.intrinsics.width as f64;
        assert!(
            width <= 2.0 * W as f64 + 2.0 * CANVAS_MARGIN + 1.0,
            "{width}"
        );
    }

    #[test]
    fn degenerate_pairs_are_refused() {
        let (first, second) = pair();
        let k = first.intrinsics;
        let same_place = camera(k, first.center(), 3.0, 1.0, 2.0);
        let err = Rectification::new(&first, &same_place)
            .unwrap_err()
            .to_string();
        assert!(err.contains("baseline"), "{err}");

        let ahead = camera(k, Vector3::new(0.0, 0.0, 1.0), 0.0, 0.0, 0.0);
        let behind = camera(k, Vector3::zeros(), 0.0, 0.0, 0.0);
        let err = Rectification::new(&behind, &ahead).unwrap_err().to_string();
        assert!(err.contains("optical axis"), "{err}");

        let mut broken = second.clone();
        broken.world_to_camera.translation.y = f64::NAN;
        let err = Rectification::new(&first, &broken).unwrap_err().to_string();
        assert!(
            err.contains("second camera") && err.contains("non-finite"),
            "{err}"
        );

        let rect = Rectification::new(&first, &second).unwrap();
        let err = rect
            .depth_from_disparity(Side::Right, &[1.0; 100])
            .unwrap_err()
            .to_string();
        let size = format!("{}×{}", rect.intrinsics.width, rect.intrinsics.height);
        assert!(err.contains("100") && err.contains(&size), "{err}");
        let err = rect
            .disparity_from_depth(Side::Left, &[1.0; 7])
            .unwrap_err()
            .to_string();
        assert!(err.contains('7') && err.contains("76800"), "{err}");
    }
}
