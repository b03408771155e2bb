//! A shell of Gaussians for the sky and the far background of a capture.
//!
//! The stereo start has no depth where the photos show no texture to match or nothing near
//! enough to measure: the sky, distant trees and houses. Left empty, those pixels are filled
//! during training by Gaussians pulled in front of the cameras, floaters that tear as soon as the
//! view moves. The shell puts Gaussians there from the start, on the sphere where the fusion
//! paper's Eq. (2) already puts the far scene: every block of a training view in which the stereo
//! cloud accepted no point gives one Gaussian where the ray through the block's centre meets the
//! sphere of radius `B_far` around `T` (beyond the contracted points, which lie within
//! `B_near`), in the block's mean colour. Gaussians rather than a learned background image,
//! because they reach every render path as they are (training, the transition, leave-one-out,
//! the viewer), and move in with the optimiser where a block was a near surface after all.

use fewview_geom::contract::Contraction;
use fewview_geom::stereo::hierarchy::HierarchicalCloud;
use fewview_geom::stereo::pairs::StereoView;
use nalgebra::Vector3;

/// Whether a run's stereo start adds the shell.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum SkyShell {
    /// On for a capture whose poses the run estimated from its photos, off for a dataset that
    /// brings its own (the curated benchmarks, reproduced as their papers ran them), but for
    /// DTU's protocol ([`crate::benchmark::Protocol::sky_shell`]).
    #[default]
    Auto,
    On,
    Off,
}

impl SkyShell {
    /// Whether the shell is on, for a run on a folder of photos (`photos`) or a dataset.
    pub fn resolve(self, photos: bool) -> bool {
        match self {
            Self::Auto => photos,
            Self::On => true,
            Self::Off => false,
        }
    }
}

/// The side (pixels) of the blocks that each give one shell Gaussian.
pub const SHELL_BLOCK_PX: usize = 16;

/// The shell's Gaussians: positions, colours and isotropic scales (scene units).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Shell {
    pub positions: Vec<[f32; 3]>,
    pub colors: Vec<[f32; 3]>,
    pub scales: Vec<f32>,
    /// The sphere's radius around `T` (`B_far`).
    pub radius: f64,
}

/// The shell of `views` around the stereo `cloud` ([`HierarchicalCloud::pixel_regions`] says
/// which pixels hold a point): one Gaussian per `block`×`block` block without a point, where its
/// centre ray meets the sphere of radius `B_far` around `T`, unless it falls in a block of an
/// earlier view that gave one. Each Gaussian's scale is half a block at its distance, so
/// neighbours overlap into a closed surface. `None` without a contraction, which sets the
/// sphere.
pub fn sky_shell(views: &[StereoView], cloud: &HierarchicalCloud, block: usize) -> Option<Shell> {
    let contraction = cloud.contraction.as_ref()?;
    let radius = contraction.b_far;
    let mut shell = Shell {
        radius,
        ..Shell::default()
    };
    // Per view so far, which of its blocks gave a Gaussian (or would have).
    let mut empty_blocks: Vec<Vec<bool>> = Vec::new();
    for (view, regions) in views.iter().zip(&cloud.pixel_regions) {
        let camera = view.camera;
        let w = camera.width() as usize;
        let (cols, rows) = (w / block, camera.height() as usize / block);
        let angle = block as f64 / camera.intrinsics.fx;
        let origin = camera.center();
        let empty: Vec<bool> = (0..cols * rows)
            .map(|b| !block_pixels(b % cols, b / cols, block, w).any(|p| regions[p].is_some()))
            .collect();
        for by in 0..rows {
            for bx in 0..cols {
                if !empty[by * cols + bx] {
                    continue;
                }
                let pixels = block_pixels(bx, by, block, w);
                let (u, v) = (
                    ((bx as f64) + 0.5) * block as f64,
                    ((by as f64) + 0.5) * block as f64,
                );
                let direction = (camera.unproject(u, v, 1.0) - origin).normalize();
                let Some(distance) = exit_distance(contraction, &origin, &direction) else {
                    continue;
                };
                let x = origin + direction * distance;
                if views
                    .iter()
                    .zip(&empty_blocks)
                    .any(|(earlier, empty)| in_empty_block(earlier, empty, &x, block))
                {
                    continue;
                }
                shell.positions.push([x.x as f32, x.y as f32, x.z as f32]);
                shell.colors.push(mean_color(view, pixels));
                shell.scales.push((0.5 * angle * distance) as f32);
            }
        }
        empty_blocks.push(empty);
    }
    Some(shell)
}

/// Whether `x` is seen by `view` inside one of its blocks flagged in `empty`.
fn in_empty_block(view: &StereoView, empty: &[bool], x: &Vector3<f64>, block: usize) -> bool {
    let camera = view.camera;
    let (w, h) = (camera.width() as usize, camera.height() as usize);
    let Some((u, v, _)) = camera.project(x) else {
        return false;
    };
    if !(u >= 0.0 && v >= 0.0) {
        return false;
    }
    let (bx, by) = (u as usize / block, v as usize / block);
    bx < w / block && by < h / block && empty[by * (w / block) + bx]
}

