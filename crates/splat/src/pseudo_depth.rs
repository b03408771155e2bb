//! The stereo start's depth seen from between the training views: at each iteration the points
//! stereo accepted in the training views (R^c fully, R^o half, R^s not:
//! [`crate::stereo_depth::TIER_WEIGHTS`]) are reprojected into a pseudo view
//! ([`crate::train::pseudo::pseudo_camera`]), and the render of that view is pulled to their
//! depth by the relative L1 of [`crate::stereo_depth`].
//!
//! On a training view the render can match the photo with Gaussians anywhere along each ray;
//! from between the views a Gaussian at the wrong depth lands on the wrong pixel, so the same
//! depth constrains geometry that the training views leave free. This is the depth
//! regulariser on pseudo views of FSGS ("FSGS: Real-Time Few-shot View Synthesis using Gaussian
//! Splatting", §3.3, which takes a monocular network's depth of the pseudo view) with our own
//! stereo instead: metric, and only where it was confirmed.
//!
//! The target of a pseudo view keeps each pixel's nearest point. Points are sparser than the
//! pseudo view's pixels where it sees a surface more obliquely, so a far point can show
//! through a hole in a near surface; a pixel is kept only when its depth is within
//! [`OCCLUSION_MARGIN`] of the nearest depth within [`OCCLUSION_RADIUS`] pixels.

use burn::tensor::Tensor;
use fewview_geom::stereo::hierarchy::{HierarchicalCloud, Region};
use fewview_scene::Camera;
use nalgebra::Vector3;

use crate::raster::RenderCamera;
use crate::stereo_depth::{pixel_weight, weighted_relative_depth_l1};
use crate::train::pseudo::pseudo_camera;
use crate::train::{LossContext, LossTerm, TrainError};

/// A pixel's depth counts when it is at most this fraction behind the nearest depth around it.
pub const OCCLUSION_MARGIN: f32 = 0.05;

/// The half-width (pixels) of the window a pixel's depth is compared against.
pub const OCCLUSION_RADIUS: usize = 2;

/// The stereo depth loss on pseudo views (see the module docs).
#[derive(Clone)]
pub struct PseudoDepthTerm {
    cameras: Vec<Camera>,
    /// World points of the weighted stereo pixels, with their tier's weight.
    points: Vec<(Vector3<f64>, f32)>,
    weight: f32,
    seed: u64,
}

impl PseudoDepthTerm {
    /// The term from a stereo start's cloud of the training views with these cameras (in
    /// training order), weight `weight`; `seed` draws the pseudo views.
    pub fn new(cameras: Vec<Camera>, cloud: &HierarchicalCloud, weight: f32, seed: u64) -> Self {
        Self::from_depths(
            cameras,
            &cloud.pixel_depths,
            &cloud.pixel_regions,
            weight,
            seed,
        )
    }

    /// The same from each view's per-pixel depth (0: none) and tier, row-major.
    pub fn from_depths(
        cameras: Vec<Camera>,
        depths: &[Vec<f32>],
        regions: &[Vec<Option<Region>>],
        weight: f32,
        seed: u64,
    ) -> Self {
        let mut points = Vec::new();
        for (camera, (depths, regions)) in cameras.iter().zip(depths.iter().zip(regions)) {
            let w = camera.width() as usize;
            for (p, (&d, &r)) in depths.iter().zip(regions).enumerate() {
                let tier = pixel_weight(d, r);
                if tier > 0.0 {
                    let (u, v) = ((p % w) as f64 + 0.5, (p / w) as f64 + 0.5);
                    points.push((camera.unproject(u, v, d as f64), tier));
                }
            }
        }
        Self {
            cameras,
            points,
            weight,
            seed,
        }
    }

    /// The depth target of `camera` and its per-pixel weight (row-major, 0: none): the nearest
    /// point at each pixel, where no nearer surface around it hides it.
    pub fn target(&self, camera: &Camera) -> (Vec<f32>, Vec<f32>) {
        let (w, h) = (camera.width() as usize, camera.height() as usize);
        let mut depth = vec![f32::INFINITY; w * h];
        let mut weight = vec![0.0f32; w * h];
        for (x, tier) in &self.points {
            if let Some((p, z)) = camera.pixel_of(x)
                && (z as f32) < depth[p]
            {
                depth[p] = z as f32;
                weight[p] = *tier;
            }
        }
        let nearest = window_min(&depth, w, h, OCCLUSION_RADIUS);
        for p in 0..w * h {
            if !depth[p].is_finite() || depth[p] > nearest[p] * (1.0 + OCCLUSION_MARGIN) {
                depth[p] = 0.0;
                weight[p] = 0.0;
            }
        }
        (depth, weight)
    }
}

/// The smallest value within `radius` pixels (a square window) of each pixel.
fn window_min(values: &[f32], w: usize, h: usize, radius: usize) -> Vec<f32> {
    let min_along = |src: &[f32], along_rows: bool| {
        let mut out = vec![f32::INFINITY; w * h];
        for y in 0..h {
            for x in 0..w {
                let (c, n) = if along_rows { (x, w) } else { (y, h) };
                let (lo, hi) = (c.saturating_sub(radius), (c + radius).min(n - 1));
                let at = |k: usize| if along_rows { y * w + k } else { k * w + x };
                out[y * w + x] = (lo..=hi).map(|k| src[at(k)]).fold(f32::INFINITY, f32::min);
            }
        }
        out
    };
    min_along(&min_along(values, true), false)
}

