//! Virtual cameras between adjacent training views (the fusion paper, "Splat-based Gradient-domain
//! Fusion for Seamless View Transition"): the views the fusion term renders while training, and
//! the path a transition video follows.

use fewview_geom::stereo::pairs::{OverlapRule, StereoView, stereo_pairs};
use fewview_scene::Camera;
use rand::{Rng, RngExt};

use crate::error::FusionError;

/// Two adjacent training views (indices into the run's training views, in baseline order).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Neighbours {
    pub first: usize,
    pub second: usize,
}

/// A virtual camera `t` of the way from `neighbours.first` to `neighbours.second`.
#[derive(Clone, Debug)]
pub struct VirtualView {
    pub neighbours: Neighbours,
    pub t: f64,
    pub camera: Camera,
}

/// The range of `t` virtual cameras are drawn from: away from the training views themselves,
/// where the photometric loss already decides every pixel.
pub const T_RANGE: (f64, f64) = (0.2, 0.8);

/// The camera a fraction `t ∈ [0, 1]` of the way from `a` to `b`: centre by linear
/// interpolation, rotation by SLERP, and the intrinsics (and image size) of the nearer view, so
/// that the virtual image has the resolution of the photo it is compared with.
pub fn virtual_camera(a: &Camera, b: &Camera, t: f64) -> Camera {
    let nearer = if t <= 0.5 { a } else { b };
    Camera::new(nearer.intrinsics, a.interpolate(b, t).world_to_camera)
}

/// The adjacent pairs of the training views: consecutive views along their baseline and the
/// two ends when they overlap, or, for a rig around an object, each view with its nearest
/// overlapping view (the stereo start's pairs, [`stereo_pairs`]). Views that share nothing are
/// an error naming them.
pub fn adjacent_pairs(views: &[StereoView]) -> Result<Vec<Neighbours>, FusionError> {
    let pairs = stereo_pairs(views, &OverlapRule::default())?;
    Ok(pairs
        .into_iter()
        .map(|(first, second)| Neighbours { first, second })
        .collect())
}

/// Draws a virtual view: a pair uniformly, then `t ~ U(0.2, 0.8)`.
pub fn sample_virtual(
    cameras: &[Camera],
    pairs: &[Neighbours],
    rng: &mut impl Rng,
) -> Option<VirtualView> {
    if pairs.is_empty() {
        return None;
    }
    let neighbours = pairs[rng.random_range(0..pairs.len())];
    let t = rng.random_range(T_RANGE.0..T_RANGE.1);
    let camera = virtual_camera(&cameras[neighbours.first], &cameras[neighbours.second], t);
    Some(VirtualView {
        neighbours,
        t,
        camera,
    })
}

#[cfg(test)]
mod tests {
    use fewview_scene::Intrinsics;
    use nalgebra::Vector3;
    use rand::SeedableRng;
    use rand::rngs::StdRng;

    use super::*;

    fn cameras() -> (Camera, Camera) {
        let a = Camera::look_at(
            Intrinsics::centered(100.0, 64, 48),
            Vector3::new(-1.0, -4.0, 1.0),
            Vector3::zeros(),
            Vector3::z(),
        );
        let b = Camera::look_at(
            Intrinsics::centered(120.0, 64, 48),
            Vector3::new(1.5, -3.5, 1.4),
            Vector3::new(0.2, 0.1, 0.0),
            Vector3::z(),
        );
        (a, b)
    }

    fn pose_difference(a: &Camera, b: &Camera) -> f64 {
        let m = a.world_to_camera.to_matrix4() - b.world_to_camera.to_matrix4();
        m.abs().max()
    }

    #[test]
    fn virtual_cameras_at_the_ends_are_the_training_cameras() {
        let (a, b) = cameras();
        let v0 = virtual_camera(&a, &b, 0.0);
        let v1 = virtual_camera(&a, &b, 1.0);
        assert!(pose_difference(&v0, &a) < 1e-12);
        assert!(pose_difference(&v1, &b) < 1e-12);
        assert_eq!(v0.intrinsics, a.intrinsics);
        assert_eq!(v1.intrinsics, b.intrinsics);
    }

    #[test]
    fn the_centre_moves_linearly_and_the_intrinsics_are_the_nearer_views() {
        let (a, b) = cameras();
        for t in [0.2, 0.45, 0.55, 0.8] {
            let v = virtual_camera(&a, &b, t);
            let want = a.center() * (1.0 - t) + b.center() * t;
            assert!((v.center() - want).norm() < 1e-12);
            let nearer = if t < 0.5 { &a } else { &b };
            assert_eq!(v.intrinsics, nearer.intrinsics);
            // The rotation angle from a grows linearly with t (SLERP).
            let qa = a.world_to_camera.quaternion();
            let qb = b.world_to_camera.quaternion();
            let qv = v.world_to_camera.quaternion();
            let total = qa.angle_to(&qb);
            assert!((qa.angle_to(&qv) - t * total).abs() < 1e-9);
        }
    }

    #[test]
    fn sampled_views_lie_in_the_open_range() {
        let (a, b) = cameras();
        let pairs = [Neighbours {
            first: 0,
            second: 1,
        }];
        let mut rng = StdRng::seed_from_u64(3);
        for _ in 0..200 {
            let v = sample_virtual(&[a.clone(), b.clone()], &pairs, &mut rng).unwrap();
            assert!(v.t >= T_RANGE.0 && v.t < T_RANGE.1);
        }
        assert!(sample_virtual(&[a, b], &[], &mut rng).is_none());
    }
}
