//! Initial Gaussians: from a point cloud (COLMAP `points3D`, a PLY) or random points in the scene
//! bounds, with the reference code's initial scales (root of the mean squared distance to the 3
//! nearest neighbours), identity rotations and opacity 0.1.

use std::num::NonZero;

use fewview_scene::{Camera, Image, PointCloud};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;

use crate::model::GaussianModel;

/// Initial opacity of every Gaussian (the reference code's 0.1).
pub const INITIAL_OPACITY: f32 = 0.1;

/// `sqrt(mean squared distance to the 3 nearest other points)`, floored at `sqrt(1e-7)` as the
/// reference code's `distCUDA2` + clamp.
pub fn knn_scales(points: &[[f32; 3]]) -> Vec<f32> {
    if points.len() < 2 {
        return vec![1e-7f32.sqrt(); points.len()];
    }
    let tree: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(points).expect("non-empty");
    let k = 4.min(points.len());
    points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let found = tree
                .query(p)
                .nearest_n::<SquaredEuclidean<f32>>(NonZero::new(k).expect("k ≥ 2"))
                .execute();
            // Drop the point itself (distance 0, or a duplicate: either way one entry).
            let mut dists: Vec<f32> = found
                .iter()
                .filter(|r| r.item as usize != i)
                .map(|r| r.distance)
                .collect();
            dists.truncate(3);
            let mean = dists.iter().sum::<f32>() / dists.len().max(1) as f32;
            mean.max(1e-7).sqrt()
        })
        .collect()
}

/// Gaussians at the points of a cloud, with their colours.
pub fn from_points(cloud: &PointCloud, sh_degree: usize) -> GaussianModel {
    let scales = knn_scales(&cloud.positions);
    let mut model = GaussianModel::new(sh_degree);
    for ((p, c), s) in cloud.positions.iter().zip(&cloud.colors).zip(scales) {
        model.push_isotropic(*p, s, *c, INITIAL_OPACITY);
    }
    model
}

/// Gaussians at the points of a stereo start ([`crate::stereo_start::StereoStart`]), each
/// point standing for a patch of `footprints[i]` scene units (`spacing` pixels wide) of the view
/// it was seen in. They take kNN scales as [`from_points`], unless those would make a render
/// cost more than [`OVERDRAW_BUDGET`] Gaussian–pixel pairs per pixel ([`start_overdraw`]): then
/// each scale is capped at [`PATCH_SCALE_CAP`] patches, so that points whose neighbours lie far
/// off (the sky, the unmatched parts of a view) start no wider than they were seen. Returns the
/// model and, when capped, the overdraw before and after.
pub fn from_stereo_points(
    cloud: &PointCloud,
    sh_degree: usize,
    footprints: &[f32],
    spacing: f32,
) -> (GaussianModel, Option<(f64, f64)>) {
    let mut scales = knn_scales(&cloud.positions);
    let before = start_overdraw(&scales, footprints, spacing);
    let capped = (before > OVERDRAW_BUDGET).then(|| {
        for (s, f) in scales.iter_mut().zip(footprints) {
            *s = s.min(PATCH_SCALE_CAP * f);
        }
        (before, start_overdraw(&scales, footprints, spacing))
    });
    let mut model = GaussianModel::new(sh_degree);
    for ((p, c), s) in cloud.positions.iter().zip(&cloud.colors).zip(scales) {
        model.push_isotropic(*p, s, *c, INITIAL_OPACITY);
    }
    (model, capped)
}

/// The most Gaussian–pixel pairs per pixel a stereo start may cost a render before its scales
/// are capped ([`from_stereo_points`]): the demo scene's and fern's starts cost less and are left
/// as they are; a street whose sky and road the stereo start covers sparsely costs three times
/// as much.
pub const OVERDRAW_BUDGET: f64 = 48.0;

/// The largest initial scale of a capped stereo-start Gaussian, in patches: twice the patch, so
/// that a point among regularly spaced neighbours keeps its kNN scale (about 1.15 patches).
pub const PATCH_SCALE_CAP: f32 = 2.0;

/// The pairs per pixel of one view that Gaussians of `scales` cost when each covers its 3σ disc
/// in the view it was seen in (`footprints` and `spacing` as in [`from_stereo_points`]), every
/// view seeing them all: `Σ π (3σ / pixel size)²` over one view's pixels.
pub fn start_overdraw(scales: &[f32], footprints: &[f32], spacing: f32) -> f64 {
    if footprints.is_empty() {
        return 0.0;
    }
    let area: f64 = scales
        .iter()
        .zip(footprints)
        .map(|(&s, &f)| {
            let radius_px = 3.0 * s as f64 * spacing as f64 / f as f64;
            std::f64::consts::PI * radius_px * radius_px
        })
        .sum();
    // The points of one view cover its pixels once at the sample's spacing.
    let pixels = footprints.len() as f64 * (spacing as f64).powi(2);
    area / pixels
}

