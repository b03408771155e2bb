//! A free-viewpoint path around the person: the rig's cameras in order of their angle around
//! the point they look at, joined by SLERP, so that a video of the sequence can circle the
//! person once while the frames play.

use fewview_scene::Camera;
use fewview_scene::camera::{axes_meeting_point, camera_path};
use nalgebra::Vector3;

/// `n` cameras circling the rig once: the rig's cameras sorted by azimuth about their mean up
/// direction (around the point their axes meet), the loop closed, and the path between them
/// sampled evenly. Empty when `n` or `rig` is empty.
pub fn orbit_cameras(rig: &[Camera], n: usize) -> Vec<Camera> {
    if rig.is_empty() || n == 0 {
        return Vec::new();
    }
    let poses: Vec<_> = rig.iter().map(|c| c.world_to_camera).collect();
    let centre = axes_meeting_point(&poses);
    // Image rows run downwards, so a camera's up is minus its y axis (in world coordinates).
    let up: Vector3<f64> = poses
        .iter()
        .map(|p| -p.rotation.row(1).transpose())
        .sum::<Vector3<f64>>()
        .normalize();
    let any = if up.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = up.cross(&any).normalize();
    let e2 = up.cross(&e1);
    let azimuth = |c: &Camera| {
        let d = c.center() - centre;
        d.dot(&e2).atan2(d.dot(&e1))
    };
    let mut keys: Vec<Camera> = rig.to_vec();
    keys.sort_by(|a, b| azimuth(a).total_cmp(&azimuth(b)));
    keys.push(keys[0].clone());
    let per_segment = n.div_ceil(rig.len());
    let mut path = camera_path(&keys, per_segment);
    path.truncate(n);
    path
}

#[cfg(test)]
mod tests {
    use super::*;
    use fewview_scene::Intrinsics;
    use std::f64::consts::{PI, TAU};

    fn ring(count: usize) -> Vec<Camera> {
        (0..count)
            .map(|i| {
                let a = i as f64 / count as f64 * TAU;
                let eye = Vector3::new(3.0 * a.cos(), 3.0 * a.sin(), 1.0);
                let k = Intrinsics::centered(200.0, 64, 64);
                Camera::look_at(k, eye, Vector3::new(0.0, 0.0, 1.0), Vector3::z())
            })
            .collect()
    }

    /// A shuffled ring of 6 cameras is visited in angular order: every 4th of 24 path cameras
    /// is a rig camera, consecutive ones 60° apart, and the path steps evenly in between.
    #[test]
    fn a_shuffled_ring_is_visited_in_angular_order() {
        let rig = ring(6);
        let shuffled: Vec<Camera> = [3, 0, 5, 1, 4, 2].iter().map(|&i| rig[i].clone()).collect();
        let path = orbit_cameras(&shuffled, 24);
        assert_eq!(path.len(), 24);
        let angle = |c: &Camera| c.center().y.atan2(c.center().x);
        let mut steps = Vec::new();
        for (k, cam) in path.iter().enumerate() {
            if k % 4 == 0 {
                let nearest = rig
                    .iter()
                    .map(|r| (r.center() - cam.center()).norm())
                    .fold(f64::INFINITY, f64::min);
                assert!(nearest < 1e-9, "path camera {k} is no rig camera");
            }
            let next = &path[(k + 1) % path.len()];
            let turn = (angle(next) - angle(cam) + PI).rem_euclid(TAU) - PI;
            steps.push(turn.to_degrees());
        }
        // One way round; centres move along chords, not the circle, so the steps are only
        // nearly even (13.9° and 16.1° on a 60° chord in quarters).
        let sign = steps[0].signum();
        for (k, s) in steps.iter().enumerate() {
            assert!((s * sign - 15.0).abs() < 1.2, "step {k}: {s:.2}°");
        }
    }

    #[test]
    fn empty_inputs_give_an_empty_path() {
        assert!(orbit_cameras(&[], 10).is_empty());
        assert!(orbit_cameras(&ring(3), 0).is_empty());
    }
}
