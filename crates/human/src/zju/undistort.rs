//! Lens undistortion of ZJU-MoCap views into pinhole images with the same `K`, so that the
//! rest of the engine (fewview-scene's cameras have no distortion) sees ideal pinhole views.
//!
//! The model is OpenCV's (Brown–Conrady) with `D = (k1, k2, p1, p2[, k3])`: a normalised point
//! `(x, y)`, `r² = x² + y²`, is seen at
//! `x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2x²)` and
//! `y_d = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2y²) + 2 p2 x y`.
//! Each output pixel's centre is unprojected with `K`, distorted, and projected with `K` again to
//! find where to sample the recorded image, as `cv2.initUndistortRectifyMap(K, D, None, K, ...)`
//! followed by `cv2.remap` does: bilinear for colour, nearest (ties to even, as OpenCV rounds) for
//! masks, zero outside the recorded image. Pixel coordinates here are OpenCV's (centres at
//! integers), the convention `K` was calibrated in.

use fewview_scene::Image;
use nalgebra::Matrix3;

use crate::maps::Mask;

/// OpenCV's radial-tangential distortion coefficients.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Distortion {
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
    pub k3: f64,
}

impl Distortion {
    /// From OpenCV's `D` with 4 or 5 coefficients (`k3 = 0` for 4); `None` for other lengths.
    pub fn from_coefficients(d: &[f64]) -> Option<Self> {
        match *d {
            [k1, k2, p1, p2] => Some(Self {
                k1,
                k2,
                p1,
                p2,
                k3: 0.0,
            }),
            [k1, k2, p1, p2, k3] => Some(Self { k1, k2, p1, p2, k3 }),
            _ => None,
        }
    }

    pub fn is_zero(&self) -> bool {
        [self.k1, self.k2, self.p1, self.p2, self.k3]
            .iter()
            .all(|&v| v == 0.0)
    }

    /// Where the lens puts the normalised point `(x, y)`.
    pub fn apply(&self, x: f64, y: f64) -> (f64, f64) {
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let xd = x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y;
        (xd, yd)
    }
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
                let (xd, yd) = d.apply(x, y);
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
        let map = UndistortMap::new(&k, &Distortion::default(), 20, 15);
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

    #[test]
    fn tangential_terms_follow_the_formula() {
        let d = Distortion::from_coefficients(&[0.0, 0.0, 0.01, -0.02]).unwrap();
        let (xd, yd) = d.apply(0.3, -0.2);
        let r2 = 0.13;
        assert!((xd - (0.3 + 2.0 * 0.01 * 0.3 * -0.2 - 0.02 * (r2 + 2.0 * 0.09))).abs() < 1e-15);
        assert!((yd - (-0.2 + 0.01 * (r2 + 2.0 * 0.04) + 2.0 * -0.02 * 0.3 * -0.2)).abs() < 1e-15);
        assert!(Distortion::from_coefficients(&[0.1; 8]).is_none());
    }
}
