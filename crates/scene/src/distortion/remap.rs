//! Undistorting an image into an ideal pinhole: the output camera ([`undistorted_intrinsics`],
//! COLMAP's `image_undistorter` rule), resampling ([`undistort_image`], bilinear or bicubic,
//! [`Resample`]) and the validity mask of the output pixels that the photo covers
//! ([`valid_mask`]).

use serde::{Deserialize, Serialize};

use super::lens::LensCamera;
use crate::camera::Intrinsics;
use crate::image::Image;

/// How the undistorted image is framed (COLMAP's `blank_pixels` option, 0 or 1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum UndistortFit {
    /// No blank border: every output pixel lies inside the photo, and photo pixels near the
    /// border that curve outside the rectangle are lost (`blank_pixels = 0`, COLMAP's default).
    #[default]
    NoBorder,
    /// Every photo pixel is kept: the output grows to hold the whole undistorted photo and its
    /// blank border is marked invalid in the view's validity mask (`blank_pixels = 1`).
    AllPixels,
}

/// COLMAP's bounds on how much the output image may shrink or grow (`min_scale`, `max_scale`).
const MIN_SCALE: f64 = 0.2;
const MAX_SCALE: f64 = 2.0;

/// The pinhole camera undistorted images of `lens` are resampled to, as COLMAP's
/// `UndistortCamera`: the same focal lengths, the size scaled per axis so that the undistorted
/// border pixels of the photo (their centres) just fill it ([`UndistortFit::NoBorder`]) or
/// just fit in it ([`UndistortFit::AllPixels`]), clamped to `[0.2, 2]`, and the principal point
/// scaled with the size. `None` when a border pixel does not undistort (see
/// [`LensCamera::check_invertible`]).
pub fn undistorted_intrinsics(lens: &LensCamera, fit: UndistortFit) -> Option<Intrinsics> {
    let k = lens.intrinsics;
    if lens.distortion.is_none() {
        return Some(k);
    }
    let (w, h) = (k.width as f64, k.height as f64);
    let ideal = |u: f64, v: f64| -> Option<(f64, f64)> {
        let (x, y) = lens.undistort_normalized(u, v)?;
        Some((k.fx * x + k.cx, k.fy * y + k.cy))
    };
    let (mut left, mut right, mut top, mut bottom) = (
        [f64::MAX, f64::MIN],
        [f64::MAX, f64::MIN],
        [f64::MAX, f64::MIN],
        [f64::MAX, f64::MIN],
    );
    let widen = |r: &mut [f64; 2], v: f64| {
        r[0] = r[0].min(v);
        r[1] = r[1].max(v);
    };
    for y in 0..k.height {
        let v = y as f64 + 0.5;
        widen(&mut left, ideal(0.5, v)?.0);
        widen(&mut right, ideal(w - 0.5, v)?.0);
    }
    for x in 0..k.width {
        let u = x as f64 + 0.5;
        widen(&mut top, ideal(u, 0.5)?.1);
        widen(&mut bottom, ideal(u, h - 0.5)?.1);
    }
    let (cx, cy) = (k.cx, k.cy);
    // The scale that keeps every photo pixel, and the one that leaves no blank pixel.
    let all_x = (cx / (cx - left[0])).min((w - 0.5 - cx) / (right[1] - cx));
    let all_y = (cy / (cy - top[0])).min((h - 0.5 - cy) / (bottom[1] - cy));
    let fill_x = (cx / (cx - left[1])).max((w - 0.5 - cx) / (right[0] - cx));
    let fill_y = (cy / (cy - top[1])).max((h - 0.5 - cy) / (bottom[0] - cy));
    let (sx, sy) = match fit {
        UndistortFit::NoBorder => (1.0 / fill_x, 1.0 / fill_y),
        UndistortFit::AllPixels => (1.0 / all_x, 1.0 / all_y),
    };
    if !(sx.is_finite() && sy.is_finite()) {
        return None;
    }
    let (sx, sy) = (
        sx.clamp(MIN_SCALE, MAX_SCALE),
        sy.clamp(MIN_SCALE, MAX_SCALE),
    );
    let width = (sx * w).max(1.0) as u32;
    let height = (sy * h).max(1.0) as u32;
    Some(Intrinsics {
        fx: k.fx,
        fy: k.fy,
        cx: cx * width as f64 / w,
        cy: cy * height as f64 / h,
        width,
        height,
    })
}