impl LossTerm for PseudoDepthTerm {
    fn name(&self) -> &str {
        "pseudo-depth"
    }

    fn loss(&mut self, ctx: &LossContext<'_>) -> Result<Option<Tensor<1>>, TrainError> {
        let Some(camera) = pseudo_camera(&self.cameras, self.seed, ctx.iteration) else {
            return Ok(None);
        };
        let (depth, weights) = self.target(&camera);
        let render = ctx.render(&RenderCamera::from(&camera)).image;
        let [h, w, _] = render.dims();
        let rendered = render.slice([0..h, 0..w, 3..4]);
        Ok(weighted_relative_depth_l1(rendered, &depth, &weights).map(|l| l * self.weight))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::pseudo::tests::camera_on_x_axis;

    /// The size of [`camera_on_x_axis`]'s image.
    const W: usize = 64;
    const H: usize = 48;

    /// A camera at `x` on the x axis looking down +z.
    fn camera_at(x: f64) -> Camera {
        camera_on_x_axis(x, 60.0)
    }

    /// The z-depth at each pixel of a camera at `x` of a plane z = 4 with a square z = 2 in front
    /// of it (|x_world| < 0.5, |y_world| < 0.5).
    fn scene_depth(x: f64) -> Vec<f32> {
        let cam = camera_at(x);
        (0..W * H)
            .map(|p| {
                let (u, v) = ((p % W) as f64 + 0.5, (p / W) as f64 + 0.5);
                let near = cam.unproject(u, v, 2.0);
                if near.x.abs() < 0.5 && near.y.abs() < 0.5 {
                    2.0
                } else {
                    4.0
                }
            })
            .collect()
    }

    fn term(xs: &[f64], region: Region) -> PseudoDepthTerm {
        let cameras: Vec<Camera> = xs.iter().map(|&x| camera_at(x)).collect();
        let depths: Vec<Vec<f32>> = xs.iter().map(|&x| scene_depth(x)).collect();
        let regions = vec![vec![Some(region); W * H]; xs.len()];
        PseudoDepthTerm::from_depths(cameras, &depths, &regions, 1.0, 0)
    }

    /// Seen from a training camera, the target is that view's own depth at every pixel (each
    /// pixel's point reprojects onto it), with R^c's weight; R^s points give no target.
    #[test]
    fn a_training_camera_sees_its_own_depth() {
        let t = term(&[0.0], Region::Consistent);
        let (depth, weight) = t.target(&camera_at(0.0));
        let truth = scene_depth(0.0);
        let kept = weight.iter().filter(|&&w| w == 1.0).count();
        assert!(kept > W * H * 9 / 10, "{kept} of {} pixels", W * H);
        for p in 0..W * H {
            if weight[p] > 0.0 {
                assert!((depth[p] - truth[p]).abs() < 1e-4, "pixel {p}");
            }
        }
        let (_, none) = term(&[0.0], Region::Single).target(&camera_at(0.0));
        assert!(none.iter().all(|&w| w == 0.0));
    }

    /// From between two cameras the reprojected depth is the scene's where it is kept (away
    /// from the square's outline, where a pixel's centre and its points may lie on either
    /// side): the plane never shows through the square, and most pixels get a target.
    #[test]
    fn a_pseudo_view_gets_the_scenes_depth_without_the_background_through_holes() {
        let t = term(&[-0.3, 0.3], Region::Overlap);
        let (depth, weight) = t.target(&camera_at(0.1));
        let truth = scene_depth(0.1);
        let mut kept = 0;
        let edge = |p: usize| {
            let (x, y) = (p % W, p / W);
            let near = |xx: usize, yy: usize| truth[yy * W + xx] != truth[p];
            (x.saturating_sub(1)..=(x + 1).min(W - 1))
                .any(|xx| (y.saturating_sub(1)..=(y + 1).min(H - 1)).any(|yy| near(xx, yy)))
        };
        for p in 0..W * H {
            if weight[p] > 0.0 {
                kept += 1;
                if edge(p) {
                    continue;
                }
                assert_eq!(weight[p], 0.5);
                assert!(
                    (depth[p] - truth[p]).abs() < 0.05 * truth[p],
                    "pixel {p}: {} against {}",
                    depth[p],
                    truth[p]
                );
            }
        }
        assert!(kept > W * H * 3 / 4, "{kept} of {} pixels", W * H);
    }

    /// The window minimum against a direct scan.
    #[test]
    fn window_min_is_the_minimum_of_the_square() {
        let values: Vec<f32> = (0..W * H).map(|p| ((p * 7919) % 101) as f32).collect();
        let got = window_min(&values, W, H, 2);
        for y in 0..H {
            for x in 0..W {
                let mut m = f32::INFINITY;
                for yy in y.saturating_sub(2)..=(y + 2).min(H - 1) {
                    for xx in x.saturating_sub(2)..=(x + 2).min(W - 1) {
                        m = m.min(values[yy * W + xx]);
                    }
                }
                assert_eq!(got[y * W + x], m);
            }
        }
    }
}
