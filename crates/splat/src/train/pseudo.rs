//! Pseudo views: cameras between the training cameras, where sparse-view regularisers look at
//! what no photo shows. CoR-GS's co-regularisation ([`super::pair`]) and the stereo depth seen
//! from between the views ([`crate::pseudo_depth`]) draw the same ones.

use fewview_scene::Camera;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

/// The pseudo view of `iteration` among `cameras`: a training camera drawn at random, its
/// nearest other, and a random point between them (rotations by SLERP; the fusion module's
/// virtual views). The same `seed` and iteration give the same camera; `None` with fewer than
/// two cameras.
///
/// CoR-GS perturbs a training camera's position by Gaussian noise and averages two rotations;
/// at a few views that stays as close to the training cameras as this does.
pub fn pseudo_camera(cameras: &[Camera], seed: u64, iteration: usize) -> Option<Camera> {
    if cameras.len() < 2 {
        return None;
    }
    let mut rng = StdRng::seed_from_u64(seed ^ (iteration as u64).rotate_left(17));
    let i = rng.random_range(0..cameras.len());
    let c = cameras[i].center();
    let j = (0..cameras.len())
        .filter(|&j| j != i)
        .min_by(|&a, &b| {
            let d = |k: usize| (cameras[k].center() - c).norm();
            d(a).total_cmp(&d(b))
        })
        .expect("two cameras");
    Some(cameras[i].interpolate(&cameras[j], rng.random::<f64>()))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use fewview_scene::{Intrinsics, Se3};
    use nalgebra::{Matrix3, Vector3};

    /// A 64×48 camera of focal length `focal` (pixels) at `x` on the x axis, looking down +z.
    pub(crate) fn camera_on_x_axis(x: f64, focal: f64) -> Camera {
        let k = Intrinsics {
            fx: focal,
            fy: focal,
            cx: 32.0,
            cy: 24.0,
            width: 64,
            height: 48,
        };
        Camera::new(k, Se3::new(Matrix3::identity(), Vector3::new(-x, 0.0, 0.0)))
    }

    fn camera_at(x: f64) -> Camera {
        camera_on_x_axis(x, 50.0)
    }

    /// Each pseudo view lies between a camera and its nearest other: with cameras at 0, 1, 10
    /// and 11 on a line, none falls in the gap between 1 and 10, and both pairs are drawn.
    #[test]
    fn pseudo_views_lie_between_nearest_neighbours() {
        let cams = [0.0, 1.0, 10.0, 11.0].map(camera_at);
        let (mut near, mut far) = (0, 0);
        for it in 1..200 {
            let c = pseudo_camera(&cams, 7, it).unwrap().center();
            assert!(c.y.abs() < 1e-12 && c.z.abs() < 1e-12);
            match c.x {
                x if (0.0..=1.0).contains(&x) => near += 1,
                x if (10.0..=11.0).contains(&x) => far += 1,
                x => panic!("iteration {it}: a pseudo view at {x}"),
            }
            assert_eq!(pseudo_camera(&cams, 7, it).unwrap().center(), c);
        }
        assert!(near > 50 && far > 50, "{near} / {far}");
        assert!(pseudo_camera(&cams[..1], 7, 1).is_none());
    }
}