/// Where the centre of output pixel `(x, y)` of the pinhole camera `out` lies in the photo of
/// `lens` (continuous pixel coordinates, half-integer centres).
fn source_position(lens: &LensCamera, out: &Intrinsics, x: usize, y: usize) -> (f64, f64) {
    let u = (x as f64 + 0.5 - out.cx) / out.fx * lens.intrinsics.fx + lens.intrinsics.cx;
    let v = (y as f64 + 0.5 - out.cy) / out.fy * lens.intrinsics.fy + lens.intrinsics.cy;
    lens.distort_pixel(u, v)
}

/// Whether a photo position lies on the photo (inside its `width × height` rectangle).
fn on_photo(lens: &LensCamera, (u, v): (f64, f64)) -> bool {
    let k = &lens.intrinsics;
    (0.0..=k.width as f64).contains(&u) && (0.0..=k.height as f64).contains(&v)
}

/// How an undistorted pixel is read from the photo between its pixel centres.
///
/// Bilinear is what COLMAP's `image_undistorter` and OpenCV's `cv2.undistort` use, hence the
/// default. It low-passes the photo (a half-pixel shift halves the contrast of the finest
/// detail), which leaves undistorted photos blurrier than a pinhole would have taken them;
/// bicubic keeps more of that detail at the price of slight ringing at sharp edges.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Resample {
    /// The 2×2 neighbours weighted linearly (`cv2.INTER_LINEAR`).
    #[default]
    Bilinear,
    /// The 4×4 neighbours weighted by Keys' cubic convolution kernel with `a = −0.75`
    /// (`cv2.INTER_CUBIC`; "Cubic convolution interpolation for digital image processing").
    Bicubic,
}

impl Resample {
    pub fn name(self) -> &'static str {
        match self {
            Resample::Bilinear => "bilinear",
            Resample::Bicubic => "bicubic",
        }
    }
}

impl std::fmt::Display for Resample {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Resample {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "bilinear" => Ok(Resample::Bilinear),
            "bicubic" => Ok(Resample::Bicubic),
            _ => Err(format!(
                "unknown resampling kernel {s:?}: expected bilinear or bicubic"
            )),
        }
    }
}

/// OpenCV's cubic convolution parameter (`INTER_CUBIC`); Keys' paper analyses `a = −0.5`.
const CUBIC_A: f32 = -0.75;

/// The four weights of Keys' cubic kernel for taps at offsets −1, 0, 1, 2 from the sample's
/// left neighbour, `t` in `[0, 1)` past it (OpenCV's `interpolateCubic`).
fn cubic_weights(t: f32) -> [f32; 4] {
    let a = CUBIC_A;
    let w0 = ((a * (t + 1.0) - 5.0 * a) * (t + 1.0) + 8.0 * a) * (t + 1.0) - 4.0 * a;
    let w1 = ((a + 2.0) * t - (a + 3.0)) * t * t + 1.0;
    let s = 1.0 - t;
    let w2 = ((a + 2.0) * s - (a + 3.0)) * s * s + 1.0;
    [w0, w1, w2, 1.0 - w0 - w1 - w2]
}

/// Pixel index `i` clamped into `0..n` (the edge pixel repeats, `cv2.BORDER_REPLICATE`);
/// positions far outside (or NaN) clamp without overflowing.
fn clamp_index(i: f64, n: usize) -> usize {
    let last = n.saturating_sub(1);
    if i.is_nan() || i <= 0.0 {
        0
    } else if i >= last as f64 {
        last
    } else {
        i as usize
    }
}

/// The left/top neighbour of a continuous position (half-integer pixel centres) and how far
/// past its centre the position lies, in `[0, 1)`. A position that is not finite (a lens
/// evaluated far outside its range) reads the edge pixel it points to.
fn split_position(p: f64) -> (f64, f32) {
    let f = p - 0.5;
    if !f.is_finite() {
        return (f, 0.0);
    }
    let i = f.floor();
    (i, (f - i) as f32)
}