/// A view for frustum sampling: camera, image and the depth range to sample.
pub struct FrustumView<'a> {
    pub camera: &'a Camera,
    pub image: &'a Image,
    pub near: f64,
    pub far: f64,
}

/// `count` random points inside the training frustums: a random view, a random pixel, and a depth
/// uniform in disparity between the view's near and far bounds; each point takes the colour of
/// the pixel it was drawn through. (Our reading of "random initialisation in the scene bounds"
/// for forward-facing captures, whose bounds are the views' depth ranges.)
pub fn random_in_frustums(views: &[FrustumView<'_>], count: usize, seed: u64) -> PointCloud {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut cloud = PointCloud::default();
    if views.is_empty() {
        return cloud;
    }
    for _ in 0..count {
        let v = &views[rng.random_range(0..views.len())];
        let (w, h) = (v.image.width, v.image.height);
        let (x, y) = (rng.random_range(0..w), rng.random_range(0..h));
        let u = x as f64 + rng.random::<f64>();
        let vv = y as f64 + rng.random::<f64>();
        let disparity = 1.0 / v.far + (1.0 / v.near - 1.0 / v.far) * rng.random::<f64>();
        let p = v.camera.unproject(u, vv, 1.0 / disparity);
        cloud.positions.push([p.x as f32, p.y as f32, p.z as f32]);
        let px = v.image.pixel(x, y);
        cloud.colors.push([px[0], px[1], px[2]]);
    }
    cloud
}

/// `count` points uniform in the box `[lo, hi]`, each coloured by the first of `views` it projects
/// into (grey 0.5 when none sees it).
pub fn random_in_box(
    lo: [f64; 3],
    hi: [f64; 3],
    count: usize,
    seed: u64,
    views: &[(&Camera, &Image)],
) -> PointCloud {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut cloud = PointCloud::default();
    for _ in 0..count {
        let p: [f64; 3] = std::array::from_fn(|a| lo[a] + (hi[a] - lo[a]) * rng.random::<f64>());
        let mut color = [0.5f32; 3];
        for (cam, img) in views {
            if let Some((u, v, _)) = cam.project(&nalgebra::Vector3::from(p))
                && u >= 0.0
                && v >= 0.0
                && (u as usize) < img.width
                && (v as usize) < img.height
            {
                let px = img.pixel(u as usize, v as usize);
                color = [px[0], px[1], px[2]];
                break;
            }
        }
        cloud.positions.push(p.map(|v| v as f32));
        cloud.colors.push(color);
    }
    cloud
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knn_scales_match_brute_force() {
        let mut rng = StdRng::seed_from_u64(3);
        let pts: Vec<[f32; 3]> = (0..300)
            .map(|_| std::array::from_fn(|_| rng.random::<f32>()))
            .collect();
        let fast = knn_scales(&pts);
        for (i, p) in pts.iter().enumerate() {
            let mut d: Vec<f32> = pts
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, q)| (0..3).map(|a| (p[a] - q[a]).powi(2)).sum())
                .collect();
            d.sort_by(f32::total_cmp);
            let want = ((d[0] + d[1] + d[2]) / 3.0).sqrt();
            assert!((fast[i] - want).abs() < 1e-5, "{i}: {} vs {want}", fast[i]);
        }
    }

    #[test]
    fn frustum_points_project_back_to_their_pixel() {
        let cam = Camera::look_at(
            fewview_scene::Intrinsics::centered(50.0, 40, 30),
            nalgebra::Vector3::new(0.0, 0.0, -5.0),
            nalgebra::Vector3::zeros(),
            nalgebra::Vector3::new(0.0, -1.0, 0.0),
        );
        let mut img = Image::new(40, 30, 3);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = (i % 255) as f32 / 255.0;
        }
        let views = [FrustumView {
            camera: &cam,
            image: &img,
            near: 2.0,
            far: 8.0,
        }];
        let cloud = random_in_frustums(&views, 200, 1);
        for (p, c) in cloud.positions.iter().zip(&cloud.colors) {
            let (u, v, z) = cam
                .project(&nalgebra::Vector3::new(
                    p[0] as f64,
                    p[1] as f64,
                    p[2] as f64,
                ))
                .unwrap();
            assert!((2.0 - 1e-4..=8.0 + 1e-4).contains(&z));
            assert_eq!(img.pixel(u as usize, v as usize), c);
        }
    }
}
