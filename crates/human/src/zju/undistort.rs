//! Lens undistortion of ZJU-MoCap views into pinhole images with the same `K`, so that the
//! rest of the engine (fewview-scene's cameras have no distortion) sees ideal pinhole views.
//!
//! The lens model is OpenCV's Brown–Conrady one, `D = (k1, k2, p1, p2[, k3])`, evaluated by
//! [`fewview_scene::distortion::Distortion`] ([`distortion_from_opencv`] reads `D`). Each output
//! pixel's centre is unprojected with `K`, distorted, and projected with `K` again to find where
//! to sample the recorded image, as `cv2.initUndistortRectifyMap(K, D, None, K, ...)` followed
//! by `cv2.remap` does: bilinear for colour, nearest (ties to even, as OpenCV rounds) for masks,
//! zero outside the recorded image.
//!
//! Only this sampling map lives here, because it follows conventions that the scene crate's
//! [`fewview_scene::distortion::undistort_image`] does not, and switching would change the
//! undistorted views: pixel centres at integers (OpenCV's, the convention `K` was calibrated in)
//! rather than at half-integers, zero beyond the recorded image (`BORDER_CONSTANT`) rather than
//! the repeated edge pixel (`BORDER_REPLICATE`), bilinear weights in `f64` rather than `f32`, and
//! a nearest-neighbour mode for masks, which the scene crate has none of.

use fewview_scene::Image;
use fewview_scene::distortion::Distortion;
use nalgebra::Matrix3;

use crate::maps::Mask;

/// The lens of OpenCV's `D` with 4 or 5 coefficients (`k3 = 0` for 4), the lengths ZJU-MoCap
/// calibrations use; `None` for other lengths.
pub fn distortion_from_opencv(d: &[f64]) -> Option<Distortion> {
    matches!(d.len(), 4 | 5).then(|| Distortion::opencv(d))
}

/// For every pixel of the undistorted image, the position in the recorded image to sample
/// (OpenCV pixel coordinates).
#[derive(Clone, Debug)]
pub struct UndistortMap {
    pub width: usize,
    pub height: usize,
    /// Row-major `(x, y)` per output pixel.
    pub source: Vec<[f64; 2]>,
}

impl UndistortMap {
    /// The map of a camera with intrinsics `k` (OpenCV convention) and distortion `d`, for a
    /// `width × height` image.
    pub fn new(k: &Matrix3<f64>, d: &Distortion, width: usize, height: usize) -> Self {
        let (fx, fy, cx, cy) = (k[(0, 0)], k[(1, 1)], k[(0, 2)], k[(1, 2)]);
        let mut source = Vec::with_capacity(width * height);
        for v in 0..height {
            let y = (v as f64 - cy) / fy;
            for u in 0..width {
                let x = (u as f64 - cx) / fx;
                let (xd, yd) = d.distort(x, y);
                source.push([fx * xd + cx, fy * yd + cy]);
            }
        }
        Self {
            width,
            height,
            source,
        }
    }

    /// The undistorted colour image: bilinear samples of `img`, neighbours outside it count as 0.
    pub fn remap_bilinear(&self, img: &Image) -> Image {
        let c = img.channels;
        let mut out = Image::new(self.width, self.height, c);
        for (dst, &[x, y]) in out.data.chunks_exact_mut(c).zip(&self.source) {
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = (x - x0, y - y0);
            let corners = [
                (0, 0, (1.0 - fx) * (1.0 - fy)),
                (1, 0, fx * (1.0 - fy)),
                (0, 1, (1.0 - fx) * fy),
                (1, 1, fx * fy),
            ];
            for (dx, dy, w) in corners {
                let (xi, yi) = (x0 as i64 + dx, y0 as i64 + dy);
                if w == 0.0 || xi < 0 || yi < 0 || xi >= img.width as i64 || yi >= img.height as i64
                {
                    continue;
                }
                let src = img.pixel(xi as usize, yi as usize);
                for (o, s) in dst.iter_mut().zip(src) {
                    *o += (w * *s as f64) as f32;
                }
            }
        }
        out
    }

    /// The undistorted mask: the nearest recorded pixel (false outside the recorded image).
    pub fn remap_nearest(&self, mask: &Mask) -> Mask {
        let data = self
            .source
            .iter()
            .map(|&[x, y]| mask.get(x.round_ties_even() as i64, y.round_ties_even() as i64))
            .collect();
        Mask::new(self.width, self.height, data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_distortion_is_the_identity_map() {
        let k = Matrix3::new(50.0, 0.0, 9.5, 0.0, 40.0, 7.0, 0.0, 0.0, 1.0);
        let map = UndistortMap::new(&k, &Distortion::opencv(&[0.0; 5]), 20, 15);
        for (i, p) in map.source.iter().enumerate() {
            let (u, v) = ((i % 20) as f64, (i / 20) as f64);
            assert!((p[0] - u).abs() < 1e-12 && (p[1] - v).abs() < 1e-12);
        }
        let mut img = Image::new(20, 15, 3);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i % 7) as f32 / 7.0;
        }
        assert_eq!(map.remap_bilinear(&img), img);
    }

    /// The map against OpenCV's equations written out: radial `1 + k1 r² + k2 r⁴ + k3 r⁶` and
    /// tangential `p1, p2` terms, in OpenCV pixels (centres at integers).
    #[test]
    fn map_follows_the_opencv_formula() {
        let (k1, k2, p1, p2, k3) = (-0.3, 0.12, 0.01, -0.02, -0.05);
        let d = distortion_from_opencv(&[k1, k2, p1, p2, k3]).unwrap();
        let (fx, fy, cx, cy) = (50.0, 40.0, 9.5, 7.0);
        let k = Matrix3::new(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0);
        let map = UndistortMap::new(&k, &d, 20, 15);
        for (i, p) in map.source.iter().enumerate() {
            let (x, y) = (((i % 20) as f64 - cx) / fx, ((i / 20) as f64 - cy) / fy);
            let r2 = x * x + y * y;
            let radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
            let xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
            let yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
            assert!((p[0] - (fx * xd + cx)).abs() < 1e-12, "{i}: {p:?}");
            assert!((p[1] - (fy * yd + cy)).abs() < 1e-12, "{i}: {p:?}");
        }
    }

    #[test]
    fn opencv_d_needs_four_or_five_coefficients() {
        let four = distortion_from_opencv(&[0.1, -0.2, 0.01, 0.02]).unwrap();
        assert_eq!(four, Distortion::opencv(&[0.1, -0.2, 0.01, 0.02, 0.0]));
        assert!(distortion_from_opencv(&[0.1; 3]).is_none());
        assert!(distortion_from_opencv(&[0.1; 8]).is_none());
    }
}