/// Writes into `px` (one value per channel) the photo read at `(u, v)` by bilinear
/// interpolation.
fn sample_bilinear(photo: &Image, (u, v): (f64, f64), px: &mut [f32]) {
    let ((x0, ax), (y0, ay)) = (split_position(u), split_position(v));
    let (xa, xb) = (
        clamp_index(x0, photo.width),
        clamp_index(x0 + 1.0, photo.width),
    );
    let (ya, yb) = (
        clamp_index(y0, photo.height),
        clamp_index(y0 + 1.0, photo.height),
    );
    for (ch, out) in px.iter_mut().enumerate() {
        let top = photo.get(xa, ya, ch) * (1.0 - ax) + photo.get(xb, ya, ch) * ax;
        let bottom = photo.get(xa, yb, ch) * (1.0 - ax) + photo.get(xb, yb, ch) * ax;
        *out = top * (1.0 - ay) + bottom * ay;
    }
}

/// Writes into `px` the photo read at `(u, v)` by bicubic interpolation, clamped to `[0, 1]`
/// (the kernel overshoots at sharp edges; OpenCV saturates the same way for 8- and 16-bit
/// photos).
fn sample_bicubic(photo: &Image, (u, v): (f64, f64), px: &mut [f32]) {
    let ((x0, ax), (y0, ay)) = (split_position(u), split_position(v));
    let (wx, wy) = (cubic_weights(ax), cubic_weights(ay));
    let xs: [usize; 4] = std::array::from_fn(|i| clamp_index(x0 + i as f64 - 1.0, photo.width));
    let ys: [usize; 4] = std::array::from_fn(|i| clamp_index(y0 + i as f64 - 1.0, photo.height));
    for (ch, out) in px.iter_mut().enumerate() {
        let mut sum = 0.0f32;
        for (&y, &wy) in ys.iter().zip(&wy) {
            let row: f32 = xs
                .iter()
                .zip(&wx)
                .map(|(&x, &w)| photo.get(x, y, ch) * w)
                .sum();
            sum += row * wy;
        }
        *out = sum.clamp(0.0, 1.0);
    }
}

/// `photo` (taken through `lens`, any channel count) resampled to the pinhole camera `out`:
/// each output pixel centre is mapped through the lens into the photo and read there with the
/// `resample` kernel (the photo's edge pixels repeat beyond it), as `cv2.remap` with
/// `INTER_LINEAR` or `INTER_CUBIC` and `BORDER_REPLICATE` reads `cv2.initUndistortRectifyMap`'s
/// maps.
pub fn undistort_image(
    photo: &Image,
    lens: &LensCamera,
    out: &Intrinsics,
    resample: Resample,
) -> Image {
    let (w, h, c) = (out.width as usize, out.height as usize, photo.channels);
    let mut data = vec![0.0f32; w * h * c];
    if photo.width == 0 || photo.height == 0 || w * c == 0 {
        return Image::from_vec(w, h, c, data);
    }
    let sample = match resample {
        Resample::Bilinear => sample_bilinear,
        Resample::Bicubic => sample_bicubic,
    };
    for (y, row) in data.chunks_exact_mut(w * c).enumerate() {
        for (x, px) in row.chunks_exact_mut(c).enumerate() {
            sample(photo, source_position(lens, out, x, y), px);
        }
    }
    Image::from_vec(w, h, c, data)
}

/// The validity mask of an undistorted image (1 channel): 1 where the output pixel's centre
/// maps onto the photo, 0 in the blank border. `None` when every pixel is valid.
pub fn valid_mask(lens: &LensCamera, out: &Intrinsics) -> Option<Image> {
    let (w, h) = (out.width as usize, out.height as usize);
    let mut mask = Image::new(w, h, 1);
    let mut all = true;
    for y in 0..h {
        for x in 0..w {
            let inside = on_photo(lens, source_position(lens, out, x, y));
            all &= inside;
            mask.data[y * w + x] = if inside { 1.0 } else { 0.0 };
        }
    }
    (!all).then_some(mask)
}
