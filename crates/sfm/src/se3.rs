//! Poses as small motions: the exponential map of se(3) the adjustments step through, and the
//! similarity that puts an adjusted set of cameras back where a reference set stands.

use fewview_geom::similarity::umeyama;
use fewview_scene::{Se3, axes_meeting_point};
use nalgebra::{Matrix3, Vector3};

/// The skew-symmetric matrix `[w]ₓ`.
fn skew(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

/// The exponential map of se(3), `ξ = (w, u)` with the rotation part first (BARF's
/// `se3_to_SE3`): `R = exp([w]ₓ)`, `t = V u`, `V = I + (1 − cos θ)/θ² [w]ₓ + (θ − sin θ)/θ³ [w]ₓ²`.
pub fn se3_exp(xi: &[f64; 6]) -> Se3 {
    let w = Vector3::new(xi[0], xi[1], xi[2]);
    let u = Vector3::new(xi[3], xi[4], xi[5]);
    let theta = w.norm();
    let wx = skew(&w);
    let (a, b, c) = if theta < 1e-8 {
        (1.0, 0.5, 1.0 / 6.0)
    } else {
        (
            theta.sin() / theta,
            (1.0 - theta.cos()) / (theta * theta),
            (theta - theta.sin()) / (theta * theta * theta),
        )
    };
    let r = Matrix3::identity() + wx * a + wx * wx * b;
    let v = Matrix3::identity() + wx * b + wx * wx * c;
    Se3::new(r, v * u)
}

/// `refined` moved, as a rigid set, by the similarity that lays it best onto `reference`:
/// Umeyama's least-squares fit of the camera centres and of the points where each camera's
/// axis passes nearest the set's common look-at point. The epipolar constraints fix the
/// cameras relative to each other but not where the set sits in the world, and
/// Levenberg–Marquardt drifts along that similarity, which can move the object partly outside
/// the unit sphere the field lives in, where the joint training cannot fit it. The initial
/// poses, however noisy, look at the object on average; this puts the refined set back where
/// they were. (Anchoring on one view instead, as Alg. 1 does for evaluation, carries that
/// view's own noise to all the others.)
pub fn into_frame_of(refined: &[Se3], reference: &[Se3]) -> Vec<Se3> {
    let landmarks = |poses: &[Se3]| -> Vec<Vector3<f64>> {
        let target = axes_meeting_point(poses);
        let centres: Vec<Vector3<f64>> = poses.iter().map(|p| p.inverse().translation).collect();
        let on_axes = poses.iter().zip(&centres).map(|(p, c)| {
            let forward: Vector3<f64> = p.rotation.row(2).transpose();
            c + forward * (target - c).dot(&forward)
        });
        centres.iter().copied().chain(on_axes).collect()
    };
    let Ok(sim) = umeyama(&landmarks(refined), &landmarks(reference), true) else {
        return refined.to_vec();
    };
    refined.iter().map(|p| sim.apply_to_pose(p)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_of_pure_rotation_and_translation() {
        let e = se3_exp(&[0.0, 0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0]);
        let p = e.transform_point(&Vector3::new(1.0, 0.0, 0.0));
        assert!((p - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-12);
        let e = se3_exp(&[0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
        assert!((e.translation - Vector3::new(1.0, 2.0, 3.0)).norm() < 1e-12);
        // exp(ξ) for a screw motion: compare with the matrix exponential of the 4×4 twist.
        let xi = [0.3, -0.2, 0.5, 0.7, 0.1, -0.4];
        let e = se3_exp(&xi);
        let mut twist = nalgebra::Matrix4::zeros();
        twist
            .fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&skew(&Vector3::new(xi[0], xi[1], xi[2])));
        twist[(0, 3)] = xi[3];
        twist[(1, 3)] = xi[4];
        twist[(2, 3)] = xi[5];
        // Taylor series of exp to convergence.
        let mut term = nalgebra::Matrix4::identity();
        let mut sum = nalgebra::Matrix4::identity();
        for k in 1..30 {
            term = term * twist / k as f64;
            sum += term;
        }
        assert!((e.to_matrix4() - sum).norm() < 1e-12);
    }
}
