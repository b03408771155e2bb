//! Crops around the person at a fixed scale, so that a CPU-sized network sees the person large
//! and the background not at all.
//!
//! One crop per camera for a whole run: its centre is the projection of the person's box (the
//! union of the training frames' visual hulls, a 3D box), its scale is one number for every
//! camera. Both come from the input cameras' masks of the training frames only, so that a
//! held-out camera gets its crop without its own images being read.

use fewview_scene::{Camera, Image};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::hull::Bounds;
use crate::maps::{DepthMap, Mask};

/// A window of a camera's image, resampled to `size` pixels: output pixel `(i, j)` has its
/// centre at source point `origin + ((i, j) + ½) / scale`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Crop {
    /// Source point (pixels, continuous) of the output's top-left corner.
    pub origin: [f64; 2],
    /// Output pixels per source pixel.
    pub scale: f64,
    /// Output `[width, height]`.
    pub size: [usize; 2],
}

/// The eight corners of `bounds`.
fn corners(bounds: &Bounds) -> impl Iterator<Item = Vector3<f64>> + '_ {
    (0..8).map(move |c| {
        let pick = |axis: usize| {
            if c >> axis & 1 == 0 {
                bounds.min[axis]
            } else {
                bounds.max[axis]
            }
        };
        Vector3::new(pick(0), pick(1), pick(2))
    })
}

/// The pixel box `[u0, v0, u1, v1]` `bounds` projects to in `camera`; `None` if a corner is
/// behind it.
pub fn projected_box(bounds: &Bounds, camera: &Camera) -> Option<[f64; 4]> {
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for p in corners(bounds) {
        let (u, v, _) = camera.project(&p)?;
        b = [b[0].min(u), b[1].min(v), b[2].max(u), b[3].max(v)];
    }
    Some(b)
}

/// The largest scale at which every camera's projected box, grown by `margin` (a fraction of
/// its size), fits in `size`; never above 1 (no upsampling).
pub fn common_scale(bounds: &Bounds, cameras: &[Camera], size: [usize; 2], margin: f64) -> f64 {
    cameras
        .iter()
        .filter_map(|c| projected_box(bounds, c))
        .map(|b| {
            let (w, h) = (
                (b[2] - b[0]) * (1.0 + margin),
                (b[3] - b[1]) * (1.0 + margin),
            );
            (size[0] as f64 / w).min(size[1] as f64 / h)
        })
        .fold(1.0, f64::min)
}

impl Crop {
    /// The crop of `camera` centred on the projection of `bounds` (its box's centre), at `scale`.
    pub fn centred(bounds: &Bounds, camera: &Camera, scale: f64, size: [usize; 2]) -> Self {
        let k = &camera.intrinsics;
        let (cu, cv) = projected_box(bounds, camera)
            .map(|b| (0.5 * (b[0] + b[2]), 0.5 * (b[1] + b[3])))
            .unwrap_or((0.5 * k.width as f64, 0.5 * k.height as f64));
        let half = [0.5 * size[0] as f64 / scale, 0.5 * size[1] as f64 / scale];
        Self {
            origin: [cu - half[0], cv - half[1]],
            scale,
            size,
        }
    }

    /// The camera whose image is the crop: principal point moved, focal lengths scaled.
    pub fn camera(&self, camera: &Camera) -> Camera {
        let mut out = camera.clone();
        let k = &mut out.intrinsics;
        k.fx *= self.scale;
        k.fy *= self.scale;
        k.cx = (k.cx - self.origin[0]) * self.scale;
        k.cy = (k.cy - self.origin[1]) * self.scale;
        k.width = self.size[0] as u32;
        k.height = self.size[1] as u32;
        out
    }

    /// Source point of output pixel `(i, j)`'s centre.
    fn source(&self, i: usize, j: usize) -> [f64; 2] {
        [
            self.origin[0] + (i as f64 + 0.5) / self.scale,
            self.origin[1] + (j as f64 + 0.5) / self.scale,
        ]
    }

    /// A pixel position of the source image in the crop.
    pub fn point(&self, p: [f64; 2]) -> [f64; 2] {
        [
            (p[0] - self.origin[0]) * self.scale,
            (p[1] - self.origin[1]) * self.scale,
        ]
    }

    /// The image resampled bilinearly (black outside the source), averaged over a grid of
    /// samples per output pixel when the crop shrinks the image, so that it does not alias.
    pub fn image(&self, image: &Image) -> Image {
        let taps = (1.0 / self.scale).ceil().max(1.0) as usize;
        let c = image.channels;
        let [w, h] = self.size;
        let mut data = vec![0.0f32; w * h * c];
        for j in 0..h {
            for i in 0..w {
                let px = &mut data[(j * w + i) * c..(j * w + i + 1) * c];
                for (dy, dx) in (0..taps).flat_map(|a| (0..taps).map(move |b| (a, b))) {
                    let offset = |d: usize| ((d as f64 + 0.5) / taps as f64 - 0.5) / self.scale;
                    let [x, y] = self.source(i, j);
                    let s = bilinear(image, x + offset(dx), y + offset(dy));
                    for k in 0..c {
                        px[k] += s[k] / (taps * taps) as f32;
                    }
                }
            }
        }
        Image {
            width: w,
            height: h,
            channels: c,
            data,
        }
    }

