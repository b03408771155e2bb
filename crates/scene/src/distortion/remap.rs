//! Undistorting an image into an ideal pinhole: the output camera ([`undistorted_intrinsics`],
//! COLMAP's `image_undistorter` rule), bilinear resampling ([`undistort_image`]) and the
//! validity mask of the output pixels that the photo covers ([`valid_mask`]).

use serde::{Deserialize, Serialize};

use super::LensCamera;
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

/// `photo` (taken through `lens`, any channel count) resampled to the pinhole camera `out`:
/// each output pixel centre is mapped through the lens into the photo and read there by
/// bilinear interpolation (the photo's edge pixels repeat beyond it), as `cv2.remap` with
/// `INTER_LINEAR` reads `cv2.initUndistortRectifyMap`'s maps.
pub fn undistort_image(photo: &Image, lens: &LensCamera, out: &Intrinsics) -> Image {
    let (w, h, c) = (out.width as usize, out.height as usize, photo.channels);
    let mut data = vec![0.0f32; w * h * c];
    let (pw, ph) = (photo.width as isize, photo.height as isize);
    for (y, row) in data.chunks_exact_mut(w * c).enumerate() {
        for x in 0..w {
            let (u, v) = source_position(lens, out, x, y);
            let (fx, fy) = (u - 0.5, v - 0.5);
            let (x0, y0) = (fx.floor(), fy.floor());
            let (ax, ay) = ((fx - x0) as f32, (fy - y0) as f32);
            let clamp =
                |i: f64, n: isize| (i.max(-1.0).min(n as f64) as isize).clamp(0, n - 1) as usize;
            let (xa, xb) = (clamp(x0, pw), clamp(x0 + 1.0, pw));
            let (ya, yb) = (clamp(y0, ph), clamp(y0 + 1.0, ph));
            for ch in 0..c {
                let top = photo.get(xa, ya, ch) * (1.0 - ax) + photo.get(xb, ya, ch) * ax;
                let bottom = photo.get(xa, yb, ch) * (1.0 - ax) + photo.get(xb, yb, ch) * ax;
                row[x * c + ch] = top * (1.0 - ay) + bottom * ay;
            }
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