/// The row-major pixel indices of block `(bx, by)` of an image `width` wide.
fn block_pixels(
    bx: usize,
    by: usize,
    block: usize,
    width: usize,
) -> impl Iterator<Item = usize> + Clone {
    (by * block..(by + 1) * block)
        .flat_map(move |y| (bx * block..(bx + 1) * block).map(move |x| y * width + x))
}

/// How far along the unit `direction` from `origin` the ray leaves the sphere of radius
/// `B_far` around `T`, when it does in front of the origin.
fn exit_distance(c: &Contraction, origin: &Vector3<f64>, direction: &Vector3<f64>) -> Option<f64> {
    let offset = origin - c.center;
    let b = direction.dot(&offset);
    let discriminant = b * b - (offset.norm_squared() - c.b_far * c.b_far);
    if discriminant < 0.0 {
        return None;
    }
    let t = -b + discriminant.sqrt();
    (t > 0.0).then_some(t)
}

/// The mean RGB of `pixels` of `view`'s image.
fn mean_color(view: &StereoView, pixels: impl Iterator<Item = usize>) -> [f32; 3] {
    let image = view.image;
    let c = image.channels;
    let (mut sum, mut n) = ([0.0f32; 3], 0);
    for p in pixels {
        let px = &image.data[p * c..(p + 1) * c];
        for (k, s) in sum.iter_mut().enumerate() {
            *s += px[k.min(c - 1)];
        }
        n += 1;
    }
    sum.map(|s| s / n.max(1) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fewview_geom::contract::ContractionKind;
    use fewview_geom::mesh::Points;
    use fewview_geom::stereo::hierarchy::{Region, RegionCounts};
    use fewview_scene::{Camera, Image, Intrinsics};

    fn cloud(regions: Vec<Option<Region>>, b_far: f64) -> HierarchicalCloud {
        let n = regions.len();
        HierarchicalCloud {
            points: Points::from_positions(Vec::new()),
            regions: Vec::new(),
            sources: Vec::new(),
            counts: RegionCounts::default(),
            contraction: Some(Contraction {
                center: Vector3::zeros(),
                b_near: b_far / 2.0,
                b_far,
                kind: ContractionKind::Paper,
                view: Some(0),
            }),
            pixel_regions: vec![regions],
            pixel_depths: vec![vec![0.0; n]],
            skipped: Vec::new(),
        }
    }

    /// A camera at `T` looking down +z, 64×32 pixels in blocks of 16: the left half holds stereo
    /// points, the right half (sky-blue) does not. The right half's 4 blocks give 4 Gaussians,
    /// each exactly `B_far` from `T` on its block's centre ray, sky-blue, half a block wide at
    /// that distance; a second view looking the same way adds none.
    #[test]
    fn blocks_without_points_become_gaussians_on_the_far_sphere() {
        let camera = Camera::look_at(
            Intrinsics::centered(32.0, 64, 32),
            Vector3::zeros(),
            Vector3::z(),
            -Vector3::y(),
        );
        let mut image = Image::filled(64, 32, &[0.2, 0.2, 0.2]);
        for y in 0..32 {
            for x in 32..64 {
                for (c, v) in [0.4, 0.6, 0.9].into_iter().enumerate() {
                    image.set(x, y, c, v);
                }
            }
        }
        let regions: Vec<Option<Region>> = (0..64 * 32)
            .map(|p| (p % 64 < 32).then_some(Region::Consistent))
            .collect();
        let view = StereoView {
            name: "a",
            camera: &camera,
            image: &image,
            depth_bounds: None,
            mask: None,
            sparse_points: &[],
        };
        let mut twice = cloud(regions.clone(), 10.0);
        twice.pixel_regions.push(regions);
        let shell = sky_shell(&[view, view], &twice, 16).unwrap();
        assert_eq!(shell.positions.len(), 4);
        for ((p, c), s) in shell.positions.iter().zip(&shell.colors).zip(&shell.scales) {
            let x = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            assert!((x.norm() - 10.0).abs() < 1e-4, "{x:?}");
            let (u, v, _) = camera.project(&x).unwrap();
            // Block centres: 8 px plus a multiple of 16.
            let off_centre = |t: f64| ((t - 8.0) / 16.0 - ((t - 8.0) / 16.0).round()).abs();
            assert!(u > 32.0 && off_centre(u) < 1e-4, "{u}");
            assert!(off_centre(v) < 1e-4, "{v}");
            for (got, want) in c.iter().zip([0.4, 0.6, 0.9]) {
                assert!((got - want).abs() < 1e-5, "{c:?}");
            }
            assert!((*s as f64 - 0.5 * 0.5 * 10.0).abs() < 1e-5, "{s}");
        }
    }

    /// A camera off `T` inside the sphere meets it once in front; one outside it and facing
    /// away never does.
    #[test]
    fn rays_leave_the_sphere_in_front_of_the_camera() {
        let c = cloud(Vec::new(), 5.0).contraction.unwrap();
        let inside = Vector3::new(3.0, 0.0, 0.0);
        let t = exit_distance(&c, &inside, &Vector3::x()).unwrap();
        assert!((t - 2.0).abs() < 1e-12);
        let t = exit_distance(&c, &inside, &-Vector3::x()).unwrap();
        assert!((t - 8.0).abs() < 1e-12);
        let outside = Vector3::new(6.0, 0.0, 0.0);
        assert_eq!(exit_distance(&c, &outside, &Vector3::x()), None);
    }
}