    /// The mask at the output pixels' centres (nearest source pixel; outside is background).
    pub fn mask(&self, mask: &Mask) -> Mask {
        let [w, h] = self.size;
        let data = (0..w * h)
            .map(|p| {
                let [x, y] = self.source(p % w, p / w);
                mask.get(x.floor() as i64, y.floor() as i64)
            })
            .collect();
        Mask::new(w, h, data)
    }

    /// The depth map at the output pixels' centres (nearest source pixel; 0 outside).
    pub fn depth(&self, depth: &DepthMap) -> DepthMap {
        let [w, h] = self.size;
        let data = (0..w * h)
            .map(|p| {
                let [x, y] = self.source(p % w, p / w);
                let (x, y) = (x.floor(), y.floor());
                let inside = x >= 0.0 && y >= 0.0;
                if inside && (x as usize) < depth.width && (y as usize) < depth.height {
                    depth.get(x as usize, y as usize)
                } else {
                    0.0
                }
            })
            .collect();
        DepthMap {
            width: w,
            height: h,
            data,
        }
    }
}

/// Bilinear sample at continuous point `(x, y)` (pixel centres at half-integers), black
/// outside.
fn bilinear(image: &Image, x: f64, y: f64) -> [f32; 4] {
    let (x, y) = (x - 0.5, y - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    let mut out = [0.0f32; 4];
    for (dx, dy, wgt) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        let (xi, yi) = (x0 as i64 + dx, y0 as i64 + dy);
        if xi < 0 || yi < 0 || xi >= image.width as i64 || yi >= image.height as i64 {
            continue;
        }
        let p = (yi as usize * image.width + xi as usize) * image.channels;
        for k in 0..image.channels.min(4) {
            out[k] += wgt * image.data[p + k];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use fewview_scene::{Intrinsics, Se3};

    use super::*;

    fn camera() -> Camera {
        let k = Intrinsics {
            fx: 500.0,
            fy: 500.0,
            cx: 200.0,
            cy: 150.0,
            width: 400,
            height: 300,
        };
        Camera::new(
            k,
            Se3::new(nalgebra::Matrix3::identity(), Vector3::new(0.0, 0.0, 4.0)),
        )
    }

    /// A world point projects to the same place through the crop's camera as through the
    /// original followed by the crop's pixel map.
    #[test]
    fn cropped_camera_agrees_with_the_pixel_map() {
        let cam = camera();
        let bounds = Bounds {
            min: [-0.3, -0.6, -0.2],
            max: [0.3, 0.6, 0.2],
        };
        let scale = common_scale(&bounds, std::slice::from_ref(&cam), [64, 128], 0.1);
        let crop = Crop::centred(&bounds, &cam, scale, [64, 128]);
        let cropped = crop.camera(&cam);
        for p in [Vector3::new(0.1, -0.2, 0.05), Vector3::new(-0.3, 0.6, 0.2)] {
            let (u, v, _) = cam.project(&p).unwrap();
            let (cu, cv, _) = cropped.project(&p).unwrap();
            let want = crop.point([u, v]);
            assert!((cu - want[0]).abs() < 1e-9 && (cv - want[1]).abs() < 1e-9);
            // Every corner of the box lands inside the crop, with the margin.
            assert!(cu > 0.0 && cu < 64.0 && cv > 0.0 && cv < 128.0, "{cu} {cv}");
        }
        // The box's nearest face (1.2 m high at 3.8 m) spans 157.9 px; grown 10 % it fits 128 px.
        let want = 128.0 / (1.1 * 500.0 * 1.2 / 3.8);
        assert!((scale - want).abs() < 1e-9, "{scale} vs {want}");
    }

    /// A linear ramp is reproduced exactly by bilinear sampling at scale 1 and averaged
    /// correctly when the crop halves the image.
    #[test]
    fn ramps_survive_resampling() {
        let (w, h) = (40, 30);
        let data: Vec<f32> = (0..w * h)
            .flat_map(|p| {
                let x = (p % w) as f32 + 0.5;
                [x, x, x]
            })
            .collect();
        let image = Image {
            width: w,
            height: h,
            channels: 3,
            data,
        };
        for scale in [1.0, 0.5] {
            let crop = Crop {
                origin: [6.0, 4.0],
                scale,
                size: [10, 8],
            };
            let out = crop.image(&image);
            for j in 0..8 {
                for i in 0..10 {
                    let want = 6.0 + (i as f32 + 0.5) / scale as f32;
                    let got = out.data[(j * 10 + i) * 3];
                    assert!(
                        (got - want).abs() < 1e-4,
                        "scale {scale} ({i},{j}): {got} vs {want}"
                    );
                }
            }
        }
    }
}
